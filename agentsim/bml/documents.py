"""The blocks of a BML document as other realizers write them: where each ``<bml>`` is (:func:`find_blocks`:
the root, an envelope such as ``<act>`` or ``<fml-apml>``, or several in one file), what was adapted on the
way (:class:`Notes`), and the small readings of an element tree the lenient reader's
:class:`~agentsim.bml.dialects.Adapter` shares (a behaviour's implied start, the marks of a speech, whose an
attribute prefix is).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Callable, Iterable

from agentsim.animation.lexicon import Lexicon
from agentsim.animation.units import motion_unit
from agentsim.bml.dialect_tables import DRAFT_NAMESPACES, UNMAPPED_HINTS
from agentsim.bml.vocabulary import BML_NAMESPACE
from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour
from agentsim.core.engine import stretch_times
from agentsim.core.xmltree import FOREST, Node
from agentsim.errors import ScheduleError

NUMBER = re.compile(r"^\s*[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\s*$")
"""A number as an attribute may hold it (a time in seconds)."""


@dataclass
class Notes:
    """What was adapted, in order, each said once (with how many times it happened), and the behaviour
    elements the adaptations touched (:attr:`current`: the one being read, touched by what is noted
    meanwhile)."""

    counts: dict[str, int] = field(default_factory=dict)
    touched: dict[int, Node] = field(default_factory=dict)  # id() of an element -> it, in order
    current: Node | None = None

    def add(self, note: str, *nodes: Node) -> None:
        self.counts[note] = self.counts.get(note, 0) + 1
        self.touch(*(nodes or ((self.current,) if self.current is not None else ())))

    def touch(self, *nodes: Node) -> None:
        """These behaviour elements were adapted."""
        for node in nodes:
            self.touched.setdefault(id(node), node)

    def behaviour_ids(self, kept: Iterable[str]) -> list[str]:
        """The ids (as named at the end) of the behaviours touched that are among ``kept``, in order."""
        kept = set(kept)
        ids = (node.attrs.get("id", "").strip() for node in self.touched.values())
        return list(dict.fromkeys(i for i in ids if i in kept))

    def extend(self, notes) -> None:
        for note in notes:
            self.add(note)

    def __bool__(self) -> bool:
        return bool(self.counts)

    def lines(self) -> list[str]:
        return [note if n == 1 else f"{note} ({n} times)" for note, n in self.counts.items()]


@dataclass
class Envelope:
    """A ``<bml>`` found in a document: the element, what its envelope said, and what could not be used."""

    node: Node
    notes: Notes = field(default_factory=Notes)
    character: str | None = None
    losses: list[tuple[str, Node]] = field(default_factory=list)
    #: what writes the block instead of the Adapter, called with the envelope and the block namer (EML's)
    reader: Callable[["Envelope", Callable[[], str]], None] | None = None
    #: warnings of their own kind: (kind, message, element)
    warnings: list[tuple[str, str, Node]] = field(default_factory=list)


def seconds(value: float) -> str:
    """A time written back into an attribute, as exactly as a float prints (to the nanosecond)."""
    return repr(round(value, 9))


def remove_nodes(node: Node, gone: set[int]) -> None:
    """Take the elements whose ``id()`` is in ``gone`` out of the tree under ``node``."""
    node.children = [c for c in node.children if isinstance(c, str) or id(c) not in gone]
    for child in node.elements():
        remove_nodes(child, gone)


def speech_marks(node: Node) -> set[str]:
    """The names of the sync points written in a speech (``<sync id>``, ``<tm id>``, ``<mark name>``)."""
    names = set()
    for child in node.elements():
        if child.local in ("sync", "tm"):
            names.add(child.attrs.get("id", "").strip())
        elif child.local == "mark":
            names.add(child.attrs.get("name", "").strip().rsplit(":", 1)[-1])
        names |= speech_marks(child)
    return names


def implied_start(node: Node, lexicon: Lexicon | None = None) -> float:
    """Where a behaviour would start, from its numeric sync times and its preferred timing (as the animation
    planner with ``lexicon`` times it)."""
    kind = BEHAVIOUR_TYPES[node.local]
    numbers = {k: float(v) for k, v in node.attrs.items() if k in kind.syncs and NUMBER.match(v)}
    if "start" in numbers or not numbers:
        return numbers.get("start", 0.0)
    try:
        preferred = motion_unit(Behaviour("", kind.name, list(kind.syncs), dict(node.attrs)), lexicon).preferred()
    except KeyError:
        return min(numbers.values())
    # as the planners do: the preferred timing stretched linearly between the known keys
    try:
        return stretch_times(preferred, {kind.syncs.index(k): t for k, t in numbers.items()}, 0.0)[0]
    except ScheduleError:  # its times are out of order: the scheduler will say so; here, the earliest will do
        return min(numbers.values())


def is_smartbody(prefix: str, uri: str | None) -> bool:
    """Whether an attribute prefix is SmartBody's (``sbm:``, declared as ict.usc.edu or not declared at all);
    attributes of other namespaces are BML 1.0 extensions, reported as such by the strict reader."""
    return uri is not None and "ict.usc.edu" in uri or uri is None and prefix == "sbm"


def is_bml_uri(uri: str | None) -> bool:
    return uri in (None, "", BML_NAMESPACE) or uri in DRAFT_NAMESPACES


def find_blocks(root: Node, forest: bool) -> list[Envelope]:
    """The ``<bml>`` blocks of a document, in order: the root itself, those of an ``<act>`` (VHT/NVBG: its
    ``<participant>`` is the character) or ``<fml-apml>`` (Greta: the ``<fml>`` part is reported), or
    several written one after another. Empty if there is none."""
    if root.local == "bml":
        return [Envelope(root)]
    found: list[Envelope] = []
    if root.tag == FOREST:
        tops = root.elements()
        blocks = sum(1 for top in tops if top.local == "bml")
        for top in tops:
            if top.local == "bml":
                envelope = Envelope(top)
                if blocks > 1:
                    envelope.notes.add(f"{blocks} <bml> blocks in one document: each realized as a block, in order")
                found.append(envelope)
            else:
                found.extend(find_blocks(top, False))
        return found
    character = None
    losses: list[tuple[str, Node]] = []
    for child in root.elements():
        if child.local == "participant" and child.attrs.get("id", "").strip():
            if child.attrs.get("role", "actor") == "actor" or character is None:
                character = child.attrs["id"].strip()
        elif child.local == "bml":
            found.append(Envelope(child))
        elif child.local == "fml":
            losses.append((f"the <fml> part of <{root.tag}> is not supported: {UNMAPPED_HINTS['fml']}; only its "
                           "<bml> is realized", child))
        else:
            inner = find_blocks(child, False)
            if inner:
                found.extend(inner)
            else:
                losses.append((f"<{child.tag}> in <{root.tag}> is not BML and is ignored", child))
    for envelope in found:
        envelope.notes.add(f"envelope <{root.tag}>: the <bml> inside it realized as a block")
        if character:
            envelope.character = character
        envelope.losses = losses + envelope.losses
        losses = []  # reported with the first block only
    return found
