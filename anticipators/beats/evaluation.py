"""Evaluation of beats committed ahead of time, and a driver that runs trackers over audio.

A tracker's output is a sequence of updates ``(t, beats)``: having heard audio up to ``t`` seconds,
it predicts the upcoming beats ``beats``. A performer that must act ``lookahead`` seconds before a beat
sounds plays the *committed sequence* (:func:`committed_beats`): every beat ``b`` that the update in
force at ``b - lookahead`` predicted, i.e. predicted by the update at ``u`` with
``u <= b - lookahead < u_next`` (``u_next`` the next update's time). That sequence is what is scored
(:func:`score_beats`, :func:`score_committed`): ``mir_eval.beat``'s F-measure (70 ms window), CMLt,
AMLt and P-score after trimming both sequences with ``mir_eval.beat.trim_beats`` (the first 5 s left
out by default), so that an extra or doubled beat counts against the tracker, and timing errors of the
committed beats that hit a reference beat, in milliseconds.
"""

from __future__ import annotations

import math
import os
import time as _time
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "normalize_updates",
    "committed_beats",
    "beat_f_measure",
    "score_beats",
    "score_committed",
    "time_to_correct",
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


def committed_beats(updates, lookahead: float = 0.2, end: float | None = None) -> np.ndarray:
    """The beats a performer that must act ``lookahead`` seconds early would produce.

    Every beat ``b`` predicted by the update at time ``u`` such that ``u <= b - lookahead < u_next``,
    ``u_next`` being the next update's time (infinity after the last update): each beat as the tracker
    predicted it at the latest update at least ``lookahead`` seconds before it sounds.

    Parameters
    ----------
    updates : sequence
        ``[(t, beats), ...]`` or ``[{"t": t, "beats": beats}, ...]`` in order of time.
    lookahead : float
        How long before a beat the performer must act on it (seconds, at least 0).
    end : float, optional
        Beats after this time (the end of the audio) are left out.

    Returns
    -------
    numpy.ndarray
        Committed beat times in seconds, increasing.
    """
    if lookahead < 0:
        raise ValueError("lookahead must be at least 0")
    times, beats = normalize_updates(updates)
    out = []
    for i, (u, pred) in enumerate(zip(times, beats)):
        u_next = times[i + 1] if i + 1 < times.size else math.inf
        lead = pred - lookahead
        keep = pred[np.isfinite(pred) & (lead >= u) & (lead < u_next)]
        if end is not None:
            keep = keep[keep <= end]
        out.append(keep)
    if not out:
        return np.zeros(0)
    return np.sort(np.concatenate(out))


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


def score_beats(
    reference: Sequence[float],
    estimated: Sequence[float],
    skip: float = 5.0,
    window: float = 0.07,
    *,
    continuity: bool = True,
) -> dict:
    """Score a beat sequence against reference beats with ``mir_eval.beat``.

    Both sequences are trimmed with ``mir_eval.beat.trim_beats(beats, skip)`` (beats before ``skip``
    seconds left out), then scored.

    Parameters
    ----------
    reference : sequence of float
        Reference beat times in seconds.
    estimated : sequence of float
        The tracker's beats (a committed sequence, :func:`committed_beats`).
    skip : float
        Beats before this time (seconds) are left out of both (5 s, the protocol's).
    window : float
        F-measure tolerance in seconds (mir_eval's 70 ms).
    continuity : bool
        Whether to compute CMLt, AMLt and P-score (they import mir_eval and scipy.stats, about 1.5 s
        the first time); without them only the F-measure and the timing errors.

    Returns
    -------
    dict
        ``f_measure`` (mir_eval's, NaN without reference beats), ``cmlt``, ``amlt``, ``p_score`` (with
        ``continuity``); ``mae_ms``, ``mean_error_ms`` (positive: late), ``median_abs_error_ms``: errors
        of the nearest estimated beat to each reference beat, over the reference beats it hits (within
        ``window``); ``n_reference``, ``n_estimated`` (after trimming); ``silent``: no estimated beat.
    """
    ref = np.sort(np.asarray(reference, float).reshape(-1))
    est = np.sort(np.asarray(estimated, float).reshape(-1))
    ref, est = ref[ref >= skip], est[est >= skip]  # mir_eval.beat.trim_beats
    nan = float("nan")
    if ref.size == 0:
        f = nan
    else:
        f = float(beat_f_measure(ref, est, window))
    out = {"f_measure": f}
    if continuity:
        out.update(_continuity(ref, est, skip))
    err = np.zeros(0)
    if ref.size and est.size:
        k = np.clip(np.searchsorted(est, ref), 1, max(est.size - 1, 1))
        lo = est[np.minimum(k - 1, est.size - 1)]
        hi = est[np.minimum(k, est.size - 1)]
        nearest = np.where(np.abs(lo - ref) <= np.abs(hi - ref), lo, hi)
        err = nearest - ref
        err = err[np.abs(err) <= window]
    out.update(
        mae_ms=float(np.mean(np.abs(err)) * 1000) if err.size else nan,
        mean_error_ms=float(np.mean(err) * 1000) if err.size else nan,
        median_abs_error_ms=float(np.median(np.abs(err)) * 1000) if err.size else nan,
        n_reference=int(ref.size),
        n_estimated=int(est.size),
        silent=bool(est.size == 0),
    )
    return out


