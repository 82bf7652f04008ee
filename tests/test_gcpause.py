"""The collection pause: many objects made in it skip the young generations, and their garbage is still
collected."""

from __future__ import annotations

import gc
import weakref

import pytest

from agentsim.core import gcpause
from agentsim.core.gcpause import paused_collection


class Cell:
    """A small object that can be part of a cycle."""

    def __init__(self) -> None:
        self.other: Cell | None = None


@pytest.fixture
def collector(monkeypatch):
    """A clean collector (enabled, nothing frozen) and a fresh budget; restored afterwards."""
    was_enabled = gc.isenabled()
    gc.unfreeze()  # a live service run earlier in this process froze what it had made (gc.freeze())
    gc.enable()
    gc.collect()
    monkeypatch.setattr(gcpause, "_moved", 0)
    monkeypatch.setattr(gcpause, "_budget", 10 ** 9)
    yield
    gc.collect()
    if not was_enabled:
        gc.disable()


def test_many_objects_made_in_a_pause_go_to_the_oldest_generation(collector):
    with paused_collection():
        kept = [Cell() for _ in range(3 * gcpause.FEW)]
        assert not gc.isenabled()
    assert gc.isenabled()
    assert gc.get_count()[0] < gcpause.FEW  # the youngest generation does not hold them
    assert gcpause._moved >= len(kept)


def test_few_objects_stay_young(collector):
    with paused_collection():
        kept = [Cell() for _ in range(100)]
    assert gcpause._moved == 0
    assert len(kept) == 100


def test_nested_pauses_end_with_the_outermost(collector):
    with paused_collection():
        with paused_collection():
            pass
        assert not gc.isenabled()
    assert gc.isenabled()


def test_cycles_among_moved_objects_are_collected_once_the_budget_is_spent(collector, monkeypatch):
    with paused_collection():
        cells = [Cell() for _ in range(2 * gcpause.FEW)]
        a, b = Cell(), Cell()
        a.other, b.other = b, a
        probe = weakref.ref(a)
    del a, b, cells
    assert probe() is not None  # a cycle in the oldest generation: the young collections never see it
    monkeypatch.setattr(gcpause, "_budget", 0)
    with paused_collection():
        made = [Cell() for _ in range(2 * gcpause.FEW)]
    assert probe() is None  # the full collection made when the budget ran out freed it
    assert gcpause._moved == 0 and gcpause._budget >= gcpause.GROWTH * gcpause.FLOOR
    assert len(made) == 2 * gcpause.FEW


def test_nothing_moves_while_the_program_has_frozen_objects(collector):
    gc.freeze()
    try:
        with paused_collection():
            kept = [Cell() for _ in range(3 * gcpause.FEW)]
        assert gcpause._moved == 0  # left young, as without the move
    finally:
        gc.unfreeze()
    assert len(kept) == 3 * gcpause.FEW
