"""What a ``<speech>`` says: its words, its sync points and how stretches of it are spoken.

BML 1.0 writes ``<speech><text>words <sync id="s1"/> words</text></speech>``. Other realizers write marks
inline in the speech element (Greta's and the Vienna draft's ``<tm id>``, NVBG's and SmartBody's SSML
``<mark name>``), plain text, or SSML speech (``type="application/ssml+xml"``, perhaps in ``<speak>``), and
SSML markup inside the text: ``<emphasis>``, ``<prosody>``, ``<break>``, ``<say-as>``, ``<sub>``. The lenient
reading takes all of them and keeps every word; the strict one reads BML 1.0 and, where markup it does not
know stands in the text, still speaks the words inside it and says so.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Iterable

from agentsim.core.xmltree import Node

#: SSML elements whose words are spoken with a prosody span around them (attributes kept as written).
SPANS = {"emphasis": ("level",), "prosody": ("rate", "pitch", "volume"), "say-as": ("interpret-as", "format")}
#: Elements inside a speech that are not text: they are read elsewhere, or are descriptions of it.
NOT_TEXT = {"description", "pitchaccent", "boundary"}
#: SSML elements that only group words; their words are spoken, the grouping is not used.
GROUPING = {"speak", "s", "p", "voice", "lang", "phoneme", "token", "w", "audio", "emotion", "voice-transform"}


@dataclass
class SpeechReading:
    """The text of a speech, normalized (runs of white space are one space), with sync points at offsets,
    prosody spans on those offsets, what the reading adapted (lenient) and what it could not use."""

    text: str = ""
    marks: list[tuple[int, str]] = field(default_factory=list)
    prosody: list[tuple[str, int, int, tuple[tuple[str, str], ...]]] = field(default_factory=list)
    adapted: list[str] = field(default_factory=list)
    problems: list[tuple[str, Node]] = field(default_factory=list)


_SPACE = re.compile(r"\s+")


def normalize_space(raw: str, offsets: Iterable[int] = ()) -> tuple[str, dict[int, int]]:
    """Collapse runs of white space to one space and strip the ends.

    Returns the new text and, for each of ``offsets`` into ``raw`` (0 to ``len(raw)``), the offset it maps
    to: in a run of white space, its first character maps to the space (before it), the rest after it. Only
    the offsets asked for are mapped (a map of every offset of a text of megabytes weighed 36 bytes a
    character).
    """
    wanted = sorted(set(offsets))
    mapped: dict[int, int] = {}
    i = 0  # the next offset to map
    length = 0  # of the text made so far, up to the end of the last run
    done = 0  # of ``raw`` read so far
    for run in _SPACE.finditer(raw) if wanted else ():  # (\s is what str.isspace says is white space)
        if i == len(wanted):
            break
        start, end = run.span()
        here = length + start - done  # where the run begins in the new text
        while i < len(wanted) and wanted[i] < end:
            o = wanted[i]
            mapped[o] = here - (start - o) if o < start else here if (o == start or start == 0) else here + 1
            i += 1
        length = here + (1 if start > 0 else 0)  # a run inside the text (or at its end) becomes one space;
        done = end  # a leading one is dropped
    for o in wanted[i:]:
        mapped[o] = length + o - done
    return _SPACE.sub(" ", raw).strip(), mapped


class _Walk:
    """Gathers raw text, marks and spans from a speech's content, in raw offsets."""

    def __init__(self, speech_id: str, lenient: bool, reading: SpeechReading):
        self.speech_id = speech_id
        self.lenient = lenient
        self.reading = reading
        self.raw: list[str] = []
        self.length = 0
        self.marks: list[tuple[int, str, Node]] = []
        self.spans: list[tuple[str, int, int, tuple[tuple[str, str], ...]]] = []
        self.timed_syncs = 0

    def put(self, text: str) -> None:
        self.raw.append(text)
        self.length += len(text)

    def adapt(self, note: str) -> None:
        if note not in self.reading.adapted:
            self.reading.adapted.append(note)

    def mark(self, name: str, node: Node) -> None:
        self.marks.append((self.length, name.strip(), node))

    def walk(self, node: Node, top: bool = False) -> None:
        for child in node.children:
            if isinstance(child, str):
                self.put(child)
                continue
            local = child.local
            if local == "sync":
                self.mark(child.attrs.get("id", ""), child)
                if "time" in child.attrs:
                    self.timed_syncs += 1
            elif not self.lenient:
                # BML 1.0 allows only <sync> in the text: other markup is not read, but its words are spoken
                self.reading.problems.append((f"speech {self.speech_id}: <{child.tag}> in the text is not BML "
                                              "1.0: its markup is ignored and its words are spoken", child))
                self.walk(child)
            elif local == "tm":
                self.adapt("time markers <tm id> in the speech read as its sync points")
                self.mark(child.attrs.get("id", ""), child)
            elif local == "mark":
                self.adapt("SSML <mark name> read as sync points of the speech")
                name = child.attrs.get("name", "").strip()
                if name.startswith(f"{self.speech_id}:"):  # SEMAINE qualifies them with the speech's id
                    name = name[len(self.speech_id) + 1:]
                    self.adapt("mark names qualified with the speech id read without it")
                self.mark(name, child)
            elif top and local in NOT_TEXT:
                continue
            elif local == "break":
                attrs = tuple((k, child.attrs[k]) for k in ("time", "strength") if k in child.attrs)
                self.spans.append(("break", self.length, self.length, attrs))
                self.adapt("SSML <break> in the text spoken as a pause")
                self.walk(child)
            elif local in SPANS:
                start = self.length
                self.walk(child)
                attrs = tuple((k, child.attrs[k]) for k in SPANS[local] if k in child.attrs)
                self.spans.append((local, start, self.length, attrs))
                self.adapt(f"SSML <{local}> in the text: spoken with it where the speech engine can")
            elif local == "sub":
                alias = child.attrs.get("alias")
                if alias is None:
                    self.walk(child)
                else:
                    self.put(f" {alias} ")
                    self.adapt("SSML <sub alias> spoken as its alias")
            elif local in GROUPING:
                self.walk(child)
                if local != "speak":
                    self.adapt(f"SSML <{local}> in the text: its words are spoken, the element is not used")
            else:
                self.walk(child)
                self.adapt(f"<{child.tag}> in the speech text: its words are spoken, the element is not used")


