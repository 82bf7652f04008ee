"""de Melo's Expression Markup Language (EML: "Gesticulation Expression in Virtual Humans", 2006, section 3.6
and Appendix D) read as one BML block, each adaptation noted as the other dialects' are.

* The core: ``<eml name>`` is the block (its name the block's id), ``<head>`` holds BEML's configuration
  (reported, not realized), ``<body>`` the clauses, each at its ``time``.
* Time and synchronisation: ``time`` is an expression of seconds (``5``, ``1.5s``, ``2m``, ``1h``,
  ``250ms``) and names (a clause's ``timeId``: when it begins; a ``<tm name>``: its word in the speech)
  added and subtracted (``t1+4s-1s``, ``5+t1``); at most one name of a speech's word in one expression, and
  not subtracted, since BML pegs a time to one sync point. A time that names something is where it says;
  a time of numbers alone counts from its container: the document's start in ``<body>``, the beginning
  of a ``<par>``, the end of the clause before it in a ``<seq>`` (the beginning for the first). A clause
  ends when its speech does (``voice-text``), after its ``duration`` (``gesture-key``), with its last
  clause (``seq``), with its latest (``par``), or when it begins (the others). ``repetitionCount`` plays
  a ``seq`` or ``par`` that many times, each ``duration`` seconds after the one before (when it is
  given), else after the one before ends; names inside an iteration mean that iteration's clauses, and
  from outside, the first's.
* VEML: ``<voice-text>`` is a speech starting at its time; inside it ``<tm name event>`` is a sync point
  (``onStart``: the onset of the next word; ``onEnd`` and ``onPhone`` are read as the onsets of the word
  after and of the word itself, said as adaptations), ``<emph level>``, ``<rate speed>``, ``<pitch base
  middle>``, ``<volume level>`` and ``<break level msec type>`` go to the speech engine as SSML's
  emphasis, prosody and break, ``<div>`` groups words, ``<pron sub>`` and ``<sayas mode>`` are SSML's sub
  and say-as. ``<voice-say>`` of text is a speech without sync points.
* GEML: ``<gesture-key>`` becomes a MURML gesture (:mod:`agentsim.bml.eml_gestures`) whose stroke is at
  the key's time; a key that would start before the block (its time less its preparation) is clamped to
  the block's start, its stroke at its time or :data:`MIN_PREPARATION` after the block's start, whichever
  is later; ``<gesture-is-on isOn="false">`` leaves out the keys after it (in document order)
  until one turns gestures on again.
* ``<event type>`` is a sync point without motion (``event`` behaviour); ``<null>`` only takes time.

What cannot be read is said, one warning each: a time expression that is not one (the clause is left
out), an element EML does not have or that has no counterpart here (left out); the rest of the
document is realized.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from agentsim.bml.documents import Envelope, seconds
from agentsim.bml.eml_gestures import SIDES, UNSUPPORTED, GestureKeys, preparation
from agentsim.bml.vocabulary import BML_NAMESPACE
from agentsim.core.xmltree import Node

#: Clauses: what ``<body>``, ``<seq>`` and ``<par>`` hold.
CLAUSES = {"voice-text", "voice-say", "gesture-key", "gesture-is-on", "seq", "par", "null", "event"}
#: VEML's SABLE elements inside a ``<voice-text>`` and the SSML each is read as (None: its words only).
VEML = {"tm": "sync", "emph": "emphasis", "rate": "prosody", "pitch": "prosody", "volume": "prosody",
        "break": "break", "div": None, "pron": "sub", "sayas": "say-as", "engine": None}
#: Units of a time expression, in seconds.
UNITS = {"": 1.0, "s": 1.0, "ms": 0.001, "m": 60.0, "h": 3600.0}
#: SABLE's descriptive values and the SSML ones they are read as.
RATES = {"fastest": "x-fast", "fast": "fast", "medium": "medium", "slow": "slow", "slowest": "x-slow"}
PITCHES = {"highest": "x-high", "high": "high", "medium": "medium", "low": "low", "lowest": "x-low",
           "default": "default"}
VOLUMES = {"loudest": "x-loud", "loud": "loud", "medium": "medium", "quiet": "soft"}
BREAKS = {"large": "strong", "medium": "medium", "small": "weak", "none": "none"}
EMPHASES = ("strong", "moderate", "none", "reduced")
#: The least time (seconds) a gesture key clamped to the block's start has to prepare its stroke.
MIN_PREPARATION = 0.15
#: Words a minute a rate given as a number is read against (espeak-ng's default).
WORDS_PER_MINUTE = 175.0
_TERM = re.compile(r"\s*([+-])?\s*(?:(\d+(?:\.\d*)?|\.\d+)\s*(ms|s|m|h)?(?![\w.])|([A-Za-z_][\w.]*))\s*")
_ID = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_WORD = re.compile(r"\S+")
BML = {"": BML_NAMESPACE}


class TimeError(ValueError):
    """A time that cannot be read or placed, with the reason."""


@dataclass(frozen=True)
class Time:
    """A time as BML writes it: ``offset`` seconds after the block's start, or after the sync point ``ref``."""

    ref: str | None = None
    offset: float = 0.0

    def plus(self, other: "Time") -> "Time":
        if self.ref is not None and other.ref is not None:
            raise TimeError(f"it adds two points of speech, {self.ref} and {other.ref}")
        return Time(self.ref or other.ref, self.offset + other.offset)

    def text(self) -> str:
        if self.ref is None:
            return seconds(self.offset)
        if abs(self.offset) < 1e-12:
            return self.ref
        digits = f"{abs(self.offset):.9f}".rstrip("0").rstrip(".")
        return f"{self.ref}{'+' if self.offset > 0 else '-'}{digits}"


