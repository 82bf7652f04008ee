"""The beat follower: a Kalman filter over beats that follows onsets, switches to sudden changes,
rates its confidence and predicts upcoming beats.

Filter
    State (time of the latest beat, beat period, change of period per beat, the last decaying by
    :attr:`BeatFollower.PERIOD_CHANGE_DECAY` a beat). Once the audio around an expected beat has been
    heard (+-20 % of a period, at most 100 ms, plus ``ready_delay``), the follower asks its onset
    picker (:class:`anticipators.beats.onsets.OnsetPicker`) for the salient onset there. An onset within
    the innovation gate (4 standard deviations, at least 35 ms) updates the filter; otherwise the
    filter only advances. Ramps and rubato are followed through the period-change state.

Sudden changes
    A salient onset outside the gate is kept as a candidate. If, a beat later, the grid finds nothing
    better while a salient onset lies where a tempo change (period = the new interval) or a phase
    change (same period) would put the next beat, the filter restarts there.

Confidence in [0, 1]
    ``clip((hit - 0.5) / 0.35) * clip((periodicity - 0.1) / 0.2)``, where ``hit`` is a moving average
    (weight 0.25 per beat) of expected beats that found an acceptable onset, and ``periodicity`` (set
    by the owner from the tempo analysis, :func:`anticipators.beats.tempo.periodicity_at`) how periodic
    onset strength is at the tracked period; 0 while ``out_of_range`` (a pulse faster than the tempo
    range). A grid that misses every other beat (a pulse slower than the range), noise and silence
    get (almost) none. While confidence is below ``confidence_threshold`` predictions continue the
    last state the follower was confident in.

Prediction
    :meth:`BeatFollower.predict` extrapolates the filter state: about one beat period ahead of the
    latest observed beat at any time.
"""

from __future__ import annotations

import bisect
import math
from typing import Callable

import numpy as np

__all__ = ["BeatFollower"]

#: An onset picker: ``pick(expected, tol)`` -> ``(time, timed_on_waveform, strength)`` or None.
Pick = Callable[[float, float], "tuple[float, bool, float] | None"]


