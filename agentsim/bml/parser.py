"""BML parser: XML text in, :class:`~agentsim.core.block.Block` objects out, every problem with line and column.

:func:`parse_bml` reads one BML 1.0 block, strictly. :func:`parse_document` reads what a document holds:
strictly, one BML 1.0 block; leniently (the default), also BML as other realizers write it (see
:mod:`agentsim.bml.dialects`) and de Melo's Expression Markup Language (:mod:`agentsim.bml.eml`), several
blocks to a document, each adaptation said in one ``NONSTANDARD_BML`` warning of its block. Problems that spoil a whole block refuse it
(:class:`~agentsim.errors.BMLError`); problems with one behaviour or constraint become
:class:`~agentsim.core.block.ParseWarning` entries and the rest of the block is kept.
"""

from __future__ import annotations

import functools
import json
import itertools
import math
import re
from dataclasses import dataclass
from typing import Callable

from agentsim.animation.lexicon import Lexicon
from agentsim.bml import lexemes
from agentsim.bml.dialect_tables import DRAFT_NAMESPACES
from agentsim.bml.dialects import Adapter
from agentsim.bml.documents import Envelope, Notes, find_blocks
from agentsim.bml.spelling import fold_case, without_doctype
from agentsim.bml.speech_text import read_speech
from agentsim.core.xmltree import Captured, Node, encode, held_attribute, read_forest, read_tree
from agentsim.bml.vocabulary import (BML_NAMESPACE, BMLA_BLOCK_ATTRIBUTES, BMLA_NAMESPACE, CONSTRAINT_KINDS,
                                     DIALECT_BEHAVIOURS, EXTENSION_BEHAVIOURS, PARAMETER_CHILDREN, READ_ATTRIBUTES)
from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block, Constraint, ParseWarning, SyncRef
from agentsim.errors import BMLError

#: Largest time or offset (seconds) accepted in a reference; beyond it a behaviour is refused.
MAX_TIME = 1.0e6
#: Largest document read (bytes); a larger one is refused before it is parsed.
MAX_DOCUMENT = 8 * 1024 * 1024
#: Longest sync reference (characters), and longest number in one; longer ones are refused.
MAX_REFERENCE = 256
MAX_NUMBER = 32
#: Most behaviours one block may hold, and most sync points one behaviour may have; beyond them the rest of
#: the block is ignored, with a warning.
MAX_BEHAVIOURS = 10_000
MAX_SYNCS = 100_000
#: Most words one speech may have (100,000 words take some ten hours to say); a longer one is ignored.
MAX_WORDS = 100_000

ALL_SYNC_NAMES = {s for t in BEHAVIOUR_TYPES.values() for s in t.syncs}
#: The BML 1.0 core behaviour elements (the extension ones live in their own namespaces).
CORE_BEHAVIOURS = set(BEHAVIOUR_TYPES) - set().union(*EXTENSION_BEHAVIOURS.values()) - DIALECT_BEHAVIOURS
#: Attributes an extension behaviour cannot do without.
REQUIRED_ATTRIBUTES = {"interrupt": ("target",), "activate": ("target",), "parametervaluechange": ("target", "paramId"),
                       "audiofile": ("fileName",), "controller": ("class",)}
_COMPOSITION_LIST = re.compile(r"^(APPEND-AFTER|CHUNK-AFTER)\s*\((?P<ids>[^()]*)\)$", re.I)


def id_list(text: str) -> tuple[str, ...]:
    """Block ids in a BMLA list: separated by spaces or commas."""
    return tuple(dict.fromkeys(x for x in re.split(r"[\s,]+", text.strip()) if x))
_NAME = r"[A-Za-z_][\w.\-]*"
_NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_LAZY_NAME = r"[A-Za-z_][\w.\-]*?"
_REF = re.compile(
    rf"^(?P<path>{_LAZY_NAME}(?::{_LAZY_NAME}){{1,2}})\s*(?:(?P<sign>[+-])\s*(?P<offset>{_NUMBER}))?$"
)
# EMBR numbers the sync points of a speech (``<sync id="1"/>``, referred to as ``s1:1``): the lenient reader
# takes a sync name that starts with a digit after a behaviour id.
_LENIENT_REF = re.compile(
    rf"^(?P<path>{_LAZY_NAME}:\d[\w.\-]*?)\s*(?:(?P<sign>[+-])\s*(?P<offset>{_NUMBER}))?$"
)
_ABSOLUTE = re.compile(rf"^[+-]?{_NUMBER}$")
# (``[^<>]``: a try that fails stops at the next tag, so the search stays linear in the text)
_BLOCK_ID = re.compile(r"<(?:\w+:)?bml\b[^<>]*?\bid\s*=\s*[\"']([^\"'<>]*)[\"']", re.S)


