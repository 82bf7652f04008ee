"""Tempo estimation from onset strength by autocorrelation, on plain arrays with an explicit frame rate.

The autocorrelation (FFT, unbiased, normalised to 1 at lag 0) of a stretch of onset strength scores
each candidate beat period ``L`` (in frames, half-frame steps, between ``60 / max_bpm`` and
``60 / min_bpm`` seconds) by the weighted mean autocorrelation at ``L, 2L, 3L, 4L`` (weights
:data:`HARMONIC_WEIGHTS`; multiples beyond 60 % of the stretch are left out) times a log-normal tempo
preference (centre ``prior_bpm``, ``prior_octaves`` wide) that decides between metrical levels. The
best candidate is refined by a parabola through its neighbours' scores. A pulse faster than
``max_bpm`` that is as periodic as the best candidate (:attr:`TempoEstimate.fast_pulse`) marks the
tempo as out of range.

Like ``librosa.beat.tempo(onset_envelope=...)``, this works on any onset envelope: pass the values and
their frame rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["HARMONIC_WEIGHTS", "TempoEstimate", "TempoEstimator", "estimate_tempo", "periodicity_at"]

HARMONIC_WEIGHTS = (1.0, 0.7, 0.5, 0.4)
"""Weights of the autocorrelation at 1, 2, 3 and 4 beat periods in a candidate period's score."""


def periodicity_at(autocorrelation: np.ndarray | None, lag: float) -> float:
    """How periodic onset strength is at a grid of ``lag`` frames.

    The largest autocorrelation within 5 % of 1, 2 or 3 periods (the autocorrelation peaks are
    narrow, so a grid that is slightly off in tempo still counts as periodic).

    Parameters
    ----------
    autocorrelation : numpy.ndarray or None
        Normalised autocorrelation by lag in frames (None: nothing is periodic).
    lag : float
        Beat period in frames.

    Returns
    -------
    float
        Autocorrelation (1 = perfectly periodic), 0 without an autocorrelation.
    """
    ac = autocorrelation
    if ac is None:
        return 0.0
    best = 0.0
    for k in (1.0, 2.0, 3.0):
        lo = int(math.floor(0.95 * k * lag))
        hi = int(math.ceil(1.05 * k * lag)) + 1
        if hi > ac.size:
            break
        best = max(best, float(ac[lo:hi].max()))
    return best


@dataclass(frozen=True)
class TempoEstimate:
    """One tempo estimate over a stretch of onset strength.

    Attributes
    ----------
    frame_rate : float
        Frames per second of the onset strength (Hz).
    autocorrelation : numpy.ndarray
        Normalised autocorrelation (1 at lag 0) by lag in frames.
    lags : numpy.ndarray
        Candidate beat periods in frames.
    scores : numpy.ndarray
        Score of each candidate (harmonic autocorrelation times tempo preference).
    lag : float
        Best beat period in frames, refined between candidates.
    score : float
        Score of the best candidate.
    fast_pulse : bool
        Whether a pulse faster than the tempo range is as periodic as the best candidate.
    """

    frame_rate: float
    autocorrelation: np.ndarray
    lags: np.ndarray
    scores: np.ndarray
    lag: float
    score: float
    fast_pulse: bool

    @property
    def period(self) -> float:
        """Best beat period in seconds."""
        return self.lag / self.frame_rate

    @property
    def bpm(self) -> float:
        """Best tempo in beats per minute."""
        return 60.0 * self.frame_rate / self.lag

    def score_at(self, lag: float) -> float:
        """Score of a beat period of ``lag`` frames (interpolated between candidates)."""
        return float(np.interp(lag, self.lags, self.scores))

    def periodicity_at(self, lag: float) -> float:
        """:func:`periodicity_at` of this estimate's autocorrelation at ``lag`` frames."""
        return periodicity_at(self.autocorrelation, lag)


