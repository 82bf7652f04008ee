"""The scheduler on hand-built blocks: composition, the one re-timing path, predictions and their tolerance,
drops and the recording, with exact times."""

from __future__ import annotations

import pytest
import simpy

from agentsim.bml.parser import parse_ref
from agentsim.core.anticipator import Anticipator
from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block
from agentsim.core.feedback import FeedbackLog
from agentsim.core.pegboard import ComputedPeg, OffsetPeg, PegBoard
from agentsim.core.scheduler import FRAME, Scheduler
from agentsim.core.timed import KeyRef
from agentsim.engines.animation import AnimationEngine
from agentsim.engines.wait import WaitEngine


class Beats(Anticipator):
    """Beats every half second from 1 s: ``beat1`` at 1.0, ``beat2`` at 1.5, ..."""

    def make_peg(self, sync_id):
        if sync_id.startswith("beat"):
            return 0.5 + 0.5 * int(sync_id[4:])
        return False


def behaviour(bid, kind="gesture", **refs):
    return Behaviour(bid, kind, list(BEHAVIOUR_TYPES[kind].syncs), {"lexeme": "BEAT"} if kind == "gesture" else {},
                     {sync: parse_ref(text) for sync, text in refs.items()})


def block(bid, *behaviours, composition="MERGE"):
    return Block(bid, composition=composition, behaviours=list(behaviours))


@pytest.fixture
def world():
    env = simpy.Environment()
    board = PegBoard()
    log = FeedbackLog()
    scheduler = Scheduler.build(env, board, log)
    for engine in (AnimationEngine(scheduler.context), WaitEngine(scheduler.context)):
        scheduler.add_engine(engine)
    beats = Beats("m")
    beats.attach(env, board)
    scheduler.add_anticipator(beats)
    return env, scheduler, log, beats


def predictions(log):
    return [(p["globalTime"], {b["id"]: b["syncs"] for b in p["behaviours"]}) for p in log.of_type("predictionFeedback")]



def at(env, t, action):
    def process():
        yield env.timeout(t - env.now)
        action()
    env.process(process())


def test_a_moved_anticipator_peg_re_times_and_predicts_only_what_moved_by_more_than_a_frame(world):
    env, scheduler, log, beats = world
    scheduler.submit(block("b", behaviour("g1", stroke="anticipators:m:beat2"), behaviour("g2", stroke="3")))
    at(env, 0.2, lambda: beats.move("beat2", 1.51))  # 10 ms: less than a frame
    at(env, 0.4, lambda: beats.move("beat2", 1.55))  # 50 ms from what was predicted
    env.run(until=10)
    said = predictions(log)
    assert [t for t, _ in said] == [0.0, 0.4]
    assert set(said[0][1]) == {"g1", "g2"} and set(said[1][1]) == {"g1"}  # only the behaviour that moved
    assert said[1][1]["g1"]["stroke"] == 1.55 == log.sync_times()["b:g1:stroke"]
    assert said[1][1]["g1"]["start"] == pytest.approx(1.10, abs=1e-12) == log.sync_times()["b:g1:start"]


def test_a_move_that_spoils_a_behaviour_drops_it_with_a_warning_at_that_time(world):
    env, scheduler, log, beats = world
    scheduler.submit(block("b", behaviour("g1", start="anticipators:m:beat2", end="anticipators:m:beat3"),
                           behaviour("g2", stroke="3")))
    at(env, 0.7, lambda: beats.move("beat3", 1.52))  # 20 ms after its start: shorter than a beat's 0.1 s
    env.run(until=10)
    (warning,) = log.warnings()
    assert (warning["id"], warning["globalTime"], warning["modifiedBehaviours"]) == ("b:g1", 0.7, ["g1"])
    assert "after re-timing" in warning["description"] and "shorter" in warning["description"]
    assert not [k for k in log.sync_times() if k.startswith("b:g1:")]
    assert [f["id"] for f in log.of_type("blockProgress")] == ["b:start", "b:end"]
    (drop,) = scheduler.recording().drops
    assert (drop.block, drop.behaviour, drop.time, drop.warning_type) == ("b", "g1", 0.7, "IMPOSSIBLE_TO_SCHEDULE")


def test_append_starts_exactly_when_the_earlier_block_ends_even_after_it_moved(world):
    env, scheduler, log, beats = world
    scheduler.submit(block("b1", behaviour("g1", end="anticipators:m:beat3")))
    scheduler.submit(block("b2", behaviour("w", "wait", start="0", end="0.5"), composition="APPEND"))
    at(env, 0.5, lambda: beats.move("beat3", 2.5))
    env.run(until=10)
    ends = {f["id"]: f["globalTime"] for f in log.of_type("blockProgress")}
    assert ends["b1:end"] == 2.5 == ends["b2:start"] and ends["b2:end"] == 3.0
    b2 = [p for p in log.of_type("predictionFeedback") if p["id"] == "b2"]
    assert [(p["globalTime"], p["bml"]["globalStart"]) for p in b2] == [(0.0, 2.0), (0.5, 2.5)]


def test_replace_cuts_every_earlier_block_now_and_records_the_cut(world):
    env, scheduler, log, _ = world
    scheduler.submit(block("b1", behaviour("g1", start="1"), behaviour("g2", start="5")))
    at(env, 1.2, lambda: scheduler.submit(block("b2", behaviour("g3"), composition="REPLACE")))
    env.run(until=10)
    progress = {f["id"]: f["globalTime"] for f in log.of_type("blockProgress")}
    assert progress == {"b1:start": 0.0, "b1:end": 1.2, "b2:start": 1.2, "b2:end": 2.15}
    recording = scheduler.recording()
    cut = {(d.behaviour, d.time, d.warning_type) for d in recording.drops}
    assert cut == {("g1", 1.2, "INTERRUPTED"), ("g2", 1.2, "INTERRUPTED")}
    g1 = recording.behaviour("b1:g1")
    assert (g1.state, g1.stopped, g1.started, g1.passed[:2]) == ("dropped", 1.2, True, (True, False))
    assert [b.state for b in recording.blocks] == ["ended", "ended"]


