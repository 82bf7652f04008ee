"""Evaluation of beat predictions made ahead of time, and a driver that runs trackers over audio.

A tracker's output is a sequence of updates ``(t, beats)``: having heard audio up to ``t`` seconds,
it predicts the upcoming beats ``beats``. To judge predictions made ``lookahead`` seconds ahead, each
true beat ``b`` is paired with the last update made at or before ``b - lookahead`` and that update's
predicted beat nearest to ``b`` (:func:`select_predictions`). :func:`evaluate_predictions` scores
those with mir_eval's beat F-measure (70 ms window; :func:`beat_f_measure`) and reports timing errors in
milliseconds.
"""

from __future__ import annotations

import os
import time as _time
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "normalize_updates",
    "select_predictions",
    "evaluate_predictions",
    "track_file",
    "track_and_evaluate",
]


def normalize_updates(updates) -> tuple[np.ndarray, list[np.ndarray]]:
    """Update times and predicted beat arrays from ``[(t, beats), ...]`` or ``[{"t": t, "beats": beats}, ...]``.

    Parameters
    ----------
    updates : sequence
        Updates as pairs or as dicts with keys ``"t"`` and ``"beats"``, in order of time.

    Returns
    -------
    times : numpy.ndarray
        Update times in seconds.
    beats : list of numpy.ndarray
        Predicted beat times of each update.
    """
    times, beats = [], []
    for u in updates:
        if isinstance(u, Mapping):
            t, b = u["t"], u["beats"]
        else:
            t, b = u
        times.append(float(t))
        beats.append(np.asarray(b, float).reshape(-1))
    times_arr = np.asarray(times, float)
    if times_arr.size > 1 and np.any(np.diff(times_arr) < 0):
        raise ValueError("updates must be in order of time")
    return times_arr, beats


def select_predictions(updates, true_beats: Sequence[float], lookahead: float = 0.2) -> np.ndarray:
    """The prediction of each true beat made at least ``lookahead`` seconds before it.

    For each true beat ``b``, take the last update made at or before ``b - lookahead`` and its predicted
    beat nearest to ``b``.

    Parameters
    ----------
    updates : sequence
        ``[(t, beats), ...]`` or ``[{"t": t, "beats": beats}, ...]`` in order of time.
    true_beats : sequence of float
        Reference beat times in seconds.
    lookahead : float
        How long before a beat its prediction must have been made, in seconds.

    Returns
    -------
    numpy.ndarray
        One predicted time per true beat (NaN where no update qualifies or it predicts nothing).
    """
    times, beats = normalize_updates(updates)
    true_beats = np.asarray(true_beats, float).reshape(-1)
    out = np.full(true_beats.shape, np.nan)
    idx = np.searchsorted(times, true_beats - lookahead, side="right") - 1
    for i, (b, k) in enumerate(zip(true_beats, idx)):
        if k < 0:
            continue
        pred = beats[k]
        if pred.size:
            out[i] = pred[np.argmin(np.abs(pred - b))]
    return out


#: The largest beat time (s) mir_eval's beat metrics accept.
MAX_BEAT_TIME = 30000.0


def beat_f_measure(reference: np.ndarray, estimated: np.ndarray, window: float = 0.07) -> float:
    """mir_eval's beat F-measure (``mir_eval.beat.f_measure``), the same number, without importing
    mir_eval (which imports scipy.stats, a second and a half).

    Both arrays are sorted beat times in seconds. An estimate ``e`` may match a reference beat ``r`` when
    ``e - window <= r <= e + window`` (mir_eval's hit test); the matching is a largest one, each beat used
    at most once. The neighbours of each reference beat are a run of the sorted estimates whose ends move
    only forward from one reference beat to the next, so matching each one to the earliest estimate still
    free is a largest matching.
    """
    reference = np.asarray(reference, float)
    estimated = np.asarray(estimated, float)
    for beats in (reference, estimated):
        if (beats > MAX_BEAT_TIME).any() or beats.ndim != 1 or (np.diff(beats) < 0).any():
            raise ValueError("beat times must be increasing seconds, at most 30,000")
    if estimated.size == 0 or reference.size == 0:
        return 0.0
    low, high = estimated - window, estimated + window
    matched = 0
    j = 0
    for r in reference:
        while j < len(estimated) and high[j] < r:
            j += 1  # too early for this reference beat, so for every later one
        if j < len(estimated) and low[j] <= r:
            matched += 1
            j += 1
    precision = float(matched) / len(estimated)
    recall = float(matched) / len(reference)
    if precision == 0 and recall == 0:
        return 0.0
    return (1 + 1**2) * precision * recall / ((1**2) * precision + recall)


