"""Onset-envelope front ends: causal log-mel spectral flux of audio, or precomputed onset strength.

An envelope source turns the samples heard so far into onset strength, one value per frame, and
keeps recent history of both. :class:`SpectralFluxEnvelope` computes it from audio (causal STFT
frames, Hann window of about 23-32 ms, a power of two in samples; hop 10 ms; 40 mel bands of
log-compressed magnitude ``log(1 + 100 |X|)`` and their half-wave rectified frame-to-frame increase
summed over bands). A frame is computed once all its samples have been heard; its time is the
window centre. Frames are computed in numpy batches only when asked for (:meth:`~SpectralFluxEnvelope.update`).

:class:`ArrayEnvelope` serves onset strength made beforehand (by hand, or by another front end),
revealed frame by frame as samples are counted; it has no waveform. Both follow
:class:`EnvelopeSource`, which is all :class:`~anticipators.beats.tracking.CausalBeatTracker` asks of
its front end.

All times are seconds from the first sample heard; frame indices are absolute (frame 0 is the first).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

__all__ = ["mono_samples", "EnvelopeSource", "SpectralFluxEnvelope", "ArrayEnvelope"]

_FLOAT32 = np.dtype(np.float32)


def mono_samples(block) -> np.ndarray:
    """Mono float32 samples with NaN and infinities replaced by zeros.

    A 2-D block is taken as ``(samples, channels)`` (or ``(channels, samples)`` when its first axis is
    shorter than 9) and averaged over channels.
    """
    x = block
    if type(x) is not np.ndarray or x.ndim != 1 or x.dtype != _FLOAT32:
        x = np.asarray(block)
        if x.ndim == 2:
            x = x.mean(axis=0 if x.shape[0] < 9 and x.shape[1] > x.shape[0] else 1)
        elif x.ndim != 1:
            x = x.reshape(-1)
        x = x.astype(np.float32, copy=False)
    # a NaN or an infinity makes the sum of squares non-finite (as does a sum too large for float32:
    # then the samples are checked one by one)
    if not math.isfinite(x.dot(x)) and not np.isfinite(x).all():
        x = np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)
    return x


def _hz_to_mel(hz: float) -> float:
    """Slaney's mel scale (linear to 1 kHz, logarithmic above), as librosa computes it."""
    f_sp = 200.0 / 3
    mel = hz / f_sp
    if hz >= 1000.0:
        mel = 1000.0 / f_sp + np.log(hz / 1000.0) / (np.log(6.4) / 27.0)
    return mel


def _mel_to_hz(mels: np.ndarray) -> np.ndarray:
    f_sp = 200.0 / 3
    min_log_mel = 1000.0 / f_sp
    hz = f_sp * mels
    log = mels >= min_log_mel
    hz[log] = 1000.0 * np.exp(np.log(6.4) / 27.0 * (mels[log] - min_log_mel))
    return hz


