"""Stories from Praat TextGrids, and tellings to them.

:func:`import_textgrid` reads an annotation made in Praat (or exported from ELAN or Anvil): an interval
tier of words and a tier of gestures. :func:`export_textgrid` writes a telling on the audio's time axis
(seconds from the start of ``narration.wav``): the words, the phones (a stressed vowel ends in ``ˈ``),
the gestures where the annotation puts them (on their stressed syllables) and the strokes where the
realizer really passed them, so the three can be checked against the sound.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from agentsim.animation.scene import DEFAULT_SCENE
from scenarios.storytelling.markup import Story, StoryError, gesture_from_tag, parse_story
from speech_timing.backend import Utterance

__all__ = ["import_textgrid", "export_textgrid", "split_tags", "written_labels"]

_BRACKETED = re.compile(r"\[([^\[\]]*)\]")


def split_tags(label: str) -> list[str]:
    """The tags of one gesture-tier label: ``"[nod][beat]"``, ``"nod beat"`` or ``"nod, beat"``."""
    label = label.strip()
    if "[" in label:
        return [t.strip() for t in _BRACKETED.findall(label) if t.strip()]
    return [t for t in re.split(r"[\s,;]+", label) if t]


def import_textgrid(path: str | Path, words_tier: str = "words", gestures_tier: str = "gestures",
                    scene: dict | None = None, title: str | None = None) -> Story:
    """Read an annotated story from a Praat TextGrid.

    Parameters
    ----------
    path : str or Path
        The TextGrid (long or short format).
    words_tier : str
        Interval tier whose non-empty labels are the words spoken, in order (punctuation may be part of
        a label: ``time,``).
    gestures_tier : str
        Point or interval tier whose labels are tags of the annotation format without or with brackets
        (``beat``, ``point:door``, ``[nod][beat]``). A gesture belongs to the word being spoken at its
        time (a point's time, an interval's start), or to the next word when it falls in a pause.
    scene : dict, optional
        Extra named targets (metres), as ``@scene`` declares them in a story file.
    title : str, optional
        The story's title (default: the file name).

    Returns
    -------
    Story

    Raises
    ------
    StoryError
        If the file or a tier is missing, or a tag makes no sense.
    """
    from praatio import textgrid

    path = Path(path)
    if not path.is_file():
        raise StoryError(f"no TextGrid file {str(path)!r}")
    from agentsim.core.inputs import read_limited

    read_limited(path, what=f"the TextGrid {str(path)!r}")  # weighed first: past 8 MB refused, unread
    try:
        grid = textgrid.openTextgrid(str(path), includeEmptyIntervals=False)
    except Exception as exc:  # praatio raises several types for malformed files
        raise StoryError(f"cannot read the TextGrid {str(path)!r}: {exc}") from None
    names = list(grid.tierNames)
    for tier_name in (words_tier, gestures_tier):
        if tier_name not in names:
            raise StoryError(f"{path}: no tier {tier_name!r} (tiers: {', '.join(names)})")
    words_t = grid.getTier(words_tier)
    if not isinstance(words_t, textgrid.IntervalTier):
        raise StoryError(f"{path}: the {words_tier!r} tier must be an interval tier")
    words = [(float(e.start), float(e.end), e.label.strip()) for e in words_t.entries if e.label.strip()]
    if not words:
        raise StoryError(f"{path}: the {words_tier!r} tier has no words")
    ends = np.array([w[1] for w in words])
    scene = {k.lower(): tuple(float(c) for c in v) for k, v in (scene or {}).items()}
    targets = {k.lower() for k in DEFAULT_SCENE} | set(scene)
    tags: list[list[str]] = [[] for _ in words]
    gestures_t = grid.getTier(gestures_tier)
    for entry in gestures_t.entries:
        t = float(entry.time if isinstance(gestures_t, textgrid.PointTier) else entry.start)
        k = int(np.searchsorted(ends, t, side="right"))
        if k >= len(words):
            raise StoryError(f"{path}: gesture {entry.label!r} at {t:.3f} s comes after the last word")
        for tag in split_tags(entry.label):
            gesture_from_tag(tag, k, targets, f"{path}: tier {gestures_tier!r} at {t:.3f} s", 0, 0)  # checks the tag
            tags[k].append(tag)
    lines = [f"@scene {name} {x!r} {y!r} {z!r}" for name, (x, y, z) in scene.items()]
    lines.append(" ".join("".join(f"[{tag}]" for tag in tags[k]) + label for k, (_, _, label) in enumerate(words)))
    story = parse_story("\n".join(lines) + "\n", name=str(path), title=title or path.stem)
    return story


def written_labels(text: str, utterance: Utterance) -> list[tuple[str, float, float]]:
    """The words tier: each run of ``text`` between spaces (punctuation and all) over the time of the
    spoken words it holds. A run with no spoken word of its own (a word the voice said together with
    the one before, a lone dash) joins the label before it, so the labels joined by spaces give back
    ``text`` (white space collapsed)."""
    words = utterance.words
    labels: list[list] = []
    pending = ""
    i = 0
    for match in re.finditer(r"\S+", text):
        a, b = match.span()
        while i < len(words) and words[i].char_start < a:
            i += 1
        j = i
        while j < len(words) and words[j].char_start < b:
            j += 1
        token = match.group(0)
        if j > i:
            labels.append([pending + token, words[i].start, words[j - 1].end])
            pending = ""
        elif labels:
            labels[-1][0] += " " + token
        else:
            pending += token + " "
        i = j
    return [(label, start, end) for label, start, end in labels]


def export_textgrid(path: str | Path, story: Story, utterance: Utterance, planned: Sequence[float],
                    realized: Sequence[float] | None = None, ids: Sequence[str] | None = None,
                    to_axis: Callable[[float], float] | None = None, axis: str = "") -> Path:
    """Write a telling as a TextGrid, on the audio's time axis or (``to_axis``) the run's.

    Tiers: ``words`` (:func:`written_labels`) and ``phones`` (intervals; a stressed vowel's label ends
    in ``ˈ``), ``gestures``
    (points at each gesture's planned syllable time, labelled with its tag; tags on one word share a
    point: ``nod beat``) and, when ``realized`` is given, ``strokes`` (points where each gesture's sync
    point was passed, labelled ``id error_ms``).

    Parameters
    ----------
    path : str or Path
        Where to write (long TextGrid format).
    story : Story
    utterance : Utterance
        The speech as synthesised (its times are the audio's).
    planned : sequence of float
        Audio time (s) of each gesture's stressed syllable.
    realized : sequence of float, optional
        Audio time (s) at which each gesture's sync point was passed (NaN: never).
    ids : sequence of str, optional
        BML id of each gesture (labels of the ``strokes`` tier).
    to_axis : callable, optional
        Maps an audio time (of ``utterance`` and ``planned``) to the TextGrid's axis (the run's: where the
        audio was heard); ``realized`` is already on that axis.
    axis : str
        Said by an empty point tier named ``axis: ...`` (which axis the times are on).
    """
    from praatio import textgrid
    from praatio.utilities.constants import Interval, Point

    at = to_axis if to_axis is not None else (lambda x: x)
    planned = [at(float(p)) for p in planned]
    end = float(at(utterance.duration))
    start = 0.0
    if realized is not None:
        finite = [float(t) for t in realized if np.isfinite(t)]
        start = math.floor(min([0.0] + finite) * 1000.0) / 1000.0  # a stroke may come before the audio
        end = math.ceil(max([end] + finite) * 1000.0) / 1000.0

    def intervals(items):
        out, last = [], start
        for label, a, b in items:
            a, b = max(a, last), min(b, end)
            if b - a > 1e-6 and label:
                out.append(Interval(a, b, label))
                last = b
        return out

    grid = textgrid.Textgrid(start, end)
    grid.addTier(textgrid.IntervalTier(
        "words", intervals((label, at(a), at(b)) for label, a, b in written_labels(story.text, utterance)), start, end))
    grid.addTier(textgrid.IntervalTier(
        "phones", intervals((p.symbol + ("ˈ" if p.stressed else ""), at(p.start), at(p.end))
                            for p in utterance.phonemes), start, end))
    points: dict[float, list[str]] = {}
    for g, t in zip(story.gestures, planned):
        points.setdefault(float(t), []).append(g.label)
    grid.addTier(textgrid.PointTier("gestures", [Point(t, " ".join(labels)) for t, labels in sorted(points.items())],
                                    start, end))
    if realized is not None:
        ids = list(ids) if ids is not None else [str(i) for i in range(len(story.gestures))]
        strokes: dict[float, list[str]] = {}
        for gid, t, p in zip(ids, realized, planned):
            if np.isfinite(t):
                strokes.setdefault(float(t), []).append(f"{gid} {1000.0 * (t - p):+.1f}ms")
        grid.addTier(textgrid.PointTier("strokes", [Point(t, " ".join(v)) for t, v in sorted(strokes.items())],
                                        start, end))
    if axis:
        grid.addTier(textgrid.PointTier(f"axis: {axis}", [], start, end))
    path = Path(path)
    grid.save(str(path), format="long_textgrid", includeBlankSpaces=True)
    return path