def terms(text: str) -> list[tuple[float, str | None]]:
    """A time expression's terms: (signed seconds, None) or (sign, name); :class:`TimeError` if it is none."""
    out: list[tuple[float, str | None]] = []
    pos = 0
    if not text.strip():
        raise TimeError("it is empty")
    while pos < len(text):
        match = _TERM.match(text, pos)
        if match is None or match.end() == pos or (out and match.group(1) is None):
            raise TimeError(f"it is not seconds and names joined by + and - (at {text[pos:].strip()!r})")
        sign, number, unit, name = match.groups()
        factor = -1.0 if sign == "-" else 1.0
        out.append((factor * float(number) * UNITS[unit or ""], None) if name is None else (factor, name))
        pos = match.end()
    return out


@dataclass(eq=False)
class Clause:
    """One clause as it plays (a repeated container's clauses once per iteration)."""

    node: Node
    scope: "Scope"
    iteration: "Iteration | None"  # the container's iteration it is in (None: in <body>)
    previous: "Clause | None" = None  # the clause before it in a <seq>
    id: str = ""
    iterations: list["Iteration"] = field(default_factory=list)


@dataclass(eq=False)
class Iteration:
    owner: Clause
    index: int
    children: list[Clause] = field(default_factory=list)


class Scope:
    """Names (timeIds and time markers) and what they mean; a repeated container's iteration has its own."""

    def __init__(self, parent: "Scope | None" = None):
        self.parent = parent
        self.names: dict[str, Clause | Time] = {}

    def find(self, name: str):
        scope = self
        while scope is not None:
            if name in scope.names:
                return scope.names[name]
            scope = scope.parent
        return None


