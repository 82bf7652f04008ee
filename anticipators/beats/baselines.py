"""Baseline beat trackers: extrapolating the last inter-onset interval, and librosa's offline beat tracker.

:class:`IOIBaselineTracker` extrapolates the last interval between the strongest recent onsets;
:func:`librosa_offline_beats` runs librosa's offline dynamic-programming ``beat_track`` on the whole
audio (it sees the future, so it is an upper bound on detection rather than a competitor).
"""

from __future__ import annotations

import math

import numpy as np

from anticipators.beats.envelope import SpectralFluxEnvelope, mono_samples

__all__ = ["IOIBaselineTracker", "librosa_offline_beats"]


class IOIBaselineTracker:
    """Baseline: extrapolate the last inter-onset interval between the strongest recent onsets.

    Onsets are local maxima of :class:`SpectralFluxEnvelope` (over +-30 ms, decided 30 ms late) above
    1.5 times the mean of the last 4 s. Among onsets of the last 3 s, those at least half as strong as
    the strongest are "strong"; the interval between the last two strong onsets, doubled or halved
    into the tempo range, is the period, and beats are predicted at the last strong onset plus
    multiples of it.

    Parameters
    ----------
    sample_rate : int
        Sample rate in Hz.
    min_bpm, max_bpm : float
        Tempo range.
    """

    def __init__(self, sample_rate: int, min_bpm: float = 60.0, max_bpm: float = 200.0) -> None:
        self.sample_rate = int(sample_rate)
        self.min_bpm, self.max_bpm = float(min_bpm), float(max_bpm)
        self.envelope = SpectralFluxEnvelope(self.sample_rate, keep_seconds=8.0)
        self._batch = self.envelope.n_fft + int(0.025 * self.sample_rate)
        self._w = 3
        self._checked = 0  # next absolute frame to check for a peak
        self._onsets: list[tuple[float, float]] = []
        self._anchor = None
        self._period = None
        self.confidence = 0.0
        self.tempo_bpm = float("nan")

    @property
    def time(self) -> float:
        """Seconds of audio heard so far."""
        return self.envelope.n_samples / self.sample_rate

    def process(self, block) -> None:
        """Hear the next block of audio (onsets are looked for every 25 ms of audio)."""
        envelope = self.envelope
        envelope.append(mono_samples(block))
        if envelope.n_samples - envelope.n_frames * envelope.hop < self._batch or envelope.update() == 0:
            return
        w = self._w
        lo = max(self._checked, envelope.first_kept + w)
        hi = envelope.n_frames - w  # frames whose +-w neighbourhood is complete
        if hi <= lo:
            return
        o = envelope.values(lo - w, hi + w)
        win = np.lib.stride_tricks.sliding_window_view(o, 2 * w + 1)
        centre = win[:, w]
        hist = envelope.values(envelope.n_frames - int(4 * envelope.fps), envelope.n_frames)
        thr = max(1.5 * float(hist.mean()), 1e-3)
        peaks = np.nonzero((centre >= win.max(axis=1)) & (centre > thr))[0]
        for k in peaks:
            self._onsets.append((float(envelope.frame_time(lo + k)), float(centre[k])))
        self._checked = hi
        now = self.time
        self._onsets = [o_ for o_ in self._onsets if o_[0] > now - 3.0]
        if len(self._onsets) < 2:
            if not self._onsets:
                self.confidence = 0.0
            return
        strengths = np.array([s for _, s in self._onsets])
        strong = [t for t, s in self._onsets if s >= 0.5 * strengths.max()]
        if len(strong) < 2:
            return
        ioi = strong[-1] - strong[-2]
        p_min, p_max = 60.0 / self.max_bpm, 60.0 / self.min_bpm
        while ioi < p_min:
            ioi *= 2.0
        while ioi > p_max:
            ioi /= 2.0
        prev = self._period
        self._anchor, self._period = strong[-1], ioi
        self.tempo_bpm = 60.0 / ioi
        self.confidence = 1.0 if prev is not None and abs(ioi - prev) < 0.1 * prev else 0.5

    def predict(self, horizon_beats: int = 4) -> np.ndarray:
        """The next ``horizon_beats`` beats at or after :attr:`time` (empty before two strong onsets)."""
        if self._anchor is None or horizon_beats <= 0:
            return np.zeros(0)
        k0 = max(math.ceil((self.time - self._anchor) / self._period - 1e-9), 1)
        return self._anchor + self._period * np.arange(k0, k0 + horizon_beats)


def librosa_offline_beats(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Beat times (seconds) by librosa's offline ``beat_track`` on the whole signal (an upper bound)."""
    import librosa

    y = mono_samples(audio)
    _, beats = librosa.beat.beat_track(y=y, sr=int(sample_rate), units="time")
    return np.asarray(beats, float)
