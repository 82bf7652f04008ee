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
    """F-measure and timing errors of the beats the tracker committed ``lookahead`` ahead
    (:func:`anticipators.beats.evaluation.score_committed`; beats before ``skip`` seconds left out)."""
    from anticipators.beats.evaluation import score_committed

    beats = np.asarray(true_beats, float)
    beats = beats[np.isfinite(beats)]
    if beats.size == 0 or not updates:
        return {"f_measure": None, "mae_ms": None, "n_beats": 0}
    # the piece ends with its last beat: what the ears commit after it (the ensemble has stopped, the
    # conductor too) is not scored, as beats beyond the audio are not in the real-music protocol
    result = score_committed(updates, beats, lookahead=lookahead, skip=skip, continuity=False,
                             end=float(beats[-1]) + 0.07)
    out = {"f_measure": result["f_measure"], "mae_ms": result["mae_ms"], "mean_error_ms": result["mean_error_ms"],
           "n_beats": result["n_reference"], "n_committed": result["n_estimated"], "lookahead_s": lookahead}
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


def recovery_index(tempo: np.ndarray, target: np.ndarray, first: int, tolerance: float = TOLERANCE) -> int | None:
    """Index of the beat from which ``tempo`` stays within ``tolerance`` of ``target`` to the end: ``first``
    plus :func:`beats_to_recover` (None: never)."""
    beats = beats_to_recover(tempo, target, first, tolerance)
    return None if beats is None else first + beats


def recovery_phrase(beats: int | None, tolerance: float = TOLERANCE) -> str:
    """How a title says :func:`beats_to_recover`: ``"recovered in 6 beats"``, or ``"did not recover to
    within 2 %"`` when it is None (never a "None")."""
    if beats is None:
        return f"did not recover to within {tolerance * 100:g} %"
    return f"recovered in {beats} beat{'' if beats == 1 else 's'}"


def asynchrony_series(onsets: np.ndarray, ictus: dict[int, float]) -> dict:
    """The asynchrony of every conducted beat that was played, as :func:`asynchrony` measures it: each
    musician's onset minus the ictus of its beat (ms).

    ``onsets`` holds musicians in rows and beats (index 0 is beat 1) in columns. Returns ``beats`` (beat
    numbers), ``times`` (their ictus, s), ``musicians`` (ms, one row per musician, NaN where one did not
    play) and ``mean`` (ms, the mean over the musicians who played), for the beats at least one played.
    """
    onsets = np.atleast_2d(np.asarray(onsets, float))
    beats = [b for b in sorted(ictus) if 1 <= b <= onsets.shape[1] and np.isfinite(onsets[:, b - 1]).any()]
    times = np.array([ictus[b] for b in beats], float)
    per = (onsets[:, [b - 1 for b in beats]] - times[None, :]) * 1000.0 if beats else np.empty((onsets.shape[0], 0))
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(per, axis=0) if beats else np.empty(0)
    return {"beats": np.array(beats, int), "times": times, "musicians": per, "mean": mean}


