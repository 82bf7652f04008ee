"""The BMLA/BMLT examples ``docs/howto/bmla.md`` points to, realized in the pairings it gives: each does what its
comment says, with no warning."""

from __future__ import annotations

from pathlib import Path

import pytest
import soundfile

from agentsim.realizer import Realizer

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "bmla"


def realize(*files: str, at: tuple[float, ...] = ()) -> dict[str, float]:
    """Sync and block times (global) of the files submitted at the given times (default all at 0)."""
    realizer = Realizer()
    for i, name in enumerate(files):
        path = EXAMPLES / name
        realizer.submit_at(at[i] if at else 0.0, path.read_bytes(), source=str(path))
    realizer.run()
    # nothing is warned about: an interruption asked for says what it cut in the feedback's status
    assert realizer.feedback.warnings() == []
    times = {f["id"]: f["globalTime"] for f in realizer.feedback.items
             if f["type"] in ("syncPointProgress", "blockProgress")}
    return times


@pytest.fixture(scope="module")
def talk() -> dict[str, float]:
    return realize("talk.xml")


def test_barging_in_stops_the_speech_and_answers_at_once():
    times = realize("talk.xml", "barge_in.xml", at=(0, 2.5))
    assert times["talk:s1:end"] == times["reply:answer:start"] == times["reply:start"] == 2.5
    assert "talk:s1:w2" not in times and "talk:g3:start" not in times
    # the beat on its way retracts from where it is; the block ends when it is back
    assert times["talk:g2:start"] < 2.5 == times["talk:g2:relax"] < times["talk:end"] == times["talk:g2:end"]


def test_an_interrupting_block_starts_when_its_target_has_ended():
    times = realize("talk.xml", "interrupt_block.xml", at=(0, 2))
    assert times["talk:end"] == times["instead:start"] == 2.0
    assert times["instead:no:start"] == times["instead:shake:end"]


def test_excluded_behaviours_go_on_after_an_interrupt(talk):
    times = realize("talk.xml", "keep_talking.xml")
    assert times["quiet:still:start"] == 1.5
    assert times["talk:s1:end"] == talk["talk:s1:end"] and times["talk:s1:w4"] == talk["talk:s1:w4"]
    assert times["talk:g1:end"] == talk["talk:g1:end"] < 1.5  # over before the interrupt
    assert not {"talk:g2:start", "talk:g3:start", "talk:g4:start", "talk:n1:start"} & set(times)


def test_a_preplanned_block_waits_for_its_activation():
    on_start = realize("preplanned.xml", "on_start.xml", at=(0, 1))
    assert on_start["ready:start"] == on_start["both:start"] == 1.0
    activated = realize("preplanned.xml", "activate.xml")
    assert activated["ready:start"] == activated["go:nod:end"] > 0
    assert activated["ready:g1:stroke"] == activated["ready:s1:end"]


def test_a_chunk_starts_when_the_chunk_before_it_subsides(talk):
    times = realize("talk.xml", "second_chunk.xml")
    subsides = max(t for k, t in talk.items() if k.endswith((":relax", "s1:end")))
    assert times["more:start"] == pytest.approx(subsides, abs=1e-9)
    assert times["more:g1:stroke"] == times["more:s1:w0"]


def test_append_after_waits_for_the_named_block_only(talk):
    times = realize("talk.xml", "append_after.xml")
    assert times["after:start"] == times["talk:end"] == talk["talk:end"]


def test_parameter_changes_leave_the_timing_alone(talk):
    times = realize("talk.xml", "softer.xml")
    assert {k: v for k, v in times.items() if k.startswith("talk:")} == talk
    assert times["softer:fade:end"] == 2.0


def test_a_sound_file_plays_for_its_length():
    times = realize("applause.xml")
    length = soundfile.info(str(EXAMPLES / "audio" / "applause.wav")).duration
    assert times["applause:clap:end"] == pytest.approx(length, abs=1e-6)
    assert times["applause:n1:start"] == times["applause:clap:end"]


def test_a_transition_fills_the_gap_between_two_motions():
    times = realize("transition.xml")
    assert times["settle:t1:start"] == times["settle:turn:end"]
    assert times["settle:t1:end"] == times["settle:nod1:start"] == 2.0