def evaluate_predictions(
    updates,
    true_beats: Sequence[float],
    lookahead: float = 0.2,
    skip: float = 8.0,
    window: float = 0.07,
) -> dict:
    """Score beat predictions made ``lookahead`` seconds ahead.

    Parameters
    ----------
    updates : sequence
        ``[(t, beats), ...]`` or ``[{"t": t, "beats": beats}, ...]`` in order of time.
    true_beats : sequence of float
        Reference beat times in seconds.
    lookahead : float
        Prediction lead in seconds (0.2 s by default).
    skip : float
        True beats before this time (seconds) are left out.
    window : float
        F-measure tolerance in seconds (mir_eval's default 70 ms).

    Returns
    -------
    dict
        ``f_measure``: mir_eval beat F-measure of the selected predictions against the true beats
        (a true beat without a prediction is a miss; a predicted time chosen for two beats counts
        twice); ``mae_ms``: mean absolute error of the selected predictions in ms; ``mean_error_ms``:
        mean signed error (positive = predicted late) in ms; ``median_abs_error_ms``;
        ``within_window``: fraction of true beats whose prediction is within ``window``;
        ``n_beats``: true beats scored; ``n_predicted``: of them with a prediction.
    """
    true_beats = np.sort(np.asarray(true_beats, float).reshape(-1))
    ref = true_beats[true_beats >= skip]
    pred = select_predictions(updates, ref, lookahead)
    have = np.isfinite(pred)
    err = pred[have] - ref[have]
    est = np.sort(pred[have])
    if ref.size == 0:
        f = float("nan")
    elif est.size == 0:
        f = 0.0
    else:
        f = float(beat_f_measure(ref, est, window))
    nan = float("nan")
    return {
        "f_measure": f,
        "mae_ms": float(np.mean(np.abs(err)) * 1000) if err.size else nan,
        "mean_error_ms": float(np.mean(err) * 1000) if err.size else nan,
        "median_abs_error_ms": float(np.median(np.abs(err)) * 1000) if err.size else nan,
        "within_window": float(np.mean(np.abs(err) <= window) * have.mean()) if err.size else 0.0,
        "n_beats": int(ref.size),
        "n_predicted": int(have.sum()),
    }


def _load_audio(source, sample_rate: int | None) -> tuple[np.ndarray, int]:
    if isinstance(source, (str, os.PathLike)):
        import soundfile as sf

        audio, sr = sf.read(os.fspath(source), dtype="float32", always_2d=True)
        return audio.mean(axis=1), int(sr)
    if sample_rate is None:
        raise ValueError("sample_rate is needed when audio is given as an array")
    audio = np.asarray(source, np.float32)
    if audio.ndim == 2:
        audio = audio.mean(axis=1)
    return audio, int(sample_rate)


def track_file(
    source,
    tracker_name: str = "causal",
    block_size: int = 512,
    *,
    sample_rate: int | None = None,
    horizon_beats: int = 4,
    tracker_options: dict | None = None,
) -> dict:
    """Run a tracker over audio block by block and record its predictions.

    A tracker with a ``track`` method (:meth:`~anticipators.beats.tracking.CausalBeatTracker.track`) records
    them itself: the same updates as asking for predictions after every block, without asking while
    they cannot have changed.

    Parameters
    ----------
    source : str or path-like or numpy.ndarray
        An audio file (read with soundfile, mixed to mono) or mono samples.
    tracker_name : {"causal", "baseline", "librosa_offline"}
        :class:`~anticipators.beats.tracking.CausalBeatTracker`, the
        :class:`~anticipators.beats.baselines.IOIBaselineTracker`, or librosa's offline beat tracker
        (one update at 0 s holding every beat it finds in the whole audio).
    block_size : int
        Samples per block fed to the tracker.
    sample_rate : int, optional
        Sample rate of ``source`` when it is an array.
    horizon_beats : int
        Beats asked of ``predict`` after each block.
    tracker_options : dict, optional
        Keyword arguments for the tracker.

    Returns
    -------
    dict
        ``{"tracker": name, "audio_seconds": float, "wall_seconds": float, "sample_rate": int,
        "updates": [{"t": T, "beats": [...]}, ...]}``, with an update after every block whose
        predictions differ from the previous update's.
    """
    from anticipators.beats.baselines import librosa_offline_beats
    from anticipators.beats.tracking import make_tracker

    audio, sr = _load_audio(source, sample_rate)
    audio_seconds = audio.size / sr
    updates: list[dict] = []
    if tracker_name == "librosa_offline":
        t0 = _time.perf_counter()
        beats = librosa_offline_beats(audio, sr)
        wall = _time.perf_counter() - t0
        updates.append({"t": 0.0, "beats": [float(b) for b in beats]})
    else:
        tracker = make_tracker(tracker_name, sr, **(tracker_options or {}))
        block_size = max(int(block_size), 1)
        last = None
        t0 = _time.perf_counter()
        if hasattr(tracker, "track"):  # the same updates, asked for only when they may change
            updates = tracker.track(audio, block_size, horizon_beats)
        else:
            for a in range(0, audio.size, block_size):
                tracker.process(audio[a : a + block_size])
                pred = tracker.predict(horizon_beats).tolist()
                if pred != last:  # (a NaN differs from every number, itself too, as in np.array_equal)
                    updates.append({"t": tracker.time, "beats": pred})
                    last = pred
        wall = _time.perf_counter() - t0
    return {
        "tracker": tracker_name,
        "audio_seconds": float(audio_seconds),
        "wall_seconds": float(wall),
        "sample_rate": int(sr),
        "updates": updates,
    }


def track_and_evaluate(
    source,
    true_beats: Sequence[float],
    tracker_name: str = "causal",
    block_size: int = 512,
    *,
    sample_rate: int | None = None,
    lookahead: float = 0.2,
    skip: float = 8.0,
    tracker_options: dict | None = None,
) -> dict:
    """:func:`track_file` followed by :func:`evaluate_predictions`; adds ``real_time_factor``.

    Returns
    -------
    dict
        The evaluation figures plus ``tracker``, ``audio_seconds``, ``wall_seconds`` and
        ``real_time_factor`` (wall time over audio time).
    """
    run = track_file(source, tracker_name, block_size, sample_rate=sample_rate, tracker_options=tracker_options)
    res = evaluate_predictions(run["updates"], true_beats, lookahead=lookahead, skip=skip)
    res.update(
        tracker=tracker_name,
        audio_seconds=run["audio_seconds"],
        wall_seconds=run["wall_seconds"],
        real_time_factor=run["wall_seconds"] / max(run["audio_seconds"], 1e-9),
    )
    return res
