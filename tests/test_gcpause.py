"""The collection pause: many objects made in it skip the young generations, and their garbage is still
collected; it is a program's choice, shared by its threads, and a realizer given none leaves the collector
alone."""

from __future__ import annotations

import gc
import threading
import weakref

import pytest

from agentsim.core import gcpause
from agentsim.core.gcpause import CollectionPause
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = "http://www.bml-initiative.org/bml/bml-1.0"


class Cell:
    """A small object that can be part of a cycle."""

    def __init__(self) -> None:
        self.other: Cell | None = None


@pytest.fixture
def pause():
    """A clean collector (enabled, nothing frozen) and a fresh pause with a large budget; restored afterwards."""
    was_enabled = gc.isenabled()
    gc.unfreeze()  # a live service run earlier in this process froze what it had made (gc.freeze())
    gc.enable()
    gc.collect()
    made = CollectionPause()
    made.budget = 10 ** 9
    yield made
    gc.collect()
    if not was_enabled:
        gc.disable()


def test_many_objects_made_in_a_pause_go_to_the_oldest_generation(pause):
    with pause.paused():
        kept = [Cell() for _ in range(3 * gcpause.FEW)]
        assert not gc.isenabled()
    assert gc.isenabled()
    assert gc.get_count()[0] < gcpause.FEW  # the youngest generation does not hold them
    assert pause.moved >= len(kept)


def test_few_objects_stay_young(pause):
    with pause.paused():
        kept = [Cell() for _ in range(100)]
    assert pause.moved == 0
    assert len(kept) == 100


def test_nested_pauses_end_with_the_outermost(pause):
    with pause.paused():
        with pause.paused():
            pass
        assert not gc.isenabled()
    assert gc.isenabled()


def test_a_collector_the_program_turned_off_stays_off(pause):
    gc.disable()
    try:
        with pause.paused():
            kept = [Cell() for _ in range(3 * gcpause.FEW)]
        assert not gc.isenabled() and pause.moved == 0
    finally:
        gc.enable()
    assert len(kept) == 3 * gcpause.FEW


def test_cycles_among_moved_objects_are_collected_once_the_budget_is_spent(pause):
    with pause.paused():
        cells = [Cell() for _ in range(2 * gcpause.FEW)]
        a, b = Cell(), Cell()
        a.other, b.other = b, a
        probe = weakref.ref(a)
    del a, b, cells
    assert probe() is not None  # a cycle in the oldest generation: the young collections never see it
    pause.budget = 0
    with pause.paused():
        made = [Cell() for _ in range(2 * gcpause.FEW)]
    assert probe() is None  # the full collection made when the budget ran out freed it
    assert pause.moved == 0 and pause.budget >= gcpause.GROWTH * gcpause.FLOOR
    assert len(made) == 2 * gcpause.FEW


def test_nothing_moves_while_the_program_has_frozen_objects(pause):
    gc.freeze()
    try:
        with pause.paused():
            kept = [Cell() for _ in range(3 * gcpause.FEW)]
        assert pause.moved == 0  # left young, as without the move
    finally:
        gc.unfreeze()
    assert len(kept) == 3 * gcpause.FEW


def test_two_threads_sharing_a_pause_keep_the_collector_off_until_the_last_leaves(pause):
    # the live service reads in one thread and plans in another: one pause shared by both
    entered, release = threading.Event(), threading.Event()
    seen: list[bool] = []

    def other():
        with pause.paused():
            entered.set()
            release.wait(10.0)
            seen.append(gc.isenabled())

    thread = threading.Thread(target=other)
    with pause.paused():
        thread.start()
        assert entered.wait(10.0)
    assert not gc.isenabled()  # this thread left, the other is still inside
    release.set()
    thread.join(10.0)
    assert seen == [False] and gc.isenabled()


def _collector_switches(monkeypatch) -> list[str]:
    """Every call to gc.disable and gc.enable from now on, in order."""
    calls: list[str] = []
    disable, enable = gc.disable, gc.enable
    monkeypatch.setattr(gc, "disable", lambda: (calls.append("disable"), disable())[1])
    monkeypatch.setattr(gc, "enable", lambda: (calls.append("enable"), enable())[1])
    return calls


DOCUMENT = f'<bml xmlns="{NS}" id="b1"><gesture id="g1" lexeme="BEAT"/><head id="h1" lexeme="NOD"/></bml>'


def test_a_realizer_leaves_the_collector_alone_unless_given_a_pause(pause, monkeypatch):
    calls = _collector_switches(monkeypatch)
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(DOCUMENT)
    realizer.run()
    assert calls == [] and gc.isenabled()
    paused = Realizer(tts=BuiltinBackend(), gc_pause=pause)
    assert paused.submit(DOCUMENT) is not None
    assert calls == ["disable", "enable"]  # one pause for reading and planning the document
    assert len(paused.read_document(DOCUMENT)) == 1 and calls == ["disable", "enable"] * 2


def test_the_command_line_pauses_the_collector_while_it_reads_and_plans(pause, monkeypatch, tmp_path, capsys):
    from agentsim.cli import main
    from agentsim.cli.options import collection_pause

    document = tmp_path / "doc.xml"
    document.write_text(DOCUMENT)
    calls = _collector_switches(monkeypatch)
    assert main(["realize", str(document), "--tts", "builtin"]) == 0
    assert calls == ["disable", "enable"]  # one pause: the document read and planned
    assert collection_pause() is collection_pause()  # one for the process, whose collector it is
    assert '"id": "b1:end"' in capsys.readouterr().out
