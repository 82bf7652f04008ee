"""Time pegs and the PegBoard on hand-built cases: offsets, moves, caches, computed pegs, the board."""

from __future__ import annotations

import pytest

from agentsim.core.pegboard import ComputedPeg, OffsetPeg, PegBoard, TimePeg


def test_offset_pegs_follow_their_base_through_a_chain():
    base = TimePeg(1.0)
    a = OffsetPeg(base, 0.5)
    b = OffsetPeg(a, -0.25)
    assert (a.time, b.time) == (1.5, 1.25)
    base.set(2.0)
    assert (a.time, b.time) == (2.5, 2.25)
    assert b.root() is base and base.root() is base
    # setting an offset peg moves its base, keeping the tie
    b.set(3.0)
    assert base.time == 2.75 and a.time == 3.25


def test_unknown_base_gives_unknown_times_and_cannot_be_set_through():
    base = TimePeg(None)
    peg = OffsetPeg(base, 1.0)
    assert peg.time is None
    with pytest.raises(ValueError):
        peg.set(2.0)
    with pytest.raises(ValueError):
        OffsetPeg(None, 1.0).set(1.0)


def test_a_long_chain_evaluates_without_recursion_and_caches_until_anything_moves():
    base = TimePeg(0.0)
    peg = base
    for _ in range(5000):
        peg = OffsetPeg(peg, 0.001)
    assert peg.time == pytest.approx(5.0, abs=1e-9)
    base.set(1.0)
    assert peg.time == pytest.approx(6.0, abs=1e-9)


def test_shift_rebase_and_freeze():
    block = TimePeg(10.0)
    other = TimePeg(3.0)
    peg = OffsetPeg(other, 1.0)
    peg.shift(0.5)
    assert peg.time == 4.5 and peg.offset == 1.5
    peg.rebase(block, 2.0)
    assert peg.time == 12.0
    peg.rebase(other, 1.0)
    peg.freeze(block)  # keeps its time, now relative to the block
    assert peg.base is block and peg.offset == -6.0 and peg.time == 4.0
    other.set(100.0)
    assert peg.time == 4.0


class Moving(ComputedPeg):
    """A computed peg whose source is a list cell."""

    __slots__ = ("source",)

    def __init__(self, source):
        super().__init__(None, name="moving")
        self.source = source

    def compute(self):
        return self.source[0]


def test_a_computed_peg_cannot_be_set_and_its_dependants_see_it_change_once_caches_are_dropped():
    source = [1.0]
    peg = Moving(source)
    tied = OffsetPeg(peg, 0.5)
    assert tied.time == 1.5
    source[0] = 2.0
    assert tied.time == 1.5  # cached: nothing said the source changed
    assert tied.cache is peg.cache  # an offset peg shares its base's cache
    peg.cache.invalidate()
    assert tied.time == 2.5
    with pytest.raises(ValueError, match="computed"):
        peg.set(3.0)


def test_the_board_reports_moves_except_when_quiet():
    board = PegBoard()
    moved = []
    board.on_move(moved.append)
    peg = board.block_peg("b1", 0.0)
    assert board.block_peg("b1") is peg
    peg.set(1.0)
    peg.set(1.0)  # no change, no report
    with board.quiet():
        with board.quiet():
            peg.set(2.0)
        peg.set(3.0)
    peg.set(4.0)
    assert moved == [peg, peg] and peg.time == 4.0
    fresh = board.new_block_peg("b1", 5.0)
    assert fresh is not peg and board.block_peg("b1") is fresh and fresh.name == "b1:start"


def test_sync_points_are_found_lazily_and_forgotten_per_block():
    board = PegBoard()
    made = []

    def peg_for(i):
        made.append(i)
        return TimePeg(float(i))

    board.register_behaviour("b1", "g1", ["start", "stroke", "end"], peg_for)
    board.register_behaviour("b2", "g1", ["start", "end"], lambda i: TimePeg(10.0 + i))
    assert made == []
    peg, offset = board.find_sync("b1", "g1", "stroke")
    assert (peg.time, offset, made) == (1.0, 0.0, [1])
    assert board.find_sync("b1", "g1", "stroke")[0] is peg and made == [1]  # made once
    assert board.find_sync("b1", "g1", "relax") is None
    assert board.find_sync("b1", "g2", "start") is None
    board.forget_block("b1")
    assert board.find_sync("b1", "g1", "stroke") is None
    assert board.find_sync("b2", "g1", "end")[0].time == 11.0
