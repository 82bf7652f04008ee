"""The scheduler's parts on their own: the composer, the retimer and the interrupter driven with fake engines,
a fake block book and a fake reporter (no realizer, no scheduler), with exact times, pegs, states and what
each returns; and the states of runs and behaviours as the strings they print as."""

from __future__ import annotations

import itertools
import json

import pytest
import simpy

from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block
from agentsim.core.composition import Composer
from agentsim.core.interruption import Interrupter
from agentsim.core.pegboard import PegBoard, TimePeg
from agentsim.core.recording import DropRecord
from agentsim.core.retiming import Retimer
from agentsim.core.scheduler import Scheduler
from agentsim.core.timed import BehaviourState, BlockRun, BlockState, KeyRef, SyncPeg, TimedBehaviour

#: A gesture's preferred timing, in halves, quarters and eighths: every time warped from it is exact.
PREFERRED = [0.0, 0.25, 0.375, 0.5, 0.625, 0.75, 1.0]


class FakePlanner:
    def __init__(self):
        self.plan: dict[TimedBehaviour, None] = {}
        self.reasons: dict[str, str] = {}  # behaviour id -> why its timing is invalid
        self.unjudged: set[str] = set()

    def judges(self, timed):
        return timed.id not in self.unjudged

    def invalid(self, timed, times=None):
        return self.reasons.get(timed.id)

    def remove(self, timed):
        self.plan.pop(timed, None)


class FakePlan:
    def __init__(self):
        self.kicked: list[list[str] | None] = []

    def kick(self, moved=None):
        self.kicked.append(None if moved is None else [t.id for t in moved])


class FakeEngine:
    """Records what it is told; an interruption leaves what :attr:`cut` says."""

    def __init__(self, cut=None):
        self.planner = FakePlanner()
        self.plan = FakePlan()
        self.cut = cut
        self.removed: list[str] = []
        self.stops: list[tuple[str, float]] = []

    def remove(self, timed):
        self.removed.append(timed.id)
        self.planner.remove(timed)

    def interruption(self, timed, now):
        return self.cut

    def stopped(self, timed, now):
        self.stops.append((timed.id, now))


class FakeBook:
    def __init__(self, *runs):
        self.runs = list(runs)
        self.all_runs = list(runs)
        self.drops: list[DropRecord] = []
        self.structure_version = 0

    def find(self, block_id):
        return next((r for r in reversed(self.all_runs) if r.id == block_id), None)

    def changed(self):
        self.structure_version += 1

    def live_behaviours(self):
        return [t for r in self.runs for t in r.live()]

    def add_drop(self, record):
        self.drops.append(record)


class FakeReporter:
    def __init__(self):
        self.said: list[tuple] = []

    def warn(self, target, kind, description, character, modified=(), line=None, column=None, adaptations=()):
        self.said.append(("warn", target, kind, description, list(modified)))

    def block_progress(self, run, which, time, interrupted=False):
        self.said.append(("block", run.id, which, time, interrupted))

    def prediction(self, run, start, end, entries):
        self.said.append(("prediction", run.id, start, end, entries))


#: The order the fake behaviours are planned in (a realizer's PegBoard numbers its own).
PLANNED = itertools.count()


def run_of(env, block_id, start=0.0, state=BlockState.PENDING, **block):
    run = BlockRun(Block(block_id, **block), TimePeg(start, name=f"{block_id}:start"), env.event())
    if state is not BlockState.PENDING:
        run.start()
    return run


def gesture(run, behaviour_id, keys, engine=None, **attributes):
    """A gesture of ``run`` with its keys at ``{index: time or peg}`` (the others warped from :data:`PREFERRED`)."""
    behaviour = Behaviour(behaviour_id, "gesture", list(BEHAVIOUR_TYPES["gesture"].syncs), dict(attributes))
    pegs = [keys.get(i) for i in range(len(PREFERRED))]
    timed = TimedBehaviour(run, behaviour, PREFERRED, [None if k is None else KeyRef(k if isinstance(k, TimePeg)
                                                                                    else TimePeg(k)) for k in pegs],
                           engine if engine is not None else FakeEngine(), next(PLANNED))
    run.timed.append(timed)
    return timed


# ---------------------------------------------------------------------------------------------- states
def test_the_states_print_and_compare_as_the_strings_they_were():
    assert f"{BlockState.PENDING} {BehaviourState.DROPPED}" == "pending dropped"
    assert BehaviourState.FINISHED == "finished" and "running" == BlockState.RUNNING
    assert json.dumps({"state": BehaviourState.ACTIVE}) == '{"state": "active"}'
    assert Scheduler.__bases__ == (object,)


