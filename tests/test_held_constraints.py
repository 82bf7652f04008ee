"""A block's ``<constraint>`` is held as the XML reader's events and read from them at once where it is plain: the
tree, the blocks and every warning are those of the reader that makes every element a node.

The documents are the BML test files and seeded random ones whose constraints hold everything the readers treat
apart: other elements, prefixes, names in capitals, references of every form (absolute times, anticipators,
draft spellings, aliases, white space, ones that do not read), anchors, missing ``ref``, text, comments, CDATA,
namespace declarations and nesting deeper than the events are held for (then made into nodes at once).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agentsim.bml import parser
from agentsim.core import xmltree
from agentsim.errors import BMLError

HERE = Path(__file__).resolve().parent
FILES = sorted({*HERE.glob("bml-examples/*.xml"), *HERE.glob("bml-examples-asap/**/*.xml"),
                *HERE.glob("dialects/**/*.xml"), *HERE.glob("bml/**/*.xml")})
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
REFS = ["b1:end", "b2:start+0.5", "b1:stroke-0.25", "0", "1.5", "anticipators:m:beat1", "b1:stroke_start",
        "b2:relax", " b1:end", "b1:end ", "b1:", "zz:start", "b1:end+1e3", "bml1:b1:end", "b2:ready", "b1:strokeEnd",
        "b1:end+99999999", "é:start", "b1:\nend"]
KINDS = ["synchronize", "synchronize", "before", "after", "foo", "bml:synchronize", "SYNCHRONIZE"]


def _random_document(rng: np.random.Generator) -> str:
    def ref() -> str:
        return str(rng.choice(REFS)).replace("&", "&amp;").replace("<", "&lt;")

    def content(depth: int) -> str:
        parts = []
        for _ in range(int(rng.integers(0, 4))):
            roll = rng.random()
            if roll < 0.55:
                parts.append(f'<sync ref="{ref()}"/>')
            elif roll < 0.62:
                parts.append("<sync/>")
            elif roll < 0.68:
                parts.append(f'<sync ref="{ref()}"><sync ref="b1:end"/></sync>')
            elif roll < 0.74:
                parts.append(" text ")
            elif roll < 0.79:
                parts.append("<!-- a comment -->")
            elif roll < 0.83:
                parts.append("<![CDATA[ <sync/> ]]>")
            elif roll < 0.855:
                parts.append(f'<sync xmlns:x="urn:x" ref="{ref()}"/>')
            elif roll < 0.88:  # (the reference after another attribute, or none but another)
                parts.append(f'<sync id="s1" ref="{ref()}"/>' if rng.random() < 0.7 else '<sync id="s1"/>')
            elif roll < 0.92 and depth < 30:
                deep = int(rng.integers(1, 22))
                parts.append("<n>" * deep + "<sync ref='b1:end'/>" + "</n>" * deep)
            else:
                parts.append(f'<x:sync xmlns:x="urn:x" ref="{ref()}"/>')
        return "".join(parts)

    constraints = []
    for _ in range(int(rng.integers(0, 3))):
        children = []
        for _ in range(int(rng.integers(0, 5))):
            kind = str(rng.choice(KINDS))
            anchor = f' ref="{ref()}"' if rng.random() < 0.5 else ""
            if rng.random() < 0.2:  # (the anchor after another attribute)
                anchor = f' id="k1"{anchor}'
            declared = ' xmlns:bml="http://www.bml-initiative.org/bml/bml-1.0"' if kind.startswith("bml:") else ""
            children.append(f"<{kind}{anchor}{declared}>{content(0)}</{kind}>")
        space = "\n  " if rng.random() < 0.5 else ""
        owner = ' id="c1"' if rng.random() < 0.3 else ""
        constraints.append(f"<constraint{owner}>{space}{space.join(children)}{space}</constraint>")
    behaviours = '<gesture id="b1" lexeme="BEAT"/><speech id="b2"><text>Hello <sync id="m"/>there.</text></speech>'
    body = behaviours + "".join(constraints)
    if rng.random() < 0.2:
        body = f"<required>{body}</required>"
    newline = "\n" if rng.random() < 0.5 else ""
    return f'<bml {NS} id="bml1">{newline}{body}</bml>'


def _read(read, text: str):
    """What a reader makes of ``text``: its blocks (each field, warnings included), or the error it raises."""
    try:
        found = read(text)
    except BMLError as exc:
        return ("error", str(exc), exc.line, exc.column)
    blocks = found if isinstance(found, list) else [found]
    return [repr(b) if not isinstance(b, parser.Refused) else (b.block_id, str(b.error), b.error.line, b.error.column)
            for b in blocks]


def _nodes(node, out: list) -> list:
    out.append((node.tag, node.local, node.prefix, dict(node.attrs), node.line, node.column,
                sorted(node.namespaces.items())))
    for child in node.children:
        if isinstance(child, str):
            out.append(child)
        else:
            _nodes(child, out)
    out.append("/")
    return out


def _both(text: str, monkeypatch) -> None:
    """The trees, the lenient and the strict reader's blocks, with constraints held and without."""
    for read in (parser.parse_document, parser.parse_bml):
        held = _read(read, text)
        with monkeypatch.context() as patch:
            patch.setattr(parser, "HELD", frozenset())
            made = _read(read, text)
        assert held == made, text
    try:
        plain_made: dict = {}
        plain = xmltree.read_forest(text, made=plain_made)
    except BMLError as exc:
        with pytest.raises(BMLError) as again:
            xmltree.read_forest(text, capture=parser.HELD)
        assert (str(again.value), again.value.line, again.value.column) == (str(exc), exc.line, exc.column)
        return
    held_made: dict = {}
    held = xmltree.read_forest(text, made=held_made, capture=parser.HELD)
    assert held[1] == plain[1] and _nodes(held[0], []) == _nodes(plain[0], []), text
    assert held_made["names"] == plain_made["names"] and len(held_made["scopes"]) == len(plain_made["scopes"])


