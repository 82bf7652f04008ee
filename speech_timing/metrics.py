"""Metrics of speech-gesture synchrony and of animator-time smoothness.

Pure functions of numpy arrays in the style of ``mir_eval``: inputs are validated, times are seconds,
and only the summaries meant for reports (:func:`error_summary`) are in milliseconds.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

__all__ = ["sync_errors", "error_summary", "snaps", "stall_time", "rate_range", "frame_rates", "evaluate",
           "STALL_RATE", "DEFAULT_FRAME"]

#: Animator-time rate below which the animation counts as stalled.
STALL_RATE = 0.5
#: Frame period (s) at which animator time is sampled: 60 Hz.
DEFAULT_FRAME = 1.0 / 60.0


def _vector(name: str, values) -> np.ndarray:
    """``values`` as a 1-D float array of finite numbers (ValueError otherwise)."""
    array = np.asarray(values, dtype=float)
    if array.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, not of shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must contain only finite numbers")
    return array


def _trajectory(t, t_a) -> tuple[np.ndarray, np.ndarray]:
    """Validated clock samples ``t`` (strictly increasing) and animator times ``t_a`` of equal length."""
    t = _vector("t", t)
    t_a = _vector("t_A", t_a)
    if len(t) != len(t_a):
        raise ValueError(f"t and t_A must have the same length ({len(t)} != {len(t_a)})")
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("t must be strictly increasing")
    return t, t_a


def sync_errors(stroke_times, true_onsets) -> np.ndarray:
    """Signed synchronisation error of each gesture stroke: ``stroke - onset`` (s).

    Parameters
    ----------
    stroke_times : array_like of float
        Simulation time of each stroke.
    true_onsets : array_like of float
        Simulation time at which the syllable or word each stroke is aimed at is heard; same length.

    Returns
    -------
    numpy.ndarray
        Errors in seconds; positive means the stroke is late. Empty for empty input.
    """
    strokes = _vector("stroke_times", stroke_times)
    onsets = _vector("true_onsets", true_onsets)
    if len(strokes) != len(onsets):
        raise ValueError(f"stroke_times and true_onsets must have the same length "
                         f"({len(strokes)} != {len(onsets)})")
    return strokes - onsets


def error_summary(errors) -> "OrderedDict[str, float]":
    """Summary of synchronisation errors, in milliseconds.

    Parameters
    ----------
    errors : array_like of float
        Signed errors in seconds (:func:`sync_errors`).

    Returns
    -------
    OrderedDict
        ``p50``, ``p95``, ``max`` and ``mean`` of the *absolute* errors, ``signed_mean`` (positive:
        late on average) and ``n``. All NaN (``n`` = 0) for no errors.
    """
    e = _vector("errors", errors)
    if len(e) == 0:
        nan = float("nan")
        return OrderedDict(p50=nan, p95=nan, max=nan, mean=nan, signed_mean=nan, n=0)
    a = np.abs(e) * 1000.0
    return OrderedDict(p50=float(np.percentile(a, 50)), p95=float(np.percentile(a, 95)), max=float(a.max()),
                       mean=float(a.mean()), signed_mean=float(e.mean() * 1000.0), n=int(len(e)))


def frame_rates(t, t_a) -> np.ndarray:
    """Rate ``d t_A / d t`` over each frame (between consecutive samples); empty for < 2 samples."""
    t, t_a = _trajectory(t, t_a)
    if len(t) < 2:
        return np.zeros(0)
    return np.diff(t_a) / np.diff(t)


def snaps(t, t_a, frame: float = DEFAULT_FRAME) -> int:
    """Number of frames in which animator time visibly jumps.

    Parameters
    ----------
    t : array_like of float
        Clock times of the samples (strictly increasing; normally every ``frame`` seconds).
    t_a : array_like of float
        Animator time at each sample.
    frame : float
        Frame period (s), 1/60 by default.

    Returns
    -------
    int
        Frames where ``t_A`` advances by more than one frame more than the clock did
        (``d t_A > d t + frame``) or goes back by more than one frame (``d t_A < -frame``).
    """
    t, t_a = _trajectory(t, t_a)
    if not frame > 0:
        raise ValueError("frame must be positive")
    if len(t) < 2:
        return 0
    d_a, d_t = np.diff(t_a), np.diff(t)
    return int(np.count_nonzero((d_a > d_t + frame) | (d_a < -frame)))


def stall_time(t, t_a, threshold: float = STALL_RATE) -> float:
    """Total clock time (s) of the frames in which animator time advances slower than ``threshold``.

    A stuck animation (rate 0) and one running backwards both count.
    """
    t, t_a = _trajectory(t, t_a)
    if len(t) < 2:
        return 0.0
    d_t = np.diff(t)
    return float(d_t[np.diff(t_a) < threshold * d_t].sum())


def rate_range(t, t_a) -> tuple[float, float]:
    """Smallest and largest rate ``d t_A / d t`` over the frames (NaN, NaN for < 2 samples)."""
    rates = frame_rates(t, t_a)
    if len(rates) == 0:
        return float("nan"), float("nan")
    return float(rates.min()), float(rates.max())


def evaluate(stroke_times, true_onsets, t, t_a, frame: float = DEFAULT_FRAME) -> "OrderedDict[str, object]":
    """All metrics of one run, in an ordered dict.

    Parameters
    ----------
    stroke_times, true_onsets : array_like of float
        Stroke times and the true onsets they aim at (s).
    t, t_a : array_like of float
        Animator time sampled at clock times ``t`` (every ``frame`` seconds).
    frame : float
        Frame period (s).

    Returns
    -------
    OrderedDict
        ``error_ms`` (:func:`error_summary`), ``snaps``, ``stall_s`` and ``rate`` (``min``, ``max``).
    """
    low, high = rate_range(t, t_a)
    return OrderedDict(
        error_ms=error_summary(sync_errors(stroke_times, true_onsets)),
        snaps=snaps(t, t_a, frame),
        stall_s=stall_time(t, t_a),
        rate=OrderedDict(min=low, max=high),
    )
