"""A running plan re-times when an anticipator moves its pegs: exact peg and feedback times."""

from __future__ import annotations

import pytest

from agentsim.realizer import Realizer
from anticipators.metronome import Metronome

BEATS = """<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="bml1">
  <gesture id="g2" lexeme="BEAT" stroke="anticipators:metronome:beat2"/>
  <gesture id="g3" lexeme="BEAT" stroke="anticipators:metronome:beat3"/>
  <gesture id="g4" lexeme="BEAT" stroke="anticipators:metronome:beat4" end="anticipators:metronome:beat5"/>
  <speech id="speech1" start="anticipators:metronome:beat6"><text>And now we speak.</text></speech>
  <head id="nod1" lexeme="NOD" stroke="speech1:end"/>
</bml>"""


def run_with_tempo_change(at: float | None, bpm: float = 60.0, doc: str = BEATS):
    metronome = Metronome("metronome", bpm=120)  # beat n at (n - 1) * 0.5 s
    realizer = Realizer(anticipators=[metronome])
    realizer.submit(doc)
    if at is not None:
        def change():
            yield realizer.env.timeout(at)
            metronome.set_tempo(bpm)
        realizer.env.process(change())
    realizer.run()
    return realizer, metronome


def glob(realizer):
    return realizer.feedback.sync_times()


def test_metronome_pegs_respace_from_the_change_on():
    m = Metronome("m", bpm=120)
    pegs = [m.peg(f"beat{n}") for n in range(1, 6)]
    assert [p.time for p in pegs] == [0.0, 0.5, 1.0, 1.5, 2.0]
    # At 0.8 s, 60 % of the beat after beat2 (0.5 s) has gone: the rest, 40 % of the new 1 s period,
    # brings beat3 to 1.2 s.
    m.set_tempo(60, at=0.8)
    assert [p.time for p in pegs] == pytest.approx([0.0, 0.5, 1.2, 2.2, 3.2], abs=1e-12)
    m.set_phase(1.75, at=0.8)  # the next beat moves; those after it follow at the tempo
    assert [p.time for p in pegs] == [0.0, 0.5, 1.75, 2.75, 3.75]
    assert m.peg("beat0") is None and m.peg("downbeat") is None
    with pytest.raises(ValueError):
        m.set_tempo(0)


def test_plan_without_change_follows_the_metronome():
    realizer, _ = run_with_tempo_change(None)
    t = glob(realizer)
    assert (t["bml1:g2:stroke"], t["bml1:g3:stroke"], t["bml1:g4:stroke"], t["bml1:g4:end"]) == (0.5, 1.0, 1.5, 2.0)
    assert t["bml1:speech1:start"] == 2.5
    assert t["bml1:nod1:stroke"] == t["bml1:speech1:end"]


def test_tempo_change_retimes_everything_tied_to_the_moved_pegs():
    realizer, _ = run_with_tempo_change(0.8)
    t = glob(realizer)
    # Before the change: as planned.
    assert t["bml1:g2:stroke"] == 0.5
    # g3 started at 0.55 (0.45 s before its planned stroke); its stroke follows beat3 to 1.2.
    assert t["bml1:g3:start"] == pytest.approx(0.55, abs=1e-12)
    assert t["bml1:g3:stroke"] == pytest.approx(1.2, abs=1e-12)
    # g4 is stretched between beat4 and beat5, which moved to 2.2 and 3.2.
    assert (t["bml1:g4:stroke"], t["bml1:g4:end"]) == pytest.approx((2.2, 3.2), abs=1e-12)
    # Speech follows beat6 rigidly, and the nod tied to the speech end follows the speech.
    assert t["bml1:speech1:start"] == pytest.approx(4.2, abs=1e-12)
    assert t["bml1:nod1:stroke"] == t["bml1:speech1:end"]
    feedback = realizer.feedback
    predictions = feedback.of_type("predictionFeedback")
    assert [p["globalTime"] for p in predictions] == [0.0, 0.8]
    after = {b["id"]: b for b in predictions[1]["behaviours"]}
    assert after["g4"]["syncs"]["stroke"] == t["bml1:g4:stroke"]
    assert after["speech1"]["globalStart"] == t["bml1:speech1:start"]
    # Every sync point fed back at the time the last prediction gave it.
    for beh in after.values():
        for sync, time in beh["syncs"].items():
            if f"bml1:{beh['id']}:{sync}" in t and beh["id"] != "g3":
                assert t[f"bml1:{beh['id']}:{sync}"] == pytest.approx(time, abs=1e-12)
    assert not feedback.warnings()


def test_ready_of_a_started_gesture_is_warped_between_its_passed_start_and_the_moved_stroke():
    realizer, _ = run_with_tempo_change(0.8)
    t = glob(realizer)
    # BEAT preferred keys: start 0, ready 0.30, stroke 0.45 -> ready at 2/3 of start..stroke.
    assert t["bml1:g3:ready"] == pytest.approx(0.55 + (1.2 - 0.55) * 0.30 / 0.45, abs=1e-12)


def test_behaviour_made_invalid_by_the_change_is_dropped_with_a_warning():
    doc = BEATS.replace('<gesture id="g3" lexeme="BEAT" stroke="anticipators:metronome:beat3"/>',
                        '<gesture id="g3" lexeme="BEAT" start="anticipators:metronome:beat3" '
                        'end="anticipators:metronome:beat4"/>')
    realizer, _ = run_with_tempo_change(0.8, bpm=6000.0, doc=doc)  # beats 0.01 s apart: too short a beat
    warnings = realizer.feedback.warnings()
    assert [w["modifiedBehaviours"] for w in warnings] == [["g3"]]
    assert warnings[0]["globalTime"] == 0.8 and "shorter" in warnings[0]["description"]
    t = glob(realizer)
    assert "bml1:g3:start" not in t
    # beat3 at 0.8 + 0.4 * 0.01 s, beat4 one period later.
    assert t["bml1:g4:stroke"] == pytest.approx(0.814, abs=1e-12)
    ends = [f for f in realizer.feedback.items if f["id"] == "bml1:end"]
    assert len(ends) == 1


def test_same_run_twice_gives_identical_feedback():
    a, _ = run_with_tempo_change(0.8)
    b, _ = run_with_tempo_change(0.8)
    assert a.feedback.items == b.feedback.items