def guess_block_id(text: str | bytes) -> str:
    """The ``id`` of the ``<bml>`` element, read leniently (for naming a block that fails to parse)."""
    if isinstance(text, bytes):
        text = text[:MAX_DOCUMENT].decode("utf-8", "replace")
    else:
        text = text[:MAX_DOCUMENT].encode("utf-8", "replace").decode("utf-8")
    match = _BLOCK_ID.search(text)
    return match.group(1)[:MAX_REFERENCE] if match else ""


def parse_ref(text: str, line: int | None = None, column: int | None = None, lenient: bool = False) -> SyncRef:
    """Parse a sync reference: ``2.5``, ``g1:stroke``, ``g1:end+0.5``, ``bml2:g1:start-2``,
    ``anticipators:metronome:beat3+0.1``. ``line`` and ``column`` locate it for error messages; ``lenient``
    also takes names that start with a digit (``s1:1``)."""
    raw = text.strip()
    try:
        if len(raw) > MAX_REFERENCE:
            raise BMLError(f"sync reference {raw[:40]!r}... is {len(raw)} characters long (at most {MAX_REFERENCE})")
        return _parse_ref(raw, lenient)
    except BMLError as exc:
        raise BMLError(exc.reason, line, column) from None


# The usual form (plain names, an offset with no exponent and no spaces) read without backtracking; what it
# reads, the general pattern reads the same way.
_PLAIN_REF = re.compile(r"([A-Za-z_]\w*):([A-Za-z_]\w*)(?::([A-Za-z_]\w*))?(?:([+-])(\d+(?:\.\d*)?))?\Z")


_LONG_NUMBER = re.compile(rf"\d{{{MAX_NUMBER + 1},}}")
# (a reference made from its seven fields at once, as a tuple is: SyncRef is one, and a block reads thousands)
_new_ref = tuple.__new__


@functools.lru_cache(maxsize=4096)
def _parse_ref(raw: str, lenient: bool = False) -> SyncRef:
    if len(raw) > MAX_NUMBER and _LONG_NUMBER.search(raw):
        raise BMLError(f"invalid sync reference {raw!r}: a number in it has more than {MAX_NUMBER} digits")
    plain = _PLAIN_REF.match(raw)
    if plain is not None:
        first, second, third, sign, number = plain.groups()
        if third is None and number is None:  # the commonest form, ``g1:stroke``, made at once
            return _new_ref(SyncRef, ("sync", 0.0, None, first, second, None, raw))
        parts = [first, second] if third is None else [first, second, third]
    else:
        if _ABSOLUTE.match(raw):
            value = float(raw)
            _check_magnitude(value, raw)
            return SyncRef("absolute", offset=value, text=raw)
        match = _REF.match(raw) or (_LENIENT_REF.match(raw) if lenient else None)
        if not match:
            raise BMLError(f"invalid sync reference {raw!r}: expected a number, behaviour:sync[+-offset], "
                           "block:behaviour:sync or anticipators:id:sync")
        parts = match.group("path").split(":")
        sign, number = match.group("sign"), match.group("offset")
    offset = 0.0
    if number is not None:
        offset = float(number) * (-1.0 if sign == "-" else 1.0)
        _check_magnitude(offset, raw)
    if len(parts) == 3 and parts[0] == "anticipators":
        return SyncRef("anticipator", offset=offset, anticipator=parts[1], sync=parts[2], text=raw)
    block = parts[0] if len(parts) == 3 else None
    return _new_ref(SyncRef, ("sync", offset, block, parts[-2], parts[-1], None, raw))


_match_plain = _PLAIN_REF.match


def _in_bml(uri: str | None, prefix: str | None) -> bool:
    """Whether an element of namespace ``uri`` written with ``prefix`` is BML's (no namespace declared, unprefixed,
    counts as BML's)."""
    return uri in (None, "", BML_NAMESPACE) if prefix is None else uri == BML_NAMESPACE


