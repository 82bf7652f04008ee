"""Engines: motion units with phases and keys, time warping, and real-time mode of the clock."""

from __future__ import annotations

import time

import pytest

from agentsim.animation.units import BEAT, NOD, motion_state
from agentsim.core.clock import make_environment
from agentsim.core.engine import stretch_times
from agentsim.errors import ScheduleError
from agentsim.realizer import Realizer
from helpers import Result, realize

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def test_stretch_between_constrained_keys_and_average_stretch_outside():
    pref = [0.0, 0.3, 0.32, 0.45, 0.55, 0.65, 0.95]
    # stroke (3) at 2.0 and end (6) at 3.0: the stroke..end span is stretched 2x, and so is the part before.
    times = stretch_times(pref, {3: 2.0, 6: 3.0})
    assert times[0] == pytest.approx(2.0 - 2 * 0.45)
    assert times[4] == pytest.approx(2.0 + 2 * 0.10)
    assert stretch_times(pref, {}, start=1.0)[3] == pytest.approx(1.45)
    with pytest.raises(ScheduleError):
        stretch_times(pref, {0: 2.0, 6: 1.0})


def test_nod_repetitions_lengthen_the_stroke_phase():
    assert NOD.preferred(3)[4] - NOD.preferred(3)[2] == pytest.approx(3 * (NOD.keys[4] - NOD.keys[2]))
    assert NOD.canonical()[0] == 0.0 and NOD.canonical()[-1] == 1.0


def test_motion_state_gives_phase_and_canonical_time():
    r = realize(f'<bml {NS} id="b"><gesture id="g" lexeme="BEAT" start="1" end="2.9"/></bml>')
    timed = r.realizer.scheduler.book.all_runs[0].timed[0]
    alphas = BEAT.canonical()
    assert motion_state(timed, 0.5) is None and motion_state(timed, 3.0) is None
    phase, alpha = motion_state(timed, r.t("g:stroke"))
    assert phase == "stroke" and alpha == pytest.approx(alphas[3])
    phase, alpha = motion_state(timed, 1.0 + 0.5 * (r.t("g:ready") - 1.0))
    assert phase == "preparation" and alpha == pytest.approx(alphas[1] / 2)
    assert motion_state(timed, 2.9) == ("retraction", pytest.approx(1.0))


def test_real_time_mode_gives_the_same_feedback_on_the_wall_clock():
    doc = f'<bml {NS} id="b"><head id="n" lexeme="NOD"/><gesture id="g" lexeme="BEAT" start="n:end"/></bml>'
    simulated = realize(doc)
    realizer = Realizer(env=make_environment(realtime=True, factor=0.2))
    realizer.submit(doc)
    started = time.perf_counter()
    realizer.run()
    wall = time.perf_counter() - started
    assert Result(realizer).items == simulated.items
    end = simulated.blocks[-1]["globalTime"]
    assert wall >= 0.2 * end * 0.95
