"""The timeline pictures: behaviours, phases, sync points, shared pegs, feedback and the words heard on one
time axis (PNG), for the whole run or a window of it, and for a long run an overview; a long run's pictures
as files, drawn side by side, are :mod:`agentsim.animation.pictures`'.

=======================  ==========================================================================================
function                 what it does
=======================  ==========================================================================================
``timeline_figure``      the detailed figure of a run or of a window of it (a matplotlib ``Figure``)
``plot_timeline``        that figure, saved as a PNG
``overview_figure``      a whole run at a glance: one row per behaviour type, thin bars, strokes as ticks
``PosePanel``            what the panel under a timeline draws of the poses, taken from a stream once
``heard_words``          the words each speech made heard, at their onsets on the run's axis
``layout_words``         which word labels fit (staggered on a few lines) at a given scale, and which do not
``run_duration``         where the run's axis ends
``time_windows``         the fixed-length windows that cover a run
``window_path``          the file of one window next to the overview (``timeline_0000-0030s.png``)
=======================  ==========================================================================================

Times are seconds on the run's axis (the simulated time of the run, the feedback's ``globalTime``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agentsim.animation.units import PHASE_NAMES
from agentsim.written import save_figure

if TYPE_CHECKING:  # the poses' module (the body, the drivers) is not loaded to draw a run that has them
    from agentsim.animation.output import PoseStream

_PHASE_COLOURS = {
    "preparation": "#9ecae1", "pre-stroke hold": "#deebf7", "stroke": "#e6550d", "post-stroke hold": "#fdd0a2",
    "retraction": "#c7e9c0", "hold": "#deebf7", "attack": "#9ecae1", "sustain": "#deebf7",
    "transition": "#bcbddc", "speech": "#d9d9d9",
}
_TYPE_COLOURS = {
    "speech": "#969696", "gesture": "#e6550d", "pointing": "#fd8d3c", "head": "#3182bd", "gaze": "#756bb1",
    "gazeShift": "#9e9ac8", "faceLexeme": "#31a354", "face": "#31a354", "faceShift": "#74c476",
    "posture": "#8c6d31", "postureShift": "#bd9e39", "locomotion": "#843c39",
}

#: Runs longer than this (s) are drawn by :func:`plot_timelines` as an overview plus windows.
LONG_RUN = 60.0
#: Length (s) of the windows :func:`plot_timelines` draws a long run in.
WINDOW = 30.0
#: Font size (points) of the words under a speech row, and how many lines they are staggered on.
WORD_FONT = 6.0
WORD_LINES = 3
#: Space (points) kept between two word labels on one line.
WORD_GAP = 4.0
#: Room (inches) right of the axis for the labels of the last words of a window.
WORD_MARGIN = 0.6
#: Height of one behaviour row (inches).
ROW_INCHES = 0.34
#: Font size (points) of the block names (``block:start``, ``block:end``) at the top of a timeline, and the
#: room kept across the axis for each of them (points; they are written upwards, so this is their height).
BLOCK_FONT = 6.0
BLOCK_PITCH = 1.45 * BLOCK_FONT
#: Resolution (dots per inch) of the timeline pictures.
DPI = 120


@dataclass(frozen=True)
class HeardWord:
    """A word as the run made it heard: its speech (``block:behaviour``), text, and its onset and end on
    the run's axis (s; the end is cut at the speech's stop if an interruption stopped it)."""

    behaviour: str
    text: str
    onset: float
    end: float


#: How far beyond a window's ends its pose panel draws the poses (s).
PANEL_MARGIN = 0.5


@dataclass(frozen=True, eq=False)
class PosePanel:
    """What the panel under a timeline draws of a run's poses, for every frame: its time (s), the heights
    (m) of the left and right wrists and the head's pitch down (degrees).

    :meth:`of` takes them from a :class:`~agentsim.animation.output.PoseStream` once, so that the windows of
    a long run do not each work out the head's orientation over the whole run again; they are plain arrays,
    which pass cheaply to the processes that draw windows side by side.
    """

    times: np.ndarray
    l_wrist: np.ndarray
    r_wrist: np.ndarray
    head_pitch: np.ndarray

    @classmethod
    def of(cls, stream: PoseStream | PosePanel) -> PosePanel:
        """The panel of ``stream`` (a panel is its own)."""
        if isinstance(stream, PosePanel):
            return stream
        fwd = stream.forward("skullbase")
        return cls(np.array(stream.times), np.array(stream.position("l_wrist")[:, 1]),
                   np.array(stream.position("r_wrist")[:, 1]), -np.degrees(np.arcsin(np.clip(fwd[:, 1], -1, 1))))

    @classmethod
    def of_poses(cls, body, times: np.ndarray, values: np.ndarray) -> PosePanel:
        """The panel of some frames of poses (``values``, a row a frame, at ``times``) of ``body``: the same
        numbers as those frames' rows of the panel of a stream of them all."""
        fk = body.forward_kinematics(np.atleast_2d(np.asarray(values, dtype=float)), ["l_wrist", "r_wrist",
                                                                                      "skullbase"])
        fwd = fk["skullbase"][0][:, :, 2]
        return cls(np.array(times, dtype=float), np.array(fk["l_wrist"][1][:, 1]), np.array(fk["r_wrist"][1][:, 1]),
                   -np.degrees(np.arcsin(np.clip(fwd[:, 1], -1, 1))))

    @classmethod
    def joined(cls, parts: list[PosePanel]) -> PosePanel:
        """The panels of consecutive stretches of frames as one."""
        return cls(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("times", "l_wrist", "r_wrist", "head_pitch")))

    def around(self, start: float, end: float) -> PosePanel:
        """The frames a window from ``start`` to ``end`` draws (:data:`PANEL_MARGIN` seconds beyond either
        end)."""
        sel = (self.times >= start - PANEL_MARGIN) & (self.times <= end + PANEL_MARGIN)
        return PosePanel(self.times[sel], self.l_wrist[sel], self.r_wrist[sel], self.head_pitch[sel])


