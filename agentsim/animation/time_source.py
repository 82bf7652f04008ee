"""The time a driver is advanced by: the clock, or animator time that follows the speech (TimeSource)."""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np


class TimeSource:
    """The time a driver is advanced by, as a function of clock time (vectorised).

    By default it is the clock itself. Given matching ``clock`` and ``driver`` times it maps clock time
    piecewise linearly onto driver time (slope 1 outside the given points). This is Chang's *animator
    time* t_A: a gesture pegged to speech is advanced by the time the speech is known to have reached
    (from phoneme or word events) instead of by the clock, so it stays on the syllable when the speech
    runs early or late.
    """

    def __init__(self, clock: Sequence[float] | None = None, driver: Sequence[float] | None = None):
        self._function: Callable[[float], float] | None = None
        if (clock is None) != (driver is None):
            raise ValueError("give both clock and driver times, or neither")
        if clock is None:
            self.clock = self.driver = None
        else:
            c = np.asarray(clock, dtype=float)
            d = np.asarray(driver, dtype=float)
            if c.shape != d.shape or c.ndim != 1 or len(c) == 0:
                raise ValueError("clock and driver times must be 1-d arrays of one length")
            if np.any(np.diff(c) < 0) or np.any(np.diff(d) < 0):
                raise ValueError("clock and driver times must not decrease")
            self.clock, self.driver = c, d

    @classmethod
    def from_events(cls, event_times: Sequence[float], estimated_times: Sequence[float],
                    naive: bool = False) -> "TimeSource":
        """Animator time from speech events: the event for unit i (a syllable or word) arrived at clock
        time ``event_times[i]`` and was estimated to happen at ``estimated_times[i]``.

        ``naive=True`` gives Chang's first formula t_A = min(dt + T_i, T_(i+1)): after an event the
        animator time runs with the clock but waits at the next estimated time until the next event
        arrives (it "sticks"). By default it is interpolated linearly between events instead.
        """
        ev = np.asarray(event_times, dtype=float)
        est = np.asarray(estimated_times, dtype=float)
        if not naive:
            return cls(ev, est)
        clock: list[float] = []
        drv: list[float] = []
        for i in range(len(ev)):
            clock.append(ev[i])
            drv.append(est[i])
            if i + 1 < len(ev):
                reach = est[i + 1] - est[i]
                stop = min(ev[i] + reach, ev[i + 1])
                clock.append(stop)
                drv.append(est[i] + (stop - ev[i]))
        return cls(clock, drv)

    @classmethod
    def from_function(cls, function: Callable[[float], float]) -> "TimeSource":
        """Driver time from any non-decreasing function of clock time, such as the ``position`` method of
        an animator time strategy in :mod:`speech_timing.animator_time` after its events are in."""
        source = cls()
        source._function = function
        source.clock = np.zeros(0)  # not the clock
        return source

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if self._function is not None:
            return np.vectorize(self._function, otypes=[float])(t) if t.size else t
        if self.clock is None:
            return t
        c, d = self.clock, self.driver
        out = np.interp(t, c, d)
        out = np.where(t < c[0], d[0] + (t - c[0]), out)
        return np.where(t > c[-1], d[-1] + (t - c[-1]), out)

    def inverse(self, tau: float) -> float:
        """The first clock time at which the driver time reaches ``tau``."""
        if self.clock is None or not math.isfinite(tau):
            return tau
        if self._function is not None:  # bisection on a non-decreasing function
            f = self._function
            lo, hi = tau - 1.0, tau + 1.0
            while f(lo) >= tau and lo > tau - 1e6:
                lo -= 2 * (hi - lo)
            while f(hi) < tau and hi < tau + 1e6:
                hi += 2 * (hi - lo)
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if f(mid) < tau else (lo, mid)
            return hi
        c, d = self.clock, self.driver
        if tau <= d[0]:
            return float(c[0] + (tau - d[0]))
        if tau > d[-1]:
            return float(c[-1] + (tau - d[-1]))
        k = int(np.searchsorted(d, tau, side="left"))
        if d[k] == d[k - 1]:
            return float(c[k - 1])
        return float(c[k - 1] + (tau - d[k - 1]) * (c[k] - c[k - 1]) / (d[k] - d[k - 1]))

    def __repr__(self) -> str:
        if self._function is not None:
            return f"TimeSource({self._function!r})"
        return "TimeSource(clock)" if self.clock is None else f"TimeSource({len(self.clock)} points)"


#: The clock: drivers are advanced by clock time unless given another TimeSource.
CLOCK = TimeSource()