class EmlReader:
    """Reads an ``<eml>`` tree into a ``<bml>`` element, noting adaptations in ``envelope``."""

    def __init__(self, envelope: Envelope, name_block):
        self.envelope = envelope
        self.root = envelope.node
        self.notes = envelope.notes
        self.name_block = name_block
        self.used: set[str] = set()
        self.counters: dict[str, int] = {}
        self.top = Scope()
        self.begins: dict[int, Time | TimeError] = {}
        self.resolving: set[int] = set()
        self.out: list[Node] = []
        self.failed: set[int] = set()
        self.gestures = GestureKeys(self.note, self.warn)
        self.gestures_on = True
        self.unsupported: dict[str, list[Node]] = {}

    # ------------------------------------------------------------------------------------------- reports
    def note(self, text: str, node: Node | None = None) -> None:
        self.notes.add(text, *((node,) if node is not None else ()))

    def warn(self, kind: str, text: str, node: Node) -> None:
        self.envelope.warnings.append((kind, f"{text} ({node.where()})", node))

    def fail(self, clause: Clause, reason: str) -> None:
        self.failed.add(id(clause))
        time = clause.node.attrs.get("time")
        what = f"time {time!r}" if time is not None else "time"
        self.warn("PARSING_FAILURE", f"EML <{clause.node.local}>: its {what} cannot be read: {reason}; not "
                  "realized", clause.node)

    def left_out(self, node: Node) -> None:
        self.unsupported.setdefault(node.local, []).append(node)

    # ------------------------------------------------------------------------------------------- the document
    def read(self) -> Node:
        root = self.root
        name = root.attrs.get("name", "").strip()
        block_id = name if _ID.match(name) else self.name_block()
        if name != block_id:
            self.note(f"EML document {name or 'without a name'}{'' if not name else ' (not an id)'}: named "
                      f"{block_id}")
        self.note("EML document read as one BML block")
        clauses: list[Clause] = []
        for part in root.elements():
            if part.local == "head":
                for child in part.elements():
                    self.left_out(child)
            elif part.local == "body":
                clauses += self.instances(part.elements(), self.top, None)
            else:
                self.left_out(part)
        for clause in clauses:
            self.emit(clause)
        for local, nodes in self.unsupported.items():
            hint = UNSUPPORTED.get(local)
            count = f"{len(nodes)} <{local}> elements" if len(nodes) > 1 else f"<{local}>"
            if hint is None:
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"{count}: not an EML element this reader knows; ignored",
                          nodes[0])
            else:
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"{count}: {hint}, which has no counterpart here; not "
                          "realized", nodes[0])
        return Node("bml", {"id": block_id}, root.line, root.column, BML, self.out)

    def new_id(self, node: Node, base: str, suffix: str = "") -> str:
        wanted = node.attrs.get("timeId", "").strip()
        if wanted and _ID.match(wanted) and f"{wanted}{suffix}" not in self.used:
            found = f"{wanted}{suffix}"
        else:
            n = self.counters.get(base, 0)
            while True:
                n += 1
                if f"{base}{n}" not in self.used:
                    break
            self.counters[base] = n
            found = f"{base}{n}"
        self.used.add(found)
        return found

    def instances(self, nodes: list[Node], scope: Scope, iteration: Iteration | None,
                  suffix: str = "") -> list[Clause]:
        """The clauses of ``nodes`` (a <body>'s, or one iteration's), their names defined in ``scope``."""
        made: list[Clause] = []
        previous = None
        for node in nodes:
            if node.local not in CLAUSES:
                self.left_out(node)
                continue
            clause = Clause(node, scope, iteration, previous if iteration and iteration.owner.node.local == "seq"
                            else None)
            name = node.attrs.get("timeId", "").strip()
            if name:
                self.define(scope, name, clause, node)
            if node.local in ("voice-text", "voice-say"):
                clause.id = self.new_id(node, "speech", suffix)
                for mark in (m for m in _walk(node) if m.local == "tm"):
                    mark_name = mark.attrs.get("name", "").strip()
                    if mark_name:
                        self.define(scope, mark_name, Time(f"{clause.id}:{mark_name}"), mark)
            elif node.local in ("gesture-key", "event"):
                clause.id = self.new_id(node, "key" if node.local == "gesture-key" else "event", suffix)
            elif node.local in ("seq", "par"):
                count = self.repetitions(node)
                for k in range(count):
                    inner = Scope(scope) if count > 1 else scope
                    it = Iteration(clause, k)
                    it.children = self.instances(node.elements(), inner, it,
                                                 suffix if k == 0 else f"{suffix}_{k + 1}")
                    clause.iterations.append(it)
                    if k == 0 and inner is not scope:  # from outside, names mean the first iteration's
                        for key, value in inner.names.items():
                            scope.names.setdefault(key, value)
            made.append(clause)
            previous = clause
        return made

    def define(self, scope: Scope, name: str, value, node: Node) -> None:
        if name in scope.names:
            self.warn("PARSING_FAILURE", f"EML name {name!r} given twice: the first one is meant", node)
            return
        scope.names[name] = value

    def repetitions(self, node: Node) -> int:
        text = node.attrs.get("repetitionCount")
        if text is None:
            return 1
        try:
            count = int(text.strip())
        except ValueError:
            count = 0
        if not 1 <= count <= 1000:
            self.warn("PARSING_FAILURE", f"<{node.local} repetitionCount={text!r}>: a whole number from 1 to 1000 "
                      "expected; played once", node)
            return 1
        if count > 1:
            self.note(f"<{node.local} repetitionCount> played as {count} iterations", node)
        return count

    # ------------------------------------------------------------------------------------------- time
    def evaluate(self, text: str, scope: Scope) -> tuple[Time, bool]:
        """A time expression's value, and whether it names something (else it counts from the container)."""
        total = Time()
        named = False
        for value, name in terms(text):
            if name is None:
                total = total.plus(Time(None, value))
                continue
            named = True
            found = scope.find(name)
            if found is None:
                raise TimeError(f"{name!r} is no timeId or time marker of the document")
            point = found if isinstance(found, Time) else self.begin(found)
            if value < 0:
                if point.ref is not None:
                    raise TimeError(f"it subtracts {name!r}, a point of speech")
                point = Time(None, -point.offset)
            total = total.plus(point)
        return total, named

    def begin(self, clause: Clause) -> Time:
        key = id(clause)
        found = self.begins.get(key)
        if isinstance(found, Time):
            return found
        if found is not None or key in self.failed:
            raise TimeError(f"it names the <{clause.node.local}> at {clause.node.where()}, whose time cannot be "
                            "read")
        if key in self.resolving:
            raise TimeError("its time depends on itself")
        self.resolving.add(key)
        try:
            text = clause.node.attrs.get("time")
            value, named = self.evaluate(text, clause.scope) if text is not None else (Time(), False)
            result = value if named else self.base(clause).plus(value)
        except TimeError as exc:
            self.begins[key] = exc
            raise
        finally:
            self.resolving.discard(key)
        self.begins[key] = result
        return result

    def base(self, clause: Clause) -> Time:
        """Where a time of numbers alone counts from."""
        if clause.previous is not None:
            return self.end(clause.previous)
        if clause.iteration is None:
            return Time()
        return self.iteration_begin(clause.iteration)

    def iteration_begin(self, it: Iteration) -> Time:
        owner = it.owner
        if it.index == 0:
            return self.begin(owner)
        length = self.duration(owner.node)
        if length is not None:
            return self.begin(owner).plus(Time(None, it.index * length))
        return self.iteration_end(owner.iterations[it.index - 1])

    def iteration_end(self, it: Iteration) -> Time:
        length = self.duration(it.owner.node)
        if length is not None:
            return self.iteration_begin(it).plus(Time(None, length))
        if not it.children:
            return self.iteration_begin(it)
        if it.owner.node.local == "seq":
            return self.end(it.children[-1])
        ends = [self.end(c) for c in it.children]
        refs = {e.ref for e in ends}
        if len(refs) > 1:
            raise TimeError(f"it counts from the end of the <par> at {it.owner.node.where()}, which ends with the "
                            "latest of clauses timed by different speeches, not known before they are spoken")
        return max(ends, key=lambda e: e.offset)

    def end(self, clause: Clause) -> Time:
        local = clause.node.local
        if local in ("voice-text", "voice-say"):
            return Time(f"{clause.id}:end")
        if local == "gesture-key":
            return self.begin(clause).plus(Time(None, self.duration(clause.node) or 0.0))
        if local in ("seq", "par"):
            return self.iteration_end(clause.iterations[-1])
        return self.begin(clause)

    @staticmethod
    def duration(node: Node) -> float | None:
        text = node.attrs.get("duration")
        if text is None:
            return None
        try:
            value = sum(v for v, name in terms(text) if name is None)
            if any(name is not None for _, name in terms(text)) or not math.isfinite(value) or value < 0:
                raise TimeError("")
        except TimeError:
            raise TimeError(f"its duration {text!r} is not a number of seconds") from None
        return value

    # ------------------------------------------------------------------------------------------- clauses
    def emit(self, clause: Clause) -> None:
        node = clause.node
        try:
            start = self.begin(clause)
            if node.local in ("seq", "par"):
                self.duration(node)
        except TimeError as exc:
            self.fail(clause, str(exc))
            return
        local = node.local
        if local in ("seq", "par"):
            for it in clause.iterations:
                for child in it.children:
                    self.emit(child)
        elif local == "voice-text":
            self.speech(clause, start)
        elif local == "voice-say":
            operation = node.attrs.get("voiceOperation", "text").strip().lower()
            if "file" in operation:
                self.left_out(node)
            else:
                self.note("VEML <voice-say> of text read as a speech without sync points", node)
                self.speech(clause, start)
        elif local == "gesture-is-on":
            on = node.attrs.get("isOn", "true").strip().lower() != "false"
            self.gestures_on = on
            self.note("<gesture-is-on isOn='true'>: gestures are always on here" if on else
                      "<gesture-is-on isOn='false'>: the gesture keys after it are left out until gestures are "
                      "turned on again", node)
        elif local == "gesture-key":
            self.gesture_key(clause, start)
        elif local == "event":
            kind = node.attrs.get("type", node.attrs.get("key", "")).strip()
            message = " ".join(filter(None, (kind, node.text().strip())))
            self.note("EML <event> realized as a sync point without motion (event behaviour)", node)
            self.out.append(Node("event", {"id": clause.id, "start": start.text(), "message": message},
                                 node.line, node.column, BML))
        # <null> only takes time: it places the clauses after it in a <seq>

    def clamp(self, start: Time, node: Node, what: str) -> Time:
        if start.ref is None and start.offset < 0:
            self.note(f"{what} before the block's start: clamped to the block's start", node)
            return Time()
        return start

    def speech(self, clause: Clause, start: Time) -> None:
        node = clause.node
        start = self.clamp(start, node, f"<{node.local}>")
        self.note(f"VEML <{node.local}> read as a speech starting at its time", node)
        writer = _SpeechText(self)
        children = writer.convert(node)
        text = Node("text", {}, node.line, node.column, BML, children)
        speech = Node("speech", {"id": clause.id, "start": start.text()}, node.line, node.column, BML, [text])
        self.notes.touch(speech)
        self.out.append(speech)

    def gesture_key(self, clause: Clause, start: Time) -> None:
        node = clause.node
        if not self.gestures_on:
            self.note("gesture keys left out while gestures are off (<gesture-is-on isOn='false'>)", node)
            return
        handedness = node.attrs.get("handedness", "right").strip().lower()
        if handedness not in SIDES:
            self.warn("PARSING_FAILURE", f"<gesture-key handedness={handedness!r}>: both, left or right; not "
                      "realized", node)
            return
        if "handedness" not in node.attrs:
            self.note("<gesture-key> without handedness played with the dominant (right) hand", node)
        try:
            length = self.duration(node)
            if length is None:
                length = 0.3
                self.note("<gesture-key> without duration given 0.3 s", node)
            description = self.gestures.form(node, SIDES[handedness], length, clause.id)
        except (TimeError, ValueError) as exc:
            self.warn("PARSING_FAILURE", f"<gesture-key>: {exc}; not realized", node)
            return
        if not description.elements()[0].elements():
            self.warn("PARSING_FAILURE", "<gesture-key> has no hand shape, palm or motion; not realized", node)
            return
        self.note("GEML <gesture-key> played as a MURML gesture: its stroke at its time, its keys through "
                  "its duration", node)
        syncs: dict[str, str] = {}
        if start.ref is None:
            first = preparation(description, {"strokeStart": start.offset, "stroke": start.offset,
                                              "strokeEnd": start.offset + length})
            if first < -1e-9:
                stroke = max(start.offset, MIN_PREPARATION)
                self.note(f"gesture-key {clause.id} would start {-first:.3f} s before the block: clamped to the "
                          f"block's start, its stroke at {stroke:.3f} s", node)
                start, syncs["start"] = Time(None, stroke), "0.0"
        syncs.update(strokeStart=start.text(), stroke=start.text(), strokeEnd=start.plus(Time(None, length)).text())
        gesture = Node("murmlgesture", {"id": clause.id, **syncs}, node.line, node.column,
                       {"": description.namespaces[""]}, [description])
        self.notes.touch(gesture)
        self.out.append(gesture)


