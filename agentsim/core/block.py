"""What a BML block is: behaviours, sync references and constraints with source positions, and the BML 1.0
core behaviour types (their default sync points, in order, and the body resource each holds)."""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass, field
from typing import Literal

RefKind = Literal["absolute", "sync", "anticipator"]


_SyncRefFields = namedtuple("_SyncRefFields", ("kind", "offset", "block", "behaviour", "sync", "anticipator", "text"),
                            defaults=(0.0, None, None, None, None, ""))


class SyncRef(_SyncRefFields):
    """A reference to a time: a number (seconds after block start), ``[block:]behaviour:sync[+-offset]``
    or ``anticipators:id:sync[+-offset]``.

    The time referred to is ``time(target) + offset``. Its fields are ``kind`` (``absolute``, ``sync`` or
    ``anticipator``), ``offset``, ``block``, ``behaviour``, ``sync``, ``anticipator`` and ``text`` (the
    reference as written). It is an immutable value, equal to another reference with the same fields
    (a tuple underneath: a block reads thousands of them, and a tuple is made several times faster than
    a frozen dataclass).
    """

    __slots__ = ()

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return tuple.__eq__(self, other)

    def __ne__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return tuple.__ne__(self, other)

    __hash__ = tuple.__hash__

    def target(self) -> str:
        if self.kind == "absolute":
            return f"{self.offset:g}"
        if self.kind == "anticipator":
            return f"anticipators:{self.anticipator}:{self.sync}"
        prefix = f"{self.block}:" if self.block else ""
        return f"{prefix}{self.behaviour}:{self.sync}"


@dataclass(slots=True)
class Behaviour:
    """One behaviour element of a block."""

    id: str
    type: str
    sync_ids: list[str]
    attributes: dict[str, str] = field(default_factory=dict)
    refs: dict[str, SyncRef] = field(default_factory=dict)
    text: str = ""
    marks: list[tuple[int, str]] = field(default_factory=list)
    #: how stretches of a speech's text are spoken: ``(kind, start, end, ((attr, value), ...))`` on text
    #: offsets, kinds as in SSML (emphasis, prosody, break, say-as); see speech_timing.backend.Prosody
    prosody: list[tuple[str, int, int, tuple[tuple[str, str], ...]]] = field(default_factory=list)
    #: parameters given by child elements (a BMLA trajectory, BMLT parameters), by name
    params: dict[str, str] = field(default_factory=dict)
    #: where its document came from (a file: relative file names are resolved beside it)
    source: str = ""
    required: bool = False
    index: int = 0
    line: int | None = None
    column: int | None = None

    def where(self) -> str:
        return f"line {self.line}, column {self.column}" if self.line is not None else "unknown position"


@dataclass
class SyncAt:
    """A sync point of this block at which a constraint grabs: ``behaviour:sync`` plus an offset."""

    behaviour: str
    sync: str
    offset: float


@dataclass(slots=True)
class Constraint:
    """A ``synchronize``, ``before`` or ``after`` constraint.

    ``synchronize``: all ``refs`` happen at one time. ``before``: every ref in ``refs`` happens at or
    before ``anchor``. ``after``: at or after ``anchor``.
    """

    kind: Literal["synchronize", "before", "after"]
    refs: list[SyncRef]
    anchor: SyncRef | None = None
    id: str = ""
    required: bool = False
    owner: str = ""
    line: int | None = None
    column: int | None = None


@dataclass
class ParseWarning:
    """A problem found while parsing that does not stop the block."""

    warning_type: str
    description: str
    behaviours: list[str] = field(default_factory=list)
    line: int | None = None
    column: int | None = None
    #: the list of what it says, one item each (a NONSTANDARD_BML warning's adaptations)
    details: list[str] = field(default_factory=list)


