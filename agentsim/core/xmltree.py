"""XML in, element trees out, with line and column of every element, read by a hardened expat reader.

The reader is defusedxml's (no entity declarations, no external references), run without namespace
processing, so that attributes with undeclared prefixes are extensions to warn about rather than fatal
errors; each element keeps the namespace declarations in scope. :func:`read_tree` reads one document;
:func:`read_forest` also reads several top-level elements one after another (several ``<bml>`` written
into one file), which XML itself does not allow.
"""

from __future__ import annotations

import re
import xml.parsers.expat
import xml.sax.handler
from defusedxml.common import DefusedXmlException
from defusedxml.expatreader import create_parser

from agentsim.errors import BMLError

#: Deepest nesting of elements read (BML nests a few levels; deeper documents are refused, not recursed into).
MAX_DEPTH = 256


class Node:
    """An element: tag as written, attributes, children (elements and text) and where it starts."""

    __slots__ = ("_tag", "local", "prefix", "attrs", "line", "column", "children", "namespaces")

    def __init__(self, tag: str, attrs: dict[str, str], line: int | None, column: int | None,
                 namespaces: dict[str, str], children: list | None = None):
        self._tag = tag  # as the setter below does
        prefix, colon, local = tag.partition(":")
        self.local = local if colon else tag
        self.prefix = prefix if colon else None
        self.attrs = attrs
        self.line = line
        self.column = column
        self.children: list[Node | str] = children if children is not None else []
        self.namespaces = namespaces

    @property
    def tag(self) -> str:
        return self._tag

    @tag.setter
    def tag(self, tag: str) -> None:
        # the tag's parts are read for every element many times over: split once, here
        self._tag = tag
        prefix, colon, local = tag.partition(":")
        #: the tag without its prefix
        self.local: str = local if colon else tag
        #: the prefix of the tag (None if it has none)
        self.prefix: str | None = prefix if colon else None

    @property
    def namespace(self) -> str | None:
        """The namespace URI of the element (None if its prefix, or the default, is not declared)."""
        return self.namespaces.get(self.prefix or "", None)

    def elements(self) -> list["Node"]:
        return [c for c in self.children if isinstance(c, Node)]

    def text(self) -> str:
        """All the text inside the element, markup left out."""
        return "".join(c if isinstance(c, str) else c.text() for c in self.children)

    def where(self) -> str:
        return f"line {self.line}, column {self.column}"

    def __repr__(self) -> str:
        return f"<{self.tag} {self.attrs!r} at {self.where()}>"


_new_node = object.__new__
_children = Node.__dict__["children"]  # (the slot itself, which Captured's property stands before)
#: How deep elements inside a held element may nest before it is read into nodes at once (far from MAX_DEPTH).
HELD_DEPTH = 16


class Captured(Node):
    """An element whose content the reader kept as expat gave it, for a reader that knows its form to read at
    once (a BML block's ``<constraint>``, thousands of ``<sync>`` elements): ``events`` (None once made into
    nodes) holds, in order, ``(tag, attributes, line, expat's column)`` where an element starts, None where one
    ends, and each text; ``shift`` is what columns on line 1 lose (see :func:`_builder`). The attributes are
    expat's list of them, names and values in turn (:func:`held_attribute` reads one).

    Its ``children`` are made from the events the first time anything asks for them: the same nodes, at the
    same places, that any other element's content is made into.
    """

    __slots__ = ("events", "shift")

    @property
    def children(self) -> list:
        events = self.events
        if events is not None:
            self.events = None
            replay = _builder(None, self.shift, b"")
            replay["seed"](self)  # (the parent of what is replayed)
            replay["replay"](events)
            replay["end"]("")  # (the text before its end tag, as its end would have added it)
            replay["close"]()
            replay.clear()
        return _children.__get__(self)

    @children.setter
    def children(self, value: list) -> None:
        self.events = None
        _children.__set__(self, value)


def held_attribute(attrs: list[str], name: str) -> str | None:
    """The value of the attribute ``name`` in the attributes of an element :class:`Captured` holds (expat's list:
    names and values in turn), or None."""
    for i in range(0, len(attrs) - 1, 2):
        if attrs[i] == name:
            return attrs[i + 1]
    return None


