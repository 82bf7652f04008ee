"""The repetition anticipator: a person's next repetitions of an exercise, predicted from a motion signal.

It listens causally to three-axis acceleration with gravity included, as a phone's or a wrist band's sensor
reports it (``DeviceMotionEvent.accelerationIncludingGravity``: at rest it reads gravity's reaction, pointing
up), or to one coordinate of a tracked point (its height), at 10-200 Hz. A repetition's *key point* is the
lowest point of the movement along the recording's mean gravity direction (the bottom of a squat): where the
upward acceleration is largest, or the coordinate smallest. Between two lowest points the body must rise and
come down again, so the acceleration turns downward between them; a dip that stays at rest (the still bottom
between lowering the weight and lifting it again, which makes two upward bumps of one repetition) does not
part two repetitions: of the bumps it joins, the key point is the largest.

Pegs: ``repN`` at the N-th repetition's key point (as found once it has passed, as predicted before), and a
rolling window ``next1``, ``next2``, ... of the upcoming ones. Nothing is predicted before the second
repetition; from then on it commits however unsure. The tempo is the mean of the last three intervals
between repetitions, so two repetitions at a new tempo re-lock it; a pause (no repetition for well past the
predicted one) keeps the next prediction just ahead of the clock until the person restarts. The restart is
sensed before its key point is found: the first bump after the pause that rises as far above rest as a key
point must (:data:`TOP_SHARE` of the swing) is the body slowing into the bottom of a repetition.
"""

from __future__ import annotations

import math
import queue
import re
from collections import deque
from pathlib import Path

import numpy as np

from agentsim.core.anticipator import PAST_TOLERANCE, Anticipator
from agentsim.errors import UsageError

_REP = re.compile(r"^rep(\d{1,9})$")
_NEXT = re.compile(r"^next(\d{1,4})$")

#: Sample rates accepted (Hz), with 2 % of slack for a sensor's jitter.
MIN_RATE, MAX_RATE = 10.0, 200.0
#: Cut-off of the smoothing the detection looks at (Hz) and the slow baseline's time constant (s).
SMOOTH_HZ, BASELINE_S, GRAVITY_S = 1.6, 2.5, 30.0
#: Shortest interval between two repetitions (s) and the share of the period that two may not be closer than.
MIN_INTERVAL, MIN_SHARE = 0.6, 0.45
#: An interval longer than this many periods is a pause: it does not count towards the tempo.
PAUSE_PERIODS = 1.6
#: Seconds of signal heard before the first repetition may be found (the averages settle).
WARM_UP = 0.4
#: The share of the swing a key point must lie above rest (the baseline), and a top of the movement below it.
#: A way of the movement taking r times as long as the other accelerates 1/r² as hard (a raised cosine of depth d
#: over T s peaks at d(π/T)²/2), so a top lies at least 1/(1 + r²) of the swing below rest: a fifth when the
#: slower way takes twice as long as the quicker, as strength training's slow lowering does.
TOP_SHARE = 0.2
#: How far ahead of the clock the next prediction is held while the person pauses (s).
HOLD_LEAD = 0.1


