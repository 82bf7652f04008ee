"""The tap-tempo anticipator: beats predicted from taps (a file, a generator, or the keyboard)."""

from __future__ import annotations

import queue
import re
import statistics
import sys
import threading
from pathlib import Path
from typing import Iterable

from agentsim.core.anticipator import Anticipator

_BEAT = re.compile(r"^beat(\d{1,9})$")


def read_taps(path: str | Path) -> list[float]:
    """Tap times from a text file: one time in seconds per line (blank lines and # comments ignored)."""
    from agentsim.core.inputs import read_text
    from agentsim.errors import UsageError

    path = Path(path)
    if not path.is_file():  # an input the command line names: a usage error, as every missing input
        raise UsageError(f"no tap file {str(path)!r}")
    times = []
    # past 8 MB it is refused unread (TooLarge, a usage error: exit status 2)
    text = read_text(path, what=f"the tap file {str(path)!r}", errors="replace")
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if line:
            try:
                times.append(float(line))
            except ValueError:
                raise ValueError(f"{path}:{number}: expected a tap time in seconds, got {line!r}") from None
    return times


class TapTempo(Anticipator):
    """Predicts ``beat1``, ``beat2``, ... from taps: the period is the median of recent inter-tap
    intervals, each divided by the number of beats it spans, so a missed tap (an interval of about two
    periods) counts as two beats and a doubled tap (an interval well under half a period) is ignored.

    Parameters
    ----------
    taps : iterable of float, or a path, optional
        Tap times in seconds (simulated time), or a text file of them (one per line). Each is perceived
        at its time by :meth:`run`.
    initial_bpm : float
        Tempo assumed before two taps have been heard.
    window : int
        Number of recent intervals the period is estimated from.
    start : float
        Before the first tap, beats are predicted at ``initial_bpm`` from this time (confidence 0).
    keyboard : bool
        In real-time mode, also take a tap from every line typed on standard input (press Enter).
    """

    def __init__(self, anticipator_id: str = "tap", taps: Iterable[float] | str | Path = (),
                 initial_bpm: float = 120.0, window: int = 8, start: float = 0.0, keyboard: bool = False):
        super().__init__(anticipator_id)
        if isinstance(taps, (str, Path)):
            taps = read_taps(taps)
        if not initial_bpm > 0:
            raise ValueError(f"tempo must be positive, got {initial_bpm!r} BPM")
        self.taps = list(taps)
        self.period = 60.0 / initial_bpm
        self.window = int(window)
        self.start = start
        self.intervals: list[float] = []
        self.beat_times: dict[int, float] = {}  # beat number -> time of the tap that marked it
        self.last_beat = 0
        self.confidence = 0.0
        self._queue: queue.Queue[float] | None = None
        if keyboard and str(keyboard).lower() not in ("0", "0.0", "false", "no"):
            self.listen_keyboard()

    def predicted(self, n: int) -> float | None:
        """Time of beat ``n``: the tap that marked it, or a prediction from the last beat and the period."""
        if n in self.beat_times:
            return self.beat_times[n]
        if self.last_beat == 0:
            return self.start + (n - 1) * self.period
        return self.beat_times[self.last_beat] + (n - self.last_beat) * self.period

    def make_peg(self, sync_id: str):
        match = _BEAT.match(sync_id)
        if not match or int(match.group(1)) < 1:
            return False
        return self.predicted(int(match.group(1)))

    def tap(self, t: float) -> None:
        """Perceive one tap at time ``t`` and move the pegs of beats not yet tapped."""
        if self.last_beat == 0:
            self.beat_times[1] = t
            self.last_beat = 1
        else:
            interval = t - self.beat_times[self.last_beat]
            # Until taps have given a period, any interval longer than a 400 BPM beat is one beat.
            beats = round(interval / self.period) if self.intervals else int(interval >= 0.15)
            if beats < 1:  # a doubled tap: too soon to be the next beat
                return
            self.intervals = (self.intervals + [interval / beats])[-self.window:]
            self.period = statistics.median(self.intervals)
            self.last_beat += beats
            self.beat_times[self.last_beat] = t
            spread = (max(self.intervals) - min(self.intervals)) / self.period if len(self.intervals) > 1 else 1
            self.confidence = max(0.0, min(1.0, (len(self.intervals) / 4.0) * (1.0 - spread)))
        for sync_id, peg in self.pegs.items():
            n = int(sync_id[4:])
            if n > self.last_beat or n in self.beat_times:
                peg.set(self.predicted(n))

    def run(self):
        if not self.taps and self._queue is None:
            return None
        return self._perceive()

    def _perceive(self):
        env = self.env
        for t in sorted(self.taps):
            if t > env.now:
                yield env.timeout(t - env.now)
            self.tap(env.now)
        while self._queue is not None:
            yield env.timeout(0.005)
            while not self._queue.empty():
                self._queue.get_nowait()
                self.tap(env.now)

    def listen_keyboard(self, stream=None) -> None:
        """In real-time mode: every line typed (Enter) is a tap at the moment it arrives."""
        self._queue = queue.Queue()
        stream = stream or sys.stdin

        def read():
            for _ in stream:
                self._queue.put(0.0)

        threading.Thread(target=read, daemon=True).start()