class Source(ComputedPeg):
    """A computed peg standing for a position on a moving timeline: its time is ``base[0] + s``."""

    __slots__ = ("base", "s")

    def __init__(self, base, s, board):
        super().__init__(None, name=f"source{s}", cache=board.cache)
        self.base, self.s = base, s

    def compute(self):
        return self.base[0] + self.s


def test_pegs_that_move_often_re_time_only_what_is_within_the_horizon(world):
    env, scheduler, log, _ = world
    run = scheduler.submit(block("b", behaviour("near", stroke="1"), behaviour("far", stroke="20")))
    base = [0.0]
    near, far = ({t.id: t for t in run.timed}[name] for name in ("near", "far"))
    # hang both from a moving timeline (as a speech hangs what is tied to its marks from animator time)
    timeline = Source(base, 0.0, scheduler.board)  # on the board's cache, as a speech's pegs are
    for timed in (near, far):
        peg = OffsetPeg(timeline, 0.0)
        timed.keys = [None if k is None else KeyRef(peg, k.offset) for k in timed.keys]
    scheduler.board.invalidate_times()
    dependants = scheduler.retimer.dependants_of([timeline])
    assert dependants.all() == [near, far]

    def drift():
        for k in range(1, 40):
            yield env.timeout(0.5)
            base[0] = 0.001 * k * k  # the timeline falls behind, faster and faster
            scheduler.pegs_moved(dependants, horizon=3.0)

    env.process(drift())
    env.run(until=30)
    said = predictions(log)
    # far is only looked at again once it is within 3 s: the last prediction before its stroke is within a
    # frame of when it came, and it was never predicted again before it came near
    far_said = [(t, syncs["far"]["stroke"]) for t, syncs in said if "stroke" in syncs.get("far", {})]
    stroke = log.sync_times()["b:far:stroke"]
    assert far_said[0] == (0.0, 20.0) and all(t >= 20.0 - 0.45 - 3.0 for t, _ in far_said[1:])
    assert abs(far_said[-1][1] - stroke) <= FRAME and len(far_said) > 1
    near_said = [(t, syncs["near"]["stroke"]) for t, syncs in said if "stroke" in syncs.get("near", {})]
    assert abs(near_said[-1][1] - log.sync_times()["b:near:stroke"]) <= FRAME


def test_the_recording_holds_actual_times_shared_pegs_and_ties(world):
    env, scheduler, log, beats = world
    scheduler.submit(block("b", behaviour("g1", stroke="anticipators:m:beat2"),
                           behaviour("g2", stroke="g1:stroke"), behaviour("g3", start="4")))
    at(env, 0.3, lambda: beats.move("beat2", 1.8))
    env.run(until=3.0)  # stop before g3 starts
    recording = scheduler.recording()
    g1, g2, g3 = (recording.behaviour(f"b:{n}") for n in ("g1", "g2", "g3"))
    assert g1.time("stroke") == g2.time("stroke") == 1.8 == recording.sync_times()["b:g1:stroke"]
    i = g1.sync_ids.index("stroke")
    assert g1.peg_groups[i] == g2.peg_groups[i] is not None and g3.peg_groups[0] != g1.peg_groups[i]
    assert g2.tied_to == ("b:g1",) and g1.tied_to == ()
    assert (g1.state, g3.state, g3.started) == ("finished", "active", False)
    assert recording.anticipators["m"]["beat2"] == 1.8 and recording.now == 3.0
    seen = recording.until(1.5)
    assert seen.behaviour("b:g1").time("stroke") is None and seen.behaviour("b:g3") is None
    assert all(f["globalTime"] <= 1.5 for f in seen.feedback)


def test_the_first_prediction_says_the_times_the_behaviours_have_once_the_block_is_timed():
    """The solver computes each behaviour's times once while no peg moves and hands them to the first
    prediction: after a constraint moved one behaviour, a cluster was shifted into the block and a gesture's
    preparation was shortened, what is predicted is what the behaviours say then, exactly."""
    from agentsim.realizer import Realizer
    from speech_timing.builtin import BuiltinBackend

    doc = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1">'
           '<gesture id="g1" lexeme="BEAT" stroke="0.2"/><head id="h1" lexeme="NOD"/>'
           '<faceLexeme id="f1" lexeme="RAISE_BROWS"/><head id="h4" lexeme="NOD"/>'
           '<head id="h5" lexeme="NOD" end="h4:start"/>'
           '<speech id="s1" start="h1:end"><text>we walk <sync id="m"/> along the river.</text></speech>'
           '<constraint><after ref="h1:end"><sync ref="f1:start"/></after></constraint></bml>')
    realizer = Realizer(tts=BuiltinBackend())
    run = realizer.submit(doc)
    (prediction,) = realizer.feedback.of_type("predictionFeedback")
    moved = {t.id: t.times() for t in run.timed}
    assert moved["g1"][:1] + moved["g1"][3:4] == [0.0, 0.2]  # its preparation shortened to the block start
    assert moved["f1"][0] == moved["h1"][-1] == 0.55  # moved after the nod
    assert moved["h5"][0] == 0.0 and moved["h4"][0] == 0.55  # the cluster shifted into the block
    assert [(e["id"], list(e["syncs"].values()), e["globalStart"]) for e in prediction["behaviours"]] == [
        (t.id, t.times(), t.planned_start) for t in run.timed]
    assert all(t.planned_start == t.times()[0] for t in run.timed)
