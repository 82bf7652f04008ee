"""BML 1.0 parser: XML text in, a :class:`~agentsim.core.block.Block` out, every problem with line and column.

The XML is read by a hardened expat reader (defusedxml: no entity declarations, no external references),
without namespace processing, so that attributes with undeclared prefixes are extensions to warn about
rather than fatal errors. Problems that spoil the whole block raise :class:`~agentsim.core.errors.BMLError`;
problems with one behaviour or constraint become :class:`~agentsim.core.block.ParseWarning` entries and the
rest of the block is kept.
"""

from __future__ import annotations

import functools
import math
import re
import xml.parsers.expat
import xml.sax.handler
from defusedxml.common import DefusedXmlException
from defusedxml.expatreader import create_parser

from agentsim.core.block import Behaviour, Block, Constraint, ParseWarning, SyncRef
from agentsim.bml.vocabulary import (BML_NAMESPACE, BMLA_BLOCK_ATTRIBUTES, BMLA_NAMESPACE, DIALECT_BEHAVIOURS,
                                     EXTENSION_BEHAVIOURS, PARAMETER_CHILDREN)
from agentsim.core.block import BEHAVIOUR_TYPES
from agentsim.core.errors import BMLError

#: Largest time or offset (seconds) accepted in a reference; beyond it a behaviour is refused.
MAX_TIME = 1.0e6

ALL_SYNC_NAMES = {s for t in BEHAVIOUR_TYPES.values() for s in t.syncs}
#: The BML 1.0 core behaviour elements (the extension ones live in their own namespaces).
CORE_BEHAVIOURS = set(BEHAVIOUR_TYPES) - set().union(*EXTENSION_BEHAVIOURS.values()) - DIALECT_BEHAVIOURS
#: Attributes an extension behaviour cannot do without.
REQUIRED_ATTRIBUTES = {"interrupt": ("target",), "activate": ("target",), "parametervaluechange": ("target", "paramId"),
                       "audiofile": ("fileName",)}
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
_ABSOLUTE = re.compile(rf"^[+-]?{_NUMBER}$")
_BLOCK_ID = re.compile(r"<(?:\w+:)?bml\b[^>]*?\bid\s*=\s*[\"']([^\"']*)[\"']", re.S)


class _Node:
    """An element: tag as written, attributes, children (elements and text) and where it starts."""

    __slots__ = ("tag", "attrs", "line", "column", "children", "namespaces")

    def __init__(self, tag: str, attrs: dict[str, str], line: int, column: int, namespaces: dict[str, str]):
        self.tag = tag
        self.attrs = attrs
        self.line = line
        self.column = column
        self.children: list[_Node | str] = []
        self.namespaces = namespaces

    @property
    def local(self) -> str:
        return self.tag.split(":", 1)[-1]

    @property
    def prefix(self) -> str | None:
        return self.tag.split(":", 1)[0] if ":" in self.tag else None

    def elements(self) -> list["_Node"]:
        return [c for c in self.children if isinstance(c, _Node)]


class _TreeBuilder:
    """Builds :class:`_Node` trees from expat callbacks, recording where each element starts."""

    def __init__(self, expat) -> None:
        self.expat = expat
        self.root: _Node | None = None
        self.stack: list[_Node] = []

    def start(self, name: str, attrs: dict[str, str]) -> None:
        parent_ns = self.stack[-1].namespaces if self.stack else {}
        namespaces = parent_ns
        if any(key.startswith("xmlns") for key in attrs):
            namespaces = dict(parent_ns)
            plain = {}
            for key, value in attrs.items():
                if key == "xmlns":
                    namespaces[""] = value
                elif key.startswith("xmlns:"):
                    namespaces[key[6:]] = value
                else:
                    plain[key] = value
            attrs = plain
        node = _Node(name, attrs, self.expat.CurrentLineNumber, self.expat.CurrentColumnNumber + 1, namespaces)
        if self.stack:
            self.stack[-1].children.append(node)
        else:
            self.root = node
        self.stack.append(node)

    def end(self, name: str) -> None:
        self.stack.pop()

    def text(self, content: str) -> None:
        if self.stack:
            children = self.stack[-1].children
            if children and isinstance(children[-1], str):
                children[-1] += content
            else:
                children.append(content)


