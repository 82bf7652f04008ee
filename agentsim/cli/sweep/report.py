"""``agentsim sweep report DIR``: a sweep's results summarised, with 95 % bootstrap confidence intervals of the
means, as a table per strategy (or as one Markdown table), and drawn as ``summary.png``.

A metric that is null in some replicates (``beats_to_recover`` of a conductor that never recovered) is
averaged over the others and says how many were null: ``6.2 [5.1, 7.4] (3 none)``; null in all: ``none``.

The points that finished are grouped by every grid key except the replicates (``over``, by default
``seed``): each group's mean of each metric gets a 95 % BCa bootstrap interval over its replicates
(:func:`scipy.stats.bootstrap`, 9,999 resamples, a fixed seed so that the report repeats itself). One table
per value of ``by`` (by default ``strategy``), a row per value of the other keys; the picture draws each
metric against ``axis`` (by default the first other key with more than one value), one line per strategy
with its interval as a band. A group of one replicate has no interval; a metric that is the same in every
replicate has an interval of no width. Failed points are left out and counted.
"""

from __future__ import annotations

import json
import math
import numbers
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agentsim.cli.sweep.results import TAKEN_PREFIX, read
from agentsim.cli.sweep.spec import ROW_COLUMNS
from agentsim.errors import AgentsimError, UsageError

#: Resamples of each bootstrap, and its seed.
RESAMPLES = 9999
SEED = 0
#: Metrics shown when neither the spec nor --metric names any: the first that vary, at most this many.
DEFAULT_METRICS = 6


@dataclass
class Cell:
    """A metric's mean over one group's replicates and its 95 % interval (NaN where there is none)."""

    mean: float
    low: float
    high: float
    n: int
    missing: int = 0  # replicates without a value (null in the JSON: a conductor that never recovered)

    def text(self) -> str:
        none = f" ({self.missing} none)" if self.missing else ""
        if self.n == 0:
            return "none" if self.missing else "-"
        if math.isnan(self.low):
            return f"{number(self.mean)} (n={self.n}){none}"
        return f"{number(self.mean)} [{number(self.low)}, {number(self.high)}]{none}"


@dataclass
class Summary:
    """The groups of a sweep's results and their cells."""

    command: str
    metrics: list[str]
    by: str | None
    axis: str | None
    over: list[str]
    others: list[str]  # grid keys that are neither by, axis nor over
    keys: list[str]  # the grid keys but the replicates, in the spec's order
    points: int
    failed: int
    groups: list[dict] = field(default_factory=list)  # {"values": {key: value}, "cells": {metric: Cell}}


def number(value: float) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if value == 0:
        return "0"
    if abs(value) >= 1000:
        return f"{value:.0f}"
    return f"{value:.3g}" if abs(value) < 1 else f"{value:.4g}" if abs(value) < 100 else f"{value:.1f}"