class _Position:
    """Where a replayed event was (what the builder reads of expat)."""

    __slots__ = ("CurrentLineNumber", "CurrentColumnNumber")


def _builder(expat, shift: int, data: bytes, capture: frozenset[str] = frozenset()) -> dict:
    """The expat callbacks that build :class:`Node` trees, recording where each element starts, and what
    they build: ``root``, and ``defaults``, the attribute defaults an internal DTD declares (``gesture
    lexeme="BEAT"``), which are not applied. ``shift`` is subtracted from columns on line 1 (text put
    before the document there).

    (Closures over local state: one element costs a call of ``start`` and one of ``end``, nothing more.)
    ``data``, the document: where it spells ``xmlns`` fewer times than a namespace could be declared in it,
    no element after that has its attributes searched for declarations.

    ``capture``: tags of the root's children whose content is held as expat's events (a :class:`Captured`
    element, the attributes as expat's list) instead of being made into nodes; content that declares a
    namespace, or nests deeper than :data:`HELD_DEPTH`, is made into nodes at once (as it would have been).
    ``replay`` makes events into nodes as ``start``, ``end`` and ``text`` would have made them where they were;
    ``seed`` puts an element on the stack (a replay's parent).
    """
    state: dict = {"root": None, "defaults": [], "scopes": [{}]}
    stack: list[Node] = []
    push, pop = stack.append, stack.pop
    # the pieces of text expat gave since the last tag, joined into one child at the next (a text of
    # megabytes comes in thousands of pieces: added one by one, it was copied as often)
    pending: list[str] = []
    # tag name -> (local, prefix): the tag's parts are split once per tag name, not per element
    tags: dict[str, tuple[str, str | None]] = {}
    new = _new_node
    # How many namespace declarations the document can still hold: the times it spells "xmlns" (an attribute
    # name is written as it is; in UTF-16, bytes of its own, every element is searched)
    utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in data[:2]
    declarations = [data.count(b"xmlns") if not utf16 else len(data)]

    def flush() -> None:
        children = stack[-1].children
        text = "".join(pending)
        pending.clear()
        if children and isinstance(children[-1], str):
            children[-1] += text
        else:
            children.append(text)

    where = expat  # (what tells where an element starts: expat, or a replayed event's place)

    def split(name: str) -> tuple[str, str | None]:
        """The tag's parts, ``(local, prefix)``, kept for every element of that name (and in ``names``)."""
        prefix, colon, local = name.partition(":")
        parts = tags[name] = (local, prefix) if colon else (name, None)
        return parts

    def start(name: str, attrs: dict[str, str]) -> None:
        if pending:
            flush()
        kind = Node
        if stack:
            if len(stack) >= MAX_DEPTH:
                raise BMLError(f"elements nested more than {MAX_DEPTH} deep", where.CurrentLineNumber,
                               where.CurrentColumnNumber + 1)
            parent = stack[-1]
            namespaces = parent.namespaces
            if capture and len(stack) == 1 and name in capture:
                kind = Captured
        else:
            parent = None
            namespaces = state["scopes"][0]
        if declarations[0] and attrs and "xmlns" in "".join(attrs) and any(key.startswith("xmlns") for key in attrs):
            namespaces = dict(namespaces)
            plain = {}
            for key, value in attrs.items():
                if key == "xmlns":
                    namespaces[""] = value
                elif key.startswith("xmlns:"):
                    namespaces[key[6:]] = value
                else:
                    plain[key] = value
            declarations[0] = max(declarations[0] - (len(attrs) - len(plain)), 0)
            attrs = plain
            state["scopes"].append(namespaces)
        line = where.CurrentLineNumber
        # (a Node made without its __init__)
        node = new(kind)
        node._tag = name
        parts = tags.get(name)
        if parts is None:
            parts = split(name)
        node.local, node.prefix = parts
        node.attrs = attrs
        node.line = line
        node.column = where.CurrentColumnNumber + 1 - (shift if line == 1 else 0)
        node.children = []
        node.namespaces = namespaces
        if parent is not None:
            parent.children.append(node)
        else:
            state["root"] = node
        push(node)
        if kind is Captured:
            hold(node)

    def end(name: str) -> None:
        if pending:
            flush()
        pop()

    def text(content: str) -> None:
        if stack:
            pending.append(content)

    def attlist(element: str, attribute: str, kind: str | None, default: str | None, required: int) -> None:
        if default is not None:
            shown = default if len(default) <= 40 else default[:37] + "..."
            state["defaults"].append(f"{element} {attribute}={shown!r}")

    def hold(node: Captured) -> None:
        # (expat's handlers while the content of ``node`` is held: closures over its events and depth)
        node.events = events = []
        node.shift = shift
        add = events.append
        depth = 0

        def held_start(name: str, attrs: list[str]) -> None:
            nonlocal depth
            if depth >= HELD_DEPTH or declarations[0] and attrs and "xmlns" in "".join(attrs[::2]):
                release()  # (made into nodes now, and read on as every element is)
                node.events = None
                replay(events)
                start(name, dict(zip(attrs[::2], attrs[1::2])))
                return
            depth += 1
            add((name, attrs, expat.CurrentLineNumber, expat.CurrentColumnNumber))
            if name not in tags:
                split(name)

        def held_end(name: str) -> None:
            nonlocal depth
            if depth:
                depth -= 1
                add(None)
                return
            release()  # the held element's own end
            end(name)

        expat.StartElementHandler, expat.EndElementHandler, expat.CharacterDataHandler = held_start, held_end, add
        expat.ordered_attributes = True  # (a held element's attributes as expat's list: smaller than a dict)

    def release() -> None:
        expat.StartElementHandler, expat.EndElementHandler, expat.CharacterDataHandler = start, end, text
        expat.ordered_attributes = False

    def replay(events: list) -> None:
        nonlocal where
        place = where = _Position()
        try:
            for event in events:
                if event is None:
                    end("")
                elif type(event) is str:
                    text(event)
                else:
                    place.CurrentLineNumber, place.CurrentColumnNumber = event[2], event[3]
                    attrs = event[1]
                    start(event[0], dict(zip(attrs[::2], attrs[1::2])))
        finally:
            where = expat

    def close() -> None:
        # (the callbacks refer to each other, and to the parser, which holds the document: cut, so that neither
        # waits for a collection)
        nonlocal expat, where, hold, release, replay
        expat = where = hold = release = replay = None

    state.update(start=start, end=end, text=text, attlist=attlist, names=tags.keys(), seed=push, replay=replay,
                 close=close)
    return state


