"""Anticipators: tap tempo, the plugin interface and entry points, BML pegged to them."""

from __future__ import annotations


import pytest

from agentsim.errors import AgentsimError
from agentsim.realizer import Realizer
from anticipators import registry
from anticipators.tap import TapTempo, read_taps

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def taps_run(taps, doc, **kwargs):
    tap = TapTempo("tap", taps=taps, **kwargs)
    realizer = Realizer(anticipators=[tap])
    realizer.submit(doc)
    realizer.run()
    return realizer, tap


def test_tap_tempo_predicts_from_intervals_and_ignores_doubled_and_missed_taps():
    tap = TapTempo("tap", initial_bpm=100)
    pegs = {n: tap.peg(f"beat{n}") for n in (1, 2, 5, 8)}
    assert pegs[5].time == pytest.approx(4 * 0.6)  # before any tap: the initial tempo from 0
    for t in (1.0, 1.5, 2.0, 2.02, 3.0):  # 2.02 doubles the tap at 2.0; 2.5 is missed
        tap.tap(t)
    assert tap.period == pytest.approx(0.5)
    assert tap.beat_times == {1: 1.0, 2: 1.5, 3: 2.0, 5: 3.0}
    assert (pegs[1].time, pegs[2].time, pegs[5].time, pegs[8].time) == pytest.approx((1.0, 1.5, 3.0, 4.5))
    assert 0 < tap.confidence <= 1


def test_bml_pegged_to_taps_is_retimed_as_taps_arrive():
    doc = f'<bml {NS} id="b"><gesture id="g" lexeme="BEAT" stroke="anticipators:tap:beat6"/></bml>'
    # Taps every 0.6 s from 1.0: beat6 is first predicted at 2.5 (120 BPM from 0), then at 1.0 + 5 * 0.6.
    realizer, _ = taps_run([1.0, 1.6, 2.2, 2.8], doc)
    times = realizer.feedback.sync_times()
    assert times["b:g:stroke"] == pytest.approx(4.0, abs=1e-12)
    predictions = [p["behaviours"][0]["syncs"]["stroke"] for p in realizer.feedback.of_type("predictionFeedback")]
    assert predictions[0] == pytest.approx(2.5) and predictions[-1] == pytest.approx(4.0)


def test_tap_file(tmp_path):
    path = tmp_path / "taps.txt"
    path.write_text("# taps\n0.5\n\n1.0 # second\n")
    assert read_taps(path) == [0.5, 1.0]
    path.write_text("0.5\nsoon\n")
    with pytest.raises(ValueError, match="taps.txt:2"):
        read_taps(path)


def test_registry_lists_builtins_and_refuses_unknown_names():
    assert {"metronome", "tap"} <= set(registry.available())
    assert registry.parse_spec("metronome:m2,bpm=90") == ("metronome", "m2", {"bpm": "90"})
    assert registry.create("metronome", "m2", bpm="90").bpm == 90.0  # read as the float it is declared
    with pytest.raises(AgentsimError, match="no anticipator named 'nope'"):
        registry.create("nope")
    with pytest.raises(AgentsimError, match="tempo must be positive"):
        registry.create("metronome", bpm=-1)


def test_keyboard_taps_in_real_time():
    import os
    import threading
    import time

    from agentsim.core.clock import make_environment
    from agentsim.core.pegboard import PegBoard

    read_fd, write_fd = os.pipe()
    tap = TapTempo("tap", initial_bpm=60)
    tap.listen_keyboard(os.fdopen(read_fd))
    env = make_environment(realtime=True)
    tap.attach(env, PegBoard())

    def typist():
        with os.fdopen(write_fd, "w") as keys:
            for _ in range(6):
                time.sleep(0.25)
                keys.write("\n")
                keys.flush()

    thread = threading.Thread(target=typist)
    thread.start()
    env.run(until=1.9)
    thread.join()
    assert tap.last_beat == 6
    assert tap.period == pytest.approx(0.25, abs=0.03)
