"""The report's picture of the physical body: the centre of mass against the support polygon.

``physics.svg`` (written by :func:`write_physics_svg` into a report's folder when the run's body was
simulated, ``--physics``) has two panels over the run's time: sideways (x, +x the body's left) and forward
(z, the way it faces), each with the support polygon's bounding box as a band and the centre of mass's
ground projection as a line; the frames where the projection is outside the band are marked below, and a
fall by a vertical line. Plain SVG, no script: it shows in the page as an image, and opens alone.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from agentsim.written import written

#: The picture's size (px) and the most points a line has (a long run's frames are thinned to these).
WIDTH, PANEL, MARGIN, MAX_POINTS = 900, 170, 48, 1500


def _panel(top: float, t: np.ndarray, com: np.ndarray, lo: np.ndarray, hi: np.ndarray, label: str,
           span: tuple[float, float]) -> list[str]:
    """One panel's SVG elements: the support band, the centre of mass, the axes and labels (m -> cm)."""
    t0, t1 = span
    low, high = float(min(lo.min(), com.min())), float(max(hi.max(), com.max()))
    pad = 0.05 * (high - low or 0.01)
    low, high = low - pad, high + pad
    inner = WIDTH - 2 * MARGIN

    def x(v):
        return MARGIN + (v - t0) / (t1 - t0 or 1.0) * inner

    def y(v):
        return top + PANEL - (v - low) / (high - low) * PANEL

    band = " ".join(f"{x(a):.1f},{y(b):.1f}" for a, b in zip(t, hi))
    band += " " + " ".join(f"{x(a):.1f},{y(b):.1f}" for a, b in zip(t[::-1], lo[::-1]))
    line = " ".join(f"{x(a):.1f},{y(b):.1f}" for a, b in zip(t, com))
    out = [f'<rect x="{MARGIN}" y="{top}" width="{inner}" height="{PANEL}" fill="none" stroke="#999"/>',
           f'<polygon class="support" points="{band}" fill="#cfe3f7" stroke="#7aa7d6" stroke-width="0.5"/>',
           f'<polyline class="com" points="{line}" fill="none" stroke="#c0392b" stroke-width="1.2"/>',
           f'<text x="{MARGIN + 4}" y="{top + 14}" font-size="12">{html.escape(label)}</text>']
    for v in (low, high):
        out.append(f'<text x="{MARGIN - 4}" y="{y(v) + 4:.1f}" font-size="10" text-anchor="end">'
                   f'{100 * v:.1f}</text>')
    return out


def write_physics_svg(path, rows) -> Path:
    """Write ``physics.svg`` from the physics CSV's rows (:data:`~agentsim.physics.simulation.CSV_COLUMNS`,
    one a frame)."""
    data = np.asarray(rows, dtype=float)
    step = max(1, int(np.ceil(len(data) / MAX_POINTS)))
    thin = data[::step]
    if len(data) and thin[-1, 0] != data[-1, 0]:
        thin = np.vstack([thin, data[-1:]])
    t = thin[:, 0]
    span = (float(data[0, 0]), float(data[-1, 0])) if len(data) else (0.0, 1.0)
    height = 2 * PANEL + 3 * MARGIN
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" '
           f'viewBox="0 0 {WIDTH} {height}" font-family="sans-serif">',
           '<title>centre of mass against the support polygon</title>']
    if len(data):
        out += _panel(MARGIN / 2, t, thin[:, 1], thin[:, 4], thin[:, 5],
                      "sideways, cm (+: the body's left): support polygon (band), centre of mass (line)", span)
        out += _panel(1.5 * MARGIN + PANEL, t, thin[:, 3], thin[:, 6], thin[:, 7],
                      "forward, cm (+: the way it faces)", span)
        inner = WIDTH - 2 * MARGIN
        bottom = 1.5 * MARGIN + 2 * PANEL
        outside = data[data[:, 8] == 0, 0]
        for v in outside[:: max(1, len(outside) // MAX_POINTS)]:
            xv = MARGIN + (v - span[0]) / (span[1] - span[0] or 1.0) * inner
            out.append(f'<line class="outside" x1="{xv:.1f}" x2="{xv:.1f}" y1="{bottom + 4}" y2="{bottom + 10}" '
                       'stroke="#c0392b"/>')
        fell = data[data[:, 10] == 1, 0]
        if len(fell):
            xv = MARGIN + (fell[0] - span[0]) / (span[1] - span[0] or 1.0) * inner
            out.append(f'<line class="fell" x1="{xv:.1f}" x2="{xv:.1f}" y1="{MARGIN / 2}" y2="{bottom}" '
                       'stroke="black" stroke-dasharray="4 3"/>')
        out.append(f'<text x="{WIDTH / 2}" y="{bottom + 26}" font-size="11" text-anchor="middle">time, s '
                   f'({span[0]:g} to {span[1]:.2f}); ticks below: frames whose centre of mass is outside the '
                   f'support polygon ({len(outside)} of {len(data)})</text>')
    out.append("</svg>")
    path = Path(path)
    with written(path) as tmp:
        tmp.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path