def test_a_run_and_a_behaviour_change_their_own_states():
    env = simpy.Environment()
    run = run_of(env, "b")
    g = gesture(run, "g", {0: 1.0, 6: 2.0})
    assert (run.state, g.state, run.live_count, run.dormant) == ("pending", "planned", 1, False)
    run.start()
    g.activate()
    assert (run.state, g.state, run.live_count) == ("running", "active", 1)
    g.finish()
    run.end(2.0)
    assert (run.state, run.ended_at, g.state, run.live_count, run.ended.triggered) == ("ended", 2.0, "finished", 0,
                                                                                       False)
    refused = run_of(env, "r")
    refused.refuse()
    assert (refused.state, refused.ended.triggered) == ("refused", True)
    dropped = gesture(run_of(env, "d"), "h", {0: 1.0, 6: 2.0})
    dropped.drop(1.5)
    assert (dropped.state, dropped.stopped, dropped.live) == ("dropped", 1.5, False)
    assert run_of(env, "p", preplan=True).dormant


# ---------------------------------------------------------------------------------------------- composer
def test_an_appended_block_waits_for_the_open_blocks_but_a_dormant_one():
    env = simpy.Environment()
    a = run_of(env, "a", state=BlockState.RUNNING)
    gesture(a, "g", {0: 1.0, 6: 3.0})
    dormant = run_of(env, "p", preplan=True)
    book, reporter = FakeBook(a, dormant), FakeReporter()
    composer = Composer(env, book, reporter)
    b = run_of(env, "b", composition="APPEND", append_after=("zz",))
    composer.link(b)
    assert b.after == [a] and b.chunk_after == []
    assert reporter.said == [("warn", "b", "NO_SUCH_TARGET", "appendAfter: there is no block 'zz'; ignored", [])]
    assert (composer.predicted_end(a), composer.awaited(b), composer.predicted_start(b)) == (3.0, 3.0, 3.0)
    assert composer.appended(b) and not composer.appended(dormant)
    waiting = composer.waits(b)
    assert waiting == [a.ended, b.wake] and not b.wake.triggered
    a.end(3.0)
    a.ended.succeed()
    env.run(until=3.0)
    assert composer.waits(b) is None and composer.predicted_end(a) == 3.0


def test_a_block_prepended_before_a_pending_one_wakes_it_and_a_circle_is_refused():
    env = simpy.Environment()
    p = run_of(env, "p")
    book, reporter = FakeBook(p), FakeReporter()
    composer = Composer(env, book, reporter)
    wake = composer.wake_event(p)
    assert composer.wake_event(p) is wake  # one event until it is woken
    n = run_of(env, "n", prepend_before=("p",))
    composer.link(n)
    assert p.after == [n] and wake.triggered and composer.wake_event(p) is not wake
    q = run_of(env, "q", prepend_before=("p",), chunk_before=("gone",))
    q.after.append(p)  # q waits for p already: p cannot wait for q
    composer.link(q)
    assert p.after == [n] and reporter.said == [
        ("warn", "q", "IMPOSSIBLE_TO_SCHEDULE", "prependBefore: block 'p' waits for this one already, directly or "
         "not; ignored", []),
        ("warn", "q", "NO_SUCH_TARGET", "chunkBefore: block 'gone' cannot wait for this one (there is no such "
         "block); ignored", [])]


def test_a_chunk_waits_until_the_earlier_one_subsides_and_coarticulates_with_it():
    env = simpy.Environment()
    a = run_of(env, "a", state=BlockState.RUNNING)
    g = gesture(a, "g", {0: 1.0, 6: 3.0})  # relax warped to 2.5
    book, reporter = FakeBook(a), FakeReporter()
    composer = Composer(env, book, reporter)
    b = run_of(env, "b", start=2.75, chunk_after=("a",))
    composer.link(b)
    assert b.chunk_after == [a] and (composer.subsiding_time(a), composer.predicted_start(b)) == (2.5, 2.5)
    right = gesture(b, "g2", {0: 2.75, 6: 4.0})
    left = gesture(b, "g3", {0: 2.75, 6: 4.0}, mode="LEFT_HAND")
    composer.coarticulate(b)
    # g's relax stays where it was (keyed to its start), its end is now g2's start, and the book knows of it
    assert g.keys[5] == KeyRef(g.keys[0].peg, 1.5) and isinstance(g.keys[6].peg, SyncPeg)
    assert g.keys[6].peg.timed is right and (g.tied[6], g.fixed[6], g.owns[6]) == (True, True, False)
    assert (g.time(5), g.end, book.structure_version) == (2.5, 2.75, 1)
    assert left.start == 2.75 and reporter.said == []
    waiting = composer.waits(b)
    assert waiting[1] is b.wake and len(waiting) == 2
    env.run(until=waiting[0])
    assert env.now == 2.5 and composer.waits(b) is None