def tempo_figure(beat_times, ensemble_bpm, target_bpm, ictus: dict[int, float], title: str = "",
                 events: list[tuple[float, str]] = (), first_index: int | None = None, onsets=None):
    """The tempo figure (a matplotlib ``Figure``; :func:`plot_tempo` saves it).

    Top panel: target, conductor and ensemble tempo over time, the tolerance band, and, with
    ``first_index`` (index of the first conducted beat), a vertical line at the beat from which the
    ensemble's tempo stays within the tolerance (:func:`recovery_index`, the beat ``beats_to_recover``
    counts to). With ``onsets`` (musicians by beats), a panel below shows the asynchrony of each beat
    (:func:`asynchrony_series`: onset minus ictus, ms), every musician's and their mean.

    Artists by ``get_gid()``: ``"recovery"`` (the line), ``"asynchrony"`` (the mean's line),
    ``"asynchrony-musicians"``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    below = onsets is not None
    fig = Figure(figsize=(10, 6.4 if below else 4.2), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2 if below else 1, 1, sharex=True, squeeze=False,
                        gridspec_kw={"height_ratios": [2.2, 1.0][:2 if below else 1]})
    ax = axes[0][0]
    bt = np.asarray(beat_times, float)
    target = np.asarray(target_bpm, float)
    n = min(bt.size, target.size)
    ok = np.isfinite(bt[:n])
    ax.plot(bt[:n][ok], target[:n][ok], color="black", linestyle="--", linewidth=1.2, label="target (score)")
    band = target[:n][ok]
    ax.fill_between(bt[:n][ok], band * (1 - TOLERANCE), band * (1 + TOLERANCE), color="#dddddd", alpha=0.6,
                    label=f"target +-{TOLERANCE * 100:g} %")
    if ictus:
        beats = np.array(sorted(ictus))
        times = np.array([ictus[b] for b in beats])
        consecutive = np.diff(beats) == 1
        if consecutive.any():
            mid = 0.5 * (times[1:] + times[:-1])
            ax.plot(mid[consecutive], 60.0 / np.diff(times)[consecutive], color="#e6550d", marker=".",
                    markersize=3, linewidth=0.8, label="conductor (ictus intervals)")
    eb = np.asarray(ensemble_bpm, float)[:n]
    good = np.isfinite(eb) & ok[:eb.size]
    ax.plot(bt[:eb.size][good], eb[good], color="#3182bd", linewidth=1.8, label="ensemble (9-beat fit)")
    if bt.size > 1:
        with np.errstate(divide="ignore", invalid="ignore"):
            raw = 60.0 / np.diff(bt)
        mids = 0.5 * (bt[1:] + bt[:-1])
        fine = np.isfinite(raw)
        ax.plot(mids[fine], raw[fine], color="#9ecae1", linewidth=0.6, label="ensemble (beat intervals)")
    panels = [a[0] for a in axes]
    recovered = None
    if first_index is not None and eb.size:
        recovered = recovery_index(eb, target[:eb.size], first_index)
    if recovered is not None and recovered < bt.size and np.isfinite(bt[recovered]):
        t = float(bt[recovered])
        for k, p in enumerate(panels):
            p.axvline(t, color="#31a354", linewidth=1.2, gid="recovery" if k == 0 else "recovery-below")
        after = recovered - first_index
        ax.annotate(f"recovered: within {TOLERANCE * 100:g} % from beat {recovered + 1} on\n"
                    f"({after} beat{'' if after == 1 else 's'} after the first ictus)", (t, 0.04),
                    xycoords=("data", "axes fraction"), xytext=(4, 0), textcoords="offset points", fontsize=7,
                    color="#31a354", ha="left", va="bottom", gid="recovery-label")
    for t, label in events:
        for p in panels:
            p.axvline(t, color="#756bb1", linewidth=0.8, linestyle=":")
        ax.text(t, ax.get_ylim()[1], label, fontsize=7, rotation=90, va="top", ha="right", color="#756bb1")
    ax.set_ylabel("tempo (BPM)")
    ax.set_title(title or "tempo")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    if below:
        bx = panels[1]
        series = asynchrony_series(onsets, ictus)
        if series["beats"].size:
            for row in series["musicians"]:
                fine = np.isfinite(row)
                bx.plot(series["times"][fine], row[fine], ".", color="#9ecae1", markersize=2.5, linestyle="none",
                        gid="asynchrony-musicians")
            bx.plot(series["times"], series["mean"], color="#08519c", linewidth=1.0, marker=".", markersize=3,
                    gid="asynchrony", label="ensemble mean")
            bx.plot([], [], ".", color="#9ecae1", label="each musician")
            mean = float(np.nanmean(series["musicians"]))
            bx.axhline(mean, color="#08519c", linewidth=0.6, linestyle="--", label=f"overall mean {mean:+.1f} ms")
            bx.legend(fontsize=7, loc="upper right", ncol=3)
        else:
            bx.text(0.5, 0.5, "no conducted beat was played", transform=bx.transAxes, ha="center", va="center",
                    fontsize=8, color="#777777")
        bx.axhline(0.0, color="black", linewidth=0.6)
        bx.set_ylabel("asynchrony (ms)\nonset - ictus")
        bx.grid(alpha=0.3)
    panels[-1].set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def plot_tempo(path: str | Path, beat_times, ensemble_bpm, target_bpm, ictus: dict[int, float],
               title: str = "", events: list[tuple[float, str]] = (), first_index: int | None = None,
               onsets=None) -> Path:
    """Target, conductor and ensemble tempo over time, with the recovery point and the asynchrony
    (:func:`tempo_figure`), as a PNG."""
    path = Path(path)
    from agentsim.written import save_figure

    save_figure(tempo_figure(beat_times, ensemble_bpm, target_bpm, ictus, title, events, first_index, onsets), path)
    return path