def recording_of(source):
    """The :class:`~agentsim.core.recording.Recording` of ``source``: itself, or a realizer's after ``run()``."""
    return source.recording() if hasattr(source, "recording") else source


def heard_words(source, start: float | None = None, end: float | None = None) -> list[HeardWord]:
    """The words of every speech of a run, in order, with their onsets on the run's axis.

    A word of speech time ``s`` is heard at ``t0 + s * (1 + drift_ppm * 1e-6)``; an interrupted speech has
    no words from its stop on (its ``stopped``, or where its behaviour was dropped or cut, if earlier).
    With ``start``/``end``, only the words whose onset lies in ``[start, end)``. ``source``: a
    :class:`~agentsim.core.recording.Recording` or a realizer after ``run()``.
    """
    recording = recording_of(source)
    cut = {b.name: b.stopped for b in recording.behaviours if b.stopped is not None}
    words = []
    for speech in recording.speech:
        scale = 1.0 + speech.drift_ppm * 1e-6
        name = f"{speech.block}:{speech.behaviour}"
        stops = [t for t in (speech.stopped, cut.get(name)) if t is not None]
        stop = min(stops) if stops else None
        for w in speech.utterance.words:
            onset = speech.t0 + w.start * scale
            off = speech.t0 + w.end * scale
            if stop is not None:
                if onset >= stop:
                    continue
                off = min(off, stop)
            if (start is not None and onset < start) or (end is not None and onset >= end):
                continue
            words.append(HeardWord(name, w.text, onset, off))
    return words


