"""Baseline beat trackers: extrapolating the last inter-onset interval, aubio's online tracker, and
librosa's offline beat tracker.

:class:`IOIBaselineTracker` extrapolates the last interval between the strongest recent onsets;
:class:`AubioTracker` wraps aubio's causal ``tempo`` (an optional package, in the ``bench`` extra:
``pip install 'agentsim[bench]'``); :func:`librosa_offline_beats` runs librosa's offline dynamic-programming ``beat_track``
on the whole audio (it sees the future, so it is an upper bound on detection rather than a competitor).
"""

from __future__ import annotations

import math

import numpy as np

from agentsim.errors import AgentsimError
from anticipators.beats.envelope import SpectralFluxEnvelope, mono_samples

__all__ = ["IOIBaselineTracker", "AubioTracker", "aubio_available", "librosa_offline_beats"]


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


def aubio_available() -> bool:
    """Whether aubio can be imported."""
    try:
        import aubio  # noqa: F401
    except ImportError:
        return False
    return True


class AubioTracker:
    """aubio's causal beat tracker (``aubio.tempo("default", ...)``), heard block by block.

    Its predictions are its last beat plus whole periods. The hop is 256 samples at up to 22.05 kHz and
    512 above (about 11.6 ms), the window twice the hop, as aubio's command line tools use them.

    Parameters
    ----------
    sample_rate : int
        Sample rate in Hz.
    hop : int, optional
        Samples per aubio hop.

    Raises
    ------
    ImportError
        When aubio is not installed.
    """

    def __init__(self, sample_rate: int, hop: int | None = None) -> None:
        try:
            import aubio
        except ImportError:
            raise AgentsimError("the aubio tracker needs aubio: pip install 'agentsim[bench]'") from None

        self.sample_rate = int(sample_rate)
        self.hop = int(hop) if hop else (256 if self.sample_rate <= 22050 else 512)
        self._tempo = aubio.tempo("default", 2 * self.hop, self.hop, self.sample_rate)
        self._pending = np.zeros(0, np.float32)
        self.n_samples = 0  # samples handed to aubio
        self.tempo_bpm = float("nan")
        self.confidence = 0.0

    @property
    def time(self) -> float:
        """Seconds of audio heard (handed to aubio in whole hops)."""
        return self.n_samples / self.sample_rate

    def process(self, block) -> None:
        """Hear the next block of audio."""
        x = np.concatenate([self._pending, mono_samples(block)])
        hop = self.hop
        n = (x.size // hop) * hop
        for a in range(0, n, hop):
            self._tempo(x[a : a + hop])
        self.n_samples += n
        self._pending = x[n:].copy()
        period = float(self._tempo.get_period_s())
        if period > 0:
            self.tempo_bpm = 60.0 / period
            self.confidence = float(self._tempo.get_confidence())

    def predict(self, horizon_beats: int = 4) -> np.ndarray:
        """Its last beat plus whole periods: the next ``horizon_beats`` at or after :attr:`time`."""
        period = float(self._tempo.get_period_s())
        if period <= 0 or horizon_beats <= 0:
            return np.zeros(0)
        beat = float(self._tempo.get_last_s())
        k = max(math.ceil((self.time - beat) / period - 1e-9), 0)
        return beat + period * np.arange(k, k + horizon_beats)


def librosa_offline_beats(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Beat times (seconds) by librosa's offline ``beat_track`` on the whole signal (an upper bound)."""
    import librosa

    y = mono_samples(audio)
    _, beats = librosa.beat.beat_track(y=y, sr=int(sample_rate), units="time")
    return np.asarray(beats, float)
