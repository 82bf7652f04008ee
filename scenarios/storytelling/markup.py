"""The story annotation format: text with gesture tags in front of words, and its compiler to BML.

A story file (UTF-8, ``.story``) is the text to be told, with a tag in square brackets in front of every
word that carries a gesture. Lines starting with ``#`` are comments; lines starting with ``@`` are
directives; everything else is the text (line breaks and blank lines are just spaces to the voice)::

    @title The Fox and the Crow
    @license Public domain.
    @scene tree 0.9 2.3 2.5      # a target: metres to the teller's left (x), up (y), ahead (z)

    [gaze:audience]A [beat]crow sat high in a [point:tree]tree, with a [icon:offer]piece of [brows]cheese.

A tag stands for one gesture whose stroke falls on the *stressed syllable* of the word right after it
(the first word starting at or after the tag). Several tags may stand in front of one word: ``[nod][beat]yes``.

=======================  ==========================================================================
tag                      gesture (BML)
=======================  ==========================================================================
``[beat]``               ``<gesture lexeme="BEAT">``, stroke on the syllable
``[point:TARGET]``       ``<pointing target="TARGET">``: the hand reaches the target on the syllable
``[icon:LEXEME]``        ``<gesture lexeme="LEXEME">``: an iconic or metaphoric stroke (CHOP, OFFER,
                         POINT_DOWN: the gesture forms the motion module knows)
``[nod]`` ``[shake]``    ``<head lexeme="NOD|SHAKE">``: the head's first extreme on the syllable
``[gaze:TARGET]``        ``<gazeShift target="TARGET">``: the eyes and head arrive on the syllable
``[brows]``              ``<faceLexeme lexeme="RAISE_BROWS">``: eyebrows fully up on the syllable
``[face:LEXEME]``        ``<faceLexeme lexeme="LEXEME">`` (FROWN, SMILE, WIDEN_EYES, SURPRISE, ...)
=======================  ==========================================================================

An emotion tag, ``[emotion:TYPE]`` or ``[emotion:TYPE,INTENSITY]`` (``[emotion:fear,6.5]``; intensity
:data:`~agentsim.expression.emotions.DEFAULT_INTENSITY` when not given), stands in front of the word it starts
on and lasts until the next emotion tag or the end of its paragraph (a blank line ends one); it becomes an
``<ex:emotion>`` (:mod:`agentsim.expression`) from that word's onset. Its type and intensity are read by the
realizer, which warns of a type it does not know or an intensity outside 0-10.

Hand gestures (``beat``, ``point``, ``icon``) take an optional last argument ``left``, ``right`` or
``both`` (``[beat:both]``, ``[point:door:left]``); without it the animation library chooses (the right hand,
or the left when the right is busy; pointing: the hand on the target's side). Targets are the points
of :data:`agentsim.animation.scene.DEFAULT_SCENE` and those a story declares with ``@scene``.

:func:`parse_story` reads the format into a :class:`Story`; :func:`compile_bml` writes the BML block that
tells it; :meth:`Story.to_markup` writes the format back.
"""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from agentsim.animation.lexicon import Lexicon
from agentsim.animation.scene import DEFAULT_SCENE
from agentsim.bml.speech_text import normalize_space
from agentsim.bml.vocabulary import BML_NAMESPACE, EXPRESSION_NAMESPACE
from agentsim.errors import AgentsimError
from scenarios.storytelling.names import ANCHORS  # where a gesture's sync point is tied (compile_bml)
from speech_timing.backend import Utterance
from speech_timing.linear_model import written_words

__all__ = ["StoryError", "Gesture", "Emotion", "Story", "parse_story", "read_story", "compile_bml", "KINDS", "HANDS",
           "ICON_LEXEMES", "ANCHORS", "anchor_sync", "mark_name", "release_mark", "release_delay", "gesture_ids"]

#: Gesture kinds of the format and the BML behaviour each becomes.
KINDS = {"beat": "gesture", "point": "pointing", "icon": "gesture", "nod": "head", "shake": "head",
         "gaze": "gazeShift", "brows": "faceLexeme", "face": "faceLexeme"}