class TempoEstimator:
    """Autocorrelation tempo estimation over onset strength at a given frame rate.

    Parameters
    ----------
    frame_rate : float
        Frames per second of the onset strength (Hz).
    min_bpm, max_bpm : float
        Range of beat tempi considered.
    prior_bpm : float
        Centre of the log-normal tempo preference that decides between metrical levels.
    prior_octaves : float
        Width (standard deviation in octaves) of the tempo preference.

    Attributes
    ----------
    min_lag, max_lag : float
        Shortest and longest beat period in frames.
    lags : numpy.ndarray
        Candidate beat periods in frames (half-frame steps within the range).
    prior : numpy.ndarray
        Tempo preference of each candidate, in (0, 1].
    harmonic_weights : numpy.ndarray
        :data:`HARMONIC_WEIGHTS`.
    """

    def __init__(
        self,
        frame_rate: float,
        min_bpm: float = 60.0,
        max_bpm: float = 200.0,
        *,
        prior_bpm: float = 120.0,
        prior_octaves: float = 1.0,
    ) -> None:
        if not 0 < min_bpm < max_bpm:
            raise ValueError("need 0 < min_bpm < max_bpm")
        fps = frame_rate
        self.frame_rate = frame_rate
        self.min_lag = 60.0 / float(max_bpm) * fps
        self.max_lag = 60.0 / float(min_bpm) * fps
        lags = np.arange(math.floor(self.min_lag), math.ceil(self.max_lag) + 0.5, 0.5)
        self.lags = lags[(lags >= self.min_lag - 1e-9) & (lags <= self.max_lag + 1e-9)]
        octaves = np.log2(60.0 * fps / self.lags / float(prior_bpm))
        self.prior = np.exp(-0.5 * (octaves / float(prior_octaves)) ** 2)
        self.harmonic_weights = np.array(HARMONIC_WEIGHTS)
        # the multiples of the candidate lags, split into whole frames and a fraction (see _harmonics)
        self._multiple_rows = np.stack([k * self.lags for k in range(1, self.harmonic_weights.size + 1)])
        self._grid_cache: dict = {}  # by (limit, size), and the grid part by size
        self._norm_cache: dict[int, np.ndarray] = {}
        # lags of a pulse faster than max_bpm
        lo = max(2.0, self.min_lag / 2.0)
        self._fast_lags = (math.ceil(lo), math.floor(self.min_lag * 0.95) + 1)  # first and stop

    def _harmonics(self, limit: float, size: int) -> tuple:
        """The harmonics' multiples of the candidate lags, one harmonic a row, on the autocorrelation's
        grid of ``size`` lags: their whole frames (clipped to the grid), the frames after them and their
        fractions (made once per ``size``); their weights (0 for a multiple that does not count: at or
        beyond ``limit`` or the last lag), which candidates have any weight (None: all), and their total
        weights (made once per ``limit`` and ``size``)."""
        key = (limit, size)
        found = self._grid_cache.get(key)
        if found is None:
            grid = self._grid_cache.get(size)
            if grid is None:
                whole = np.clip(np.floor(self._multiple_rows), 0, max(size - 2, 0)).astype(np.intp)
                grid = self._grid_cache[size] = (whole, np.minimum(whole + 1, size - 1), self._multiple_rows - whole)
            weight = np.where(self._multiple_rows < min(limit, size - 1), self.harmonic_weights[:, None], 0.0)
            wsum = np.add.reduce(weight, axis=0)  # one harmonic after another
            counted = wsum > 0
            found = (*grid, weight, None if counted.all() else counted, np.maximum(wsum, 1e-12))
            if len(self._grid_cache) > 64:
                self._grid_cache.clear()
            self._grid_cache[key] = found
        return found

    def min_frames(self) -> float:
        """Fewest frames of onset strength that :meth:`estimate` works on."""
        return 2 * self.max_lag + 4

    def estimate(self, onset_strength: np.ndarray) -> TempoEstimate | None:
        """Estimate the tempo of a stretch of onset strength.

        Parameters
        ----------
        onset_strength : numpy.ndarray
            Onset strength of consecutive frames (non-negative).

        Returns
        -------
        TempoEstimate or None
            None when the stretch is shorter than :meth:`min_frames`, constant, or nearly silent
            (mean onset strength below 0.001).
        """
        o = np.asarray(onset_strength, np.float64)
        n = o.size
        mean = np.add.reduce(o) / n if n else 0.0  # o.mean()
        o = o - mean
        energy = float(np.dot(o, o))
        max_needed = int(self.harmonic_weights.size * self.max_lag) + 2
        if n < 2 * self.max_lag + 4 or energy <= 1e-9 * max(n, 1) or mean < 1e-3:
            return None
        size = min(n, max_needed + 2)
        # the linear autocorrelation up to lag size - 1 (no wrap-around: nfft >= n + size - 1)
        nfft = 1 << int(math.ceil(math.log2(n + size - 1)))
        f = np.fft.rfft(o, nfft)
        ac = np.fft.irfft(f.real**2 + f.imag**2, nfft)[:size]
        norm = self._norm_cache.get(n)
        if norm is None:
            if len(self._norm_cache) > 64:
                self._norm_cache.clear()
            norm = self._norm_cache[n] = n - np.arange(size)
        ac = ac / norm
        ac = ac / ac[0]
        lim = 0.6 * n  # multiples beyond this are too poorly estimated to count
        whole, after, fraction, weight, counted, wsum = self._harmonics(lim, size)
        # np.interp(k * lags, grid, ac) on the whole-frame grid, as np.interp computes it where it counts:
        # slope (over one frame) times the fraction, plus the value at the frame below
        low = ac[whole]
        at = (ac[after] - low) * fraction + low
        # the harmonics added one after another (a reduction over the first axis), as the weights were
        total = np.add.reduce(weight * at, axis=0)
        scores = total / wsum * self.prior if counted is None else np.where(counted, total / wsum, 0.0) * self.prior
        i = int(np.argmax(scores))
        lag = self.lags[i]
        if 0 < i < scores.size - 1:
            y0, y1, y2 = scores[i - 1], scores[i], scores[i + 1]
            den = y0 - 2 * y1 + y2
            if den < 0:
                lag += 0.5 * 0.5 * (y0 - y2) / den
        # a pulse faster than max_bpm that is as strong as the chosen beat
        # np.interp(lag, grid, ac), as np.interp computes it
        j = int(lag)
        a0 = float(ac[j])
        best_ac = a0 if j == lag or j + 1 >= size else (float(ac[j + 1]) - a0) * (lag - j) + a0
        first, stop = self._fast_lags
        fast_ac = float(ac[first:stop].max()) if stop > first else 0.0
        fast = fast_ac >= 0.3 and fast_ac >= 0.85 * best_ac
        return TempoEstimate(self.frame_rate, ac, self.lags, scores, float(lag), float(scores[i]), bool(fast))


def estimate_tempo(
    onset_strength: np.ndarray,
    frame_rate: float,
    min_bpm: float = 60.0,
    max_bpm: float = 200.0,
    *,
    prior_bpm: float = 120.0,
    prior_octaves: float = 1.0,
) -> TempoEstimate | None:
    """Estimate the tempo of onset strength at ``frame_rate`` frames per second.

    A one-off :class:`TempoEstimator` (see there for the parameters); returns its
    :meth:`~TempoEstimator.estimate`, or None for a stretch that is too short, constant or silent.
    """
    estimator = TempoEstimator(frame_rate, min_bpm, max_bpm, prior_bpm=prior_bpm, prior_octaves=prior_octaves)
    return estimator.estimate(onset_strength)
