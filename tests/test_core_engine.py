"""Timed behaviours, planners and players on hand-built cases with exact times."""

from __future__ import annotations

import itertools
import math

import pytest
import simpy

from agentsim.core.block import GESTURE_SYNCS, Behaviour, Block
from agentsim.core.engine import Plan, Planner, Player
from agentsim.core.pegboard import OffsetPeg, TimePeg
from agentsim.core.timed import BlockRun, KeyRef, SyncPeg, TimedBehaviour

PREFERRED = [0.0, 0.30, 0.32, 0.45, 0.55, 0.65, 0.95]  # a beat


class FakeEngine:
    """Stands for an engine: only its planner is asked for here."""

    def __init__(self):
        self.planner = Planner()


PLANNED = itertools.count()  # the order in which the tests plan behaviours


def gesture(run, keys, name="g"):
    behaviour = Behaviour(name, "gesture", list(GESTURE_SYNCS))
    return TimedBehaviour(run, behaviour, PREFERRED, keys, FakeEngine(), next(PLANNED))


@pytest.fixture
def run():
    env = simpy.Environment()
    return BlockRun(Block("b"), TimePeg(0.0, name="b:start"), env.event())


def test_untied_keys_are_warped_between_tied_ones_and_passed_times_win(run):
    start, stroke, end = TimePeg(1.0), TimePeg(1.9), TimePeg(2.9)
    keys = [KeyRef(start), None, None, KeyRef(stroke), None, None, KeyRef(end)]
    g = gesture(run, keys)
    times = g.times()
    assert times[0] == 1.0 and times[3] == 1.9 and times[6] == 2.9
    # ready at 0.30 / 0.45 of start..stroke (twice the preferred span), strokeEnd at 0.1 / 0.5 of stroke..end
    assert times[1] == pytest.approx(1.0 + 0.9 * 0.30 / 0.45, abs=1e-12)
    assert times[4] == pytest.approx(1.9 + 1.0 * 0.10 / 0.50, abs=1e-12)
    assert [g.time(i) for i in range(7)] == pytest.approx(times, abs=1e-12)
    g.passed[0] = 1.2  # started late: the passed time replaces the key
    assert g.start == 1.2 and g.times()[1] == pytest.approx(1.2 + 0.7 * 0.30 / 0.45, abs=1e-12)
    stroke.set(math.inf)  # waiting for the world
    assert g.sync_time("end") == 2.9 and g.sync_time("stroke") == math.inf


def test_the_window_lists_the_sync_points_due_by_a_time(run):
    g = gesture(run, [KeyRef(TimePeg(t)) for t in (1.0, 1.3, 1.32, 1.45, 1.55, 1.65, 1.95)])
    g.next_index = 2  # two passed
    indices, times = g.window(1.5)
    assert list(indices) == [2, 3, 4] and times == [1.32, 1.45, 1.55]  # up to the first one due later
    assert list(g.window(10.0)[0]) == [2, 3, 4, 5, 6]


def test_what_a_behaviour_hangs_from_goes_through_offsets_and_other_behaviours(run):
    anchor = TimePeg(0.5, name="anchor")
    other = gesture(run, [KeyRef(OffsetPeg(anchor, 1.0))] + [None] * 5 + [KeyRef(TimePeg(3.0))], "other")
    tied = gesture(run, [None, None, None, KeyRef(OffsetPeg(SyncPeg(other, 0), 0.2)), None, None, None], "tied")
    assert tied.hangs_from({id(anchor)}) and other.hangs_from({id(anchor)})
    assert not tied.hangs_from({id(TimePeg(0.0))})
    anchor.set(1.5)
    assert tied.sync_time("stroke") == pytest.approx(2.7, abs=1e-12)  # 1.5 + 1.0 + 0.2
    with pytest.raises(ValueError):
        SyncPeg(other, 0).set(1.0)


def test_the_planner_judges_timing_after_pegs_moved(run):
    planner = Planner()
    stroke, end = TimePeg(1.45), TimePeg(1.95)
    g = gesture(run, [KeyRef(TimePeg(1.0)), None, None, KeyRef(stroke), None, None, KeyRef(end)])
    planner.add(g)
    assert planner.invalid(g) is None and planner.invalid_behaviours() == []
    stroke.set(2.5)  # after the end
    assert planner.invalid(g) == "sync points would happen out of order"
    assert planner.invalid_behaviours() == [(g, "sync points would happen out of order")]
    stroke.set(math.inf)  # not judged while it waits for the world
    assert planner.invalid(g) is None
    stroke.set(None)  # a key with no time is warped between its neighbours
    assert planner.invalid(g) is None and g.sync_time("stroke") == pytest.approx(1.0 + 0.95 * 0.45 / 0.95)
    end.set(None)  # ... but the last one has none after it
    assert planner.invalid(g) == "a sync point lost its time"
    planner.remove(g)
    assert planner.invalid_behaviours() == [] and g not in planner.plan


def test_the_player_passes_sync_points_at_their_exact_times_in_order_and_follows_moves(run):
    env = run.ended.env
    plan = Plan(env)
    passed = []
    Player(env, plan, lambda timed, i, t: passed.append((timed.id, timed.sync_ids[i], t, env.now)))
    late = TimePeg(2.0)
    a = gesture(run, [KeyRef(TimePeg(t)) for t in (1.0, 1.3, 1.32, 1.45, 1.55, 1.65, 1.95)], "a")
    b = gesture(run, [KeyRef(TimePeg(1.0))] + [None] * 5 + [KeyRef(late)], "b")
    for timed in (a, b):
        plan.behaviours[timed] = None
        timed.activate()
    plan.kick()

    def move():
        yield env.timeout(1.5)
        late.set(1.6)  # b's end moves earlier, before a's end
        plan.kick([b])

    env.process(move())
    env.run(until=5.0)
    assert all(t == now for _, _, t, now in passed)  # each passed at the exact simulated time of its key
    # equal times go in planning order: a before b at 1.0
    assert [(name, sync) for name, sync, t, _ in passed if t == 1.0] == [("a", "start"), ("b", "start")]
    ends = {name: t for name, sync, t, _ in passed if sync == "end"}
    assert ends == {"a": 1.95, "b": 1.6}
    times = [t for _, _, t, _ in passed]
    assert times == sorted(times)
    # a key moved into the past is passed at once, when the player learns of it
    c = gesture(run, [KeyRef(TimePeg(5.5))] + [None] * 5 + [KeyRef(TimePeg(6.0))], "c")
    plan.behaviours[c] = None
    c.activate()
    plan.kick([c])
    env.run(until=5.2)
    c.keys[0] = KeyRef(TimePeg(4.0))
    plan.kick([c])
    env.run(until=5.3)
    assert [(s, t) for name, s, t, _ in passed if name == "c"][0] == ("start", 5.2)