def mel_filters(sample_rate: int, n_fft: int, n_mels: int, fmin: float, fmax: float) -> np.ndarray:
    """Triangular mel filters with Slaney's area normalisation, ``(n_mels, 1 + n_fft // 2)`` float32: the
    same numbers as ``librosa.filters.mel(sr=..., n_fft=..., n_mels=..., fmin=..., fmax=...)``, computed
    in the same order of operations (without importing librosa, which takes a second with scipy.signal)."""
    weights = np.zeros((n_mels, 1 + n_fft // 2), dtype=np.float32)
    fftfreqs = np.fft.rfftfreq(n=n_fft, d=1.0 / sample_rate)
    mel_f = _mel_to_hz(np.linspace(_hz_to_mel(fmin), _hz_to_mel(fmax), n_mels + 2))
    fdiff = np.diff(mel_f)
    ramps = np.subtract.outer(mel_f, fftfreqs)
    for i in range(n_mels):
        lower = -ramps[i] / fdiff[i]
        upper = ramps[i + 2] / fdiff[i + 1]
        weights[i] = np.maximum(0, np.minimum(lower, upper))
    weights *= (2.0 / (mel_f[2:n_mels + 2] - mel_f[:n_mels]))[:, np.newaxis]
    return weights


class EnvelopeSource(Protocol):
    """What a beat tracker needs of its onset-envelope front end.

    Attributes
    ----------
    sample_rate : int
        Samples per second of the audio clock (Hz).
    hop : int
        Samples between frames.
    fps : float
        Frames per second (``sample_rate / hop``).
    n_samples : int
        Samples heard so far.
    n_frames : int
        Frames computed so far (absolute count).
    """

    sample_rate: int
    hop: int
    fps: float
    n_samples: int
    n_frames: int

    @property
    def latency(self) -> float:
        """Seconds from a frame's time until the frame is complete."""

    @property
    def first_kept(self) -> int:
        """Absolute index of the oldest frame still kept."""

    def frame_time(self, index) -> np.ndarray | float:
        """Time in seconds of absolute frame ``index``."""

    def frame_index(self, time) -> np.ndarray | float:
        """Fractional absolute frame index at ``time`` seconds."""

    def values(self, start: int, stop: int) -> np.ndarray:
        """Onset strength of absolute frames ``start .. stop - 1`` (clipped to what is kept)."""

    def audio(self, t0: float, t1: float) -> np.ndarray | None:
        """Raw samples between ``t0`` and ``t1`` seconds, or None when not available."""

    def append(self, x: np.ndarray) -> None:
        """Hear mono float32 samples without computing frames."""

    def update(self) -> int:
        """Compute all frames completed by the samples heard; returns how many."""


class SpectralFluxEnvelope:
    """Causal onset strength: log-mel spectral flux of complete STFT frames.

    Frame ``i`` covers samples ``[i * hop, i * hop + n_fft)`` and is computed as soon as they have
    been heard; its time is the window centre ``(i * hop + n_fft / 2) / sample_rate``. The value is
    ``sum_b max(0, S[i, b] - S[i - 1, b])`` with ``S = log(1 + 100 * mel magnitude)``.

    Parameters
    ----------
    sample_rate : int
        Sample rate in Hz.
    hop_seconds : float
        Frame hop in seconds (rounded to whole samples).
    frame_seconds : float
        Approximate window length in seconds (rounded to a power of two in samples).
    n_mels : int
        Number of mel bands.
    keep_seconds : float
        How much onset strength history is kept.
    keep_audio_seconds : float
        How much raw audio history is kept (for precise onset timing).
    fmax : float
        Highest frequency of the mel bands (at most half the sample rate), Hz.
    far_lag : int
        0, or frames back for a second, slower flux kept beside the onset strength for the joint
        tempo-phase filter to observe (:meth:`observation_values`): ``(flux + far_weight * far) / (1 +
        far_weight)`` with ``far = sum_b max(0, S[i, b] - S[i - far_lag, b])``, the increase over
        ``far_lag`` frames, which also counts onsets that rise over several frames (a piano note, a
        swelling chord) and are weak in the frame-to-frame flux.
    far_weight : float
        Weight of the slower flux in :meth:`observation_values`.
    """

    def __init__(
        self,
        sample_rate: int,
        hop_seconds: float = 0.01,
        frame_seconds: float = 0.03,
        n_mels: int = 40,
        keep_seconds: float = 12.0,
        keep_audio_seconds: float = 1.0,
        fmax: float = 16000.0,
        far_lag: int = 0,
        far_weight: float = 0.3,
    ) -> None:
        if sample_rate < 4000:
            raise ValueError("sample_rate must be at least 4000 Hz")
        self.sample_rate = int(sample_rate)
        self.hop = max(int(round(hop_seconds * sample_rate)), 1)
        self.n_fft = int(2 ** round(math.log2(frame_seconds * sample_rate)))
        self.fps = self.sample_rate / self.hop
        self.window = np.hanning(self.n_fft + 1)[:-1].astype(np.float32)
        mel = mel_filters(self.sample_rate, self.n_fft, n_mels, fmin=30.0, fmax=min(float(fmax), sample_rate / 2))
        self.mel_t = np.ascontiguousarray(mel.T.astype(np.float32))
        self._keep = max(int(keep_seconds * self.fps), 64)
        self._odf = np.zeros(2 * self._keep, np.float64)
        self._odf_start = 0  # absolute index of _odf[0]
        if int(far_lag) < 0 or float(far_weight) < 0:
            raise ValueError("far_lag and far_weight must not be negative")
        self.far_lag = int(far_lag)
        self.far_weight = float(far_weight)
        # the observation for the joint filter, frame for frame beside _odf (far_lag > 0)
        self._obs = np.zeros_like(self._odf) if self.far_lag > 0 else None
        self._history = None  # the last far_lag log-mel frames
        self._pending_obs = None
        self.n_frames = 0  # absolute number of frames computed
        self._prev = None  # log-mel of the previous frame
        self._keep_audio = max(int(keep_audio_seconds * self.sample_rate), self.n_fft + self.hop)
        self._raw = np.zeros(2 * self._keep_audio + self.sample_rate, np.float32)
        self._raw_start = 0  # absolute sample index of _raw[0]
        self.n_samples = 0

    @property
    def latency(self) -> float:
        """Seconds from a frame's time (window centre) until the frame is complete."""
        return self.n_fft / 2 / self.sample_rate

    def frame_time(self, index) -> np.ndarray | float:
        """Time in seconds of frame ``index`` (absolute index; scalars or arrays)."""
        if isinstance(index, (int, float)):  # the same arithmetic on one number
            return (float(index) * self.hop + self.n_fft / 2) / self.sample_rate
        return (np.asarray(index, np.float64) * self.hop + self.n_fft / 2) / self.sample_rate

    def frame_index(self, time) -> np.ndarray | float:
        """Fractional absolute frame index at ``time`` seconds (inverse of :meth:`frame_time`)."""
        if isinstance(time, (int, float)):  # the same arithmetic on one number
            return (float(time) * self.sample_rate - self.n_fft / 2) / self.hop
        return (np.asarray(time, np.float64) * self.sample_rate - self.n_fft / 2) / self.hop

    @property
    def first_kept(self) -> int:
        """Absolute index of the oldest frame still kept."""
        return self._odf_start

    def values(self, start: int, stop: int) -> np.ndarray:
        """Onset strength of absolute frames ``start .. stop - 1`` (clipped to what is kept); a view."""
        start = max(int(start), self._odf_start)
        stop = min(int(stop), self.n_frames)
        if stop <= start:
            return self._odf[:0]
        return self._odf[start - self._odf_start : stop - self._odf_start]

    def observation_values(self, start: int, stop: int) -> np.ndarray:
        """What the joint tempo-phase filter observes for absolute frames ``start .. stop - 1``: the onset
        strength mixed with the slower flux over ``far_lag`` frames (the onset strength itself when
        ``far_lag`` is 0); a view, clipped to what is kept."""
        if self._obs is None:
            return self.values(start, stop)
        start = max(int(start), self._odf_start)
        stop = min(int(stop), self.n_frames)
        if stop <= start:
            return self._obs[:0]
        return self._obs[start - self._odf_start : stop - self._odf_start]

    def audio(self, t0: float, t1: float) -> np.ndarray | None:
        """Raw samples between ``t0`` and ``t1`` seconds, or None when not (or no longer) available."""
        a = int(round(t0 * self.sample_rate))
        b = int(round(t1 * self.sample_rate))
        if a < self._raw_start or b > self.n_samples or b <= a:
            return None
        # callers get a copy: the buffer is reused
        return self._raw[a - self._raw_start : b - self._raw_start].copy()

    def append(self, x: np.ndarray) -> None:
        """Append mono float32 samples without computing frames (see :meth:`update`)."""
        n = x.size
        if n == 0:
            return
        used = self.n_samples - self._raw_start
        if used + n > self._raw.size:
            # drop audio that is neither needed for the next frame nor within the kept history
            need_from = min(self.n_frames * self.hop, self.n_samples - self._keep_audio)
            drop = max(need_from - self._raw_start, 0)
            keep = used - drop
            if keep + n > self._raw.size:
                grown = np.zeros(2 * (keep + n), np.float32)
                grown[:keep] = self._raw[drop:used]
                self._raw = grown
            else:
                self._raw[:keep] = self._raw[drop:used]
            self._raw_start += drop
            used = keep
        self._raw[used : used + n] = x
        self.n_samples += n

    def update(self) -> int:
        """Compute all frames completed by the audio appended so far; returns how many."""
        first = self.n_frames
        count = (self.n_samples - self.n_fft) // self.hop - first + 1
        if count <= 0:
            return 0
        a = first * self.hop - self._raw_start
        itemsize = self._raw.itemsize
        # frame k is _raw[a + k * hop : a + k * hop + n_fft], a strided view
        frames = np.ndarray((count, self.n_fft), np.float32, buffer=self._raw, offset=a * itemsize,
                            strides=(self.hop * itemsize, itemsize))
        spec = np.abs(np.fft.rfft(frames * self.window, axis=1)).astype(np.float32, copy=False)
        mel = spec @ self.mel_t
        mel *= 100.0
        logmel = np.log1p(mel, out=mel)
        diff = np.empty_like(logmel)
        np.subtract(logmel[0], logmel[0] if self._prev is None else self._prev, out=diff[0])
        np.subtract(logmel[1:], logmel[:-1], out=diff[1:])
        self._prev = logmel[-1].copy()
        np.maximum(diff, 0.0, out=diff)
        if self.far_lag > 0:
            k = self.far_lag
            history = self._history if self._history is not None else np.repeat(logmel[:1], k, axis=0)
            both = np.concatenate([history, logmel])
            far = np.maximum(logmel - both[:count], 0.0)  # both[i] is the frame far_lag before logmel[i]
            self._history = both[-k:].copy()
            self._pending_obs = (diff.sum(axis=1) + self.far_weight * far.sum(axis=1)) / (1.0 + self.far_weight)
        self._append_bands(diff)
        return count

    def _append_bands(self, diff: np.ndarray) -> None:
        """Keep the onset strength of new frames from their rectified flux per mel band ``(frames, bands)``."""
        self._append(diff.sum(axis=1))

    def push(self, x: np.ndarray) -> int:
        """Append mono float32 samples and compute all frames they complete; returns how many."""
        self.append(x)
        return self.update()

    def _append(self, values: np.ndarray) -> None:
        k = values.size
        used = self.n_frames - self._odf_start
        obs = self._obs
        if used + k > self._odf.size:
            keep = min(self._keep, used)
            if keep + k > self._odf.size:
                self._odf = np.concatenate([self._odf[used - keep : used], np.zeros(k + self._keep)])
                if obs is not None:
                    obs = self._obs = np.concatenate([obs[used - keep : used], np.zeros(k + self._keep)])
            else:
                self._odf[:keep] = self._odf[used - keep : used]
                if obs is not None:
                    obs[:keep] = obs[used - keep : used]
            self._odf_start = self.n_frames - keep
            used = keep
        self._odf[used : used + k] = values
        if obs is not None:
            obs[used : used + k] = self._pending_obs
            self._pending_obs = None
        self.n_frames += k


class ArrayEnvelope:
    """Precomputed onset strength, revealed frame by frame as samples are heard.

    Frame ``i`` has time ``i * hop / sample_rate`` (``i / frame_rate``) and becomes available once
    ``i * hop`` samples have been heard (the envelope has no latency). No frame exists beyond the
    array, and there is no waveform (:meth:`audio` returns None), so a tracker times onsets from
    envelope peaks alone. The samples heard only count time; their values are ignored.

    Parameters
    ----------
    onset_strength : array_like
        Onset strength of frames ``0, 1, ...`` (non-negative; any units).
    frame_rate : float
        Frames per second (Hz).
    sample_rate : int
        Samples per second of the clock that drives the envelope (Hz); ``sample_rate / frame_rate``
        must be a whole number of samples.
    """

    def __init__(self, onset_strength, frame_rate: float, sample_rate: int = 8000) -> None:
        self._strength = np.asarray(onset_strength, np.float64).reshape(-1).copy()
        self.sample_rate = int(sample_rate)
        hop = self.sample_rate / float(frame_rate)
        if hop < 1 or abs(hop - round(hop)) > 1e-9:
            raise ValueError("sample_rate / frame_rate must be a whole number of samples")
        self.hop = int(round(hop))
        self.fps = self.sample_rate / self.hop
        self.n_samples = 0
        self.n_frames = 0

    @property
    def latency(self) -> float:
        """Seconds from a frame's time until it is available: 0."""
        return 0.0

    @property
    def first_kept(self) -> int:
        """Absolute index of the oldest frame kept: 0 (everything is kept)."""
        return 0

    def frame_time(self, index) -> np.ndarray | float:
        """Time in seconds of frame ``index`` (scalars or arrays)."""
        return np.asarray(index, np.float64) * self.hop / self.sample_rate

    def frame_index(self, time) -> np.ndarray | float:
        """Fractional frame index at ``time`` seconds (inverse of :meth:`frame_time`)."""
        return np.asarray(time, np.float64) * self.sample_rate / self.hop

    def values(self, start: int, stop: int) -> np.ndarray:
        """Onset strength of frames ``start .. stop - 1`` available so far; a view."""
        start = max(int(start), 0)
        stop = min(int(stop), self.n_frames)
        if stop <= start:
            return self._strength[:0]
        return self._strength[start:stop]

    def audio(self, t0: float, t1: float) -> None:
        """No waveform: always None."""
        return None

    def append(self, x: np.ndarray) -> None:
        """Count ``x.size`` more samples heard (see :meth:`update`)."""
        self.n_samples += int(np.asarray(x).size)

    def update(self) -> int:
        """Make available every frame whose time has been heard; returns how many became available."""
        available = min(self.n_samples // self.hop + 1, self._strength.size)
        count = max(available - self.n_frames, 0)
        self.n_frames += count
        return count

    def push(self, x: np.ndarray) -> int:
        """Count samples heard and make available the frames they reach; returns how many."""
        self.append(x)
        return self.update()


BAND_FMAX = 11025.0
"""Highest frequency of :class:`BandFluxEnvelope`'s mel bands (Hz): half of 22.05 kHz, at which the learned
activation was trained."""


class BandFluxEnvelope(SpectralFluxEnvelope):
    """:class:`~anticipators.beats.envelope.SpectralFluxEnvelope` that also keeps each mel band's rectified flux.

    :meth:`bands` gives the ``(frames, n_mels)`` flux of absolute frames (the same history as
    :meth:`values`, whose frame values are their sums).
    """

    def __init__(self, *args, **kwargs) -> None:
        # the bands of a 22.05 kHz recording at every sample rate: the learned activation (:mod:`anticipators.beats.network`) learned on those
        kwargs.setdefault("fmax", BAND_FMAX)
        super().__init__(*args, **kwargs)
        self.n_mels = self.mel_t.shape[1]
        self._bands = np.zeros((self._odf.size, self.n_mels), np.float32)

    def bands(self, start: int, stop: int) -> np.ndarray:
        """Rectified flux per mel band of absolute frames ``start .. stop - 1`` (clipped to what is kept)."""
        start = max(int(start), self._odf_start)
        stop = min(int(stop), self.n_frames)
        if stop <= start:
            return self._bands[:0]
        return self._bands[start - self._odf_start : stop - self._odf_start]

    def _append_bands(self, diff: np.ndarray) -> None:
        old_start, old_frames = self._odf_start, self.n_frames
        self._append(diff.sum(axis=1))  # the onset strength, as SpectralFluxEnvelope keeps it
        start = self._odf_start
        if start != old_start or self._bands.shape[0] != self._odf.size:  # the history moved back or grew
            bands = self._bands
            if bands.shape[0] != self._odf.size:
                bands = np.zeros((self._odf.size, self.n_mels), np.float32)
            bands[: old_frames - start] = self._bands[start - old_start : old_frames - old_start]
            self._bands = bands
        self._bands[old_frames - start : self.n_frames - start] = diff