def interval(values, rng: np.random.Generator) -> Cell:
    """The mean of the finite ``values`` and its 95 % BCa bootstrap interval (percentile where BCa fails)."""
    from scipy.stats import bootstrap

    x = np.asarray([math.nan if v is None else v for v in values], dtype=float)
    missing = int(np.isnan(x).sum())
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Cell(math.nan, math.nan, math.nan, 0, missing)
    mean = float(x.mean())
    if x.size < 2:
        return Cell(mean, math.nan, math.nan, 1, missing)
    if np.ptp(x) == 0:
        return Cell(mean, mean, mean, int(x.size), missing)
    low = high = math.nan
    for method in ("BCa", "percentile"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ci = bootstrap((x,), np.mean, confidence_level=0.95, n_resamples=RESAMPLES, method=method,
                           rng=rng).confidence_interval
        low, high = float(ci.low), float(ci.high)
        if math.isfinite(low) and math.isfinite(high):
            break
    return Cell(mean, low, high, int(x.size), missing)


def load_sweep(folder: Path) -> dict:
    if not folder.is_dir():
        raise UsageError(f"no sweep folder {str(folder)!r}")
    if not (folder / "sweep.json").is_file() or not any((folder / n).is_file() for n in
                                                         ("results.parquet", "results.csv")):
        raise UsageError(f"{str(folder)!r} holds no sweep's results: run 'agentsim sweep SPEC.toml --out "
                         f"{folder}' first")
    return json.loads((folder / "sweep.json").read_text())


def numeric(table, column) -> bool:
    import pandas as pd

    return pd.api.types.is_numeric_dtype(table[column]) and not pd.api.types.is_bool_dtype(table[column])


def summarize(folder: Path, metrics: list[str] | None = None, by: str | None = None, axis: str | None = None,
              over: list[str] | None = None) -> Summary:
    """Group the finished points of the sweep in ``folder`` and bootstrap every metric's mean."""
    sweep = load_sweep(folder)
    table = read(folder)
    grid = list(sweep["grid"])
    settings = sweep.get("report", {})
    by = by or settings.get("by") or ("strategy" if "strategy" in grid else None)
    over = over or settings.get("over") or (["seed"] if "seed" in grid else [])
    for name, key in [("--by", by), ("--axis", axis)] + [("--over", k) for k in over]:
        if key is not None and key not in grid:
            raise UsageError(f"{name} {key!r} is no grid key of this sweep (its keys: {', '.join(grid)})")
    ok = table[table["status"] == "ok"]
    rest = [k for k in grid if k != by and k not in over]
    if axis is None:
        axis = settings.get("axis")
        if axis is None or axis not in rest:
            axis = next((k for k in rest if table[k].nunique() > 1), None)
    columns = [c for c in table.columns if c not in grid and c not in ROW_COLUMNS]
    metrics = list(metrics or settings.get("metrics") or [])
    if metrics:
        unknown = [m for m in metrics if m not in columns]
        if unknown:
            near = [c for c in columns if unknown[0].split(".")[-1] in c][:5]
            raise UsageError(f"no metric {unknown[0]!r} in this sweep's results"
                             + (f" (did you mean {', '.join(near)}?)" if near else ""))
        bad = [m for m in metrics if not numeric(table, m)]
        if bad:
            raise UsageError(f"metric {bad[0]!r} is not a number")
    else:
        metrics = [c for c in columns if numeric(table, c) and ok[c].nunique() > 1
                   and "seconds" not in c and "wall" not in c and not c.startswith(TAKEN_PREFIX)][:DEFAULT_METRICS]
    summary = Summary(command=" ".join(sweep["command"]), metrics=metrics, by=by, axis=axis, over=over,
                      others=[k for k in rest if k != axis], keys=[k for k in grid if k not in over], points=len(table),
                      failed=int((table["status"] != "ok").sum()))
    keys = ([by] if by else []) + [k for k in rest]
    rng = np.random.default_rng(SEED)
    order = {k: grid_order(sweep["grid"][k]) for k in keys}
    combos = ok[keys].drop_duplicates().to_dict("records") if keys else [{}]
    combos.sort(key=lambda values: [order[k].index(values[k]) if values[k] in order[k] else 0 for k in keys])
    for values in combos:
        mask = np.ones(len(ok), dtype=bool)
        for k, v in values.items():
            mask &= (ok[k] == v).to_numpy()
        group = ok[mask]
        summary.groups.append({"values": values, "cells": {m: interval(group[m].tolist(), rng) for m in metrics}})
    return summary


def grid_order(values) -> list:
    """A grid key's values in the spec's order (a named axis: its names)."""
    return list(values)


def label(values: dict, keys: list[str]) -> str:
    return ", ".join(f"{k}={values[k]}" for k in keys)


def text_tables(summary: Summary) -> str:
    """A table per value of ``by``: a row per value of the other keys, a column per metric."""
    head = (f"agentsim {summary.command}: {summary.points} points ({summary.points - summary.failed} ok, "
            f"{summary.failed} failed); mean [95 % bootstrap interval]"
            + (f" over {', '.join(summary.over)}" if summary.over else " (no replicates: set [report] over)"))
    lines = [head]
    row_keys = [k for k in summary.keys if k == summary.axis or k in summary.others]
    blocks: dict = {}
    for group in summary.groups:
        blocks.setdefault(group["values"].get(summary.by) if summary.by else None, []).append(group)
    for name, groups in blocks.items():
        lines += ["", f"{summary.by} = {name}" if summary.by else "all points"]
        header = ([" ".join(row_keys) or ""] if row_keys else []) + ["n"] + summary.metrics
        body = []
        for group in groups:
            cells = list(group["cells"].values())
            n = max((c.n for c in cells), default=0)
            body.append(([" ".join(str(group["values"][k]) for k in row_keys)] if row_keys else [])
                        + [str(n)] + [c.text() for c in cells])
        widths = [max(len(r[i]) for r in [header] + body) for i in range(len(header))]
        for r in [header] + body:
            lines.append("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip())
    return "\n".join(lines)


def markdown_table(summary: Summary) -> str:
    """One Markdown table: a row per value of ``by`` and the other keys, a column per axis value and metric."""
    axis_values = list(dict.fromkeys(g["values"][summary.axis] for g in summary.groups)) if summary.axis else [None]
    row_keys = ([summary.by] if summary.by else []) + summary.others
    header = row_keys + [m if v is None else f"{m} ({summary.axis} {v})" for v in axis_values
                         for m in summary.metrics] + ["n"]
    rows: dict = {}
    for group in summary.groups:
        key = tuple(group["values"][k] for k in row_keys)
        rows.setdefault(key, {})[group["values"].get(summary.axis)] = group["cells"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, by_axis in rows.items():
        cells = [by_axis[v][m].text() if v in by_axis else "-" for v in axis_values for m in summary.metrics]
        n = max((c.n for cs in by_axis.values() for c in cs.values()), default=0)
        lines.append("| " + " | ".join([str(k) for k in key] + cells + [str(n)]) + " |")
    return "\n".join(lines)


#: The part of the summary picture's width its title and legend may span.
MARGIN = 0.96


def fit_title(fig, text: str, room: float, fontsize: float = 11):
    """``fig``'s suptitle ``text``, wrapped on as few lines as make it at most ``room`` pixels wide."""
    import textwrap

    title = fig.suptitle(text, fontsize=fontsize)
    renderer = fig.canvas.get_renderer()
    lines = 1
    while title.get_window_extent(renderer).width > room and lines < len(text.split()):
        lines += 1
        title.set_text(textwrap.fill(text, width=math.ceil(len(text) / lines)))
    return title


def plot(summary: Summary, path: Path) -> Path:
    """Each metric against the axis, one line per strategy (and value of the other keys) with its band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = summary.metrics or []
    if not metrics:
        raise AgentsimError("no metric to draw: name one with --metric")
    columns = min(len(metrics), 3)
    rows = math.ceil(len(metrics) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(5.2 * columns, 3.8 * rows), squeeze=False)
    line_keys = ([summary.by] if summary.by else []) + summary.others
    lines: dict = {}
    for group in summary.groups:
        lines.setdefault(tuple(group["values"][k] for k in line_keys), []).append(group)
    axis_values = list(dict.fromkeys(g["values"][summary.axis] for g in summary.groups)) if summary.axis else []
    numeric_axis = bool(axis_values) and all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))
                                             for v in axis_values)
    palette = plt.get_cmap("tab10" if len(lines) <= 10 else "tab20").colors
    for index, metric in enumerate(metrics):
        ax = axes[index // columns][index % columns]
        signed = np.array([g["cells"][metric].mean for g in summary.groups], dtype=float)
        signed = signed[np.isfinite(signed)]
        means = np.abs(signed[signed != 0])
        one_sign = (signed >= 0).all() or (signed <= 0).all()
        if one_sign and means.size and means.max() / means.min() > 100:  # a metric over orders of magnitude
            ax.set_yscale("symlog", linthresh=float(means.min()))
        for n_line, (key, groups) in enumerate(lines.items()):
            name = ", ".join(str(k) for k in key) or "all"
            if summary.axis:
                at = {g["values"][summary.axis]: g["cells"][metric] for g in groups}
                xs = [v for v in axis_values if v in at]
                x = np.array(xs, dtype=float) if numeric_axis else np.array([axis_values.index(v) for v in xs])
                cells = [at[v] for v in xs]
            else:
                x, cells = np.array([n_line]), [groups[0]["cells"][metric]]
            mean = np.array([c.mean for c in cells])
            low, high = np.array([c.low for c in cells]), np.array([c.high for c in cells])
            drawn = ax.plot(x, mean, "o-" if summary.axis else "o", label=name, markersize=4,
                            color=palette[n_line % len(palette)])[0]
            if summary.axis:
                ax.fill_between(x, low, high, color=drawn.get_color(), alpha=0.18, linewidth=0)
            else:
                ax.errorbar(x, mean, yerr=[mean - low, high - mean], color=drawn.get_color(), capsize=3)
        if summary.axis:
            ax.set_xlabel(summary.axis)
            if not numeric_axis:
                ax.set_xticks(range(len(axis_values)), [str(v) for v in axis_values])
        else:
            ax.set_xticks(range(len(lines)), [", ".join(str(k) for k in key) or "all" for key in lines])
        ax.set_title(metric, fontsize=10)
        ax.grid(alpha=0.3)
    for index in range(len(metrics), rows * columns):
        axes[index // columns][index % columns].set_visible(False)
    renderer = fig.canvas.get_renderer()
    room = MARGIN * fig.bbox.width  # what a title or legend may span, in pixels
    handles, names = axes[0][0].get_legend_handles_labels()
    bottom = 0.01
    if summary.axis and names:
        for ncol in range(min(len(names), 6), 0, -1):  # as many columns as fit across the figure
            legend = fig.legend(handles, names, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
            if legend.get_window_extent(renderer).width <= room or ncol == 1:
                break
            legend.remove()
        bottom += legend.get_window_extent(renderer).height / fig.bbox.height
    over = f" over {', '.join(summary.over)}" if summary.over else ""
    fit_title(fig, f"agentsim {summary.command}: mean and 95\u00a0% bootstrap interval{over}", room)
    fig.tight_layout(rect=(0, bottom, 1, 1))  # (it keeps the subplots below the title, however many lines)
    from agentsim.written import save_figure

    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