def _parse(data: bytes, shift: int = 0, defaults: list[str] | None = None, made: dict | None = None,
           capture: frozenset[str] = frozenset()) -> Node:
    # defusedxml's reader installs the handlers that refuse entity declarations and external
    # references on its expat parser; the tree is built straight from that parser's callbacks.
    reader = create_parser(forbid_dtd=False, forbid_entities=True, forbid_external=True)
    reader.setFeature(xml.sax.handler.feature_namespaces, False)
    reader.setFeature(xml.sax.handler.feature_string_interning, True)  # (a tag name is one string: hashed once)
    reader.reset()
    expat = reader._parser
    builder = _builder(expat, shift, data, capture)
    expat.StartElementHandler = builder["start"]
    expat.EndElementHandler = builder["end"]
    expat.CharacterDataHandler = builder["text"]
    expat.buffer_text = True
    # Only the attributes the document writes: defaults an internal DTD's ATTLIST declares are not applied
    # (they could give a block its id or put a time into every element of a kind).
    expat.specified_attributes = True
    expat.AttlistDeclHandler = builder["attlist"]
    try:
        expat.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        message = xml.parsers.expat.errors.messages.get(exc.code, str(exc))
        column = exc.offset + 1 - (shift if exc.lineno == 1 else 0)
        raise BMLError(f"malformed XML: {message}", exc.lineno, column) from None
    except LookupError as exc:  # an encoding the XML declaration names that Python does not know
        raise BMLError(f"malformed XML: {exc}", 1, 1) from None
    except DefusedXmlException as exc:
        raise BMLError(f"refused XML construct ({type(exc).__name__}): entity and external references "
                       "are not allowed in BML", expat.CurrentLineNumber, expat.CurrentColumnNumber + 1) from None
    finally:
        # The reader and its expat parser refer to each other (a cycle, freed only by the collector), and the
        # parser keeps the document and the tree (through the callbacks' closures): the cycle is broken, or
        # every document read would stay in memory until a collection (dozens of them, megabytes each, in a
        # live service that makes few other objects)
        expat.StartElementHandler = expat.EndElementHandler = expat.CharacterDataHandler = None
        expat.AttlistDeclHandler = None
        root, declared = builder["root"], builder["defaults"]
        seen = {"names": set(builder["names"]), "scopes": builder["scopes"]}
        builder["close"]()
        builder.clear()  # (the callbacks and the state they fill refer to each other: another cycle)
        reader._parser = None
    if root is None:
        raise BMLError("empty document: expected a <bml> element", 1, 1)
    if defaults is not None:
        defaults.extend(declared)
    if made is not None:
        made.update(seen)
    return root


