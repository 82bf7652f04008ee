"""What a run achieved: tempo curves, recovery, asynchrony, beat-prediction scores, and the tempo plot.

The ensemble's tempo at a beat is ``60 / slope`` of the least-squares line through its beats within
``TEMPO_WINDOW`` beats around it (9: two bars of 4/4, centred), so that single onsets' noise (a 12 ms
timekeeper makes single beat intervals wander by several percent) does not count as tempo.
``beats_to_recover`` counts conducted beats from the first ictus until the ensemble's tempo stays within
``TOLERANCE`` of the score's to the end.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

TEMPO_WINDOW = 9
TOLERANCE = 0.02


def local_tempo(beat_times, window: int = TEMPO_WINDOW) -> np.ndarray:
    """Tempo (BPM) at each beat from a least-squares line through the ``window`` beats centred on it.

    NaN where the window is not complete (ends of the piece, beats not played).
    """
    t = np.asarray(beat_times, float)
    n = t.size
    out = np.full(n, np.nan)
    h = window // 2
    if n < window:
        return out
    x = np.arange(window) - h
    sxx = float(x @ x)
    windows = np.lib.stride_tricks.sliding_window_view(t, window)  # (n - window + 1, window)
    slope = windows @ x / sxx
    with np.errstate(divide="ignore", invalid="ignore"):
        out[h:n - h] = np.where(slope > 0, 60.0 / slope, np.nan)
    return out


def beats_to_recover(tempo: np.ndarray, target: np.ndarray, first: int, tolerance: float = TOLERANCE) -> int | None:
    """Beats from index ``first`` until ``tempo`` stays within ``tolerance`` of ``target`` (None: never).

    Only beats with a tempo are judged; at least one bar's worth (4) must remain within.
    """
    tempo = np.asarray(tempo, float)
    target = np.asarray(target, float)
    valid = np.nonzero(np.isfinite(tempo))[0]
    valid = valid[valid >= first]
    if valid.size == 0:
        return None
    ok = np.abs(tempo[valid] / target[valid] - 1.0) <= tolerance + 1e-12
    if ok[-1] == 0:
        return None
    bad = np.nonzero(~ok)[0]
    start = 0 if bad.size == 0 else bad[-1] + 1
    if valid.size - start < 4:
        return None
    return int(valid[start] - first)


def asynchrony(onsets: np.ndarray, ictus: dict[int, float]) -> dict:
    """Mean and standard deviation (ms) of every musician's onset minus the ictus of its beat.

    ``onsets`` holds musicians in rows and beats (index 0 is beat 1) in columns.
    """
    values = []
    for beat, c in ictus.items():
        if 1 <= beat <= onsets.shape[1]:
            col = onsets[:, beat - 1]
            values.append(col[np.isfinite(col)] - c)
    if not values:
        return {"mean": None, "sd": None, "n": 0}
    v = np.concatenate(values) * 1000.0
    return {"mean": round(float(v.mean()), 2), "sd": round(float(v.std()), 2), "n": int(v.size)}


def anticipator_scores(updates, true_beats, lookahead: float = 0.2, skip: float = 8.0) -> dict:
    """F-measure and errors of the tracker's predictions ``lookahead`` ahead (:func:`evaluate_predictions`)."""
    from agentsim.beats.evaluation import evaluate_predictions

    beats = np.asarray(true_beats, float)
    beats = beats[np.isfinite(beats)]
    if beats.size == 0 or not updates:
        return {"f_measure": None, "mae_ms": None, "n_beats": 0}
    result = evaluate_predictions(updates, beats, lookahead=lookahead, skip=skip)
    out = {"f_measure": result["f_measure"], "mae_ms": result["mae_ms"], "mean_error_ms": result["mean_error_ms"],
           "n_beats": result["n_beats"], "lookahead_s": lookahead}
    return {k: (round(v, 4) if isinstance(v, float) and math.isfinite(v) else (None if isinstance(v, float) else v))
            for k, v in out.items()}


def tempo_summary(beat_times: np.ndarray, target_bpm: np.ndarray, first_index: int) -> dict:
    """Recovery and final tempo error of the ensemble (``first_index``: index of the first conducted beat)."""
    tempo = local_tempo(beat_times)
    n = min(tempo.size, target_bpm.size)
    tempo, target = tempo[:n], target_bpm[:n]
    rec = beats_to_recover(tempo, target, first_index)
    valid = np.nonzero(np.isfinite(tempo))[0]
    final = None
    if valid.size:
        last = valid[-4:]
        final = round(float(np.mean(tempo[last] / target[last] - 1.0) * 100.0), 3)
    return {"tempo": tempo, "beats_to_recover": rec, "final_tempo_error_pct": final}


def plot_tempo(path: str | Path, beat_times, ensemble_bpm, target_bpm, ictus: dict[int, float],
               title: str = "", events: list[tuple[float, str]] = ()) -> Path:
    """Target, conductor and ensemble tempo over time, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, ax = plt.subplots(figsize=(10, 4.2))
    bt = np.asarray(beat_times, float)
    n = min(bt.size, len(target_bpm))
    ok = np.isfinite(bt[:n])
    ax.plot(bt[:n][ok], np.asarray(target_bpm)[:n][ok], color="black", linestyle="--", linewidth=1.2,
            label="target (score)")
    band = np.asarray(target_bpm)[:n][ok]
    ax.fill_between(bt[:n][ok], band * (1 - TOLERANCE), band * (1 + TOLERANCE), color="#dddddd", alpha=0.6,
                    label="target +-2 %")
    if ictus:
        beats = np.array(sorted(ictus))
        times = np.array([ictus[b] for b in beats])
        consecutive = np.diff(beats) == 1
        if consecutive.any():
            mid = 0.5 * (times[1:] + times[:-1])
            ax.plot(mid[consecutive], 60.0 / np.diff(times)[consecutive], color="#e6550d", marker=".",
                    markersize=3, linewidth=0.8, label="conductor (ictus intervals)")
    eb = np.asarray(ensemble_bpm, float)[:n]
    good = np.isfinite(eb) & ok
    ax.plot(bt[:n][good], eb[good], color="#3182bd", linewidth=1.8, label="ensemble (9-beat fit)")
    if bt.size > 1:
        raw = 60.0 / np.diff(bt)
        mids = 0.5 * (bt[1:] + bt[:-1])
        fine = np.isfinite(raw)
        ax.plot(mids[fine], raw[fine], color="#9ecae1", linewidth=0.6, label="ensemble (beat intervals)")
    for t, label in events:
        ax.axvline(t, color="#756bb1", linewidth=0.8, linestyle=":")
        ax.text(t, ax.get_ylim()[1], label, fontsize=7, rotation=90, va="top", ha="right", color="#756bb1")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tempo (BPM)")
    ax.set_title(title or "tempo")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