@dataclass
class Block:
    """A parsed BML block.

    Besides its composition, a block can say how it meets the blocks around it (the BMLA extension):

    ``append_after``
        start when these blocks have ended (``composition="APPEND-AFTER(a,b)"``, ``bmla:appendAfter``);
    ``chunk_after``
        start when these blocks subside (every behaviour past its relax, speech ended): the next chunk of
        one utterance (``CHUNK-AFTER(a,b)``, ``bmla:chunkAfter``);
    ``prepend_before``, ``chunk_before``
        make pending blocks wait for this one, appended or chunked after it;
    ``interrupt``
        interrupt these blocks when this one would start, and start when they have ended;
    ``preplan``
        plan and predict now, start only when activated;
    ``on_start``
        activate these preplanned blocks when this one starts.

    ``source`` names where the block came from (a file: relative file names in it are resolved beside it).
    """

    id: str
    character_id: str = "agent"
    composition: Literal["MERGE", "APPEND", "REPLACE"] = "MERGE"
    behaviours: list[Behaviour] = field(default_factory=list)
    constraints: list[Constraint] = field(default_factory=list)
    warnings: list[ParseWarning] = field(default_factory=list)
    line: int | None = None
    column: int | None = None
    append_after: tuple[str, ...] = ()
    chunk_after: tuple[str, ...] = ()
    prepend_before: tuple[str, ...] = ()
    chunk_before: tuple[str, ...] = ()
    interrupt: tuple[str, ...] = ()
    preplan: bool = False
    on_start: tuple[str, ...] = ()
    source: str = ""

    _index: dict[str, Behaviour] = field(default_factory=dict, init=False, repr=False, compare=False)

    def behaviour(self, behaviour_id: str) -> Behaviour | None:
        """The behaviour with this id, or None."""
        if len(self._index) != len(self.behaviours):
            self._index = {b.id: b for b in self.behaviours}
        return self._index.get(behaviour_id)


GESTURE_SYNCS = ("start", "ready", "strokeStart", "stroke", "strokeEnd", "relax", "end")
GAZE_SYNCS = ("start", "ready", "relax", "end")
FACE_SYNCS = ("start", "attackPeak", "relax", "end")
SHIFT_SYNCS = ("start", "end")


@dataclass(frozen=True)
class BehaviourType:
    """A behaviour element: its default sync points and, if it is exclusive, the resource it holds.

    Two behaviours holding the same ``resource`` cannot run at the same time (two gazes at once).
    """

    name: str
    syncs: tuple[str, ...]
    resource: str | None = None


BEHAVIOUR_TYPES: dict[str, BehaviourType] = {
    t.name: t
    for t in (
        BehaviourType("speech", ("start", "end")),
        BehaviourType("gesture", GESTURE_SYNCS),
        BehaviourType("pointing", GESTURE_SYNCS),
        BehaviourType("head", GESTURE_SYNCS),
        BehaviourType("gaze", GAZE_SYNCS, resource="gaze"),
        BehaviourType("gazeShift", SHIFT_SYNCS, resource="gazeShift"),
        BehaviourType("headDirectionShift", SHIFT_SYNCS, resource="headDirectionShift"),
        BehaviourType("faceLexeme", FACE_SYNCS),
        BehaviourType("faceFacs", FACE_SYNCS),
        BehaviourType("face", FACE_SYNCS),
        BehaviourType("faceShift", SHIFT_SYNCS),
        BehaviourType("posture", GAZE_SYNCS, resource="posture"),
        BehaviourType("postureShift", SHIFT_SYNCS, resource="postureShift"),
        BehaviourType("locomotion", SHIFT_SYNCS, resource="locomotion"),
        BehaviourType("wait", SHIFT_SYNCS),
        # BMLA and BMLT (AsapRealizer's extensions): control of other blocks and behaviours, sound files,
        # transitions between poses and physical controllers
        BehaviourType("interrupt", SHIFT_SYNCS),
        BehaviourType("activate", SHIFT_SYNCS),
        BehaviourType("parametervaluechange", SHIFT_SYNCS),
        BehaviourType("audiofile", SHIFT_SYNCS),
        BehaviourType("transition", SHIFT_SYNCS),
        BehaviourType("controller", SHIFT_SYNCS),  # a physical controller (agentsim.physics)
        # MURML (AsapRealizer's form language of gestures): a gesture or face made from its form
        BehaviourType("murmlgesture", GESTURE_SYNCS),
        BehaviourType("murmlface", FACE_SYNCS),
        # agentsim's expression extension: an emotion the camera, light and music show (agentsim.expression)
        BehaviourType("emotion", SHIFT_SYNCS),
        # What other realizers' BML is mapped to where BML 1.0 has nothing alike (read only by the lenient
        # reader): a viseme of lip sync, keyframed face channels, and a sync point without motion
        BehaviourType("lips", GAZE_SYNCS),
        BehaviourType("curves", SHIFT_SYNCS),
        BehaviourType("event", SHIFT_SYNCS),
    )
}