def read_speech(node: Node, speech_id: str, lenient: bool) -> SpeechReading | None:
    """Read the text of a ``<speech>`` element. None if it has no text to read (strict: no ``<text>``)."""
    reading = SpeechReading()
    texts = [c for c in node.elements() if c.local == "text"]
    walk = _Walk(speech_id, lenient, reading)
    if texts:
        walk.walk(texts[0])
    elif not lenient:
        return None
    else:
        walk.walk(node, top=True)
        kind = node.attrs.get("type", "")
        if kind and "ssml" in kind.lower():
            walk.adapt(f"SSML speech (type={kind!r}) read as its words, marks and prosody")
        else:
            walk.adapt("speech without <text>: the text written in the speech element read as its text")
    if lenient and not "".join(walk.raw).strip() and node.attrs.get("text", "").strip():
        walk.put(node.attrs["text"])
        walk.adapt("the text= attribute of a speech (Greta, SEMAINE) read as its text")
    if walk.timed_syncs:
        walk.adapt(f"{walk.timed_syncs} sync points of the text carry times (from a recording): the speech is "
                   "synthesised, with its own timing")
    raw = "".join(walk.raw)
    offsets = [offset for offset, _, _ in walk.marks] + [o for _, start, end, _ in walk.spans for o in (start, end)]
    reading.text, positions = normalize_space(raw, offsets)

    def at(offset: int) -> int:
        return min(positions[offset], len(reading.text))

    seen: set[str] = set()
    for offset, name, mark in walk.marks:
        if not name:
            what = "<sync> without id" if mark.local == "sync" else f"<{mark.local}> without a name"
            reading.problems.append((f"speech {speech_id}: {what} ignored", mark))
        elif name in seen or name in ("start", "end"):
            reading.problems.append((f"speech {speech_id}: duplicate sync id {name!r} ignored", mark))
        elif ":" in name:
            reading.problems.append((f"speech {speech_id}: sync id {name!r} contains ':' and is ignored", mark))
        else:
            seen.add(name)
            reading.marks.append((at(offset), name))
    for kind, start, end, attrs in walk.spans:
        reading.prosody.append((kind, at(start), at(end), attrs))
    if lenient:
        greta_prosody(node, speech_id, reading)
        crossing = crossing_spans(reading.prosody)
        if crossing:
            reading.prosody = [s for i, s in enumerate(reading.prosody) if i not in crossing]
            reading.problems.append((f"speech {speech_id}: {len(crossing)} prosody spans cross others and are not "
                                     "used (their words are spoken)", node))
    return reading


def crossing_spans(spans: list[tuple[str, int, int, tuple]]) -> set[int]:
    """Indices of the spans that cross an earlier one (overlap without one holding the other)."""
    crossing: set[int] = set()
    for i, (_, a, b, _) in enumerate(spans):
        for j in range(i):
            if j in crossing:
                continue
            _, c, d, _ = spans[j]
            if a < c < b < d or c < a < d < b:
                crossing.add(i)
                break
    return crossing


def greta_prosody(node: Node, speech_id: str, reading: SpeechReading) -> None:
    """Greta's ``<pitchaccent start end>`` and ``<boundary start end>`` (on the speech's time markers): an
    emphasis on the words between, and a pause after the boundary."""
    offsets = mark_offsets(reading)

    def offset(ref: str) -> int | None:
        ref = ref.strip()
        if ":" in ref:
            owner, _, ref = ref.partition(":")
            if owner != speech_id:
                return None
        if ref in ("start", "end"):
            return 0 if ref == "start" else len(reading.text)
        return offsets.get(ref)

    for child in node.elements():
        if child.local not in ("pitchaccent", "boundary"):
            continue
        start, end = offset(child.attrs.get("start", "")), offset(child.attrs.get("end", ""))
        if start is None and end is None:
            reading.problems.append((f"speech {speech_id}: <{child.tag}> names no time marker of the speech; "
                                     "ignored", child))
            continue
        if child.local == "pitchaccent":
            a = start if start is not None else end
            b = end if end is not None and end >= a else len(reading.text)
            level = "strong" if child.attrs.get("importance", "") in ("2", "high") else "moderate"
            reading.prosody.append(("emphasis", a, b, (("level", level),)))
            note = "Greta's <pitchaccent> spoken as an emphasis on its words"
        else:
            at = end if end is not None else start
            reading.prosody.append(("break", at, at, (("strength", "medium"),)))
            note = "Greta's <boundary> spoken as a pause at its end"
        if note not in reading.adapted:
            reading.adapted.append(note)


def mark_offsets(reading: SpeechReading) -> dict[str, int]:
    """Sync point name -> text offset."""
    return {name: offset for offset, name in reading.marks}
