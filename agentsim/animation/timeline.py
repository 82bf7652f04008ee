"""The timeline picture: behaviours, phases, sync points, shared pegs and feedback on one time axis (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agentsim.animation.output import PoseStream
from agentsim.animation.units import PHASE_NAMES

_PHASE_COLOURS = {
    "preparation": "#9ecae1", "pre-stroke hold": "#deebf7", "stroke": "#e6550d", "post-stroke hold": "#fdd0a2",
    "retraction": "#c7e9c0", "hold": "#deebf7", "attack": "#9ecae1", "sustain": "#deebf7",
    "transition": "#bcbddc", "speech": "#d9d9d9",
}


def plot_timeline(source, out_png: str | Path, stream: PoseStream | None = None, title: str | None = None,
                  width: float = 12.0) -> Path:
    """Draw what a run did on one time axis and save it as a PNG.

    ``source``: its :class:`~agentsim.core.recording.Recording`, or a realizer after ``run()``.

    One row per behaviour (block:behaviour) with its phases shaded between its sync points (dropped
    behaviours hatched up to where they stopped), a tick and label at every sync point, dashed lines
    joining sync points that share a time peg, block starts and ends, and a feedback row with every
    sync point progress (dots), prediction (diamonds) and warning (red triangles). With ``stream``, a
    panel below shows the wrist heights and head pitch of the evaluated poses with the stroke feedback.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    out_png = Path(out_png)
    recording = source.recording() if hasattr(source, "recording") else source
    items = list(recording.feedback)
    rows = list(recording.behaviours)
    n_rows = len(rows) + 1
    panels = 2 if stream is not None else 1
    height = max(2.5, 0.42 * n_rows + 1.5) + (2.2 if stream is not None else 0.0)
    fig, axes = plt.subplots(panels, 1, figsize=(width, height), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [max(3, n_rows), 3][:panels]})
    ax = axes[0][0]
    all_times: list[float] = []
    peg_points: dict[int, list[tuple[float, float]]] = {}
    labels: list[tuple[float, str]] = [(-0.45, "feedback")]
    for row, timed in enumerate(rows):
        y = n_rows - 1 - row
        times = timed.times
        known = [(s, t) for s, t in zip(timed.sync_ids, times) if t is not None]
        if not known:
            continue
        stop = None
        if timed.state == "dropped":
            passed = [t for t, p in zip(times, timed.passed) if p]
            stop = passed[-1] if passed else known[0][1]
        for (s0, t0), (s1, t1) in zip(known, known[1:]):
            phase = PHASE_NAMES.get((s0, s1), "speech" if timed.behaviour.type == "speech" else "hold")
            if timed.behaviour.type == "speech":
                phase = "speech"
            dropped_part = stop is not None and t0 >= stop
            ax.barh(y, t1 - t0, left=t0, height=0.6, color=_PHASE_COLOURS.get(phase, "#eeeeee"),
                    edgecolor="#555555", linewidth=0.4, hatch="///" if dropped_part else None,
                    alpha=0.35 if dropped_part else 1.0)
        for i, (s, t) in enumerate(zip(timed.sync_ids, times)):
            if t is None:
                continue
            all_times.append(t)
            ax.plot([t, t], [y - 0.32, y + 0.32], color="black", linewidth=0.8)
            if s == "stroke" or (timed.behaviour.type == "speech" and 0 < i < len(times) - 1):
                ax.text(t, y + 0.33, s, fontsize=5.5, ha="center", va="bottom", color="#444444")
            group = timed.peg_groups[i] if i < len(timed.peg_groups) else None
            if group is not None:
                peg_points.setdefault(group, []).append((t, y))
        label = f"{timed.name} ({timed.behaviour.type}"
        lex = timed.behaviour.attributes.get("lexeme")
        label += f" {lex})" if lex else ")"
        if timed.state == "dropped":
            label += " dropped"
        labels.append((y, label))
    for pts in peg_points.values():
        if len(pts) > 1:
            for t in sorted({round(p[0], 9) for p in pts}):
                ys = [p[1] for p in pts if abs(p[0] - t) < 1e-9]
                if len(ys) > 1:
                    ax.plot([t, t], [min(ys), max(ys)], color="#3182bd", linestyle="--", linewidth=0.8)
    y_fb = -0.2
    for f in items:
        t = f.get("globalTime")
        if t is None:
            continue
        all_times.append(t)
        kind = f["type"]
        if kind == "syncPointProgress":
            ax.plot(t, y_fb, "o", color="#636363", markersize=2.5)
        elif kind == "predictionFeedback":
            ax.plot(t, y_fb - 0.25, "D", color="#756bb1", markersize=3)
        elif kind == "warningFeedback":
            ax.plot(t, y_fb - 0.5, "^", color="#de2d26", markersize=5)
            ax.text(t, y_fb - 0.75, str(f.get("warningType", "")), fontsize=5.5, color="#de2d26", ha="center",
                    va="top")
        elif kind == "blockProgress":
            ax.axvline(t, color="#bdbdbd", linewidth=0.6, linestyle=":")
            ax.text(t, n_rows - 0.4, str(f.get("id", "")), fontsize=6, rotation=90, va="top", color="#777777")
    ax.set_yticks([y for y, _ in labels], [lab for _, lab in labels], fontsize=6.5)
    ax.set_ylim(-1.3, n_rows)
    ax.legend(handles=[Patch(color=c, label=n) for n, c in _PHASE_COLOURS.items() if n not in ("hold",)],
              loc="upper right", fontsize=6, ncol=5, framealpha=0.8)
    ax.set_title(title or "behaviours, phases, pegs and feedback")
    if stream is not None:
        bx = axes[1][0]
        for joint, colour in (("l_wrist", "#31a354"), ("r_wrist", "#e6550d")):
            bx.plot(stream.times, stream.position(joint)[:, 1], color=colour, linewidth=0.9,
                    label=f"{joint} height (m)")
        bx.set_ylabel("height (m)", fontsize=7)
        cx = bx.twinx()
        fwd = stream.forward("skullbase")
        cx.plot(stream.times, -np.degrees(np.arcsin(np.clip(fwd[:, 1], -1, 1))), color="#756bb1", linewidth=0.8,
                label="head pitch down (deg)")
        cx.set_ylabel("head pitch (deg)", fontsize=7)
        for f in items:
            if f["type"] == "syncPointProgress" and f["id"].endswith(":stroke"):
                bx.axvline(f["globalTime"], color="#de2d26", linewidth=0.6, linestyle="--")
        bx.legend(loc="upper left", fontsize=6)
        cx.legend(loc="upper right", fontsize=6)
        all_times.extend([float(stream.times[0]), float(stream.times[-1])])
    if all_times:
        lo, hi = min(all_times), max(all_times)
        pad = 0.03 * max(hi - lo, 1.0)
        axes[-1][0].set_xlim(lo - pad, hi + pad)
    axes[-1][0].set_xlabel("global time (s)")
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    plt.close(fig)
    return out_png