# ---------------------------------------------------------------------------------------------- retimer
def test_the_retimer_collects_what_moved_until_its_pass_is_due():
    env = simpy.Environment()
    run = run_of(env, "b", state=BlockState.RUNNING)
    peg = TimePeg(1.0)
    near, far = gesture(run, "near", {0: peg, 6: 2.0}), gesture(run, "far", {0: 10.0, 3: peg})
    near.planned_start, far.planned_start = 1.0, 10.0
    book = FakeBook(run)
    retimer = Retimer(env, book, FakeReporter())
    dependants = retimer.dependants_of([peg], planned_now=lambda: 0.0)
    assert dependants.all() == [near, far] and dependants.version == 0
    assert retimer.moved(dependants, horizon=1.5) is True
    assert retimer.moved(dependants, horizon=1.5) is False  # one pass per instant
    assert retimer.due() == ([near], 1.5)
    assert retimer.moved([peg]) is True and retimer.moved(dependants, horizon=1.5) is False
    assert retimer.due() == (None, None)  # every live behaviour
    assert retimer.due() == ([], 1.5)


def test_the_retimer_returns_what_became_invalid_with_the_times_it_computed():
    env = simpy.Environment()
    engine = FakeEngine()
    run = run_of(env, "b", state=BlockState.RUNNING)
    g, h, i, done = (gesture(run, name, {0: 1.0, 6: 3.0}, engine) for name in ("g", "h", "i", "done"))
    engine.planner.reasons = {"h": "sync points would happen out of order", "done": "never asked"}
    engine.planner.unjudged = {"i"}
    done.finish()
    judged = Retimer(env, FakeBook(run), FakeReporter()).retime([g, h, i, done])
    assert judged.invalid == [(h, "sync points would happen out of order")]
    assert judged.times == {g: [1.0, 1.5, 1.75, 2.0, 2.25, 2.5, 3.0], h: [1.0, 1.5, 1.75, 2.0, 2.25, 2.5, 3.0],
                            i: None}
    assert (g.state, h.state, engine.removed) == ("planned", "planned", [])  # dropping it is the caller's


def test_predictions_are_sent_when_a_sync_point_moved_beyond_the_tolerance():
    env = simpy.Environment()
    run = run_of(env, "b", state=BlockState.RUNNING)
    end = TimePeg(3.0)
    g = gesture(run, "g", {0: 1.0, 6: end}, lexeme="BEAT")
    reporter = FakeReporter()
    retimer = Retimer(env, FakeBook(run), reporter, prediction_tolerance=0.1)
    retimer.predict(run, force=True)
    syncs = dict(zip(g.sync_ids, [1.0, 1.5, 1.75, 2.0, 2.25, 2.5, 3.0]))
    assert reporter.said == [("prediction", "b", 0.0, 3.0, [{"id": "g", "type": "gesture", "globalStart": 1.0,
                                                             "globalEnd": 3.0, "syncs": syncs, "lexeme": "BEAT"}])]
    end.set(3.0625)  # the ready moves by 1/64 s, the end by 1/16: within the tolerance
    retimer.predict(run)
    assert len(reporter.said) == 1
    end.set(4.0)  # within 1.6 s, only the ready is due: it moved by 0.25 s
    retimer.predict_moved([g], until=1.6, timed_now={})
    assert reporter.said[1:] == [("prediction", "b", 0.0, 3.0, [{"id": "g", "type": "gesture", "globalStart": 1.0,
                                                                 "globalEnd": 3.0,
                                                                 "syncs": {"start": 1.0, "ready": 1.75}}])]
    assert run.predicted["g"] == [1.0, 1.75, 1.75, 2.0, 2.25, 2.5, 3.0]
    retimer.predict(run)  # the rest of it, now
    assert reporter.said[2][3] == 4.0 and reporter.said[2][4][0]["syncs"]["end"] == 4.0
    run.end(4.0)
    retimer.predict(run, force=True)  # an ended block is predicted no more
    assert len(reporter.said) == 3