def _walk(node: Node):
    for child in node.elements():
        yield child
        yield from _walk(child)


class _SpeechText:
    """A ``<voice-text>``'s content as the children of a BML ``<text>``: words, ``<sync>`` and SSML."""

    def __init__(self, reader: EmlReader):
        self.reader = reader
        self.after_word: list[Node] = []  # onEnd markers waiting for the end of the next word

    def convert(self, node: Node) -> list[Node | str]:
        out = self.children(node)
        out.extend(self.after_word)
        return out

    def children(self, node: Node) -> list[Node | str]:
        out: list[Node | str] = []
        for child in node.children:
            if isinstance(child, str):
                out.extend(self.text(child))
            else:
                out.extend(self.element(child))
        return out

    def text(self, text: str) -> list[Node | str]:
        if not self.after_word:
            return [text]
        match = _WORD.search(text)
        if match is None:
            return [text]
        waiting, self.after_word = self.after_word, []
        return [text[:match.end()], *waiting, text[match.end():]]

    def ssml(self, tag: str, attrs: dict[str, str], node: Node) -> Node:
        return Node(tag, attrs, node.line, node.column, BML, self.children(node))

    def element(self, node: Node) -> list[Node | str]:
        note = self.reader.note
        local, attrs = node.local, node.attrs
        if local == "tm":
            name = attrs.get("name", "").strip()
            event = attrs.get("event", "onStart").strip()
            sync = Node("sync", {"id": name}, node.line, node.column, BML)
            note("VEML <tm> read as sync points of the speech (onStart: the onset of the next word)", node)
            if event == "onEnd":
                note("<tm event='onEnd'> read as the onset of the word after its word (the speech's end after "
                     "the last word)", node)
                self.after_word.append(sync)
                return []
            if event == "onPhone":
                note(f"<tm event='onPhone' phone={attrs.get('phone', '')!r}> read as the onset of its word", node)
            elif event != "onStart":
                note(f"<tm event={event!r}> (not onStart, onEnd or onPhone) read as onStart", node)
            return [sync]
        if local == "emph":
            level = attrs.get("level", "moderate").strip().lower()
            if level not in EMPHASES:
                try:
                    number = float(level)
                except ValueError:
                    number = 1.0
                level = "none" if number <= 0 else "reduced" if number < 1 else "moderate" if number < 2 else "strong"
                note(f"<emph level={attrs['level']!r}> read as the emphasis {level}", node)
            note("VEML <emph> read as SSML <emphasis>", node)
            return [self.ssml("emphasis", {"level": level}, node)]
        if local in ("rate", "pitch", "volume"):
            return [self.prosody(node)]
        if local == "break":
            made: dict[str, str] = {}
            if "msec" in attrs:
                made["time"] = f"{attrs['msec'].strip()}ms"
            elif attrs.get("level", "").strip().lower() in BREAKS:
                made["strength"] = BREAKS[attrs["level"].strip().lower()]
            note("VEML <break> read as SSML <break>", node)
            out: list[Node | str] = []
            if attrs.get("type", "").strip() in ("?", "!", ".", ","):
                out.append(attrs["type"].strip() + " ")
                note("<break type> spoken as its punctuation", node)
            return [*out, Node("break", made, node.line, node.column, BML)]
        if local == "pron" and attrs.get("sub", "").strip():
            note("VEML <pron sub> spoken as its sub", node)
            return [Node("sub", {"alias": attrs["sub"].strip()}, node.line, node.column, BML, self.children(node))]
        if local == "sayas" and attrs.get("mode", "").strip():
            made = {"interpret-as": attrs["mode"].strip()}
            if attrs.get("modetype", "").strip():
                made["format"] = attrs["modetype"].strip()
            note("VEML <sayas> read as SSML <say-as>", node)
            return [self.ssml("say-as", made, node)]
        if local in VEML:
            note(f"VEML <{local}> in the text: its words are spoken, the element is not used", node)
            return self.children(node)
        self.reader.left_out(node)
        return self.children(node)

    def prosody(self, node: Node) -> Node:
        note = self.reader.note
        local, attrs = node.local, node.attrs
        made: dict[str, str] = {}
        if local == "rate":
            value = attrs.get("speed", "").strip()
            if value.lower() in RATES:
                made["rate"] = RATES[value.lower()]
            elif value.endswith("%"):
                made["rate"] = value
            elif value:
                try:
                    made["rate"] = f"{float(value) / WORDS_PER_MINUTE:.3f}"
                    note(f"<rate speed={value!r}> words a minute read as rate {made['rate']} (of "
                         f"{WORDS_PER_MINUTE:g} words a minute)", node)
                except ValueError:
                    pass
        elif local == "pitch":
            for key in ("base", "middle"):
                value = attrs.get(key, "").strip()
                if value:
                    made["pitch"] = PITCHES.get(value.lower(), value if value.endswith("%") else f"{value}Hz")
                    break
            if "range" in attrs:
                note("<pitch range> not used", node)
        else:
            value = attrs.get("level", attrs.get("discretelevel", "")).strip()
            if value:
                made["volume"] = VOLUMES.get(value.lower(), value)
        note(f"VEML <{local}> read as SSML <prosody {local}>", node)
        return self.ssml("prosody", made, node)


def read_eml(envelope: Envelope, name_block) -> None:
    """Replace the ``<eml>`` element of ``envelope`` with the ``<bml>`` block it means, noting each
    adaptation and what could not be read."""
    envelope.node = EmlReader(envelope, name_block).read()
