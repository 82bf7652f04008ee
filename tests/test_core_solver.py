"""The block solver on hand-built blocks: ties, offsets, constraints, clusters, drops, with exact times."""

from __future__ import annotations

import pytest
import simpy

from agentsim.bml.parser import parse_ref
from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block, Constraint
from agentsim.errors import ScheduleError
from agentsim.core.pegboard import PegBoard, TimePeg
from agentsim.core.solver import BlockSolver
from agentsim.core.timed import BlockRun
from agentsim.engines.animation import AnimationPlanner
from agentsim.engines.wait import WaitPlanner


class FakeEngine:
    def __init__(self, planner):
        self.planner = planner


ANIMATION = FakeEngine(AnimationPlanner())
ENGINES = {t: ANIMATION for t in AnimationPlanner.behaviour_types} | {"wait": FakeEngine(WaitPlanner())}


def behaviour(bid: str, kind: str = "gesture", required: bool = False, **refs: str) -> Behaviour:
    return Behaviour(bid, kind, list(BEHAVIOUR_TYPES[kind].syncs), {"lexeme": "BEAT"} if kind == "gesture" else {},
                     {sync: parse_ref(text) for sync, text in refs.items()}, required=required)


def solve(*items, start: float = 0.0, anticipators=None, existing=()):
    behaviours = [b for b in items if isinstance(b, Behaviour)]
    constraints = [c for c in items if isinstance(c, Constraint)]
    block = Block("b", behaviours=behaviours, constraints=constraints)
    board = PegBoard()
    run = BlockRun(block, board.new_block_peg("b", start), simpy.Environment().event())

    def anticipator_peg(name, sync):
        if anticipators is None or (name, sync) not in anticipators:
            raise ScheduleError(f"no anticipator {name!r}")
        return anticipators[(name, sync)]

    solver = BlockSolver(block, run, board, ENGINES, anticipator_peg, lambda: list(existing))
    timed = {t.id: t for t in solver.solve()}
    return solver, timed, run


def test_references_with_offsets_share_one_peg():
    solver, timed, run = solve(behaviour("g1", stroke="2"), behaviour("g2", stroke="g1:stroke+0.5"))
    assert not solver.issues
    assert timed["g1"].sync_time("stroke") == 2.0 and timed["g2"].sync_time("stroke") == 2.5
    assert timed["g2"].start == pytest.approx(2.05, abs=1e-12)  # a beat's preparation is 0.45 s
    run.block_peg.set(10.0)  # everything moves with the block
    assert timed["g1"].sync_time("stroke") == 12.0 and timed["g2"].sync_time("stroke") == 12.5


def test_a_synchronize_constraint_ties_two_free_behaviours():
    sync = Constraint("synchronize", [parse_ref("g1:stroke"), parse_ref("h1:stroke")])
    solver, timed, _ = solve(behaviour("g1", start="1"), behaviour("h1", "head"), sync)
    assert not solver.issues
    assert timed["h1"].sync_time("stroke") == timed["g1"].sync_time("stroke") == pytest.approx(1.45, abs=1e-12)


def test_anticipator_pegs_hold_what_is_tied_to_them():
    beat = TimePeg(3.0)
    _, timed, _ = solve(behaviour("g1", stroke="anticipators:m:beat2"), anticipators={("m", "beat2"): beat})
    assert timed["g1"].sync_time("stroke") == 3.0
    beat.set(4.0)
    assert timed["g1"].sync_time("stroke") == 4.0
    solver, timed, _ = solve(behaviour("g1", stroke="anticipators:none:beat2"))
    assert "g1" not in timed and "no anticipator 'none'" in solver.issues[0].description


def test_before_and_after_move_the_free_behaviour_or_drop_it_if_it_would_leave_the_block():
    after = Constraint("after", [parse_ref("g2:start")], anchor=parse_ref("g1:end"))
    solver, timed, _ = solve(behaviour("g1", start="1"), behaviour("g2"), after)
    assert not solver.issues
    assert timed["g2"].start == pytest.approx(timed["g1"].end, abs=1e-12) == pytest.approx(1.95, abs=1e-12)
    before = Constraint("before", [parse_ref("g2:end")], anchor=parse_ref("g1:start"))
    solver, timed, _ = solve(behaviour("g1", start="2"), behaviour("g2", stroke="1.9"), before)
    assert set(timed) == {"g1"} and solver.issues[0].behaviours == ["g2"]  # fixed at 1.9, it ends after 2
    # g2 (0.95 s long) would have to start 0.45 s before the block to end by 0.5: dropped, with a reason
    solver, timed, _ = solve(behaviour("g1", start="0.5"), behaviour("g2"), before)
    assert set(timed) == {"g1"} and solver.issues[0].behaviours == ["g2"]
    assert "g2:end cannot be before g1:start within the block" in solver.issues[0].description
    # a free behaviour tied 0.3 s before another free one's start is shifted so that it starts at 0
    _, timed, _ = solve(behaviour("g1"), behaviour("g2", stroke="g1:start-0.3"))
    assert min(timed["g1"].start, timed["g2"].start) == pytest.approx(0.0, abs=1e-12)
    assert timed["g2"].sync_time("stroke") == pytest.approx(timed["g1"].start - 0.3, abs=1e-12)


def test_contradictions_drop_only_what_they_spoil():
    solver, timed, _ = solve(behaviour("g1", start="1", end="1.02"), behaviour("g2", stroke="1.5"))
    assert set(timed) == {"g2"} and solver.issues[0].behaviours == ["g1"]
    assert "shorter than the shortest beat" in solver.issues[0].description
    clash = Constraint("synchronize", [parse_ref("g1:stroke"), parse_ref("2")])
    solver, timed, _ = solve(behaviour("g1", stroke="1"), clash)
    assert "cannot synchronise" in solver.issues[0].description and "g1" not in timed


def test_a_required_behaviour_that_fails_refuses_the_block():
    solver, timed, _ = solve(behaviour("g1", required=True, stroke="nothere:stroke"), behaviour("g2"))
    assert solver.failed and timed == {}
    assert any(i.description.startswith("block refused: required behaviour g1") for i in solver.issues)


def test_two_gazes_at_once_keep_the_first():
    solver, timed, _ = solve(behaviour("a", "gaze", start="1", end="3"), behaviour("b", "gaze", start="2", end="4"),
                             behaviour("c", "gaze", start="3", end="5"))
    assert set(timed) == {"a", "c"}  # c starts as a ends: no overlap
    assert solver.issues[0].behaviours == ["b"] and "gaze is already used by b:a" in solver.issues[0].description