class RepetitionTracker:
    """The causal part: samples in, repetitions found and predicted out (no clock, no pegs).

    ``push(times, samples)`` takes samples of shape (n, 3) (acceleration) or (n,) / (n, 1) (a coordinate);
    :attr:`repetitions` are the key points found, :meth:`predict` the next ones, :attr:`updates` every change
    of the predictions as ``(t, [next1, next2, ...])``, :attr:`restart` when a person who paused was sensed
    slowing into the bottom of a repetition again (None until then, and again once that repetition is found).
    """

    def __init__(self, horizon: int = 8):
        self.horizon = int(horizon)
        self.repetitions: list[float] = []
        self.intervals: list[float] = []
        self.updates: list[tuple[float, list[float]]] = []
        self.time = -math.inf
        self._started = False
        self._recent: deque = deque()  # (t, value) of the last seconds, to time a peak once it is confirmed
        self._held: float | None = None  # the next prediction while a pause holds it ahead of the clock
        self._predicted: list[float] = []
        self._segment = 0  # the first repetition after the last pause
        self.restart: float | None = None  # when the bottom of the first repetition after a pause was sensed

    # ------------------------------------------------------------------ the signal
    def _start(self, t: float, sample: np.ndarray) -> None:
        self._started = True
        self._gravity = sample.astype(float).copy()
        self._gravity_n = 1
        self._baseline = None
        self._low1 = self._low2 = 0.0
        self._power = 0.0
        self._amplitude = 0.0
        self._seeking_peak = True
        self._topped = True  # a top of the movement since the last key point (else the next bump is of its repetition)
        self._peak_value = -math.inf  # the last key point's value in the smoothed signal
        self._undo: tuple[int, bool] = (0, False)  # before the last key point: the segment, and whether it added an interval
        self._extreme = -math.inf
        self._extreme_t = t
        self._last_t = t
        scale = float(np.linalg.norm(sample)) if sample.size == 3 else 0.0
        self._floor = 0.04 * scale if scale > 0 else 0.0
        self._warm_until = t + WARM_UP

    def _value(self, t: float, sample: np.ndarray, dt: float) -> float:
        """The signal whose maxima are key points: upward acceleration, or the coordinate turned over."""
        if sample.size == 3:
            self._gravity_n += 1  # the mean of the first samples, then a slow average
            self._gravity += (sample - self._gravity) * max(1.0 / self._gravity_n, min(1.0, dt / GRAVITY_S))
            g = float(np.linalg.norm(self._gravity))
            return float(sample @ self._gravity) / g - g if g > 0 else 0.0
        return -float(sample[0])

    def push(self, times, samples) -> None:
        """Hear samples (their times in seconds, increasing) and update repetitions and predictions."""
        times = np.asarray(times, float).reshape(-1)
        samples = np.asarray(samples, float)
        samples = samples.reshape(len(times), -1)
        for t, sample in zip(times.tolist(), samples):
            self._sample(t, sample)
        if len(times):
            self.time = float(times[-1])
            self._hold()

    def _sample(self, t: float, sample: np.ndarray) -> None:
        if not self._started:
            self._start(t, sample)
        dt = max(t - self._last_t, 1e-6)
        self._last_t = t
        raw = self._value(t, sample, dt)
        if self._baseline is None:
            self._baseline = raw
        self._baseline += (raw - self._baseline) * min(1.0, dt / BASELINE_S)
        x = raw - self._baseline
        a = 1.0 - math.exp(-2.0 * math.pi * SMOOTH_HZ * dt)
        self._low1 += (x - self._low1) * a
        self._low2 += (self._low1 - self._low2) * a
        y = self._low2
        self._power += (y * y - self._power) * min(1.0, dt / 3.0)
        self._recent.append((t, raw))
        while self._recent and self._recent[0][0] < t - 4.0:
            self._recent.popleft()
        hysteresis = max(0.35 * self._amplitude, 0.6 * math.sqrt(self._power), self._floor, 1e-12)
        if self._held is not None and self.restart is None and y > TOP_SHARE * self._amplitude:
            self.restart = t  # paused, and slowing into a bottom again: the key point is at hand
        if t < self._warm_until:  # the averages settle: no extreme counts yet, and a trough comes first
            self._seeking_peak, self._extreme, self._extreme_t = False, y, t
            return
        if self._seeking_peak:
            if y > self._extreme:
                self._extreme, self._extreme_t = y, t
            elif y < self._extreme - hysteresis:
                if self._extreme > TOP_SHARE * self._amplitude:
                    self._peak(self._extreme, self._extreme_t, t)
                self._seeking_peak, self._extreme, self._extreme_t = False, y, t
        else:
            if y < self._extreme:
                self._extreme, self._extreme_t = y, t
            elif y > self._extreme + hysteresis:
                # a top of the movement lies well below rest (TOP_SHARE); a shallower dip, a pause at the bottom,
                # joins the bumps on either side into one repetition
                if self._extreme <= -TOP_SHARE * self._amplitude:
                    self._trough, self._topped = self._extreme, True
                self._seeking_peak, self._extreme, self._extreme_t = True, y, t

    def _peak(self, value: float, t_smooth: float, now: float) -> None:
        """A maximum of the smoothed signal confirmed at ``now``: time it on the signal itself, and keep it (or,
        when no top of the movement parts it from the last key point, keep the larger of the two)."""
        joined = not self._topped and bool(self.repetitions)
        if joined and value <= self._peak_value:
            return
        trough = getattr(self, "_trough", None)
        if trough is not None and not joined:
            swing = value - trough
            self._amplitude = swing if self._amplitude == 0 else self._amplitude + 0.3 * (swing - self._amplitude)
        delay = 2.0 / (2.0 * math.pi * SMOOTH_HZ)  # the two averages' delay at low frequencies
        period = self.period
        half = 0.25 * period if period else 0.3
        centre = t_smooth - delay
        window = [(ti, xi) for ti, xi in self._recent if centre - half <= ti <= centre + half]
        t_key = centre
        if len(window) >= 3:
            ts = np.array([w[0] for w in window])
            xs = np.array([w[1] for w in window])
            k = max(1, int(round(0.2 / max(float(np.median(np.diff(ts))), 1e-6))))
            smooth = np.convolve(xs, np.ones(k) / k, mode="same") if 1 < k < len(xs) else xs
            top = float(ts[int(np.argmax(smooth))])
            reach = 0.15 * period if period else 0.25
            near = np.abs(ts - top) <= reach
            t_key = top
            if near.sum() >= 3:  # the vertex of a parabola fitted to the top of the peak
                a, b, _ = np.polyfit(ts[near] - top, xs[near], 2)
                if a < 0:
                    t_key = top + float(np.clip(-b / (2 * a), -reach, reach))
        t_key = min(t_key, now)
        if joined:  # the same repetition's larger bump: it replaces the key point found
            self._segment, counted = self._undo
            self.repetitions.pop()
            if counted:
                self.intervals.pop()
            period = self.period
        undo = (self._segment, False)
        if self.repetitions:
            gap = t_key - self.repetitions[-1]
            shortest = max(MIN_INTERVAL, MIN_SHARE * period) if period else MIN_INTERVAL
            if gap < shortest and not joined:
                self._topped = True  # a second bump by its timing: the next one is timed afresh
                return  # a second bump of the same repetition
            if period is None or gap <= PAUSE_PERIODS * period:
                self.intervals.append(gap)
                undo = (self._segment, True)
            else:
                self._segment = len(self.repetitions)  # a restart: the phase is carried from here on
        self._undo, self._peak_value, self._topped = undo, value, False
        self.repetitions.append(t_key)
        self._held = None
        self.restart = None
        self._announce(now)

    # ------------------------------------------------------------------ predictions
    @property
    def period(self) -> float | None:
        """The tempo as seconds between repetitions: the mean of the last three intervals (None before two
        repetitions)."""
        if not self.intervals:
            return None
        return float(np.mean(self.intervals[-3:]))

    @property
    def tempo_per_minute(self) -> float | None:
        return None if self.period is None else 60.0 / self.period

    def predict(self, k: int | None = None) -> list[float]:
        """The next ``k`` (default: the horizon) key points predicted (empty before two repetitions)."""
        return list(self._predicted[: self.horizon if k is None else k])

    def _compute(self) -> list[float]:
        period = self.period
        if period is None:
            return []
        recent = self.repetitions[max(self._segment, len(self.repetitions) - 2):][::-1]  # the last key points, each carried on by the period
        weights = (0.6, 0.4)[: len(recent)]
        first = sum(w * (r + (j + 1) * period) for j, (w, r) in enumerate(zip(weights, recent))) / sum(weights)
        if self._held is not None:
            first = self._held
        return [first + i * period for i in range(self.horizon)]

    def _announce(self, now: float) -> None:
        predicted = self._compute()
        if predicted != self._predicted:
            self._predicted = predicted
            self.updates.append((now, list(predicted)))

    def _hold(self) -> None:
        """While the person pauses (no repetition by :data:`PAUSE_PERIODS` periods after the last), keep the
        next key point just ahead of the clock."""
        period = self.period
        if period is None or not self._predicted:
            return
        if self.time > self.repetitions[-1] + period * PAUSE_PERIODS:
            self._held = self.time + HOLD_LEAD
            self._announce(self.time)

    def key_point(self, n: int) -> float | None:
        """The ``n``-th repetition's key point (from 1): as found, or as predicted (None before two)."""
        if n <= len(self.repetitions):
            return self.repetitions[n - 1]
        ahead = n - len(self.repetitions)
        if not self._predicted:
            return None
        if ahead <= len(self._predicted):
            return self._predicted[ahead - 1]
        return self._predicted[-1] + (ahead - len(self._predicted)) * (self.period or 0.0)