#: Hand arguments and their BML ``mode``.
HANDS = {"left": "LEFT_HAND", "right": "RIGHT_HAND", "both": "BOTH_HANDS"}
#: Gesture lexemes an ``icon`` may name: the strokes of the built-in lexicon other than the beat.
ICON_LEXEMES = tuple(sorted(k for k in Lexicon.builtin().strokes if k not in ("BEAT", "DEFAULT")))
#: Face lexemes a ``face`` may name: those of the built-in lexicon.
FACE_LEXEMES = tuple(sorted(Lexicon.builtin().faces))

_TAG = re.compile(r"\[([^\[\]\n]*)\]")
_SCENE = re.compile(r"^(?P<name>[A-Za-z_][\w\-]*)\s*[:=]?\s+(?P<x>\S+)[\s,]+(?P<y>\S+)[\s,]+(?P<z>\S+)\s*$")
_NAME = re.compile(r"^[A-Za-z_][\w\-]*$")


class StoryError(AgentsimError):
    """A story that cannot be read: a missing file, or a tag or directive that makes no sense (a usage error:
    exit status 2)."""

    exit_status = 2


@dataclass(frozen=True)
class Gesture:
    """One annotated gesture: a tag of the format on one word.

    Parameters
    ----------
    kind : str
        A key of :data:`KINDS`.
    word : int
        Index of its word in :attr:`Story.words`.
    target : str
        Pointing or gaze target ('' for other kinds).
    lexeme : str
        BML lexeme (BEAT, CHOP, NOD, RAISE_BROWS, ...); '' for pointing and gaze.
    hand : str
        BML mode (LEFT_HAND, RIGHT_HAND, BOTH_HANDS) or '' to let the motion module choose.
    line, column : int
        Where the tag is in the story file (0 if unknown); not compared.
    """

    kind: str
    word: int
    target: str = ""
    lexeme: str = ""
    hand: str = ""
    line: int = field(default=0, compare=False)
    column: int = field(default=0, compare=False)

    @property
    def behaviour(self) -> str:
        """The BML behaviour element this gesture becomes."""
        return KINDS[self.kind]

    @property
    def label(self) -> str:
        """The tag as written in the format, without brackets (``point:door:left``)."""
        parts = [self.kind]
        if self.kind in ("point", "gaze"):
            parts.append(self.target)
        elif self.kind == "icon" or (self.kind == "face"):
            parts.append(self.lexeme.lower())
        if self.hand:
            parts.append(next(k for k, v in HANDS.items() if v == self.hand))
        return ":".join(parts)


@dataclass(frozen=True)
class Emotion:
    """An emotion of a story: its type and intensity as written, from the onset of word ``word`` to that of
    word ``end`` (None: to the end of the speech)."""

    kind: str
    intensity: str
    word: int
    end: int | None

    @property
    def label(self) -> str:
        """The tag as written in the format, without brackets (``emotion:fear,6.5``)."""
        return f"emotion:{self.kind}" + (f",{self.intensity}" if self.intensity else "")


