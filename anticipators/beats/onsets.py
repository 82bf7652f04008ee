"""Onsets near an expected time: the salient onset-strength peak, timed precisely on the waveform.

:class:`OnsetPicker` looks, around the time a beat is expected, for the strongest onset-strength
peak (favouring the expectation) of an envelope source (:mod:`anticipators.beats.envelope`). A peak is
salient when it is over twice the recent mean onset strength. Its time, interpolated between frames,
comes a little after the energy onset (``peak_bias``); where the envelope keeps the waveform,
:func:`waveform_onset` times the onset instead: the first difference of the samples, its energy in
0.5 ms blocks locates the rise, then the first sample after a quiet stretch that climbs 10 % of the
way from the floor to the peak (the same rule as :func:`agentsim.music.onsets.energy_onsets`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["WAVEFORM_BEFORE", "WAVEFORM_AFTER", "waveform_onset", "OnsetPicker"]

WAVEFORM_BEFORE = 0.04
"""Precise timing looks this far (seconds) before a coarse onset."""

WAVEFORM_AFTER = 0.03
"""And this far (seconds) after it."""


def waveform_onset(x: np.ndarray, sample_rate: int, first_sample: int = 0) -> float:
    """Time of the onset of the rise in a stretch of waveform.

    Parameters
    ----------
    x : numpy.ndarray
        Mono samples (at least 16).
    sample_rate : int
        Sample rate in Hz.
    first_sample : int
        Absolute index of ``x[0]`` (sample 0 is at 0 s).

    Returns
    -------
    float
        Onset time in seconds, or NaN when ``x`` holds no rise after a quieter stretch.
    """
    sr = sample_rate
    blk = max(int(round(sr * 0.0005)), 1)
    y = x[1:] - x[:-1]  # np.diff(x)
    m = (y.size // blk) * blk
    z = y[:m].reshape(-1, blk).astype(np.float64)
    e = np.sqrt(np.add.reduce(z * z, axis=1) / blk)  # the RMS of each block, as np.mean(z ** 2, axis=1)
    pk = int(np.argmax(e))
    if pk == 0 or e[pk] <= 0:
        return float("nan")
    floor = float(e[:pk].min())
    level = floor + 0.1 * (e[pk] - floor)
    below = np.nonzero(e[: pk + 1] < level)[0]
    if below.size == 0:
        return float("nan")
    k = int(below[-1])
    start = first_sample + 1  # diff shifts by one sample
    # sample-level: the first sample after a quiet stretch that reaches 10 % of the rise
    a = max((k + 1) * blk - int(0.012 * sr), 0)
    q = (k + 1) * blk - int(0.002 * sr)
    if q - a < blk:
        de = e[k + 1] - e[k]
        frac = (level - e[k]) / de if de > 0 else 1.0
        return (start + (k + frac + 0.5) * blk) / sr
    floor_s = float(np.abs(y[a:q]).max())
    rise = np.abs(y[q : q + int(0.02 * sr)])
    peak_s = float(rise.max())
    if peak_s <= floor_s:
        return (start + (k + 1) * blk) / sr
    # the first sample from q on that reaches the level: no later than the peak, so within the rise
    j = q + int(np.argmax(rise >= floor_s + 0.1 * (peak_s - floor_s)))
    return (start + j) / sr


class OnsetPicker:
    """Salient onsets of an envelope source near expected times.

    Parameters
    ----------
    envelope : anticipators.beats.envelope.EnvelopeSource
        Onset strength (and, if it keeps it, the waveform) heard so far.
    peak_bias : float
        Seconds subtracted from interpolated onset-strength peaks (they come after energy onsets).
    onset_bias : float
        Seconds subtracted from onsets timed on the waveform.

    Attributes
    ----------
    recent_mean : float
        Mean recent onset strength; a peak must exceed twice this to be salient. The owner keeps it up
        to date (0 at first).
    """

    def __init__(self, envelope, peak_bias: float = 0.0, onset_bias: float = 0.0) -> None:
        self.envelope = envelope
        self.peak_bias = float(peak_bias)
        self.onset_bias = float(onset_bias)
        self.recent_mean = 0.0

    def onset_near(self, t: float) -> float:
        """Precise onset time (s) near ``t`` from the waveform, or NaN when the audio is not available.

        Looks from :data:`WAVEFORM_BEFORE` before ``t`` to :data:`WAVEFORM_AFTER` after it
        (:func:`waveform_onset`), less ``onset_bias``.
        """
        x = self.envelope.audio(t - WAVEFORM_BEFORE, t + WAVEFORM_AFTER)
        if x is None or x.size < 16:
            return float("nan")
        sr = self.envelope.sample_rate
        first = int(round((t - WAVEFORM_BEFORE) * sr))
        return waveform_onset(x, sr, first) - self.onset_bias

    def pick(self, expected: float, tol: float) -> tuple[float, bool, float] | None:
        """The salient onset within ``tol`` seconds of ``expected``.

        The strongest onset-strength frame in the window, weighted by ``1 - 0.5 (offset / tol)^2``,
        if it is salient; timed by a parabola through it and its neighbours (less ``peak_bias``), or on
        the waveform (:meth:`onset_near`) when that lies within 30 ms.

        Returns
        -------
        tuple of (float, bool, float) or None
            The onset time (s), whether it was timed on the waveform, and its onset strength; None when
            nothing salient lies in the window or the window is not (or no longer) complete.
        """
        envelope = self.envelope
        i0 = int(math.ceil(float(envelope.frame_index(expected - tol))))
        i1 = int(math.floor(float(envelope.frame_index(expected + tol))))
        if i0 < envelope.first_kept + 1 or i1 >= envelope.n_frames - 1 or i1 <= i0:
            return None
        o = envelope.values(i0 - 1, i1 + 2)
        seg = o[1:-1]
        times = envelope.frame_time(np.arange(i0, i1 + 1))
        weight = 1.0 - 0.5 * ((times - expected) / tol) ** 2
        k = int(np.argmax(seg * weight))
        peak = seg[k]
        if not (peak > 2.0 * self.recent_mean and peak > 1e-3):
            return None
        y0, y1, y2 = o[k], o[k + 1], o[k + 2]
        den = y0 - 2 * y1 + y2
        d = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        t_coarse = float(envelope.frame_time(i0 + k + max(min(d, 0.5), -0.5))) - self.peak_bias
        fine = self.onset_near(t_coarse)
        if math.isfinite(fine) and abs(fine - t_coarse) < 0.03:
            return fine, True, float(peak)
        return t_coarse, False, float(peak)