def _plain_ref(text: str) -> SyncRef | None:
    """``text`` read as :func:`_parse_ref` reads it if it is a short reference of the usual form
    (``g1:stroke``, ``g1:end+0.5``: one behaviour's sync point, an offset in range), else None (then
    :func:`parse_ref` reads it, or says what is wrong with it). A block's constraints are mostly such.

    (Read with string methods where the text is ASCII and plainly of that form, which is quicker than the
    pattern, what follows the colon once for all references that share it; anything else, by
    :data:`_PLAIN_REF`.)"""
    if len(text) > MAX_NUMBER:
        return None
    first, colon, rest = text.partition(":")
    if colon and text.isascii() and first.isidentifier():  # (an ASCII identifier: [A-Za-z_][A-Za-z0-9_]*)
        read = _rests.get(rest)
        if read is None:
            read = _read_rest(rest)
            if len(_rests) < _KEPT_RESTS:
                _rests[rest] = read
        if read is _OUT_OF_RANGE:
            return None
        if read is not _BY_PATTERN:
            return _new_ref(SyncRef, ("sync", read[1], None, first, read[0], None, text))
    return _matched_ref(text)


#: What follows the colon of references read by :func:`_plain_ref`: its sync point and offset, or one of the
#: two marks below (the same few tails, ``end``, ``start+0.5``, follow thousands of behaviours' names).
_rests: dict[str, tuple[str, float]] = {}
_KEPT_RESTS = 4096
_BY_PATTERN, _OUT_OF_RANGE = ("", 0.0), ("", 1.0)


def _read_rest(rest: str) -> tuple[str, float]:
    """``(sync, offset)`` of what follows the colon of a reference whose text is ASCII; :data:`_OUT_OF_RANGE`
    for an offset too large, :data:`_BY_PATTERN` for another form (the pattern reads it)."""
    sign = "+" if "+" in rest else "-" if "-" in rest else None
    if sign is None:
        return (rest, 0.0) if rest.isidentifier() else _BY_PATTERN
    second, _, number = rest.partition(sign)
    if second.isidentifier() and number[:1].isdigit() and number.replace(".", "", 1).isdigit():
        offset = float(number) * (-1.0 if sign == "-" else 1.0)
        return _OUT_OF_RANGE if abs(offset) > MAX_TIME else (second, offset)
    return _BY_PATTERN


def _matched_ref(text: str) -> SyncRef | None:
    """:func:`_plain_ref` of ``text`` (at most :data:`MAX_NUMBER` characters), read by :data:`_PLAIN_REF`."""
    plain = _match_plain(text)
    if plain is None:
        return None
    first, second, third, sign, number = plain.groups()
    if third is not None:
        return None
    offset = 0.0
    if number is not None:
        offset = float(number) * (-1.0 if sign == "-" else 1.0)
        if abs(offset) > MAX_TIME:
            return None
    return _new_ref(SyncRef, ("sync", offset, None, first, second, None, text))


def _check_magnitude(value: float, raw: str) -> None:
    if not math.isfinite(value) or abs(value) > MAX_TIME:
        raise BMLError(f"time {raw!r} is out of range (at most {MAX_TIME:g} s)")


@dataclass
class Refused:
    """A block of a document that cannot be used: its id (as far as it can be told) and why."""

    block_id: str
    error: BMLError


def _checked(text: str | bytes) -> bytes:
    """The document as bytes, if it is valid Unicode and not larger than :data:`MAX_DOCUMENT`."""
    if len(text) > MAX_DOCUMENT:
        raise BMLError(f"the document is {len(text) / 1048576:.1f} MB long: at most {MAX_DOCUMENT // 1048576} MB "
                       "is read", 1, 1)
    data = encode(text)
    if len(data) > MAX_DOCUMENT:
        raise BMLError(f"the document is {len(data) / 1048576:.1f} MB long: at most {MAX_DOCUMENT // 1048576} MB "
                       "is read", 1, 1)
    return data