@functools.lru_cache(maxsize=4096)
def _text_width(text: str, size: float) -> float:
    """Width (points) of ``text`` in the default font at ``size`` points (measured once per text and size:
    the words of a story come back again and again)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path

    return text_to_path.get_text_width_height_descent(text, FontProperties(size=size), ismath=False)[0]


def layout_words(words: list[HeardWord], x0: float, x1: float, inches: float, lines: int = WORD_LINES,
                 size: float = WORD_FONT, margin: float = WORD_MARGIN) -> tuple[list[tuple[HeardWord, int]],
                                                                                list[HeardWord]]:
    """Where the labels of ``words`` go on an axis from ``x0`` to ``x1`` seconds drawn ``inches`` wide.

    Each label starts at its word's onset; in onset order, a word takes the first of ``lines`` lines on
    which it does not overlap the label before it (``WORD_GAP`` points apart), or is left out if none is
    free or its label would reach further than ``margin`` inches past the axis. Returns ``(word, line)``
    of the labels drawn and the words left out.
    """
    per_point = (x1 - x0) / (inches * 72.0) if inches > 0 and x1 > x0 else 0.0
    limit = x1 + margin * 72.0 * per_point
    ends = [-math.inf] * lines
    placed, skipped = [], []
    for word in sorted(words, key=lambda w: w.onset):
        right = word.onset + _text_width(word.text, size) * per_point
        line = next((k for k in range(lines) if ends[k] + WORD_GAP * per_point <= word.onset), None)
        if line is None or right > limit:
            skipped.append(word)
            continue
        ends[line] = right
        placed.append((word, line))
    return placed, skipped


def run_duration(source) -> float:
    """Where a run's axis ends (s): the latest of the recording's time, every known sync point, feedback
    and the end of every speech heard."""
    recording = recording_of(source)
    ends = [float(recording.now), 0.0]
    for b in recording.behaviours:
        ends += [t for t in b.times if t is not None and math.isfinite(t)]
    ends += [f["globalTime"] for f in recording.feedback if math.isfinite(f.get("globalTime", math.nan))]
    for s in recording.speech:
        end = s.t0 + s.utterance.duration * (1.0 + s.drift_ppm * 1e-6)
        ends.append(end if s.stopped is None else min(end, s.stopped))
    return max(e for e in ends if math.isfinite(e))


def time_windows(duration: float, window: float = WINDOW) -> list[tuple[float, float]]:
    """The windows ``[k * window, (k + 1) * window)`` that cover ``[0, duration]``: ``ceil(duration / window)``
    of them (one at least)."""
    if not window > 0:
        raise ValueError(f"a window must last a positive number of seconds, not {window}")
    n = max(1, math.ceil(duration / window - 1e-9))
    return [(k * window, (k + 1) * window) for k in range(n)]


def _seconds_tag(x: float) -> str:
    return f"{int(round(x)):04d}" if abs(x - round(x)) < 1e-9 else f"{x:06.1f}"


def window_path(png: str | Path, start: float, end: float) -> Path:
    """The file of one window next to the overview ``png``: ``timeline.png`` gives
    ``timeline_0000-0030s.png`` for 0 to 30 s."""
    png = Path(png)
    return png.with_name(f"{png.stem}_{_seconds_tag(start)}-{_seconds_tag(end)}s{png.suffix or '.png'}")


def _span(times) -> tuple[float, float] | None:
    known = [t for t in times if t is not None and math.isfinite(t)]
    return (min(known), max(known)) if known else None


def _visible(record, start: float | None, end: float | None) -> bool:
    span = _span(record.times)
    if span is None:
        return False
    return (start is None or span[1] >= start) and (end is None or span[0] < end)


def _label(record) -> str:
    label = f"{record.name} ({record.behaviour.type}"
    lex = record.behaviour.attributes.get("lexeme")
    label += f" {lex})" if lex else ")"
    if record.state == "dropped":
        label += " dropped"
    return label


def _extent(recording, panel: PosePanel | None) -> tuple[float, float]:
    """The x range that shows all of a run: every known sync point, feedback and pose, a little padded."""
    times = [t for b in recording.behaviours for t in b.times if t is not None and math.isfinite(t)]
    times += [f["globalTime"] for f in recording.feedback if math.isfinite(f.get("globalTime", math.nan))]
    if panel is not None and len(panel.times):
        times += [float(panel.times[0]), float(panel.times[-1])]
    if not times:
        return 0.0, 1.0
    a, b = min(times), max(times)
    pad = 0.03 * max(b - a, 1.0)
    return a - pad, b + pad


def _title_y() -> float:
    """Where a title sits (axes coordinates): the ``axes.titley`` setting, or the top of the axes."""
    import matplotlib

    y = matplotlib.rcParams["axes.titley"]
    return 1.0 if y is None else float(y)


def _box(left: float, width: float, y: float, height: float) -> list[tuple[float, float]]:
    """The corners of a bar from ``left`` that is ``width`` long, centred on ``y`` (as ``barh`` draws it)."""
    bottom, top = y - 0.5 * height, y + 0.5 * height
    return [(left, bottom), (left + width, bottom), (left + width, top), (left, top)]


def _tight_layout(fig, **options) -> None:
    """Lay ``fig`` out once (``Figure.tight_layout``) and leave it with no layout engine: the place holder
    that ``tight_layout`` leaves behind would have ``savefig`` lay out every artist in a pass of its own
    before drawing, to no effect."""
    import matplotlib

    fig.tight_layout(**options)
    with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)


def _new_figure(width: float, height: float, rows: int = 1, ratios=None, sharex: bool = True):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=sharex, squeeze=False, gridspec_kw={"height_ratios": ratios})
    return fig, [a[0] for a in axes]


def timeline_figure(source, stream: PoseStream | PosePanel | None = None, title: str | None = None,
                    width: float = 12.0, start: float | None = None, end: float | None = None):
    """The detailed figure of what a run did (a matplotlib ``Figure``; :func:`plot_timeline` saves it).

    ``source``: its :class:`~agentsim.core.recording.Recording`, or a realizer after ``run()``. With
    ``start`` and/or ``end`` (s on the run's axis), only that window is drawn: behaviours wholly outside
    it are left out (no row), feedback outside it too, and the axis spans exactly the window.

    One row per behaviour (block:behaviour) with its phases shaded between its sync points (dropped
    behaviours hatched from where they stopped), a tick at every sync point and a label at every stroke,
    dashed lines joining sync points that share a time peg, block starts and ends (named in a band above
    the rows, a name moved aside where two would overlap), and a feedback row
    with every sync point progress (dots), prediction (diamonds) and warning (red triangles). Under each
    speech row, the words heard (:func:`heard_words`), each label starting at its word's onset (a tick
    marks every onset), staggered on up to ``WORD_LINES`` lines; labels that would overlap at this width
    are left out, and a note above the axis says how many. With ``stream`` (the evaluated poses, or their
    :class:`PosePanel`), a panel below shows the wrist heights and head pitch with the stroke feedback.

    The bars of a row are one ``PolyCollection`` (the hatched bars of a dropped behaviour another), the
    ticks and pegs one ``LineCollection`` each. Artists a reader (or a test) can find by ``get_gid()``:
    ``"word"`` (a word's label, a ``Text`` at its onset), ``"word-note"``, ``"behaviour:<block:behaviour>"``
    (a row's bars), ``"block-name"`` (a block start's or end's name).
    """
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.patches import Patch

    recording = recording_of(source)
    panel = None if stream is None else PosePanel.of(stream)
    window = start is not None or end is not None
    if window:
        lo = 0.0 if start is None else float(start)
        hi = run_duration(recording) if end is None else float(end)
        if not hi > lo:
            raise ValueError(f"a window must end after it starts ({lo:g} s to {hi:g} s)")
    rows = [r for r in recording.behaviours if _visible(r, start, end)]
    words_by_row: dict[str, list[HeardWord]] = {}
    for w in heard_words(recording, start, end):
        words_by_row.setdefault(w.behaviour, []).append(w)
    if window:
        x0, x1 = lo, hi
    else:
        x0, x1 = _extent(recording, panel)
    # lines of words each speech row needs, at the axis width the labels on the left are likely to leave
    labels_width = max([_text_width(_label(r), 6.5) for r in rows] + [0.0]) / 72.0
    guess = width - labels_width - 0.6 - WORD_MARGIN - (0.6 if panel is not None else 0.1)
    lines_of = {name: max([line + 1 for _, line in layout_words(words, x0, x1, guess)[0]] + [1])
                for name, words in words_by_row.items()}
    line_step = 8.5 / (72.0 * ROW_INCHES)  # data units between two lines of words
    band_of = {name: 0.4 + lines * line_step for name, lines in lines_of.items()}
    # y of each row, bottom up: the feedback row below 0, each behaviour 1 higher, a speech with words
    # another band for them
    ys: list[float] = []
    y = 0.0
    for record in reversed(rows):
        y += 1.0 + band_of.get(record.name, 0.0)
        ys.append(y)
    ys.reverse()
    # the block starts and ends are named in a band of their own above the rows, as long as the longest name
    blocks = sorted((f["globalTime"], str(f.get("id") or "")) for f in recording.feedback
                    if f["type"] == "blockProgress" and math.isfinite(f.get("globalTime", math.nan))
                    and (not window or lo <= f["globalTime"] <= hi))
    block_band = (max(_text_width(name, BLOCK_FONT) for _, name in blocks) / 72.0 / ROW_INCHES + 0.2
                  if blocks else 0.0)
    top = y + 1.0 + block_band
    units = top + 1.3
    panels = 2 if panel is not None else 1
    height = max(2.5, ROW_INCHES * units + 1.6) + (2.2 if panel is not None else 0.0)
    fig, axes = _new_figure(width, height, panels, [max(3.0, units), 3.0][:panels])
    ax = axes[0]
    peg_points: dict[int, list[tuple[float, float]]] = {}
    labels: list[tuple[float, str]] = [(-0.45, "feedback")]
    bars: list[tuple[float, float, float, str, bool, str]] = []  # y, left, width, colour, dropped, row
    ticks: list[list[tuple[float, float]]] = []
    speech_ticks: list[list[tuple[float, float]]] = []
    for record, y in zip(rows, ys):
        times = record.times
        known = [(s, t) for s, t in zip(record.sync_ids, times) if t is not None and math.isfinite(t)]
        stop = None
        if record.state == "dropped":
            passed = [t for t, p in zip(times, record.passed) if p and t is not None]
            stop = passed[-1] if passed else known[0][1]
        is_speech = record.behaviour.type == "speech"
        for (s0, t0), (s1, t1) in zip(known, known[1:]):
            if window and (t1 < lo or t0 > hi):
                continue
            phase = "speech" if is_speech else PHASE_NAMES.get((s0, s1), "hold")
            bars.append((y, t0, t1 - t0, _PHASE_COLOURS.get(phase, "#eeeeee"), stop is not None and t0 >= stop,
                         record.name))
        has_words = record.name in words_by_row
        for i, (s, t) in enumerate(zip(record.sync_ids, times)):
            if t is None or not math.isfinite(t):
                continue
            inside = not window or lo - 1.0 <= t <= hi + 1.0
            if is_speech and 0 < i < len(times) - 1:
                if inside:
                    speech_ticks.append([(t, y - 0.3), (t, y + 0.3)])
                    if not has_words:
                        ax.text(t, y + 0.33, s, fontsize=5.5, ha="center", va="bottom", color="#444444",
                                clip_on=True)
            elif inside:
                ticks.append([(t, y - 0.32), (t, y + 0.32)])
                if s == "stroke":
                    ax.text(t, y + 0.33, s, fontsize=5.5, ha="center", va="bottom", color="#444444",
                            clip_on=True)
            group = record.peg_groups[i] if i < len(record.peg_groups) else None
            if group is not None:  # a speech's pegs are joined from under its words, not across them
                peg_points.setdefault(group, []).append((t, y - band_of[record.name] if has_words else y))
        labels.append((y, _label(record)))
    for dropped in (False, True):  # the hatched bars over the others
        of_row: dict[str, list] = {}
        for b in bars:
            if b[4] == dropped:
                of_row.setdefault(b[5], []).append(b)
        for name, part in of_row.items():
            ax.add_collection(PolyCollection([_box(b[1], b[2], b[0], 0.6) for b in part],
                                             facecolors=[b[3] for b in part], edgecolors="#555555", linewidths=0.4,
                                             hatch="///" if dropped else None, alpha=0.35 if dropped else 1.0,
                                             gid=f"behaviour:{name}"))
    pegs = []
    for pts in peg_points.values():
        if len(pts) > 1:
            for t in sorted({round(p[0], 9) for p in pts}):
                ys_t = [p[1] for p in pts if abs(p[0] - t) < 1e-9]
                if len(ys_t) > 1 and (not window or lo <= t <= hi):
                    pegs.append([(t, min(ys_t)), (t, max(ys_t))])
    ax.add_collection(LineCollection(pegs, colors="#3182bd", linestyles="--", linewidths=0.6, alpha=0.6))
    ax.add_collection(LineCollection(ticks, colors="black", linewidths=0.8))
    ax.add_collection(LineCollection(speech_ticks, colors="#888888", linewidths=0.4))
    y_fb = -0.2
    marks: dict[str, list[float]] = {}
    for f in recording.feedback:
        t = f.get("globalTime")
        if t is None or not math.isfinite(t) or (window and not lo <= t <= hi):
            continue
        kind = f["type"]
        marks.setdefault(kind, []).append(t)
        if kind == "warningFeedback":
            ax.text(t, y_fb - 0.75, str(f.get("warningType") or "warning"), fontsize=5.5, color="#de2d26",
                    ha="center", va="top", clip_on=True)
    for kind, dy, style, colour, size in (("syncPointProgress", 0.0, "o", "#636363", 2.5),
                                          ("predictionFeedback", 0.25, "D", "#756bb1", 3),
                                          ("warningFeedback", 0.5, "^", "#de2d26", 5)):
        if marks.get(kind):
            ax.plot(marks[kind], [y_fb - dy] * len(marks[kind]), style, color=colour, markersize=size,
                    linestyle="none")
    if marks.get("blockProgress"):
        ax.vlines(marks["blockProgress"], -1.3, top, colors="#bdbdbd", linewidths=0.6, linestyles=":")
    ax.set_yticks([y for y, _ in labels], [lab for _, lab in labels], fontsize=6.5)
    # the rows' axis has no label to place beside its many tick labels: placing it (measuring every tick label
    # at every layout and every draw) is skipped
    ax.yaxis.set_label_coords(0.0, 0.5)
    ax.set_ylim(-1.3, top)
    fig.legend(handles=[Patch(color=c, label=n) for n, c in _PHASE_COLOURS.items() if n != "hold"],
               loc="lower center", fontsize=6.5, ncol=10, frameon=False, handlelength=1.2, columnspacing=1.2)
    # at the top of the axes, above which no tick label lies: matplotlib need not look for any (measuring
    # every row's label) to place it
    ax.set_title(title or "behaviours, phases, pegs and feedback", loc="left", fontsize=10,
                 pad=15 if words_by_row else 6, y=_title_y())
    note = ax.text(0.0, 1.005, "", transform=ax.transAxes, ha="left", va="bottom", fontsize=6.5,
                   color="#555555", gid="word-note")
    if panel is not None:
        bx = axes[1]
        times = panel.times
        sel = slice(None) if not window else (times >= lo - PANEL_MARGIN) & (times <= hi + PANEL_MARGIN)
        for joint, heights, colour in (("l_wrist", panel.l_wrist, "#31a354"), ("r_wrist", panel.r_wrist, "#e6550d")):
            bx.plot(times[sel], heights[sel], color=colour, linewidth=0.9, label=f"{joint} height (m)")
        bx.set_ylabel("height (m)", fontsize=7)
        cx = bx.twinx()
        cx.plot(times[sel], panel.head_pitch[sel], color="#756bb1", linewidth=0.8, label="head pitch down (deg)")
        cx.set_ylabel("head pitch (deg)", fontsize=7)
        strokes = [f["globalTime"] for f in recording.feedback if f["type"] == "syncPointProgress"
                   and f["id"].endswith(":stroke") and (not window or lo <= f["globalTime"] <= hi)]
        if strokes:
            bx.vlines(strokes, 0, 1, transform=bx.get_xaxis_transform(), colors="#de2d26", linewidths=0.6,
                      linestyles="--")
        bx.legend(loc="upper left", fontsize=6)
        cx.legend(loc="upper right", fontsize=6)
    axes[-1].set_xlim(x0, x1)
    axes[-1].set_xlabel("time of the run (s)")
    _tight_layout(fig, rect=(0.0, 0.3 / height, 1.0, 1.0))
    if words_by_row:
        _draw_words(fig, ax, dict(zip((r.name for r in rows), ys)), words_by_row, lines_of, x0, x1, line_step, note)
    _draw_block_names(fig, ax, blocks, top, x0, x1)  # after the words: they can narrow the axis
    return fig


def spread(xs: list[float], gap: float, lo: float = -math.inf, hi: float = math.inf) -> list[float]:
    """Positions as near to the sorted ``xs`` as they can be with at least ``gap`` between neighbours, inside
    ``[lo, hi]`` where there is room: a run of labels too close together is spaced out around where it wants
    to be (the mean of its members' wishes)."""
    groups: list[list] = []  # [members, sum of the position each member wants for the group's first]

    def first(group) -> float:
        n, wish = group
        return min(max(wish / n, lo), hi - (n - 1) * gap)

    for x in xs:
        groups.append([1, float(x)])
        while len(groups) > 1 and first(groups[-2]) + groups[-2][0] * gap > first(groups[-1]):
            n, wish = groups.pop()
            groups[-1] = [groups[-1][0] + n, groups[-1][1] + wish - n * groups[-1][0] * gap]
    return [first(group) + k * gap for group in groups for k in range(group[0])]


def _draw_block_names(fig, ax, blocks: list[tuple[float, str]], top: float, x0: float, x1: float) -> None:
    """Name each block start and end at the top of its line (after the layout is final: how far apart the
    names must be in seconds depends on the axis' width), moved aside where two would overlap."""
    if not blocks:
        return
    inches = ax.get_position().width * fig.get_figwidth()
    gap = BLOCK_PITCH / 72.0 * (x1 - x0) / inches
    for x, (_, name) in zip(spread([t for t, _ in blocks], gap, x0, x1 - gap), blocks):
        ax.text(x, top - 0.1, name, fontsize=BLOCK_FONT, rotation=90, va="top", ha="left", color="#777777",
                clip_on=True, gid="block-name")


def _draw_words(fig, ax, row_y: dict[str, float], words_by_row: dict[str, list[HeardWord]],
                lines_of: dict[str, int], x0: float, x1: float, line_step: float, note) -> None:
    """Label the words under their speech rows (after the layout is final: the labels depend on the axis'
    width) and say in ``note`` how many were left out."""
    from matplotlib.collections import LineCollection

    right = fig.subplotpars.right
    fig.subplots_adjust(right=min(right, 1.0 - WORD_MARGIN / fig.get_figwidth()))
    inches = ax.get_position().width * fig.get_figwidth()
    drawn = left_out = 0
    lines_used = 0
    for name, words in words_by_row.items():
        y = row_y[name]
        placed, skipped = layout_words(words, x0, x1, inches, lines=lines_of[name])
        ax.add_collection(LineCollection([[(w.onset, y - 0.3), (w.onset, y - 0.42)] for w in words],
                                         colors="#252525", linewidths=0.5))
        for w, line in placed:
            ax.text(w.onset, y - 0.42 - line * line_step, w.text, fontsize=WORD_FONT, ha="left", va="top",
                    color="#252525", clip_on=False, gid="word")
            lines_used = max(lines_used, line + 1)
        drawn += len(placed)
        left_out += len(skipped)
    total = drawn + left_out
    lines = f" on {lines_used} lines" if lines_used > 1 else ""
    if left_out:
        text = (f"words: {drawn} of {total} labelled at their onsets{lines}; {left_out} left out where they would "
                f"overlap at this width (a tick marks every onset)")
    else:
        text = f"words: all {total} labelled at their onsets{lines}"
    note.set_text(text)


def plot_timeline(source, out_png: str | Path, stream: PoseStream | PosePanel | None = None, title: str | None = None,
                  width: float = 12.0, start: float | None = None, end: float | None = None) -> Path:
    """Draw what a run did on one time axis (:func:`timeline_figure`) and save it as a PNG.

    ``start``/``end``: draw only that window of the run's axis (s). Returns the file written.
    """
    out_png = Path(out_png)
    fig = timeline_figure(source, stream=stream, title=title, width=width, start=start, end=end)
    save_figure(fig, out_png, dpi=DPI)
    return out_png


def _lanes(spans: list[tuple[float, float]], most: int = 8) -> list[int]:
    """A lane for each span so that spans of one lane do not overlap (at most ``most`` lanes: past that, a
    span goes where the lane ends first)."""
    ends: list[float] = []
    out = [0] * len(spans)
    for i in sorted(range(len(spans)), key=lambda i: spans[i]):
        a, b = spans[i]
        lane = next((k for k, e in enumerate(ends) if e <= a), None)
        if lane is None:
            if len(ends) < most:
                ends.append(b)
                lane = len(ends) - 1
            else:
                lane = int(np.argmin(ends))
        ends[lane] = max(ends[lane], b)
        out[i] = lane
    return out


def overview_figure(source, title: str | None = None, width: float = 16.0, window: float | None = None):
    """A whole run at a glance (a matplotlib ``Figure``): one row per behaviour type, each behaviour a thin
    bar from its first to its last sync point (overlapping ones on lanes of their row, dropped ones
    hatched), strokes as black ticks, warnings as red triangles; no phases. With ``window``, the
    boundaries of the windows :func:`plot_timelines` draws in detail are marked and named.

    A row's bars are one ``PolyCollection`` (its dropped behaviours' another), its strokes one
    ``LineCollection``. Artists by ``get_gid()``: ``"overview:<type>"`` (a row's bars, a bar a path),
    ``"overview-stroke"`` (stroke ticks).
    """
    import matplotlib
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.colors import to_rgba

    recording = recording_of(source)
    duration = run_duration(recording)
    by_type: dict[str, list] = {}
    for record in recording.behaviours:
        if _span(record.times) is not None:
            by_type.setdefault(record.behaviour.type, []).append(record)
    types = sorted(by_type, key=lambda t: (t != "speech", list(by_type).index(t)))
    warnings = [f for f in recording.feedback if f["type"] == "warningFeedback"
                and math.isfinite(f.get("globalTime", math.nan))]
    n_rows = len(types) + (1 if warnings else 0)
    fig, (ax,) = _new_figure(width, max(2.2, 0.55 * n_rows + 1.5))
    ticks, names = [], []
    for row, kind in enumerate(types):
        y = n_rows - 1 - row
        records = by_type[kind]
        spans = [_span(r.times) for r in records]
        lanes = _lanes(spans)
        n_lanes = max(lanes) + 1
        lane_h = 0.8 / n_lanes
        colour = _TYPE_COLOURS.get(kind, "#737373")
        strokes = []
        boxes: dict[bool, list] = {False: [], True: []}  # played, dropped
        for record, (a, b), lane in zip(records, spans, lanes):
            yc = y + 0.4 - (lane + 0.5) * lane_h
            boxes[record.state == "dropped"].append(_box(a, max(b - a, 1e-3), yc, 0.75 * lane_h))
            for s, t in zip(record.sync_ids, record.times):
                if s == "stroke" and t is not None and math.isfinite(t):
                    strokes.append([(t, yc - 0.45 * lane_h), (t, yc + 0.45 * lane_h)])
        for dropped, part in boxes.items():
            if part:  # no edge: the hatching in the colour of edges that are not drawn, as a bar's would be
                ax.add_collection(PolyCollection(part, facecolors=to_rgba(colour, 0.35 if dropped else 0.8),
                                                 edgecolors="none", linewidths=0, hatch="///" if dropped else None,
                                                 hatchcolors=matplotlib.rcParams["patch.edgecolor"],
                                                 gid=f"overview:{kind}"))
        if strokes:
            ax.add_collection(LineCollection(strokes, colors="black", linewidths=0.6, gid="overview-stroke"))
        n_strokes = len(strokes)
        ticks.append(y)
        names.append(f"{kind} ({len(records)}" + (f", {n_strokes} strokes)" if n_strokes else ")"))
    if warnings:
        ax.plot([f["globalTime"] for f in warnings], [0.0] * len(warnings), "^", color="#de2d26", markersize=5)
        ticks.append(0)
        names.append(f"warnings ({len(warnings)})")
    if window:
        for a, b in time_windows(duration, window):
            ax.axvline(a, color="#bdbdbd", linewidth=0.6, linestyle=":")
            ax.text(0.5 * (a + min(b, duration)), n_rows - 0.45, f"{a:g}-{b:g} s", fontsize=6, ha="center",
                    va="bottom", color="#777777")
    ax.set_yticks(ticks, names, fontsize=7)
    ax.set_ylim(-0.6, n_rows - 0.2)
    ax.set_xlim(0.0, max(duration, 1e-3))
    ax.set_xlabel("time of the run (s)")
    n = sum(len(v) for v in by_type.values())
    head = f"{title}: " if title else ""
    detail = f"; the detail is drawn per {window:g} s window" if window else ""
    ax.set_title(f"{head}overview of {n} behaviours over {duration:.1f} s (strokes as ticks{detail})",
                 loc="left", fontsize=10)
    ax.grid(axis="x", alpha=0.25)
    _tight_layout(fig)
    return fig