def _continuity(ref: np.ndarray, est: np.ndarray, skip: float) -> dict:
    """CMLt, AMLt and P-score of trimmed sequences by ``mir_eval.beat`` (0 where mir_eval gives 0 for too
    few beats)."""
    import warnings

    import mir_eval

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # mir_eval warns of empty sequences, and scores them 0
        ref_t = mir_eval.beat.trim_beats(ref, skip)
        est_t = mir_eval.beat.trim_beats(est, skip)
        _, cmlt, _, amlt = mir_eval.beat.continuity(ref_t, est_t)
        p = mir_eval.beat.p_score(ref_t, est_t)
    return {"cmlt": float(cmlt), "amlt": float(amlt), "p_score": float(p)}


def score_committed(
    updates,
    reference: Sequence[float],
    lookahead: float = 0.2,
    skip: float = 5.0,
    window: float = 0.07,
    *,
    end: float | None = None,
    continuity: bool = True,
) -> dict:
    """:func:`score_beats` of the sequence committed ``lookahead`` seconds ahead (:func:`committed_beats`).

    Returns
    -------
    dict
        :func:`score_beats`' figures plus ``lookahead`` and ``time_to_4``
        (:func:`time_to_correct` of the untrimmed sequences; None if never).
    """
    committed = committed_beats(updates, lookahead, end)
    out = score_beats(reference, committed, skip, window, continuity=continuity)
    out["lookahead"] = float(lookahead)
    out["time_to_4"] = time_to_correct(reference, committed, 4, window)
    return out


def time_to_correct(reference: Sequence[float], estimated: Sequence[float], count: int = 4,
                    window: float = 0.07, *, consecutive: bool = True) -> float | None:
    """When the tracker has first got ``count`` consecutive beats right.

    The time (s) of the last of the first ``count`` consecutive reference beats that each have an
    estimated beat within ``window``; None if there is no such run. With ``consecutive=False``, the
    time of the ``count``-th reference beat with an estimated beat within ``window``.
    """
    ref = np.sort(np.asarray(reference, float).reshape(-1))
    est = np.sort(np.asarray(estimated, float).reshape(-1))
    if ref.size < count or est.size == 0:
        return None
    k = np.searchsorted(est, ref)
    lo = np.abs(est[np.clip(k - 1, 0, est.size - 1)] - ref)
    hi = np.abs(est[np.clip(k, 0, est.size - 1)] - ref)
    hit = np.minimum(lo, hi) <= window
    run = 0
    for i, h in enumerate(hit):
        run = run + 1 if h else (run if not consecutive else 0)
        if run >= count:
            return float(ref[i])
    return None


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
    tracker_name : {"causal", "baseline", "aubio", "librosa_offline"}
        :class:`~anticipators.beats.tracking.CausalBeatTracker`, the
        :class:`~anticipators.beats.baselines.IOIBaselineTracker`, aubio's online tracker
        (:class:`~anticipators.beats.baselines.AubioTracker`, when aubio is installed) or librosa's
        offline beat tracker (one update at 0 s holding every beat it finds in the whole audio).
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
        ``{"tracker": name, "audio_seconds": float, "wall_seconds": float, "cpu_seconds": float,
        "sample_rate": int, "updates": [{"t": T, "beats": [...]}, ...]}``, with an update after every
        block whose predictions differ from the previous update's; ``cpu_seconds`` is the process's CPU
        time spent tracking (reading the file not counted).
    """
    from anticipators.beats.baselines import librosa_offline_beats
    from anticipators.beats.tracking import make_tracker

    audio, sr = _load_audio(source, sample_rate)
    audio_seconds = audio.size / sr
    updates: list[dict] = []
    if tracker_name == "librosa_offline":
        t0, c0 = _time.perf_counter(), _time.process_time()
        beats = librosa_offline_beats(audio, sr)
        wall, cpu = _time.perf_counter() - t0, _time.process_time() - c0
        updates.append({"t": 0.0, "beats": [float(b) for b in beats]})
    else:
        tracker = make_tracker(tracker_name, sr, **(tracker_options or {}))
        block_size = max(int(block_size), 1)
        last = None
        t0, c0 = _time.perf_counter(), _time.process_time()
        if hasattr(tracker, "track"):  # the same updates, asked for only when they may change
            updates = tracker.track(audio, block_size, horizon_beats)
        else:
            for a in range(0, audio.size, block_size):
                tracker.process(audio[a : a + block_size])
                pred = tracker.predict(horizon_beats).tolist()
                if pred != last:  # (a NaN differs from every number, itself too, as in np.array_equal)
                    updates.append({"t": tracker.time, "beats": pred})
                    last = pred
        wall, cpu = _time.perf_counter() - t0, _time.process_time() - c0
    return {
        "tracker": tracker_name,
        "audio_seconds": float(audio_seconds),
        "wall_seconds": float(wall),
        "cpu_seconds": float(cpu),
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
    skip: float = 5.0,
    tracker_options: dict | None = None,
    continuity: bool = True,
    end: float | None = None,
) -> dict:
    """:func:`track_file` followed by :func:`score_committed` of the beats committed ``lookahead`` ahead
    (up to ``end`` seconds, by default the end of the audio).

    Returns
    -------
    dict
        The scores plus ``tracker``, ``audio_seconds``, ``wall_seconds``, ``cpu_seconds`` and
        ``real_time_factor`` (CPU time over audio time).
    """
    run = track_file(source, tracker_name, block_size, sample_rate=sample_rate, tracker_options=tracker_options)
    res = score_committed(run["updates"], true_beats, lookahead=lookahead, skip=skip,
                          end=run["audio_seconds"] if end is None else end, continuity=continuity)
    res.update(
        tracker=tracker_name,
        audio_seconds=run["audio_seconds"],
        wall_seconds=run["wall_seconds"],
        cpu_seconds=run["cpu_seconds"],
        real_time_factor=run["cpu_seconds"] / max(run["audio_seconds"], 1e-9),
    )
    return res