class BeatFollower:
    """Kalman filter over beats, fed by onsets picked near the expected beats.

    Parameters
    ----------
    pick : callable
        ``pick(expected, tol)``: the salient onset within ``tol`` seconds of ``expected`` as
        ``(time, timed_on_waveform, strength)``, or None (:meth:`anticipators.beats.onsets.OnsetPicker.pick`).
    min_bpm, max_bpm : float
        Range of beat tempi; the period is kept within it.
    ready_delay : float
        Seconds after the end of an onset search window until its frames (and audio) are complete.
    confidence_threshold : float
        Below this confidence, :meth:`predict` keeps using the last confident state.
    process_noise : (float, float, float)
        Standard deviations (s) of the filter's per-beat changes of beat time, period and period change.
    observation_noise : float
        Standard deviation (s) of an onset timed on the waveform.
    coarse_noise : float
        Standard deviation (s) of an onset timed from onset-strength frames only.

    Attributes
    ----------
    state : numpy.ndarray or None
        ``[latest beat time (s), period (s), period change per beat (s)]``; None before :meth:`restart`.
    covariance : numpy.ndarray or None
        Covariance of ``state`` (s^2).
    hit_rate : float
        Moving average of expected beats that found an acceptable onset.
    periodicity : float
        Periodicity of onset strength at the tracked period (set by the owner).
    out_of_range : bool
        Whether a pulse faster than the tempo range dominates (set by the owner); no confidence then.
    confidence : float
        Confidence in the current predictions, in [0, 1].
    tempo_bpm : float
        Tempo of the filter state in BPM (NaN before the first grid).
    last_confident : numpy.ndarray or None
        Copy of the last state whose confidence reached ``confidence_threshold``.
    beats_observed : list of float
        Recent onset times (s) accepted as beats (at most 64 are kept).
    """

    #: Per-beat decay of the period-change state.
    PERIOD_CHANGE_DECAY = 0.8

    def __init__(
        self,
        pick: Pick,
        min_bpm: float = 60.0,
        max_bpm: float = 200.0,
        *,
        ready_delay: float = 0.0,
        confidence_threshold: float = 0.4,
        process_noise: tuple[float, float, float] = (0.002, 0.002, 0.001),
        observation_noise: float = 0.0015,
        coarse_noise: float = 0.008,
    ) -> None:
        if not 0 < min_bpm < max_bpm:
            raise ValueError("need 0 < min_bpm < max_bpm")
        self.pick = pick
        self.min_bpm = float(min_bpm)
        self.max_bpm = float(max_bpm)
        self.ready_delay = float(ready_delay)
        self.confidence_threshold = float(confidence_threshold)
        q_t, q_p, q_a = process_noise
        self._Q = np.diag([q_t**2, q_p**2, q_a**2])
        self._R = observation_noise**2
        self._R_coarse = coarse_noise**2
        rho = self.PERIOD_CHANGE_DECAY
        self._F = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, rho]])
        self._rho = float(rho)
        self._q = [float(q_t**2), float(q_p**2), float(q_a**2)]  # the diagonal of _Q
        self.state: np.ndarray | None = None
        self.covariance: np.ndarray | None = None
        self.hit_rate = 0.0
        self.periodicity = 0.0
        self.out_of_range = False
        self.last_confident: np.ndarray | None = None
        self._cand = None  # (rejected salient onset, beat before it, time it can be judged)
        self._cache_key = None
        self._cache = np.zeros(0)
        self._cache_list: list[float] = []  # the same beat times, for bisection
        self.confidence = 0.0
        self.tempo_bpm = float("nan")
        self.beats_observed: list[float] = []

    # ------------------------------------------------------------------ public API

    @property
    def locked(self) -> bool:
        """Whether a beat grid has been set."""
        return self.state is not None

    @property
    def period_range(self) -> tuple[float, float]:
        """Shortest and longest beat period (s)."""
        return 60.0 / self.max_bpm, 60.0 / self.min_bpm

    def restart(self, t_beat: float, period: float, periodicity: float | None = None) -> None:
        """Set a new beat grid: a beat at ``t_beat`` seconds, ``period`` seconds apart.

        The grid earns confidence beat by beat (hit rate 0.3); a pending candidate onset is dropped.
        ``periodicity``, if given, replaces :attr:`periodicity` before confidence is recomputed.
        """
        self.state = np.array([t_beat, period, 0.0])
        self.covariance = np.diag([0.01**2, (0.02 * period) ** 2, 0.002**2])
        self.hit_rate = 0.3  # a new grid earns confidence beat by beat
        self._cand = None
        self.tempo_bpm = 60.0 / period
        if periodicity is not None:
            self.periodicity = float(periodicity)
        self.update_confidence()

    def observe_time(self) -> float:
        """Time (s) by which the onset window of the next expected beat has been heard."""
        p = self.state[1]
        due = self.state[0] + p + min(0.2 * p, 0.1) + self.ready_delay
        if self._cand is not None:
            due = max(due, self._cand[2])
        return due

    def advance(self, now: float) -> None:
        """Advance the filter over every expected beat whose onset window has been heard by ``now``."""
        while now >= self.observe_time():
            t, p = self.state[0], self.state[1]
            expected = t + p
            tol = min(0.2 * p, 0.1)
            # Kalman prediction to the next beat
            x_pred, P_pred = self._predict_step()
            z, r, strength = self._observe(expected, tol)
            S = P_pred[0][0] + r
            accept = z is not None and abs(z - x_pred[0]) <= max(4.0 * math.sqrt(S), 0.035)
            if self._cand is not None and self._switch_hypothesis(p, strength if accept else 0.0):
                continue
            if accept:
                # x + K (z - x_0) and P - K P_0 with the gain K = P[:, 0] / S
                gain = [row[0] / S for row in P_pred]
                innovation = z - x_pred[0]
                x_pred = [x + k * innovation for x, k in zip(x_pred, gain)]
                first = P_pred[0]
                P_pred = [[v - k * f for v, f in zip(row, first)] for row, k in zip(P_pred, gain)]
                self._note_observed(z)
            elif z is not None:
                self._set_candidate(z, t, p)
            p_min, p_max = self.period_range
            x_pred[1] = min(max(x_pred[1], p_min), p_max)
            self.state = np.array(x_pred)
            self.covariance = np.array(P_pred)
            self.hit_rate = 0.75 * self.hit_rate + 0.25 * float(accept)
            self.tempo_bpm = 60.0 / self.state[1]
            self.update_confidence()

    def _predict_step(self) -> tuple[list[float], list[list[float]]]:
        """The Kalman prediction ``F x`` and ``F P F^T + Q`` of the state and covariance to the next beat,
        as lists. ``F`` (beat time plus period, period plus change, decayed change) holds only ones,
        zeros and the decay, so these sums and products are exactly what the matrix products give."""
        t, p, a = self.state.tolist()
        rho = self._rho
        P = self.covariance.tolist()
        m = [[x + y for x, y in zip(P[0], P[1])], [x + y for x, y in zip(P[1], P[2])], [rho * x for x in P[2]]]
        cov = [[row[0] + row[1], row[1] + row[2], rho * row[2]] for row in m]
        for i in range(3):
            cov[i][i] += self._q[i]
        return [t + p, p + a, rho * a], cov

    def update_confidence(self) -> None:
        """Recompute :attr:`confidence` (module notes); remember the state when confident."""
        if self.state is None:
            self.confidence = 0.0
            return
        c_period = min(max((self.periodicity - 0.1) / 0.2, 0.0), 1.0)
        # a grid that misses every other beat (a pulse slower than min_bpm) gets no confidence
        c_hit = min(max((self.hit_rate - 0.5) / 0.35, 0.0), 1.0)
        conf = c_hit * c_period
        if self.out_of_range:
            conf = 0.0
        self.confidence = float(min(max(conf, 0.0), 1.0))
        if self.confidence >= self.confidence_threshold:
            self.last_confident = self.state.copy()

    def predict(self, now: float, horizon_beats: int = 4) -> np.ndarray:
        """Predicted times of the next ``horizon_beats`` beats at or after ``now`` seconds.

        While :attr:`confidence` is below ``confidence_threshold`` the predictions continue the last
        state the follower was confident in (if any).

        Parameters
        ----------
        now : float
            Time (s) of the audio heard so far.
        horizon_beats : int
            Number of upcoming beats to predict.

        Returns
        -------
        numpy.ndarray
            Increasing beat times in seconds, all ``>= now``; empty before the first beat grid.
        """
        state = self.state
        if self.confidence < self.confidence_threshold and self.last_confident is not None:
            state = self.last_confident
        if state is None or horizon_beats <= 0:
            return np.zeros(0)
        key = (id(state), *state.tolist())
        cache = self._cache_list
        if key != self._cache_key or not cache or cache[-1] < now + 2 * key[2]:
            self._cache = self.extrapolate(state, now, horizon_beats + 8)
            self._cache_list = cache = self._cache.tolist()
            self._cache_key = key
        k = bisect.bisect_left(cache, now)
        if k + horizon_beats > len(cache):
            self._cache = self.extrapolate(state, now, horizon_beats + 8)
            self._cache_list = self._cache.tolist()
            return self._cache[:horizon_beats].copy()
        return self._cache[k : k + horizon_beats].copy()

    def predict_until(self, now: float, horizon_beats: int = 4) -> tuple[np.ndarray, float]:
        """:meth:`predict` at ``now``, and a time (s) up to which later calls give the same predictions
        and change nothing, as long as the follower is not changed (advanced, restarted, ...) meanwhile.

        Returns
        -------
        beats : numpy.ndarray
            As :meth:`predict` returns them.
        until : float
            Any later ``now`` not after this time gets ``beats`` again (infinity when nothing is predicted).
        """
        beats = self.predict(now, horizon_beats)
        if beats.size == 0:
            return beats, math.inf
        cache = self._cache_list
        k = bisect.bisect_left(cache, now)
        # a later time keeps the first beat while it is not after it, and the cache while it reaches
        # two periods beyond the time (less a margin for the rounding of that sum)
        return beats, min(cache[k], cache[-1] - 2 * self._cache_key[2] - 1e-9)

    def extrapolate(self, state: np.ndarray, now: float, count: int) -> np.ndarray:
        """Beat times from ``state`` onwards: the first ``count`` at or after ``now`` (seconds)."""
        t, p, a = float(state[0]), float(state[1]), float(state[2])
        p_min, p_max = self.period_range
        rho = self._F[2, 2]
        if now > t + 8 * p:
            # jump ahead k beats in closed form: p_j = p + a (1 - rho^j) / (1 - rho)
            k = max(math.floor((now - t) / max(p + a / (1 - rho), p_min)) - 2, 0)
            s = a / (1 - rho)
            t += k * p + s * (k - (1 - rho**k) / (1 - rho))
            p = min(max(p + s * (1 - rho**k), p_min), p_max)
            a *= rho**k
        out = []
        while len(out) < count:
            t += p
            p = min(max(p + a, p_min), p_max)
            a *= rho
            if t >= now:
                out.append(t)
        return np.asarray(out)

    # ------------------------------------------------------------------ internals

    def _observe(self, expected: float, tol: float) -> tuple[float | None, float, float]:
        """The picked onset near ``expected``: its time, variance and strength, or ``(None, 0, 0)``."""
        onset = self.pick(expected, tol)
        if onset is None:
            return None, 0.0, 0.0
        z, on_waveform, strength = onset
        return z, (self._R if on_waveform else self._R_coarse), strength

    def _note_observed(self, z: float) -> None:
        self.beats_observed.append(float(z))
        if len(self.beats_observed) > 64:
            del self.beats_observed[:32]

    def _hypotheses(self, z1: float, t0: float, p: float) -> list[tuple[float, float]]:
        """Next-beat times and periods after a rejected onset ``z1`` that followed the beat ``t0``.

        A tempo change puts the next beat at ``z1 + (z1 - t0)``, a phase change at ``z1 + p``.
        """
        p_min, p_max = self.period_range
        return [(z1 + q, q) for q in (z1 - t0, p) if p_min <= q <= p_max]

    def _set_candidate(self, z1: float, t0: float, p: float) -> None:
        hyps = self._hypotheses(z1, t0, p)
        if not hyps:
            self._cand = None
            return
        self._cand = (z1, t0, max(h + min(0.1 * q, 0.05) + self.ready_delay for h, q in hyps))

    def _switch_hypothesis(self, p: float, rival: float) -> bool:
        """Follow a sudden tempo or phase change after a salient onset fell outside the gate.

        Called for the beat after a rejected onset (``self._cand``). When a salient onset, stronger
        than ``rival`` (the onset strength the current grid found for this beat, 0 if none), lies near
        the next beat of a tempo-change or a phase-change hypothesis (:meth:`_hypotheses`), the filter
        restarts from it. Returns whether it did.
        """
        if self._cand is None:
            return False
        z1, t0, _ = self._cand
        self._cand = None
        for nxt, period in self._hypotheses(z1, t0, p):
            z2, r, strength = self._observe(nxt, min(0.1 * period, 0.05))
            if z2 is None or abs(z2 - nxt) > 0.03 or strength <= 1.2 * rival:
                continue
            if abs(z2 - z1 - period) < 0.05:
                period = z2 - z1
            self.state = np.array([z2, period, 0.0])
            self.covariance = np.diag([r, (0.02 * period) ** 2, 0.002**2])
            self._note_observed(z2)
            self.hit_rate = max(self.hit_rate, 0.75)  # two onsets agree with the new grid
            self.tempo_bpm = 60.0 / period
            self.update_confidence()
            return True
        return False