@dataclass
class Story:
    """A story to tell: its text, its words, its gestures, and the places it points at.

    Parameters
    ----------
    title : str
        The title (``@title``), or the file name.
    text : str
        What is spoken, white space collapsed (exactly the text of the BML speech).
    gestures : list of Gesture
        In text order.
    scene : dict
        Extra named points (metres) declared with ``@scene``.
    meta : dict
        The other directives (``@author``, ``@license``, ``@source``, ...).
    source : str
        Where the story was read from.
    emotions : list of Emotion
        The emotion tags, in text order.
    """

    title: str
    text: str
    gestures: list[Gesture]
    scene: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    meta: dict[str, str] = field(default_factory=dict)
    source: str = ""
    emotions: list[Emotion] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.words: list[tuple[int, int]] = written_words(self.text)

    def word_text(self, k: int) -> str:
        """The written word ``k``."""
        a, b = self.words[k]
        return self.text[a:b]

    def counts(self) -> dict[str, int]:
        """Number of gestures of each kind."""
        out: dict[str, int] = {}
        for g in self.gestures:
            out[g.kind] = out.get(g.kind, 0) + 1
        return out

    def to_markup(self, width: int = 100) -> str:
        """The story in the annotation format (directives, then the tagged text wrapped at ``width``)."""
        lines = [f"@title {self.title}"]
        lines += [f"@{k} {v}" for k, v in self.meta.items()]
        lines += [f"@scene {name} {x:g} {y:g} {z:g}" for name, (x, y, z) in self.scene.items()]
        tags: dict[int, list[str]] = {}
        for e in self.emotions:
            tags.setdefault(e.word, []).append(f"[{e.label}]")
        for g in self.gestures:
            tags.setdefault(g.word, []).append(f"[{g.label}]")
        pieces, last = [], 0
        for k, (a, _) in enumerate(self.words):
            if k in tags:
                pieces.append(self.text[last:a] + "".join(tags[k]))
                last = a
        pieces.append(self.text[last:])
        body = "".join(pieces)
        wrapped, line = [], ""
        for token in body.split(" "):
            if line and len(line) + 1 + len(token) > width:
                wrapped.append(line)
                line = token
            else:
                line = f"{line} {token}" if line else token
        if line:
            wrapped.append(line)
        return "\n".join(lines + [""] + wrapped) + "\n"


# ----------------------------------------------------------------------------------------------------
# Reading.


def read_story(path: str | Path) -> Story:
    """Read a story file (:class:`StoryError` if it does not exist or does not parse)."""
    path = Path(path)
    if not path.is_file():
        raise StoryError(f"no story file {str(path)!r}")
    try:
        from agentsim.core.inputs import read_text

        source = read_text(path, what=f"the story {str(path)!r}")
    except (OSError, UnicodeDecodeError) as exc:
        raise StoryError(f"cannot read the story {str(path)!r}: {exc}") from None
    return parse_story(source, name=str(path), title=path.stem.replace("_", " "))


