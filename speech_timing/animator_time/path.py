"""Path: the piecewise-linear future of ``t_A`` on the clock, with exact crossing times."""

from __future__ import annotations

import bisect
import math

__all__ = ["Path"]


class Path:
    """A continuous, piecewise-linear, non-decreasing function of time: the future of ``t_A``.

    It starts at time ``t`` at position ``p`` moving at ``rate``; :meth:`then` appends a change of
    rate. Before the first breakpoint the first segment is extended backwards.

    Parameters
    ----------
    t : float
        Start time (s).
    p : float
        Position at ``t`` (s of speech).
    rate : float
        Rate (speech seconds per clock second, at least 0) from ``t`` on.
    """

    __slots__ = ("times", "positions", "rates")

    def __init__(self, t: float, p: float, rate: float) -> None:
        if rate < 0:
            raise ValueError("a path may not run backwards")
        self.times = [float(t)]
        self.positions = [float(p)]
        self.rates = [float(rate)]

    def then(self, t: float, rate: float) -> "Path":
        """From time ``t`` (not before the last breakpoint) on, move at ``rate``; returns ``self``."""
        if rate < 0:
            raise ValueError("a path may not run backwards")
        if t < self.times[-1]:
            raise ValueError("breakpoints must be added in time order")
        if math.isinf(t):
            return self
        if t == self.times[-1]:
            self.rates[-1] = float(rate)
            return self
        self.positions.append(self.at(t))
        self.times.append(float(t))
        self.rates.append(float(rate))
        return self

    def _segment(self, t: float) -> int:
        return max(bisect.bisect_right(self.times, t) - 1, 0)

    def at(self, t: float) -> float:
        """Position at time ``t``."""
        i = self._segment(t)
        return self.positions[i] + self.rates[i] * (t - self.times[i])

    def rate_at(self, t: float) -> float:
        """Rate at time ``t`` (of the segment that starts at or before ``t``)."""
        return self.rates[self._segment(t)]

    def until(self, t: float, rate: float) -> "Path":
        """This path up to time ``t`` (not before its start), then at ``rate``; returns ``self``."""
        i = self._segment(t)
        p = self.at(t)
        del self.times[i + 1:], self.positions[i + 1:], self.rates[i + 1:]
        if t <= self.times[0]:
            self.positions[0], self.times[0], self.rates[0] = p, float(t), float(rate)
            return self
        return self.then(t, rate)

    def end(self) -> tuple[float, float, float]:
        """``(time, position, rate)`` of the last breakpoint."""
        return self.times[-1], self.positions[-1], self.rates[-1]

    def crossing(self, s: float, now: float) -> float:
        """Earliest time ``>= now`` at which the position reaches ``s`` (``math.inf`` if never)."""
        i = self._segment(now)
        p = self.at(now)
        if p >= s:
            return now
        t = now
        # positions never decrease: the first breakpoint after ``now`` at or past ``s`` ends the segment the
        # crossing is in (a binary search, not a scan: a long speech's path has a breakpoint per word)
        k = bisect.bisect_left(self.positions, s, i + 1)
        for j in range(max(i, k - 1), len(self.times)):
            start = t if j == i else self.times[j]
            p_start = p if j == i else self.positions[j]
            stop = self.times[j + 1] if j + 1 < len(self.times) else math.inf
            rate = self.rates[j]
            if rate > 0:
                hit = start + (s - p_start) / rate
                if hit <= stop:
                    return max(hit, now)
        return math.inf