def parse_bml(text: str | bytes, lexicon: Lexicon | None = None) -> Block:
    """Parse one BML 1.0 block, strictly. Raises :class:`BMLError` if the block as a whole cannot be used.
    Lexemes that ``lexicon`` (default: the built-in one) has no motion for are warned of."""
    defaults: list[str] = []
    block = warn_lexemes(read_block(read_tree(_checked(text), defaults, HELD), None), lexicon)
    return warn_defaults(block, defaults)


def warn_defaults(block: Block, defaults: list[str]) -> Block:
    """One warning if the document's internal DTD declared attribute defaults: they are not applied (a
    ``<!ATTLIST gesture lexeme CDATA "BEAT">`` gives no gesture a lexeme); the block itself."""
    if defaults:
        shown = ", ".join(defaults[:6]) + (f" and {len(defaults) - 6} more" if len(defaults) > 6 else "")
        block.warnings.append(ParseWarning(
            "CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"attribute defaults declared in the document type declaration "
            f"ignored ({shown}): every element has only the attributes written in it"))
    return block


def warn_lexemes(block: Block, lexicon: Lexicon | None = None) -> Block:
    """Add a warning for each kind of lexeme in ``block`` that ``lexicon`` has no motion for (it plays as its
    type's default, :mod:`agentsim.bml.lexemes`); the block itself."""
    found = lexemes.fallbacks(((b.type, b.id, b.attributes) for b in block.behaviours), lexicon)
    for (instead, items), line in zip(found.items(), lexemes.describe(found)):
        ids = [item.rsplit(" (", 1)[1][:-1] for item in items]
        block.warnings.append(ParseWarning("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", line, ids))
    return block


def parse_document(text: str | bytes, strict: bool = False, name_block: Callable[[], str] | None = None,
                   lexicon: Lexicon | None = None) -> list[Block | Refused]:
    """The blocks of a document, in order, each parsed or refused.

    ``strict``: one BML 1.0 block, read as :func:`parse_bml` reads it. Otherwise BML as other realizers
    write it is read too (see :mod:`agentsim.bml.dialects`): a block that needed adapting carries one
    ``NONSTANDARD_BML`` warning listing the adaptations, first among its warnings. ``name_block`` names the
    blocks that have no id (by default ``bml1``, ``bml2``, ... skipping the ids the document uses).
    ``lexicon`` (default: the built-in one) says which lexemes have a motion, and what foreign names become.
    """
    if strict:
        try:
            return [parse_bml(text, lexicon)]
        except BMLError as exc:
            return [Refused(guess_block_id(text), exc)]
    try:
        data = _checked(text)
    except BMLError as exc:
        return [Refused(guess_block_id(text), exc)]
    data, doctype = without_doctype(data)
    defaults: list[str] = []
    made: dict = {}
    try:
        root, forest = read_forest(data, defaults, made, HELD)
    except BMLError as exc:
        return [Refused(guess_block_id(text), exc)]
    folded = fold_case(root, made["names"])
    drafts = any(uri in DRAFT_NAMESPACES for scope in made["scopes"] for uri in scope.values())
    if root.local == "eml" and root.namespace is None:  # de Melo's Expression Markup Language
        from agentsim.bml.eml import read_eml

        envelopes = [Envelope(root, reader=read_eml)]
    else:
        envelopes = find_blocks(root, forest)
    for envelope in envelopes:
        if doctype:
            envelope.notes.add("document type declaration (an external DTD, never read) left out")
        if folded:
            envelope.notes.add("element names in another case (<BML>, <SPEECH>) read as BML's")
    if not envelopes:
        return [Refused(root.attrs.get("id", ""),
                        BMLError(f"expected a <bml> element, found <{root.tag}>", root.line, root.column))]
    taken = {e.node.attrs.get("id", "").strip() for e in envelopes}
    names = iter(name_block, None) if name_block is not None else (f"bml{n}" for n in itertools.count(1))

    def name_free() -> str:
        return next(name for name in names if name not in taken)
    results: list[Block | Refused] = []
    for envelope in envelopes:
        try:
            if envelope.reader is not None:
                envelope.reader(envelope, name_free)
            else:
                Adapter(envelope, name_free, drafts, lexicon).adapt()
            block = read_block(envelope.node, envelope.notes)
        except BMLError as exc:
            results.append(Refused(envelope.node.attrs.get("id", ""), exc))
            continue
        if not envelope.notes:  # a foreign document's lexemes are among its adaptations
            warn_lexemes(block, lexicon)
        if envelope.notes:
            lines = envelope.notes.lines()
            block.warnings.insert(0, ParseWarning(
                "NONSTANDARD_BML", f"read as BML 1.0 with {len(lines)} adaptation{'s' if len(lines) > 1 else ''}: "
                + "; ".join(lines), envelope.notes.behaviour_ids(b.id for b in block.behaviours),
                envelope.node.line, envelope.node.column, details=lines))
        for message, node in envelope.losses:
            block.warnings.append(ParseWarning("BEHAVIOR_TYPE_NOT_SUPPORTED", f"{message} ({node.where()})", [],
                                               node.line, node.column))
        for kind, message, node in envelope.warnings:
            block.warnings.append(ParseWarning(kind, message, [], node.line, node.column))
        results.append(warn_defaults(block, defaults))
    return results


