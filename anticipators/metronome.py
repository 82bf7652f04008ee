"""The metronome anticipator: beats at a tempo and phase that can be changed while a plan is playing."""

from __future__ import annotations

import math
import re

from agentsim.core.anticipator import Anticipator

#: beats are numbered up to 999,999,999 (a day at 10,000 BPM is 14.4 million)
_BEAT = re.compile(r"^beat(\d{1,9})$")


class Metronome(Anticipator):
    """Predicts ``beat1``, ``beat2``, ... at ``start + (n - 1) * 60 / bpm`` seconds.

    :meth:`set_tempo` and :meth:`set_phase` re-space the beats from the change on; beats already passed
    keep their times. A tempo change keeps the phase continuous: if 60 % of the current beat had elapsed
    at the change, the next beat comes after the remaining 40 % of the new period.
    """

    def __init__(self, anticipator_id: str = "metronome", bpm: float = 120.0, start: float = 0.0):
        super().__init__(anticipator_id)
        if not bpm > 0:
            raise ValueError(f"tempo must be positive, got {bpm!r} BPM")
        if not math.isfinite(bpm):
            raise ValueError(f"tempo must be finite, got {bpm!r} BPM")
        if not math.isfinite(start):
            raise ValueError(f"the first beat must be at a finite time, got {start!r}")
        self.period = 60.0 / bpm
        # beat ``origin_beat`` is at time ``origin``; later beats follow every ``period`` seconds
        self.origin = start
        self.origin_beat = 1

    @property
    def bpm(self) -> float:
        return 60.0 / self.period

    def beat_time(self, n: int) -> float:
        return self.origin + (n - self.origin_beat) * self.period

    def make_peg(self, sync_id: str):
        match = _BEAT.match(sync_id)
        if not match or int(match.group(1)) < 1:
            return False
        return self.beat_time(int(match.group(1)))

    def _now(self, at: float | None) -> float:
        if at is not None:
            return at
        return self.env.now if self.env is not None else self.origin

    def last_beat_before(self, t: float) -> int:
        """Number of the last beat at or before ``t`` (0 if none)."""
        n = int((t - self.origin) // self.period) + self.origin_beat
        while n >= 1 and self.beat_time(n + 1) <= t:
            n += 1
        return max(0, n if self.beat_time(n) <= t else n - 1)

    def set_tempo(self, bpm: float, at: float | None = None) -> None:
        """Change the tempo at time ``at`` (default: now): beats after it are re-spaced, earlier ones stay."""
        if not (bpm > 0 and math.isfinite(bpm)):
            raise ValueError(f"tempo must be positive and finite, got {bpm!r} BPM")
        t = self._now(at)
        last = self.last_beat_before(t)
        nxt = last + 1
        new_period = 60.0 / bpm
        if last >= 1:
            elapsed = (t - self.beat_time(last)) / self.period
            self.origin = t + (1.0 - elapsed) * new_period
        else:
            self.origin = max(t, self.beat_time(1)) if t <= self.beat_time(1) else t
        self.origin_beat = nxt
        self.period = new_period
        self._update(last)

    def set_phase(self, next_beat_time: float, at: float | None = None) -> None:
        """Move the next beat after ``at`` (default: now) to ``next_beat_time``; later beats follow it."""
        if not math.isfinite(next_beat_time):
            raise ValueError(f"the next beat must be at a finite time, got {next_beat_time!r}")
        t = self._now(at)
        nxt = self.last_beat_before(t) + 1
        self.origin, self.origin_beat = next_beat_time, nxt
        self._update(nxt - 1)

    def _update(self, last_passed: int) -> None:
        for sync_id, peg in self.pegs.items():
            n = int(sync_id[4:])
            if n > last_passed:
                peg.set(self.beat_time(n))
