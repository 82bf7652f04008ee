"""State that belongs to one realizer is owned by it, not by the process: in the realizer's core and its
animation no function has a ``global`` statement, and no module or class holds an ``itertools.count()``
(counters are kept by the object that owns them: the PegBoard, a block run, a DriverManager). Two characters
in one process, or two sweep points in one worker, then cannot disturb each other."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("agentsim/core", "agentsim/animation")
SOURCES = sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def _counters(tree: ast.Module):
    """A test of whether a node names ``itertools.count``, as this module imports it."""
    modules = {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.Import)
               for a in node.names if a.name == "itertools"}
    names = {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             and node.module == "itertools" for a in node.names if a.name == "count"}

    def is_count(node: ast.AST) -> bool:
        return ((isinstance(node, ast.Attribute) and node.attr == "count" and isinstance(node.value, ast.Name)
                 and node.value.id in modules) or (isinstance(node, ast.Name) and node.id in names))

    return is_count


def _outside_functions(body: list[ast.stmt]):
    """Every node of these statements that is not inside a function (a class's body is walked too)."""
    todo = list(body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        yield node
        todo.extend(ast.iter_child_nodes(node))


def process_state(source: str, name: str = "<module>") -> list[str]:
    """Where ``source`` keeps state for the whole process: its ``global`` statements, and the
    ``itertools.count`` its module or its classes hold."""
    tree = ast.parse(source)
    found = [f"{name}:{node.lineno}: global {', '.join(node.names)}" for node in ast.walk(tree)
             if isinstance(node, ast.Global)]
    is_count = _counters(tree)
    found += [f"{name}:{node.lineno}: an itertools.count held by the module or a class"
              for node in _outside_functions(tree.body) if is_count(node)]
    return sorted(found)


def test_the_scan_covers_both_packages():
    names = {p.relative_to(ROOT).as_posix() for p in SOURCES}
    assert {"agentsim/core/pegboard.py", "agentsim/core/timed.py", "agentsim/core/gcpause.py",
            "agentsim/animation/drivers.py", "agentsim/animation/arms.py", "agentsim/animation/lexicon.py"} <= names


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_process_wide_state(path):
    assert process_state(path.read_text(encoding="utf-8"), path.relative_to(ROOT).as_posix()) == []


@pytest.mark.parametrize("source, found", [
    ("n = 0\ndef bump():\n    global n\n    n += 1\n", 1),
    ("import itertools\n_uids = itertools.count()\n", 1),
    ("from itertools import count\n_uids = count(1)\n", 1),
    ("import itertools\nclass Driver:\n    uids = itertools.count()\n", 1),
    ("import itertools\nfrom dataclasses import dataclass, field\n@dataclass\nclass Run:\n"
     "    order: object = field(default_factory=itertools.count)\n", 1),
    # a counter an object makes for itself, or the count of a list: not process state
    ("import itertools\nclass Manager:\n    def __init__(self):\n        self.order = itertools.count()\n", 0),
    ("items = [1, 2, 1]\nones = items.count(1)\ncount = len(items)\n", 0),
])
def test_the_scan_finds_what_it_is_meant_to(source, found):
    assert len(process_state(source)) == found