def parse_story(source: str, name: str = "<story>", title: str = "") -> Story:
    """Parse the annotation format (see the module docstring).

    Parameters
    ----------
    source : str
        The story file's contents.
    name : str
        Its name, for error messages (``name:line:column: ...``).
    title : str
        Title to use when there is no ``@title``.

    Raises
    ------
    StoryError
        For an unknown tag, target, lexeme or hand, a tag in front of no word, a malformed directive,
        or a story with no words.
    """
    meta: dict[str, str] = {}
    scene: dict[str, tuple[float, float, float]] = {}
    raw_parts: list[str] = []
    breaks: list[int] = []  # offsets in the raw text of the blank lines that end paragraphs
    where: list[tuple[int, int]] = []  # (line, column) of each character of the raw text
    for number, line in enumerate(source.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith("#"):
            continue
        if stripped.startswith("@"):
            _directive(stripped, number, name, meta, scene)
            continue
        if not stripped and raw_parts:
            breaks.append(sum(map(len, raw_parts)))  # a paragraph ends here
        raw_parts.append(line + "\n")
        where.extend((number, c) for c in range(1, len(line) + 2))
    raw = "".join(raw_parts)
    targets = {k.lower() for k in DEFAULT_SCENE} | set(scene)

    plain_parts: list[str] = []
    tags: list[tuple[int, str, int, int]] = []  # (offset in the plain raw text, tag, line, column)
    plain_breaks: list[int] = []  # the paragraph breaks' offsets in the plain raw text
    plain_len, last = 0, 0
    pending = list(breaks)
    for match in _TAG.finditer(raw):
        piece = raw[last:match.start()]
        while pending and pending[0] < match.start():
            plain_breaks.append(plain_len + pending.pop(0) - last)
        plain_parts.append(piece)
        plain_len += len(piece)
        line_no, col = where[match.start()]
        tags.append((plain_len, match.group(1), line_no, col))
        last = match.end()
    plain_breaks += [plain_len + b - last for b in pending]
    plain_parts.append(raw[last:])
    plain_raw = "".join(plain_parts)
    for bracket in ("[", "]"):
        if bracket in plain_raw:
            line_no, col = _locate(raw, where, bracket)
            raise StoryError(f"{name}:{line_no}:{col}: unmatched {bracket!r}; tags look like [beat] or "
                             f"[point:door]")
    text, positions = normalize_space(plain_raw, [offset for offset, _, _, _ in tags] + plain_breaks)
    words = written_words(text)
    if not words:
        raise StoryError(f"{name}: the story has no words")
    starts = [a for a, _ in words]

    gestures: list[Gesture] = []
    felt: list[tuple[int, str, str]] = []  # (word, type, intensity) of the emotion tags
    for offset, tag, line_no, col in tags:
        at = positions[offset]
        k = bisect.bisect_left(starts, at)  # the words' starts are in order
        if k == len(starts):
            raise StoryError(f"{name}:{line_no}:{col}: the tag [{tag}] stands in front of no word")
        if tag.split(":", 1)[0].strip().lower() == "emotion":
            felt.append((k, *emotion_from_tag(tag, f"{name}:{line_no}:{col}")))
            continue
        gestures.append(gesture_from_tag(tag, k, targets, f"{name}:{line_no}:{col}", line_no, col))
    gestures.sort(key=lambda g: g.word)  # stable: tags on one word keep their order
    paragraphs = sorted({bisect.bisect_left(starts, positions[b]) for b in plain_breaks} - {0, len(starts)})
    emotions = []
    felt.sort(key=lambda e: e[0])
    for n, (k, kind, intensity) in enumerate(felt):
        ends = [p for p in paragraphs if p > k] + ([felt[n + 1][0]] if n + 1 < len(felt) else [])
        emotions.append(Emotion(kind, intensity, k, min(ends) if ends else None))
    return Story(meta.pop("title", title or Path(name).stem), text, gestures, scene, meta, name, emotions)


def emotion_from_tag(tag: str, where: str) -> tuple[str, str]:
    """The type and intensity (as written, '' when not given) of an emotion tag (without brackets)."""
    _, _, value = tag.partition(":")
    kind, _, intensity = value.partition(",")
    kind, intensity = kind.strip().lower(), intensity.strip()
    if not kind or "," in intensity:
        raise StoryError(f"{where}: malformed tag [{tag}]; expected [emotion:TYPE] or [emotion:TYPE,INTENSITY]")
    return kind, intensity


def _locate(raw: str, where: list[tuple[int, int]], ch: str) -> tuple[int, int]:
    """Line and column of the first ``ch`` of ``raw`` that is not part of a tag."""
    masked = _TAG.sub(lambda m: " " * len(m.group(0)), raw)
    i = masked.index(ch)
    return where[i]


def _directive(line: str, number: int, name: str, meta: dict, scene: dict) -> None:
    key, _, value = line[1:].partition(" ")
    key, value = key.strip().lower(), value.strip()
    if not key:
        raise StoryError(f"{name}:{number}:1: a directive needs a name, as in @title or @scene")
    if key == "scene":
        match = _SCENE.match(value.split("#", 1)[0].strip())
        try:
            point = tuple(float(match.group(c)) for c in "xyz") if match else None
        except ValueError:
            point = None
        if point is None:
            raise StoryError(f"{name}:{number}:1: expected '@scene NAME X Y Z' (metres: X to the teller's left, "
                             f"Y up, Z ahead), got {line!r}")
        scene[match.group("name").lower()] = point
    else:
        meta[key] = value


def gesture_from_tag(tag: str, word: int, targets: set[str], where: str, line: int, column: int) -> Gesture:
    """The gesture a tag (without brackets) stands for."""
    parts = [p.strip() for p in tag.split(":")]
    kind = parts[0].lower()
    if kind not in KINDS:
        raise StoryError(f"{where}: unknown tag [{tag}]; known: " + ", ".join(
            f"[{k}]" for k in ("beat", "point:TARGET", "icon:LEXEME", "nod", "shake", "gaze:TARGET", "brows",
                               "face:LEXEME")))
    args = parts[1:]
    hand = ""
    needs = 1 if kind in ("point", "gaze", "icon", "face") else 0
    if kind in ("beat", "point", "icon") and len(args) == needs + 1 and args[-1].lower() in HANDS:
        hand = HANDS[args.pop().lower()]  # [point:left] points to the left; [point:left:right] with the right hand
    if len(args) != needs or any(not a for a in args):
        form = {0: f"[{kind}]", 1: f"[{kind}:{'TARGET' if kind in ('point', 'gaze') else 'LEXEME'}]"}[needs]
        extra = " (hand gestures may end in :left, :right or :both)" if kind in ("beat", "point", "icon") else ""
        raise StoryError(f"{where}: malformed tag [{tag}]; expected {form}{extra}")
    if kind in ("point", "gaze"):
        target = args[0].lower()
        if target not in targets:
            raise StoryError(f"{where}: unknown target {args[0]!r} in [{tag}]; known: {', '.join(sorted(targets))} "
                             f"(declare others with @scene NAME X Y Z)")
        return Gesture(kind, word, target=target, hand=hand, line=line, column=column)
    if kind == "icon":
        lexeme = args[0].upper()
        if lexeme not in ICON_LEXEMES:
            raise StoryError(f"{where}: unknown gesture [{tag}]; the motion module knows {', '.join(ICON_LEXEMES)}")
        return Gesture(kind, word, lexeme=lexeme, hand=hand, line=line, column=column)
    if kind == "face":
        lexeme = args[0].upper()
        if lexeme not in FACE_LEXEMES:
            raise StoryError(f"{where}: unknown face [{tag}]; the motion module knows {', '.join(FACE_LEXEMES)}")
        return Gesture(kind, word, lexeme=lexeme, line=line, column=column)
    lexeme = {"beat": "BEAT", "nod": "NOD", "shake": "SHAKE", "brows": "RAISE_BROWS"}[kind]
    return Gesture(kind, word, lexeme=lexeme, hand=hand, line=line, column=column)


# ----------------------------------------------------------------------------------------------------
# Compiling.


def anchor_sync(gesture: Gesture) -> str:
    """The sync point of a gesture that lands on its syllable: the stroke of a gesture, pointing or head
    movement, the attack peak of a face, the end of a gaze shift."""
    return {"gesture": "stroke", "pointing": "stroke", "head": "stroke", "faceLexeme": "attackPeak",
            "gazeShift": "end"}[gesture.behaviour]


def mark_name(word: int, anchor: str = "stress") -> str:
    """The speech sync id placed in front of word ``word``: ``w12.stress`` (a phoneme-level mark on the
    stressed vowel, :class:`~scenarios.storytelling.voice.PhonemeMarks`) or ``w12`` (the word onset)."""
    return f"w{word}.stress" if anchor == "stress" else f"w{word}"


def release_delay(gesture: Gesture) -> float | None:
    """Seconds from a gesture's syllable sync point to its end as its motion unit prefers them (None for
    a gaze shift, which ends on its syllable)."""
    from agentsim.animation import units

    unit = {"beat": units.BEAT, "icon": units.GESTURE, "point": units.POINTING, "nod": units.NOD,
            "shake": units.SHAKE, "brows": units.FACE, "face": units.FACE}.get(gesture.kind)
    if unit is None:
        return None
    index = 1 if gesture.behaviour == "faceLexeme" else 3  # attackPeak of a face, stroke of the others
    return float(unit.keys[-1] - unit.keys[index])


def release_mark(word: int, delay: float, anchor: str = "stress", offset: float = 0.0) -> str:
    """The speech sync id a gesture's ``end`` is tied to: ``delay`` seconds of speech after its syllable
    mark (``w12.stress.d500``; with ``anchor="offset"`` the word mark plus offset and delay, ``w12.d583``)."""
    if anchor == "stress":
        return f"{mark_name(word, anchor)}.d{round(delay * 1000)}"
    return f"{mark_name(word, anchor)}.d{round((offset + delay) * 1000)}"


def gesture_ids(story: Story) -> list[str]:
    """BML id of each gesture: its kind and its number among the gestures of that kind (``beat12``)."""
    counts: dict[str, int] = {}
    ids = []
    for g in story.gestures:
        counts[g.kind] = counts.get(g.kind, 0) + 1
        ids.append(f"{g.kind}{counts[g.kind]}")
    return ids


def compile_bml(story: Story, timeline: Utterance | None = None, anchor: str = "stress",
                release: bool | None = None, block_id: str = "story", speech_id: str = "speech1",
                start: float = 1.0, character: str = "storyteller") -> str:
    """The BML block that tells ``story``: one speech with a sync mark in front of every annotated word,
    and one behaviour per gesture with its syllable sync point tied to that mark (and one ``<ex:emotion>`` per
    emotion, from the onset of its word, ``w12``, to that of its end's or the speech's end).

    Parameters
    ----------
    story : Story
        What to tell.
    timeline : Utterance, optional
        The planned utterance of ``story.text`` (what the planner will know under ``timing="tts"``).
        Needed for ``anchor="offset"`` and for ``release``.
    anchor : {"stress", "offset", "word"}
        How a gesture reaches its stressed syllable. ``"stress"``: the mark is phoneme-level,
        ``<sync id="w12.stress"/>`` (the backend must be wrapped in
        :class:`~scenarios.storytelling.voice.PhonemeMarks`), so the sync point is the stressed vowel
        itself on the speech's timeline: ``stroke="speech1:w12.stress"``. ``"offset"``: the mark is the
        word onset and the stroke is tied to it plus the stressed vowel's offset in ``timeline``:
        ``stroke="speech1:w12+0.083000"``. ``"word"``: the word onset, no offset (plain BML).
    release : bool, optional
        Also tie each gesture's ``end`` to a delayed mark, ``end="speech1:w12.stress.d500"``
        (:func:`release_mark`: its syllable plus the time from stroke to end its motion unit prefers),
        so that the gesture ends on the speech's timeline too (unless that is after the speech's end).
        Default: when ``timeline`` is given
        (the delayed marks must stand in the text in time order, which needs the timeline). Without it
        the end hangs at an offset after the stroke; under an animator-time strategy the realizer reads
        a speech sync point that animator time has passed as *now*, so such a key keeps receding and is
        passed only at the next pause in the speech's progress events, often seconds later.
    block_id, speech_id : str
        Ids of the block and of its speech.
    start : float
        Start of the speech (seconds after the block starts): room for the first preparations.
    character : str
        The block's ``characterId``.

    Returns
    -------
    str
        The BML document, one behaviour per line.
    """
    from scenarios.storytelling.voice import mark_event, stressed_onset, word_after

    if anchor not in ANCHORS:
        raise ValueError(f"anchor must be one of {ANCHORS}, not {anchor!r}")
    release = timeline is not None if release is None else release
    if timeline is None and (anchor == "offset" or release):
        raise ValueError('anchor="offset" and release marks need the planned utterance (timeline)')
    gestured = {g.word for g in story.gestures}
    felt = {e.word for e in story.emotions} | {e.end for e in story.emotions if e.end is not None}
    # With the planned utterance an emotion is pegged to a mark the speech has anyway, plus the time to its
    # word's onset: a mark of its own would add a progress event to the speech's, and so change when the
    # gestures' strokes come. Without it, an emotion's word has a mark of its own (w12).
    marked = felt if timeline is None else set()
    words = sorted(gestured | marked)
    onset: dict[int, float] = {}
    stress: dict[int, float] = {}
    if timeline is not None:
        for k in sorted(gestured | felt):
            w = word_after(timeline, story.words[k][0])
            if w is None:
                raise ValueError(f"the timeline has no word for {story.word_text(k)!r}")
            onset[k] = timeline.words[w].start
            stress[k] = stressed_onset(timeline, w)[0]
    # where each word's marks are on the timeline (a word only an emotion starts or ends on: its onset)
    base_time = {k: (stress if anchor == "stress" else onset)[k] for k in gestured} if onset else {}
    delayed: dict[str, float] = {}  # release mark -> its time on the timeline
    behaviours = []
    for gid, g in zip(gesture_ids(story), story.gestures):
        base = mark_name(g.word, anchor)
        ref = f"{speech_id}:{base}"
        offset = stress[g.word] - onset[g.word] if anchor == "offset" else 0.0
        if anchor == "offset":
            ref += f"{offset:+.6f}"
        attrs = [f'id="{gid}"']
        if g.lexeme:
            attrs.append(f'lexeme="{g.lexeme}"')
        if g.target:
            attrs.append(f'target="{g.target}"')
        if g.hand:
            attrs.append(f'mode="{g.hand}"')
        attrs.append(f'{anchor_sync(g)}="{ref}"')
        delay = release_delay(g) if release else None
        if delay is not None:
            end = release_mark(g.word, delay, anchor, offset)
            t_end = base_time[g.word] + mark_event(end)[3]
            if t_end <= timeline.duration:  # a speech has no sync points after its end
                delayed[end] = t_end
                attrs.append(f'end="{speech_id}:{end}"')
        behaviours.append(f'  <{g.behaviour} {" ".join(attrs)}/>')
    # A delayed mark is timed from the mark it names, wherever it stands; it stands in front of the first
    # annotated word whose own mark comes later, so that the speech's sync points are in time order.
    before: dict[int | None, list[str]] = {}
    # the marks in time order: the first word later than a mark is never before that of an earlier mark
    # (every word before it is no later than the earlier mark), so the search goes on from there
    first = 0
    for name, t in sorted(delayed.items(), key=lambda item: (item[1], item[0])):
        while first < len(words) and not base_time[words[first]] > t:
            first += 1
        before.setdefault(words[first] if first < len(words) else None, []).append(name)
    marks = sorted([(base_time[k], mark_name(k, anchor)) for k in gestured] + [(t, n) for n, t in delayed.items()]
                   if timeline is not None else [])

    def word_ref(k: int) -> str:
        """The sync reference of word ``k``'s onset."""
        if timeline is None:
            return f"{speech_id}:w{k}"
        at = bisect.bisect_right(marks, (onset[k] + 1e-9, "\uffff")) - 1
        base, name = marks[at] if at >= 0 else (0.0, "start")
        offset = onset[k] - base
        return f"{speech_id}:{name}" + (f"{offset:+.6f}" if abs(offset) >= 5e-7 else "")

    for n, e in enumerate(story.emotions):
        end = word_ref(e.end) if e.end is not None else f"{speech_id}:end"
        intensity = f" intensity={quoteattr(e.intensity)}" if e.intensity else ""
        behaviours.append(f'  <ex:emotion id="emotion{n + 1}" type={quoteattr(e.kind)}{intensity} '
                          f'start="{word_ref(e.word)}" end="{end}"/>')
    pieces, last = [], 0
    for k in words:
        a = story.words[k][0]
        names = before.get(k, [])
        if k in marked and not (k in gestured and mark_name(k, anchor) == f"w{k}"):
            names = names + [f"w{k}"]
        names += [mark_name(k, anchor)] if k in gestured else []
        pieces.append(escape(story.text[last:a]) + "".join(f'<sync id="{name}"/>' for name in names))
        last = a
    pieces.append(escape(story.text[last:]) + "".join(f'<sync id="{name}"/>' for name in before.get(None, [])))
    expression = f' xmlns:ex="{EXPRESSION_NAMESPACE}"' if story.emotions else ""
    lines = [f'<bml xmlns="{BML_NAMESPACE}"{expression} id={quoteattr(block_id)} characterId={quoteattr(character)}>',
             f'  <speech id={quoteattr(speech_id)} start="{start:g}"><text>{"".join(pieces)}</text></speech>']
    lines += behaviours
    lines.append("</bml>")
    return "\n".join(lines) + "\n"