def test_the_test_files_read_the_same_with_their_constraints_held(monkeypatch):
    assert len(FILES) > 100
    for path in FILES:
        _both(path.read_text(encoding="utf-8"), monkeypatch)
    # a chain of behaviours, each tied to the one before (the scheduler's benchmark block)
    parts = ['<speech id="b0"><text>We walk <sync id="m"/>along.</text></speech>']
    constraints = ['<synchronize><sync ref="b0:start"/><sync ref="0"/></synchronize><after ref="0"><sync ref="b0:end"/></after>']
    for i in range(1, 60):
        parts.append(f'<head id="b{i}" lexeme="NOD"/>')
        constraints.append(f'<synchronize><sync ref="b{i}:start"/><sync ref="b{i - 1}:end+0.05"/></synchronize>'
                           f'<after ref="b{i - 1}:start"><sync ref="b{i}:end"/></after>')
    text = f'<bml {NS} id="chain">{"".join(parts)}<constraint>{"".join(constraints)}</constraint></bml>'
    _both(text, monkeypatch)
    assert len(parser.parse_bml(text).constraints) == 2 + 2 * 59


def test_random_constraints_read_the_same_held_or_made_into_nodes(monkeypatch):
    rng = np.random.default_rng(39)
    held = let_go = 0
    for _ in range(600):
        text = _random_document(rng)
        _both(text, monkeypatch)
        root = xmltree.read_tree(text, capture=parser.HELD)
        kept = [c.events is not None for c in root.elements() if type(c) is xmltree.Captured]
        held, let_go = held + any(kept), let_go + (not all(kept))
    # (many held to their end, and many made into nodes while they were read: a declaration, or deep nesting)
    assert held > 100 and let_go > 100, (held, let_go)


def test_a_held_constraint_is_read_without_nodes_and_made_into_them_when_asked():
    """A plain ``<constraint>`` of a block is read from its events, and stays held; one the lenient reader respells
    is made into nodes first; any element asked for its children gets the nodes, at their places."""
    text = (f'<bml {NS} id="k">\n<gesture id="g1" lexeme="BEAT"/><gesture id="g2" lexeme="BEAT"/>\n'
            '<constraint id="c"> <synchronize><sync ref="g1:stroke"/><sync ref="g2:stroke+0.5"/></synchronize>'
            '<after ref="0"><sync ref="g2:end"/></after></constraint>\n'
            '<constraint><before ref="g2:stroke_start"><sync ref="g1:end"/></before></constraint></bml>')
    root = xmltree.read_tree(text, capture=parser.HELD)
    first, second = (c for c in root.elements() if c.local == "constraint")
    assert type(first) is type(second) is xmltree.Captured and first.events is not None
    block = parser.read_block(root, None)
    assert first.events is not None  # read from its events
    lines = text.split("\n")

    def at(line: int, what: str) -> tuple[int, int]:  # (1-based, as expat counts them)
        return line, lines[line - 1].index(what) + 1

    assert [(c.kind, [r.text for r in c.refs], c.anchor and c.anchor.text, c.id, c.line, c.column)
            for c in block.constraints] == [("synchronize", ["g1:stroke", "g2:stroke+0.5"], None, "c", *at(3, "<sync")),
                                            ("after", ["g2:end"], "0", "c", *at(3, "<after")),
                                            ("before", ["g1:end"], "g2:stroke_start", "", *at(4, "<before"))]
    (lenient,) = parser.parse_document(text)
    assert lenient.constraints[2].anchor.text == "g2:strokeStart"  # (respelled: from nodes)
    sync = first.elements()[0].elements()[1]
    assert (sync.tag, sync.attrs, sync.line, sync.column) == ("sync", {"ref": "g2:stroke+0.5"}, *at(3, '<sync ref="g2'))
    assert first.events is None and first.children[0] == " " and len(first.elements()) == 2


def test_a_constraint_nested_too_deep_is_refused_where_it_is_so(monkeypatch):
    deep = "<n>" * 300 + "</n>" * 300
    text = f'<bml {NS} id="d"><constraint><synchronize>{deep}</synchronize></constraint></bml>'
    with pytest.raises(BMLError, match="nested more than 256 deep") as held:
        xmltree.read_tree(text, capture=parser.HELD)
    with pytest.raises(BMLError) as made:
        xmltree.read_tree(text)
    # (the element with 256 open around it: the block, the constraint, the synchronize and 253 others)
    column = text.index("<synchronize>") + len("<synchronize>") + 253 * len("<n>") + 1
    assert (held.value.line, held.value.column) == (made.value.line, made.value.column) == (1, column)
    _both(text, monkeypatch)