def _read_tree(text: str | bytes) -> _Node:
    data = text.encode("utf-8") if isinstance(text, str) else text
    # defusedxml's reader installs the handlers that refuse entity declarations and external
    # references on its expat parser; the tree is built straight from that parser's callbacks.
    reader = create_parser(forbid_dtd=False, forbid_entities=True, forbid_external=True)
    reader.setFeature(xml.sax.handler.feature_namespaces, False)
    reader.reset()
    expat = reader._parser
    builder = _TreeBuilder(expat)
    expat.StartElementHandler = builder.start
    expat.EndElementHandler = builder.end
    expat.CharacterDataHandler = builder.text
    expat.buffer_text = True
    try:
        expat.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        message = xml.parsers.expat.errors.messages.get(exc.code, str(exc))
        raise BMLError(f"malformed XML: {message}", exc.lineno, exc.offset + 1) from None
    except DefusedXmlException as exc:
        raise BMLError(f"refused XML construct ({type(exc).__name__}): entity and external references "
                       "are not allowed in BML", expat.CurrentLineNumber, expat.CurrentColumnNumber + 1) from None
    if builder.root is None:
        raise BMLError("empty document: expected a <bml> element", 1, 1)
    return builder.root


def guess_block_id(text: str | bytes) -> str:
    """The ``id`` of the ``<bml>`` element, read leniently (for naming a block that fails to parse)."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    match = _BLOCK_ID.search(text)
    return match.group(1) if match else ""


def parse_ref(text: str, line: int | None = None, column: int | None = None) -> SyncRef:
    """Parse a sync reference: ``2.5``, ``g1:stroke``, ``g1:end+0.5``, ``bml2:g1:start-2``,
    ``anticipators:metronome:beat3+0.1``. ``line`` and ``column`` locate it for error messages."""
    try:
        return _parse_ref(text.strip())
    except BMLError as exc:
        raise BMLError(exc.reason, line, column) from None


@functools.lru_cache(maxsize=65536)
def _parse_ref(raw: str) -> SyncRef:
    if _ABSOLUTE.match(raw):
        value = float(raw)
        _check_magnitude(value, raw)
        return SyncRef("absolute", offset=value, text=raw)
    match = _REF.match(raw)
    if not match:
        raise BMLError(f"invalid sync reference {raw!r}: expected a number, behaviour:sync[+-offset], "
                       "block:behaviour:sync or anticipators:id:sync")
    parts = match.group("path").split(":")
    offset = 0.0
    if match.group("offset") is not None:
        offset = float(match.group("offset")) * (-1.0 if match.group("sign") == "-" else 1.0)
        _check_magnitude(offset, raw)
    if len(parts) == 3 and parts[0] == "anticipators":
        return SyncRef("anticipator", offset=offset, anticipator=parts[1], sync=parts[2], text=raw)
    block = parts[0] if len(parts) == 3 else None
    return SyncRef("sync", offset=offset, block=block, behaviour=parts[-2], sync=parts[-1], text=raw)


def normalize_space(raw: str) -> tuple[str, list[int]]:
    """Collapse runs of white space to one space and strip the ends.

    Returns the new text and, for every offset into ``raw`` (0 to ``len(raw)``), the offset it maps to.
    """
    out: list[str] = []
    positions = [0] * (len(raw) + 1)
    after_space = True
    for i, ch in enumerate(raw):
        positions[i] = len(out)
        if ch.isspace():
            if not after_space:
                out.append(" ")
                after_space = True
        else:
            out.append(ch)
            after_space = False
    positions[len(raw)] = len(out)
    return "".join(out).rstrip(), positions


def _check_magnitude(value: float, raw: str) -> None:
    if not math.isfinite(value) or abs(value) > MAX_TIME:
        raise BMLError(f"time {raw!r} is out of range (at most {MAX_TIME:g} s)")


def parse_bml(text: str | bytes) -> Block:
    """Parse one BML block. Raises :class:`BMLError` if the block as a whole cannot be used."""
    root = _read_tree(text)
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
    _Reader(block).read(root.elements(), required=False)
    return block


class _Reader:
    """Reads the children of a <bml> (or <required>) element into a block."""

    def __init__(self, block: Block):
        self.block = block
        self.seen: set[str] = set()

    def warn(self, kind: str, text: str, node: _Node, behaviours: list[str] | None = None) -> None:
        self.block.warnings.append(ParseWarning(kind, f"{text} (line {node.line}, column {node.column})",
                                                behaviours or [], node.line, node.column))

    def is_bml(self, node: _Node) -> bool:
        uri = node.namespaces.get(node.prefix or "", None)
        return uri in (None, "", BML_NAMESPACE) if node.prefix is None else uri == BML_NAMESPACE

    @staticmethod
    def namespace(node: _Node) -> str | None:
        return node.namespaces.get(node.prefix or "", None)

    def read(self, nodes: list[_Node], required: bool) -> None:
        for node in nodes:
            if node.local in EXTENSION_BEHAVIOURS.get(self.namespace(node), ()):
                self.behaviour(node, required)
            elif not self.is_bml(node):
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"extension element <{node.tag}> ignored", node)
            elif node.local == "required":
                self.read(node.elements(), required=True)
            elif node.local == "constraint":
                self.constraint(node, required)
            elif node.local in CORE_BEHAVIOURS:
                self.behaviour(node, required)
            else:
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"unknown behaviour <{node.tag}> ignored", node,
                          [node.attrs.get("id", "")] if node.attrs.get("id") else [])

    def behaviour(self, node: _Node, required: bool) -> None:
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
        self.seen.add(bid)
        beh = Behaviour(bid, kind.name, list(kind.syncs), dict(node.attrs), required=required,
                        index=len(self.block.behaviours), line=node.line, column=node.column)
        if kind.name == "speech":
            if not self.speech_text(node, beh):
                return
        for key, value in node.attrs.items():
            if ":" in key:
                self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"attribute {key!r} of {bid} ignored", node, [bid])
            elif key in beh.sync_ids and key in kind.syncs:
                try:
                    beh.refs[key] = parse_ref(value, node.line, node.column)
                except BMLError as exc:
                    self.warn("PARSING_FAILURE", f"{bid}: {exc.reason}; behaviour ignored", node, [bid])
                    return
            elif key in ALL_SYNC_NAMES:
                self.warn("PARSING_FAILURE", f"{bid}: <{node.tag}> has no sync point {key!r}; behaviour ignored",
                          node, [bid])
                return
        for child in node.elements():
            extension = self.namespace(child) in EXTENSION_BEHAVIOURS
            if child.local not in PARAMETER_CHILDREN and (self.is_bml(child) or extension):
                self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"{bid}: child <{child.tag}> ignored", child, [bid])
            elif extension and child.local == "trajectory":
                beh.params.update({f"trajectory.{k}": v for k, v in child.attrs.items()})
            elif extension and child.local == "parameter" and "name" in child.attrs:
                beh.params[child.attrs["name"]] = child.attrs.get("value", "")
        missing = [name for name in REQUIRED_ATTRIBUTES.get(kind.name, ()) if not node.attrs.get(name, "").strip()]
        if missing:
            self.warn("PARSING_FAILURE", f"{bid}: <{node.tag}> needs {' and '.join(missing)}; behaviour ignored",
                      node, [bid])
            return
        self.block.behaviours.append(beh)

    def speech_text(self, node: _Node, beh: Behaviour) -> bool:
        texts = [c for c in node.elements() if c.local == "text"]
        if not texts:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has no <text>; behaviour ignored", node, [beh.id])
            return False
        raw = ""
        marks: list[tuple[int, str]] = []
        for child in texts[0].children:
            if isinstance(child, str):
                raw += child
            elif child.local == "sync":
                sid = child.attrs.get("id", "").strip()
                if not sid:
                    self.warn("PARSING_FAILURE", f"speech {beh.id}: <sync> without id ignored", child, [beh.id])
                elif sid in beh.sync_ids:
                    self.warn("PARSING_FAILURE", f"speech {beh.id}: duplicate sync id {sid!r} ignored", child,
                              [beh.id])
                elif ":" in sid:
                    self.warn("PARSING_FAILURE", f"speech {beh.id}: sync id {sid!r} contains ':' and is ignored",
                              child, [beh.id])
                else:
                    marks.append((len(raw), sid))
                    beh.sync_ids.insert(len(beh.sync_ids) - 1, sid)
        beh.text, positions = normalize_space(raw)
        beh.marks = [(min(positions[offset], len(beh.text)), sid) for offset, sid in marks]
        if not beh.text:
            self.warn("PARSING_FAILURE", f"speech {beh.id} has empty text; behaviour ignored", node, [beh.id])
            return False
        return True

    def constraint(self, node: _Node, required: bool) -> None:
        for child in node.elements():
            kind = child.local
            if kind not in ("synchronize", "before", "after"):
                self.warn("PARSING_FAILURE", f"unknown constraint <{child.tag}> ignored", child)
                continue
            refs = []
            for sync in child.elements():
                if sync.local != "sync" or "ref" not in sync.attrs:
                    self.warn("PARSING_FAILURE", f"<{sync.tag}> in <{kind}> ignored: expected <sync ref=...>", sync)
                    continue
                try:
                    refs.append(parse_ref(sync.attrs["ref"], sync.line, sync.column))
                except BMLError as exc:
                    self.warn("PARSING_FAILURE", f"{exc.reason}; reference ignored", sync)
            anchor = None
            if "ref" in child.attrs:
                try:
                    anchor = parse_ref(child.attrs["ref"], child.line, child.column)
                except BMLError as exc:
                    self.warn("PARSING_FAILURE", f"{exc.reason}; constraint ignored", child)
                    continue
            if kind in ("before", "after") and anchor is None:
                self.warn("PARSING_FAILURE", f"<{kind}> needs a ref attribute; constraint ignored", child)
                continue
            if kind == "synchronize" and anchor is not None:
                refs.insert(0, anchor)
                anchor = None
            self.block.constraints.append(Constraint(kind, refs, anchor, node.attrs.get("id", ""), required,
                                                     line=child.line, column=child.column))