def read_block(root: Node, notes: Notes | None) -> Block:
    """Read a ``<bml>`` element into a block: strictly if ``notes`` is None, else leniently (what the
    reading adapts, such as a speech's text form, is added to ``notes``)."""
    if root.local != "bml":
        raise BMLError(f"expected a <bml> element, found <{root.tag}>", root.line, root.column)
    block_id = root.attrs.get("id", "").strip()
    if not block_id:
        raise BMLError("the <bml> block has no id", root.line, root.column)
    if ":" in block_id:
        raise BMLError(f"the block id {block_id!r} contains ':', which feedback ids use to join block, behaviour "
                       "and sync ids", root.line, root.column)
    composition = root.attrs.get("composition", "MERGE").strip() or "MERGE"
    lists: dict[str, tuple[str, ...]] = {}
    listed = _COMPOSITION_LIST.match(composition)
    if listed:
        field = "append_after" if listed.group(1).upper() == "APPEND-AFTER" else "chunk_after"
        lists[field] = id_list(listed.group("ids"))
        composition = "MERGE"
    composition = composition.upper()
    if composition not in ("MERGE", "APPEND", "REPLACE"):
        raise BMLError(f"unknown composition {root.attrs['composition']!r}: expected MERGE, APPEND, REPLACE, "
                       "APPEND-AFTER(ids) or CHUNK-AFTER(ids)", root.line, root.column)
    block = Block(block_id, root.attrs.get("characterId", "agent") or "agent", composition,
                  line=root.line, column=root.column)
    for key, value in root.attrs.items():
        if ":" not in key:
            continue
        prefix, _, name = key.partition(":")
        if root.namespaces.get(prefix) == BMLA_NAMESPACE and name in BMLA_BLOCK_ATTRIBUTES:
            field = BMLA_BLOCK_ATTRIBUTES[name]
            if field == "preplan":
                block.preplan = value.strip().lower() in ("true", "1", "yes")
            else:
                lists[field] = tuple(dict.fromkeys(lists.get(field, ()) + id_list(value)))
        else:
            block.warnings.append(ParseWarning("CUSTOM_ATTRIBUTE_NOT_SUPPORTED",
                                               f"attribute {key!r} of <bml> ignored", [], root.line, root.column))
    for field, ids in lists.items():
        if block_id in ids:
            block.warnings.append(ParseWarning("PARSING_FAILURE", f"block {block_id} names itself in "
                                               f"{field}; ignored", [], root.line, root.column))
            ids = tuple(i for i in ids if i != block_id)
        setattr(block, field, ids)
    _Reader(block, notes).read(root.elements(), required=False)
    return block