class RepetitionAnticipator(Anticipator):
    """Predicts a person's repetitions from a motion signal (see the module's description).

    Parameters
    ----------
    anticipator_id : str
        The id BML uses: ``anticipators:<id>:rep3``, ``anticipators:<id>:next1``.
    source : str or Path, optional
        A recording (CSV, :func:`read_motion`) heard at its own pace on the simulated clock; None when a
        scenario or the live service pushes samples with :meth:`push`.
    column : str
        With ``source``: the one column to follow (a coordinate) instead of the three axes.
    horizon : int
        How many upcoming repetitions ``nextK`` covers.
    start : float
        Simulated time at which the recording's first sample is heard.
    input : str
        ``ws``: samples arrive from the live service's clients (``{"motion": [[t, ax, ay, az], ...]}``).
    """

    def __init__(self, anticipator_id: str = "reps", source: str = "", column: str = "", horizon: int = 8,
                 start: float = 0.0, input: str = ""):
        super().__init__(anticipator_id)
        if input not in ("", "ws"):
            raise ValueError(f"input must be 'ws' (samples from the live service's clients), got {input!r}")
        self.tracker = RepetitionTracker(horizon)
        self.input = input
        self.start = float(start)
        self.recording = read_motion(source, column or None) if source else None
        self.confidence = 0.0
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()  # (samples, arrived at) from other threads
        self.client_offset: float | None = None  # the realizer's clock less the client's, least delayed seen
        self.last_client_time = -math.inf
        #: the first value and time of a signal that has not varied yet (None: nothing yet; False: it has varied,
        #: or the warning was given)
        self.still: tuple | bool | None = None

    @property
    def horizon(self) -> int:
        return self.tracker.horizon

    @property
    def updates(self) -> list[tuple[float, list[float]]]:
        return self.tracker.updates

    def make_peg(self, sync_id: str):
        rep = _REP.match(sync_id)
        if rep and int(rep.group(1)) >= 1:
            return self.tracker.key_point(int(rep.group(1)))
        upcoming = _NEXT.match(sync_id)
        if upcoming and 1 <= int(upcoming.group(1)) <= self.horizon:
            predicted = self.tracker.predict()
            k = int(upcoming.group(1)) - 1
            return predicted[k] if k < len(predicted) else None
        return False

    def push(self, times, samples) -> None:
        """Hear samples (times on the simulated clock) and move the pegs whose predictions changed."""
        before = len(self.tracker.updates)
        self.tracker.push(times, samples)
        if len(self.tracker.updates) != before:
            self.confidence = min(1.0, len(self.tracker.intervals) / 4.0)
            self.update()

    def update(self) -> None:
        """Move every peg to the tracker's latest key point for it (a peg still to come is never moved into
        the past: it keeps its time)."""
        now = self.env.now if self.env is not None else self.tracker.time
        for sync_id, peg in self.pegs.items():
            time = self.make_peg(sync_id)
            if time is None or time is False or time == peg.time:
                continue
            if peg.time is not None and peg.time >= now - PAST_TOLERANCE and time < now - PAST_TOLERANCE:
                continue
            peg.set(time)

    def run(self):
        if self.input == "ws":
            return self._hear_clients()
        return None if self.recording is None else self._hear()

    def offer(self, samples, now: float) -> str | None:
        """Samples from a live client (any thread): ``[[t, ax, ay, az], ...]`` (or ``[[t, x], ...]``), its own
        times in seconds, received at ``now`` on the realizer's clock. None if taken, else why not (one line,
        for a warning to the sender): not rows of numbers, times going back, a sample rate out of range, a
        signal of one constant value."""
        if not isinstance(samples, list) or not samples or not all(isinstance(row, list) for row in samples):
            return 'motion must be a list of samples [[t, ax, ay, az], ...] (t in seconds, m/s² with gravity)'
        width = len(samples[0])
        if width not in (2, 4) or any(len(row) != width for row in samples):
            return "each motion sample must be [t, ax, ay, az] (or [t, x]), all of one length"
        try:
            rows = np.array(samples, dtype=float)
        except (TypeError, ValueError):
            return "motion samples must hold numbers only"
        if not np.isfinite(rows).all():
            return "motion samples must hold finite numbers"
        times = rows[:, 0]
        if times[0] <= self.last_client_time or (np.diff(times) <= 0).any():
            return "motion samples' times must increase, from one message to the next too"
        if len(times) >= 3:
            rate = 1.0 / float(np.median(np.diff(times)))
            if not MIN_RATE * 0.98 <= rate <= MAX_RATE * 1.02:
                return f"motion sampled at {rate:.3g} Hz; the repetition anticipator takes {MIN_RATE:g}-{MAX_RATE:g} Hz"
        self.last_client_time = float(times[-1])
        values = rows[:, 1:]
        if self.still is None:
            self.still = (values[0].copy(), float(times[0]))
        if self.still is not False:
            if (values == self.still[0]).all():
                if times[-1] - self.still[1] >= 2.0:
                    self.still = False
                    return "the motion signal has been one constant value for 2 s: is the sensor working?"
            else:
                self.still = False
        self.inbox.put((rows, now))
        return None

    def _hear_clients(self):
        """Every 50 ms, what clients sent, its times put on the realizer's clock (the least delayed arrival
        seen decides where the client's time 0 lies)."""
        env = self.env
        while True:
            yield env.timeout(0.05)
            while True:
                try:
                    rows, arrived = self.inbox.get_nowait()
                except queue.Empty:
                    break
                offset = arrived - float(rows[-1, 0])
                self.client_offset = offset if self.client_offset is None else min(self.client_offset, offset)
                times = rows[:, 0] + self.client_offset
                keep = times > self.tracker.time
                if keep.any():
                    self.push(times[keep], rows[keep, 1:])

    def _hear(self):
        env = self.env
        times, samples = self.recording
        times = times - times[0] + self.start
        step = 0.05
        i = 0
        while i < len(times):
            t = min(times[-1], max(env.now, times[i]) + step)
            j = int(np.searchsorted(times, t, side="right"))
            if t > env.now:
                yield env.timeout(t - env.now)
            self.push(times[i:j], samples[i:j])
            i = j