def test_the_retimer_wakes_the_players_of_what_plays():
    env = simpy.Environment()
    engine = FakeEngine()
    run = run_of(env, "b", state=BlockState.RUNNING)
    g, h = gesture(run, "g", {0: 1.0, 6: 2.0}, engine), gesture(run, "h", {0: 1.0, 6: 2.0}, engine)
    g.activate()
    Retimer.kick([g, h])
    assert engine.plan.kicked == [["g"]]


# ---------------------------------------------------------------------------------------------- interrupter
def interrupter_for(env, *runs):
    book, reporter, woken = FakeBook(*runs), FakeReporter(), []
    return Interrupter(env, PegBoard(), book, reporter, woken.append), book, reporter, woken


def test_a_pending_block_interrupted_whole_starts_and_loses_every_behaviour():
    env = simpy.Environment()
    env.run(until=2.0)
    engine = FakeEngine()
    p = run_of(env, "p")
    g, h = gesture(p, "g", {0: 3.0, 6: 4.0}, engine), gesture(p, "h", {0: 3.0, 6: 4.0}, engine)
    h.behaviour.required = True
    interrupter, book, reporter, woken = interrupter_for(env, p)
    assert interrupter.interrupt(p, by="x") is True
    assert (g.state, g.stopped, h.state, engine.removed, p.gone) == ("dropped", 2.0, "dropped", ["g", "h"], [g, h])
    assert book.drops == [DropRecord("p", "g", 2.0, "INTERRUPTED", "interrupted by x"),
                          DropRecord("p", "h", 2.0, "INTERRUPTED", "interrupted by x")]
    assert reporter.said == [("warn", "p:h", "INTERRUPTED", "h: required, but interrupted by x; behaviour removed "
                              "before it started", ["h"]),
                             ("block", "p", "start", 2.0, False)]
    assert (p.state, p.interrupted, woken) == ("running", True, [p])
    p.end(2.0)
    assert interrupter.interrupt(p) is False and len(reporter.said) == 2


def test_a_started_behaviour_interrupted_keeps_what_its_engine_leaves_of_it():
    env = simpy.Environment()
    env.run(until=2.0)
    engine = FakeEngine(cut=({2, 3, 4, 5}, {6: 2.0}))
    r = run_of(env, "r", state=BlockState.RUNNING)
    g = gesture(r, "g", {0: 1.0, 6: 3.0}, engine)
    other = gesture(r, "k", {0: 1.0, 6: 3.0}, engine)
    g.activate()
    g.passed[:2] = [1.0, 1.5]
    g.next_index = 2
    interrupter, book, reporter, woken = interrupter_for(env, r)
    assert interrupter.interrupt(r, include=("g",), by="y") is True
    assert (g.state, g.interrupted, g.stopped, g.skipped, g.next_index) == ("active", True, 2.0, {2, 3, 4, 5}, 6)
    assert g.keys[6].peg.name == "r:g:end:cut" and g.end == 2.0 and g.keys[0].peg.time == 1.0
    assert (engine.stops, engine.plan.kicked, engine.removed) == ([("g", 2.0)], [["g"]], [])
    assert book.drops == [DropRecord("r", "g", 2.0, "INTERRUPTED", "interrupted by y")]
    assert (r.interrupted, other.state, reporter.said, woken) == (True, "planned", [], [])


def test_what_hangs_from_a_removed_behaviour_goes_with_it_and_another_block_is_told():
    env = simpy.Environment()
    a, b = run_of(env, "a", state=BlockState.RUNNING), run_of(env, "b", state=BlockState.RUNNING)
    shared = TimePeg(3.0, name="a:g:end")
    g = gesture(a, "g", {0: 1.0, 6: shared})
    g.owns[6] = True  # its end gives the peg its time
    h = gesture(b, "h", {0: shared, 6: 4.0})
    free = gesture(b, "free", {0: 3.0, 6: 4.0})
    interrupter, book, reporter, woken = interrupter_for(env, a, b)
    assert interrupter.interrupt(a, by="x") is True
    assert (g.state, h.state, free.state, b.gone, b.interrupted) == ("dropped", "dropped", "planned", [h], True)
    assert book.drops == [DropRecord("a", "g", 0.0, "INTERRUPTED", "interrupted by x"),
                          DropRecord("b", "h", 0.0, "INTERRUPTED", "interrupted by x: it was tied to a:g")]
    assert reporter.said == [("warn", "b:h", "INTERRUPTED", "h: interrupted by x: it was tied to a:g; behaviour "
                              "removed before it started", ["h"])]


@pytest.mark.parametrize("part", [Composer, Retimer, Interrupter])
def test_no_part_is_handed_the_scheduler(part):
    import inspect
    assert "scheduler" not in inspect.signature(part).parameters