class _Reader:
    """Reads the children of a <bml> (or <required>) element into a block (leniently if ``notes`` is given:
    the types only other realizers' BML maps to, and speech text in every form)."""

    def __init__(self, block: Block, notes: Notes | None):
        self.block = block
        self.notes = notes
        self.lenient = notes is not None
        self.seen: set[str] = set()
        self.full = False  # the block reached MAX_BEHAVIOURS
        self.refs: dict[str, SyncRef] = {}  # references read so far, by their text (blocks repeat them)

    def warn(self, kind: str, text: str, node: Node, behaviours: list[str] | None = None) -> None:
        self.block.warnings.append(ParseWarning(kind, f"{text} (line {node.line}, column {node.column})",
                                                behaviours or [], node.line, node.column))

    def ref(self, text: str, node: Node) -> SyncRef:
        """The reference ``text`` (of ``node``) read; :class:`BMLError` located at ``node`` if it is not one."""
        ref = self.refs.get(text)
        if ref is None:
            ref = self.refs[text] = _plain_ref(text) or parse_ref(text, node.line, node.column, self.lenient)
        return ref

    def is_bml(self, node: Node) -> bool:
        return _in_bml(node.namespace, node.prefix)

    def read(self, nodes: list[Node], required: bool) -> None:
        for node in nodes:
            uri = node.namespace
            if node.local in EXTENSION_BEHAVIOURS.get(uri, ()):
                self.behaviour(node, required)
            elif not _in_bml(uri, node.prefix):
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"extension element <{node.tag}> ignored", node)
            elif node.local == "required":
                self.read(node.elements(), required=True)
            elif node.local == "constraint":
                self.constraint(node, required)
            elif node.local in CORE_BEHAVIOURS or self.lenient and node.local in DIALECT_BEHAVIOURS:
                self.behaviour(node, required)
            else:
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"unknown behaviour <{node.tag}> ignored", node,
                          [node.attrs.get("id", "")] if node.attrs.get("id") else [])

    def behaviour(self, node: Node, required: bool) -> None:
        kind = BEHAVIOUR_TYPES[node.local]
        bid = node.attrs.get("id", "").strip()
        if not bid:
            self.warn("PARSING_FAILURE", f"<{node.tag}> has no id and is ignored", node)
            return
        if bid in self.seen:
            self.warn("PARSING_FAILURE", f"duplicate behaviour id {bid!r}: the second one is ignored", node, [bid])
            return
        if ":" in bid:
            self.warn("PARSING_FAILURE", f"behaviour id {bid!r} contains ':', which feedback ids use to join block, "
                      "behaviour and sync ids; behaviour ignored", node)
            return
        if len(self.block.behaviours) >= MAX_BEHAVIOURS:
            if len(self.block.behaviours) == MAX_BEHAVIOURS and not self.full:
                self.full = True
                self.warn("PARSING_FAILURE", f"the block has more than {MAX_BEHAVIOURS} behaviours: {bid} and "
                          "every behaviour after it ignored", node, [bid])
            return
        self.seen.add(bid)
        beh = Behaviour(bid, kind.name, list(kind.syncs), dict(node.attrs), {}, "", [], [], {}, "", required,
                        len(self.block.behaviours), node.line, node.column)
        if kind.name == "speech":
            if not self.speech_text(node, beh):
                return
        for key, value in node.attrs.items():
            if ":" in key:
                self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"attribute {key!r} of {bid} ignored", node, [bid])
            elif key in beh.sync_ids and key in kind.syncs:
                try:
                    beh.refs[key] = self.ref(value, node)
                except BMLError as exc:
                    self.warn("PARSING_FAILURE", f"{bid}: {exc.reason}; behaviour ignored", node, [bid])
                    return
            elif key in ALL_SYNC_NAMES:
                self.warn("PARSING_FAILURE", f"{bid}: <{node.tag}> has no sync point {key!r}; behaviour ignored",
                          node, [bid])
                return
            elif key not in READ_ATTRIBUTES and key not in beh.sync_ids:
                self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"attribute {key!r} of {bid} is not one this realizer "
                          "reads; ignored", node, [bid])
        if "repetition" in beh.attributes:
            from agentsim.animation.units import MAX_REPETITION, read_repetition  # (only when asked)

            times, problem = read_repetition(beh.attributes["repetition"])
            if problem is not None:
                beh.attributes["repetition"] = str(times)
                kind_of = "IMPOSSIBLE_TO_SCHEDULE" if times == MAX_REPETITION else "PARSING_FAILURE"
                self.warn(kind_of, f"{bid}: {problem}", node, [bid])
        for child in node.elements() if node.children else ():
            extension = child.namespace in EXTENSION_BEHAVIOURS
            if kind.name == "speech" and self.lenient:
                continue  # the speech reading took what it could, and said what it could not
            if child.local not in PARAMETER_CHILDREN and (self.is_bml(child) or extension):
                self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"{bid}: child <{child.tag}> ignored", child, [bid])
            elif kind.name in ("murmlgesture", "murmlface") and child.local == "murml-description":
                from agentsim.animation.murml_form import MurmlError, read_description

                try:
                    form = read_description(child, "face" if kind.name == "murmlface" else "gesture")
                except MurmlError as exc:
                    self.warn("PARSING_FAILURE", f"{bid}: {exc}; behaviour ignored", child, [bid])
                    return
                beh.params["murml"] = json.dumps(form, separators=(",", ":"))
            elif extension and child.local == "trajectory":
                beh.params.update({f"trajectory.{k}": v for k, v in child.attrs.items()})
            elif extension and child.local == "parameter" and "name" in child.attrs:
                beh.params[child.attrs["name"]] = child.attrs.get("value", "")
        if kind.name in ("murmlgesture", "murmlface") and "murml" not in beh.params:
            self.warn("PARSING_FAILURE", f"{bid}: <{node.tag}> has no <murml-description>; behaviour ignored", node,
                      [bid])
            return
        needed = REQUIRED_ATTRIBUTES.get(kind.name)  # (most kinds need none)
        missing = [name for name in needed if not node.attrs.get(name, "").strip()] if needed else None
        if missing:
            self.warn("PARSING_FAILURE", f"{bid}: <{node.tag}> needs {' and '.join(missing)}; behaviour ignored",
                      node, [bid])
            return
        if kind.name == "emotion":
            from agentsim.expression.emotions import emotion_problem

            problem = emotion_problem(node.attrs.get("type", "").strip(), node.attrs.get("intensity"))
            if problem is not None:
                self.warn("PARSING_FAILURE", f"{bid}: {problem}; behaviour ignored", node, [bid])
                return
        self.block.behaviours.append(beh)

    def speech_text(self, node: Node, beh: Behaviour) -> bool:
        reading = read_speech(node, beh.id, self.lenient)
        if reading is None:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has no <text>; behaviour ignored", node, [beh.id])
            return False
        for message, where in reading.problems:
            self.warn("PARSING_FAILURE", message, where, [beh.id])
        if self.notes is not None:
            self.notes.extend(reading.adapted)
        if len(reading.marks) > MAX_SYNCS:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has {len(reading.marks)} sync marks (at most "
                      f"{MAX_SYNCS}); behaviour ignored", node, [beh.id])
            return False
        for _, name in reading.marks:
            beh.sync_ids.insert(len(beh.sync_ids) - 1, name)
        beh.text, beh.marks, beh.prosody = reading.text, reading.marks, reading.prosody
        if not beh.text:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has empty text; behaviour ignored", node, [beh.id])
            return False
        words = beh.text.count(" ") + 1  # (its white space is single spaces: no list of its words is made)
        if words > MAX_WORDS:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has {words} words (at most {MAX_WORDS}, some ten hours of "
                      "speech); behaviour ignored", node, [beh.id])
            return False
        return True

    def _ref_or_warn(self, text: str, node: Node, what: str):
        """The reference ``text`` read; None, with a warning that ``what`` is ignored, if it cannot be."""
        try:
            return self.ref(text, node)
        except BMLError as exc:
            self.warn("PARSING_FAILURE", f"{exc.reason}; {what} ignored", node)
            return None

    def constraint(self, node: Node, required: bool) -> None:
        if type(node) is Captured and node.events is not None:  # (as the tree holds it: read at once if plain)
            made = self.held_constraint(node, required)
            if made is not None:
                self.block.constraints += made
                return
        owner = node.attrs.get("id", "")
        add = self.block.constraints.append
        known = self.refs  # (looked up here at once: a block's constraints repeat their references)
        plain = _plain_ref  # (and the usual form read here at once)
        for child in node.children:
            if isinstance(child, str):
                continue
            kind = child.local
            if kind not in CONSTRAINT_KINDS:
                self.warn("PARSING_FAILURE", f"unknown constraint <{child.tag}> ignored", child)
                continue
            refs = []
            for sync in child.children:
                if isinstance(sync, str):
                    continue
                text = sync.attrs.get("ref") if sync.local == "sync" else None
                if text is None:
                    self.warn("PARSING_FAILURE", f"<{sync.tag}> in <{kind}> ignored: expected <sync ref=...>", sync)
                    continue
                ref = known.get(text)
                if ref is None:
                    ref = plain(text)
                    if ref is None:
                        ref = self._ref_or_warn(text, sync, "reference")
                        if ref is None:
                            continue
                    else:
                        known[text] = ref
                refs.append(ref)
            text = child.attrs.get("ref")
            constraint = self.made(kind, refs, text, lambda text: self._ref_or_warn(text, child, "constraint"), owner,
                                   required, child.line, child.column)
            if constraint is not None:
                add(constraint)
            elif text is None:  # (else its anchor was warned of)
                self.warn("PARSING_FAILURE", f"<{kind}> needs a ref attribute; constraint ignored", child)

    def made(self, kind: str, refs: list[SyncRef], anchor_text: str | None, read, owner: str, required: bool,
             line: int | None, column: int | None) -> Constraint | None:
        """The constraint of a ``<synchronize>``, ``<before>`` or ``<after>`` with its references read, and the
        text of its ``ref`` attribute (``read`` reads one not of the usual form, None where it cannot); None
        where that does not read, or where it needs one and has none."""
        anchor = None
        if anchor_text is not None:
            anchor = self.refs.get(anchor_text) or _plain_ref(anchor_text) or read(anchor_text)
            if anchor is None:
                return None
            self.refs[anchor_text] = anchor
        if kind == "synchronize":
            if anchor is not None:
                refs.insert(0, anchor)
                anchor = None
        elif anchor is None:
            return None
        return Constraint(kind, refs, anchor, owner, required, "", line, column)

    def held_constraint(self, node: Captured, required: bool) -> list[Constraint] | None:
        """The constraints of a ``<constraint>`` whose content the tree holds as expat's events, read as
        :meth:`constraint` reads its nodes, if reading them warns of nothing (else None: then it reads the
        nodes, and warns). Its elements are plain ``<synchronize>``, ``<before>`` and ``<after>`` with
        ``<sync ref=...>`` in them, references that read, and text, which is not read."""
        owner, shift = node.attrs.get("id", ""), node.shift
        known, plain, finish, read = self.refs, _plain_ref, self.made, self.ref_at
        made: list[Constraint] = []
        level, kind, refs, anchor_text, line, column = 0, "", [], None, 0, 0
        for event in node.events:
            if event is None:  # an element ends
                level -= 1
                if level:
                    continue
                constraint = finish(kind, refs, anchor_text, read, owner, required, line,
                                    column + 1 - (shift if line == 1 else 0))
                if constraint is None:
                    return None
                made.append(constraint)
            elif type(event) is tuple:  # an element starts (text is not read)
                if level == 1:  # (in a constraint: a <sync ref=...>, the commonest)
                    level = 2
                    attrs = event[1]  # (expat's list: names and values in turn)
                    if event[0] != "sync" or not attrs:
                        return None
                    text = attrs[1] if attrs[0] == "ref" else held_attribute(attrs, "ref")
                    if text is None:
                        return None
                    ref = known.get(text)
                    if ref is None:
                        ref = plain(text)
                        if ref is None:
                            ref = read(text)
                            if ref is None:
                                return None
                        else:
                            known[text] = ref
                    refs.append(ref)
                elif level == 0:  # a constraint
                    level = 1
                    kind, attrs, line, column = event
                    if kind not in CONSTRAINT_KINDS:
                        return None
                    refs, anchor_text = [], held_attribute(attrs, "ref")
                else:
                    return None
        return made

    def ref_at(self, text: str) -> SyncRef | None:
        """:meth:`ref` of a reference held as an event, not of the usual form; None where it does not read
        (then the nodes are read, and the reference warned of where it is)."""
        try:
            ref = parse_ref(text, 0, 0, self.lenient)
        except BMLError:
            return None
        self.refs[text] = ref
        return ref


#: The elements of a block whose content its tree holds as the reader's events (see
#: :class:`~agentsim.core.xmltree.Captured`): a block's constraints, read at once where they are plain.
HELD = frozenset(("constraint",))
# (the fields the reader gives a behaviour and a constraint, in their order, are all they have)
assert list(Behaviour.__dataclass_fields__) == ["id", "type", "sync_ids", "attributes", "refs", "text", "marks",
                                                "prosody", "params", "source", "required", "index", "line", "column"]
assert list(Constraint.__dataclass_fields__) == ["kind", "refs", "anchor", "id", "required", "owner", "line", "column"]