# ---------------------------------------------------------------------------------------------- recordings
def read_motion(path: str | Path, column: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and samples of a motion recording: a CSV with a header holding ``time`` and ``ax,ay,az``
    (or ``x,y,z``), or the one ``column`` named. :class:`~agentsim.errors.UsageError` for a file that is
    not one (no time column, times going back, a constant signal, a sample rate outside 10-200 Hz)."""
    import csv
    import io

    from agentsim.core.inputs import read_text

    path = Path(path)
    if not path.is_file():
        raise UsageError(f"no motion recording {str(path)!r}")
    text = read_text(path, what=f"the motion recording {str(path)!r}", errors="replace")
    rows = list(csv.reader(io.StringIO(text)))
    rows = [r for r in rows if r and any(cell.strip() for cell in r)]
    if not rows:
        raise UsageError(f"{path}: empty; expected a CSV with a header: time and ax,ay,az (or x,y,z)")
    header = [cell.strip().lower() for cell in rows[0]]
    if "time" not in header:
        raise UsageError(f"{path}: no 'time' column (the header has {', '.join(header) or 'nothing'}); expected "
                         "time in seconds and ax,ay,az, x,y,z or a column named with --column")
    if column:
        wanted = [column.strip().lower()]
    else:
        wanted = next((names for names in (["ax", "ay", "az"], ["x", "y", "z"]) if all(n in header for n in names)),
                      None)
        if wanted is None:
            raise UsageError(f"{path}: no ax,ay,az nor x,y,z columns (the header has {', '.join(header)}); name "
                             "the one to follow with --column")
    missing = [n for n in wanted if n not in header]
    if missing:
        raise UsageError(f"{path}: no column {missing[0]!r} (the header has {', '.join(header)})")
    index = [header.index("time")] + [header.index(n) for n in wanted]
    try:
        data = np.array([[float(row[i]) for i in index] for row in rows[1:]], float).reshape(-1, len(index))
    except (ValueError, IndexError):
        for number, row in enumerate(rows[1:], 2):
            try:
                [float(row[i]) for i in index]
            except (ValueError, IndexError):
                raise UsageError(f"{path}:{number}: expected numbers in {', '.join(['time', *wanted])}, got "
                                 f"{','.join(row)!r}") from None
        raise
    return check_motion(data[:, 0], data[:, 1:], str(path))


def check_motion(times, samples, where: str = "the motion signal") -> tuple[np.ndarray, np.ndarray]:
    """``(times, samples)`` if they make a signal the tracker can follow; UsageError saying why not."""
    times = np.asarray(times, float).reshape(-1)
    samples = np.asarray(samples, float).reshape(len(times), -1)
    if len(times) < 3:
        raise UsageError(f"{where}: {len(times)} sample(s); a recording needs at least three")
    if not (np.isfinite(times).all() and np.isfinite(samples).all()):
        raise UsageError(f"{where}: a time or value that is not a finite number")
    steps = np.diff(times)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        raise UsageError(f"{where}: time goes back or stands still at sample {i + 2} ({times[i + 1]:g} s after "
                         f"{times[i]:g} s); times must increase")
    rate = 1.0 / float(np.median(steps))
    if not MIN_RATE * 0.98 <= rate <= MAX_RATE * 1.02:
        raise UsageError(f"{where}: sampled at {rate:.3g} Hz; the repetition anticipator takes {MIN_RATE:g}-"
                         f"{MAX_RATE:g} Hz")
    if float(np.ptp(samples, axis=0).max()) == 0.0:
        raise UsageError(f"{where}: the signal is one constant value ({samples[0].tolist()}): no movement to "
                         "follow")
    return times, samples


def track(times, samples, lookahead: float = 0.2, horizon: int = 8) -> dict:
    """Run the tracker over a whole recording, as it would hear it: the key points found, the committed
    predictions ``lookahead`` s ahead (:func:`~anticipators.beats.evaluation.committed_beats`), the tempo."""
    from anticipators.beats.evaluation import committed_beats

    times, samples = check_motion(times, samples)
    tracker = RepetitionTracker(horizon)
    step = max(1, int(round(0.05 * (len(times) - 1) / max(times[-1] - times[0], 1e-9))))
    for i in range(0, len(times), step):  # blocks of about 50 ms, as a live client sends them
        tracker.push(times[i:i + step], samples[i:i + step])
    committed = committed_beats(tracker.updates, lookahead, end=float(times[-1])) if tracker.updates else []
    intervals = np.diff(tracker.repetitions)
    tempo = None if len(tracker.repetitions) < 2 else round(60.0 / float(np.median(intervals)), 3)
    return {"repetitions": [round(t, 4) for t in tracker.repetitions],
            "committed": [round(float(t), 4) for t in committed],
            "tempo_per_minute": tempo, "count": len(tracker.repetitions), "updates": tracker.updates}
