"""The tests of the live service wait for what they wait for (an event, a future, a message, a counter), never
for a while: no ``time.sleep`` nor ``asyncio.sleep`` in ``tests/test_live_*.py`` and ``tests/test_serve*.py``
(a sleep is too short on busy cores and too long everywhere else)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
SCANNED = sorted({*TESTS.glob("test_live_*.py"), *TESTS.glob("test_serve*.py")})


def sleeps(source: str) -> list[int]:
    """The lines of ``source`` that call a sleep: ``time.sleep(...)``, ``asyncio.sleep(...)`` (whatever the
    module is called), or ``sleep(...)`` imported from either."""
    tree = ast.parse(source)
    imported = {alias.asname or alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                and node.module in ("time", "asyncio") for alias in node.names if alias.name == "sleep"}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if (isinstance(func, ast.Attribute) and func.attr == "sleep") or \
                (isinstance(func, ast.Name) and func.id in imported):
            found.append(node.lineno)
    return sorted(found)


def test_the_scan_finds_every_kind_of_sleep():
    assert sleeps("import time\ntime.sleep(0.1)\n") == [2]
    assert sleeps("import asyncio\nasync def f():\n    await asyncio.sleep(0)\n") == [3]
    assert sleeps("from time import sleep as nap\nnap(1)\n") == [2]
    assert sleeps("import time as t\nt.sleep(1)\n") == [2]
    assert sleeps("event.wait(1)\nws.recv(timeout=1)\nx = 'time.sleep(1)'\n") == []


def test_the_live_tests_are_scanned():
    names = {path.name for path in SCANNED}
    assert {"test_serve.py", "test_live_poses.py", "test_live_routing.py", "test_live_faults.py",
            "test_live_backlog.py", "test_live_no_sleep.py"} <= names


@pytest.mark.parametrize("path", SCANNED, ids=lambda path: path.name)
def test_no_live_test_sleeps(path):
    lines = sleeps(path.read_text(encoding="utf-8"))
    assert lines == [], f"{path.name} sleeps at line(s) {lines}: wait for an event, a future or a message"
