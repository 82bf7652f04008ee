"""Re-timing driven by speech progress goes the one way every peg move goes: validity checked, invalid
behaviours dropped with a warning, predictions sent that agree with what is later reported."""

from __future__ import annotations

import math

import pytest

from agentsim.bml.parser import parse_bml
from agentsim.core.scheduler import FRAME
from agentsim.engines.speech import SpeechConfig
from agentsim.realizer import Realizer
from speech_timing.animator_time import make_strategy
from speech_timing.backend import SpeechText
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import DeliveryModel

TEXT = ("The quick <sync id='w2'/>brown fox <sync id='w4'/>jumps over the <sync id='w7'/>lazy dog, "
        "and then <sync id='w10'/>runs home.")


def document(ends: dict[str, float] | None = None) -> str:
    """A speech at 1 s with a beat on four of its words. A gesture named in ``ends`` starts on its word
    instead and ends at the time given (seconds after the block start)."""
    ends = ends or {}
    gestures = "".join(
        f'<gesture id="g{w}" lexeme="BEAT" start="s1:w{w}" end="{ends[f"g{w}"]!r}"/>' if f"g{w}" in ends
        else f'<gesture id="g{w}" lexeme="BEAT" stroke="s1:w{w}"/>'
        for w in (2, 4, 7, 10))
    return (f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b">'
            f'<speech id="s1" start="1"><text>{TEXT}</text></speech>{gestures}</bml>')


def planned_mark(name: str) -> float:
    """Global time at which the plan puts a mark of the speech (it starts at 1 s)."""
    speech = parse_bml(document()).behaviour("s1")
    return 1.0 + BuiltinBackend().synthesize(SpeechText(speech.text, tuple(speech.marks))).mark_time(name)


def realize(delivery: DeliveryModel, seed: int = 0, doc: str | None = None, strategy: str = "best") -> Realizer:
    realizer = Realizer(tts=BuiltinBackend(), speech=SpeechConfig(strategy, delivery, seed=seed))
    realizer.submit(doc or document())
    realizer.run()
    return realizer


def test_speech_start_moves_every_tied_stroke_by_the_latency_and_says_so_at_once():
    realizer = realize(DeliveryModel(latency=0.08))
    predictions = realizer.feedback.of_type("predictionFeedback")
    assert [p["globalTime"] for p in predictions][:2] == [0.0, 1.0]
    first, at_start = ({b["id"]: b for b in p["behaviours"]} for p in predictions[:2])
    for w in (2, 4, 7, 10):
        assert first[f"g{w}"]["syncs"]["stroke"] == pytest.approx(planned_mark(f"w{w}"), abs=1e-12)
        # the strategy now expects the audio 80 ms after the request: so does every stroke tied to it
        assert at_start[f"g{w}"]["syncs"]["stroke"] == pytest.approx(planned_mark(f"w{w}") + 0.08, abs=1e-12)
    # no event ever arrives late or early here, so nothing moves again and the strokes come as predicted
    strokes = realizer.feedback.sync_times()
    for w in (2, 4, 7, 10):
        assert strokes[f"b:g{w}:stroke"] == pytest.approx(planned_mark(f"w{w}") + 0.08, abs=1e-9)
    assert not realizer.feedback.warnings()


@pytest.mark.parametrize("strategy", ["best", "chang-smooth", "skip-70ms"])
def test_the_last_prediction_before_each_stroke_is_within_a_frame_of_it(strategy):
    delivery = DeliveryModel(latency=0.08, start_jitter=0.2, drift_ppm=500.0, delay=0.05, jitter=0.03,
                             burst_probability=0.05, burst_hold=0.2)
    realizer = realize(delivery, seed=3, strategy=strategy)
    strokes = realizer.feedback.sync_times()
    predictions = realizer.feedback.of_type("predictionFeedback")
    assert len(predictions) > 2  # corrections were sent after the speech started, not only the plan
    moved = 0
    for w in (2, 4, 7, 10):
        stroke = strokes[f"b:g{w}:stroke"]
        said = [(p["globalTime"], b["syncs"]["stroke"]) for p in predictions for b in p["behaviours"]
                if b["id"] == f"g{w}" and p["globalTime"] <= stroke]
        assert abs(said[-1][1] - stroke) <= FRAME + 1e-9, (w, said[-1], stroke)
        moved += abs(said[0][1] - stroke) > FRAME
    assert moved  # the unknown latency really moved strokes, so the check above had work to do


def test_a_gesture_squeezed_below_its_shortest_at_speech_start_is_dropped_with_a_warning_then():
    # g7 starts on its word and must end 0.2 s after the word was planned; a known latency of 0.15 s
    # moves its start, leaving it 0.05 s, less than a beat's shortest (0.1 s).
    end = planned_mark("w7") + 0.2
    realizer = realize(DeliveryModel(latency=0.15), doc=document({"g7": end}))
    warnings = realizer.feedback.warnings()
    assert [(w["id"], w["globalTime"], w["warningType"]) for w in warnings] == [("b:g7", 1.0, "IMPOSSIBLE_TO_SCHEDULE")]
    assert "after re-timing" in warnings[0]["description"] and "shorter" in warnings[0]["description"]
    passed = realizer.feedback.sync_times()
    assert not [k for k in passed if k.startswith("b:g7:")]
    assert {f"b:g{w}:stroke" for w in (2, 4, 10)} <= set(passed)
    assert [f["id"] for f in realizer.feedback.items if f["type"] == "blockProgress"] == ["b:start", "b:end"]


def test_a_gesture_squeezed_by_a_progress_event_is_dropped_when_that_event_arrives():
    # No known latency, but an unknown one of up to 0.1 s: only the events reveal that the speech is late.
    # g10 starts on its word and must end 0.13 s after the word was planned, so 30 ms of lateness
    # leaves it less than a beat's shortest (0.1 s).
    delivery = DeliveryModel(latency=0.0, start_jitter=0.1, delay=0.02)
    end = planned_mark("w10") + 0.13
    realizer = realize(delivery, seed=1, doc=document({"g10": end}))
    playback = realizer.speech.playbacks[0]
    assert playback.t0 - playback.t_request > 0.03  # the speech is heard late enough to matter
    # When does the strategy itself first put w10 less than a beat's shortest (0.1 s) before g10's end?
    # Replay the same events into a fresh strategy.
    replay = make_strategy("best")
    replay.reset(playback.plan, playback.t_request)
    s = playback.timed.preferred[playback.timed.sync_ids.index("w10")]
    expected = None
    for event in playback.delivered:
        replay.on_event(event, event.arrival_time)
        if replay.crossing(s, event.arrival_time) > end - 0.1 + 1e-9:
            expected = event.arrival_time
            break
    assert expected is not None and math.isfinite(expected)
    warnings = realizer.feedback.warnings()
    assert [(w["id"], w["globalTime"]) for w in warnings] == [("b:g10", expected)]
    assert "b:g10:stroke" not in realizer.feedback.sync_times()
    assert "b:g7:stroke" in realizer.feedback.sync_times()