def encode(text: str | bytes) -> bytes:
    """A document as UTF-8 bytes; :class:`BMLError` (with line and column) for text that is not valid Unicode
    (a lone surrogate)."""
    if not isinstance(text, str):
        return text
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError as exc:
        line = text.count("\n", 0, exc.start) + 1
        column = exc.start - (text.rfind("\n", 0, exc.start) + 1) + 1
        raise BMLError(f"the document is not valid Unicode: {exc.reason} "
                       f"({text[exc.start:exc.end].encode('unicode_escape').decode('ascii')})", line, column) from None


def read_tree(text: str | bytes, defaults: list[str] | None = None, capture: frozenset[str] = frozenset()) -> Node:
    """The element tree of one XML document. Raises :class:`BMLError` (with line and column).

    ``defaults``: gets the attribute defaults the document's internal DTD declares (``gesture
    lexeme='BEAT'``); they are never applied (an element has the attributes written in it, no more).
    ``capture``: the tags of the root's children to hold as :class:`Captured` elements."""
    return _parse(encode(text), defaults=defaults, capture=capture)


#: The element that :func:`read_forest` puts around several top-level elements.
FOREST = "agentsim-document"
_DECLARATION = re.compile(rb"<\?xml\b[^>]*\?>")
_ENCODING = re.compile(rb"""encoding\s*=\s*["']([A-Za-z0-9._\-]+)["']""")
_JUNK = xml.parsers.expat.errors.messages[xml.parsers.expat.errors.codes[xml.parsers.expat.errors.XML_ERROR_JUNK_AFTER_DOC_ELEMENT]]


def read_forest(text: str | bytes, defaults: list[str] | None = None,
                made: dict | None = None, capture: frozenset[str] = frozenset()) -> tuple[Node, bool]:
    """The element tree of a document that may hold several top-level elements.

    Returns the root, and whether it is a :data:`FOREST` element made here around several elements one
    after another (XML declarations among them are dropped; positions stay those of the text given).
    ``defaults``: as for :func:`read_tree`. ``made``: gets what the tree is made of, without a walk through
    it: ``names``, the set of element names written, and ``scopes``, the namespace mappings the elements
    share (each element's ``namespaces`` is one of them). ``capture``: as for :func:`read_tree` (where the
    document has one top-level element).
    """
    data = encode(text)
    try:
        return _parse(data, defaults=defaults, made=made, capture=capture), False
    except BMLError as exc:
        if not exc.reason.endswith(_JUNK):
            raise
        first = exc
    declared = _DECLARATION.match(data.lstrip())
    if declared:
        encoding = _ENCODING.search(declared.group(0))
        if encoding and encoding.group(1).lower() not in (b"utf-8", b"utf8", b"us-ascii", b"ascii"):
            try:
                data = data.decode(encoding.group(1).decode("ascii")).encode("utf-8")
            except (LookupError, UnicodeDecodeError):
                raise first from None
    blanked = _DECLARATION.sub(lambda m: b" " * len(m.group(0)), data)
    opening = f"<{FOREST}>".encode()
    try:
        return _parse(opening + blanked + f"</{FOREST}>".encode(), shift=len(opening), made=made), True
    except BMLError:
        raise first from None
