"""Barging in: a long speech with a beat on every content word interrupted mid-sentence, while a gesture is
on its way, and another block speaking at once; with the realizer's own API and with BMLA documents."""

from __future__ import annotations

import pytest

from agentsim.engines.speech import SpeechConfig
from agentsim.realizer import Realizer
from scenarios.speech_sync import beats_on_content_words
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import CONDITIONS
from speech_timing.linear_model import TEXTS_DIR

TEXT = (TEXTS_DIR / "orchard.txt").read_text()[:900]
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'
REPLY = (f'<bml {NS} id="reply"><bmla:interrupt id="stop" target="sync"/>'
         '<speech id="answer" start="stop:start"><text>Sorry, go on.</text></speech></bml>')
BEAT_RETRACTION = 0.95 - 0.65  # relax to end of a beat


def talk(config: SpeechConfig | None = None) -> tuple[Realizer, list[int]]:
    bml, targets = beats_on_content_words(TEXT)
    realizer = Realizer(tts=BuiltinBackend(), speech=config)
    realizer.submit(bml)
    return realizer, targets


def a_moment_inside_a_gesture(realizer: Realizer, targets: list[int]) -> tuple[float, int]:
    """A time halfway through the preparation of a beat in the middle of the speech that has its hand to
    itself (the beat before it ends before it starts), from the plan."""
    first = realizer.feedback.of_type("predictionFeedback")[0]
    planned = {b["id"]: b["syncs"] for b in first["behaviours"]}
    middle = len(targets) // 2
    k = next(targets[i] for i in range(middle, len(targets))
             if planned[f"g{targets[i - 1]}"]["end"] < planned[f"g{targets[i]}"]["start"])
    syncs = planned[f"g{k}"]
    return (syncs["start"] + syncs["ready"]) / 2, k


def interrupted_ids(realizer) -> set[str]:
    """The behaviours an interruption cut (their last syncPointProgress says ``"status": "INTERRUPTED"``) or
    removed (``{"status": "removed"}`` in a prediction); an interruption asked for is no warning."""
    assert realizer.feedback.warnings() == []
    items = realizer.feedback.items
    cut = {f["id"].rsplit(":", 1)[0] for f in items
           if f["type"] == "syncPointProgress" and f.get("status") == "INTERRUPTED"}
    removed = {f"{f['id']}:{b['id']}" for f in items if f["type"] == "predictionFeedback"
               for b in f["behaviours"] if b.get("status") == "removed"}
    assert not cut & removed
    return cut | removed


@pytest.mark.parametrize("config", [None, SpeechConfig("best", CONDITIONS["A"], seed=1)],
                         ids=["as planned", "animator time"])
@pytest.mark.parametrize("how", ["api", "bmla"])
def test_a_long_speech_interrupted_mid_sentence(config, how):
    realizer, targets = talk(config)
    t, k = a_moment_inside_a_gesture(realizer, targets)

    def barge_in():
        yield realizer.env.timeout(t)
        if how == "api":
            assert realizer.interrupt("sync")
        else:
            realizer.submit(REPLY)

    realizer.env.process(barge_in())
    realizer.run()
    items = realizer.feedback.items
    syncs = realizer.feedback.sync_times()
    # the speech ends at the interrupt; of the gestures under way, those before their relax relax now and
    # retract, those retracting go on; nothing else of the block is fed back after the interrupt
    assert syncs["sync:speech1:end"] == t
    started = [j for j in targets if syncs.get(f"sync:g{j}:start", t + 1) < t < syncs[f"sync:g{j}:end"]]
    relaxed_now = [j for j in started if syncs[f"sync:g{j}:relax"] == t]
    assert k in relaxed_now and f"sync:g{k}:stroke" not in syncs  # it never got to its stroke
    for j in started:
        relax, end = syncs[f"sync:g{j}:relax"], syncs[f"sync:g{j}:end"]
        assert relax <= t and end == pytest.approx(relax + BEAT_RETRACTION, abs=1e-9)
    after = {f["id"] for f in items if f["type"] == "syncPointProgress" and f["id"].startswith("sync:")
             and f["globalTime"] > t}
    assert after == {f"sync:g{j}:end" for j in started}
    marks = [f["id"] for f in items if f["id"].startswith("sync:speech1:w") and f["globalTime"] <= t]
    assert marks and not [m for m in syncs if m.startswith("sync:speech1:w") and syncs[m] > t]
    blocks = {f["id"]: f["globalTime"] for f in items if f["type"] == "blockProgress"}
    assert blocks["sync:end"] == max(syncs[e] for e in after)
    # the later gestures never start; the prediction says they are gone
    later = [j for j in targets if f"sync:g{j}:start" not in syncs]
    assert later and not [s for s in syncs if any(s.startswith(f"sync:g{j}:") for j in later)]
    gone = {b["id"] for f in items if f["type"] == "predictionFeedback" for b in f["behaviours"]
            if b.get("status") == "removed"}
    assert gone == {f"g{j}" for j in later} and min(later) > max(started)
    # every behaviour cut or removed is said so in the feedback, with no warning: it was asked for; the
    # block's end says it was interrupted
    cut = interrupted_ids(realizer)
    assert [f["id"] for f in items if f["type"] == "blockProgress" and f.get("status")] == ["sync:end"]
    assert {"sync:speech1", f"sync:g{k}"} | {f"sync:g{j}" for j in later} <= cut
    assert cut <= {"sync:speech1"} | {f"sync:g{j}" for j in started + later}
    # no peg of the board points into what was removed
    assert all(realizer.board.find_sync("sync", f"g{j}", "stroke") is None for j in later)
    recording = realizer.recording()
    assert recording.speech[0].stopped == t
    assert recording.behaviour(f"sync:g{k}").interrupted
    assert recording.behaviour(f"sync:g{later[0]}").state == "dropped"
    if how == "bmla":  # the reply speaks at once
        assert syncs["reply:answer:start"] == t == blocks["reply:start"]


def test_a_block_that_interrupts_starts_when_the_interrupted_one_has_ended():
    realizer, targets = talk()
    t, k = a_moment_inside_a_gesture(realizer, targets)
    realizer.submit_at(t, f'<bml {NS} id="next" bmla:interrupt="sync"><head id="n" lexeme="NOD"/></bml>')
    realizer.run()
    blocks = {f["id"]: f["globalTime"] for f in realizer.feedback.items if f["type"] == "blockProgress"}
    assert blocks["next:start"] == blocks["sync:end"] >= realizer.feedback.sync_times()[f"sync:g{k}:end"]
    assert realizer.feedback.sync_times()[f"sync:g{k}:end"] == pytest.approx(t + BEAT_RETRACTION, abs=1e-12)


def test_interrupting_only_some_behaviours_leaves_the_rest_playing():
    realizer, targets = talk()
    t, k = a_moment_inside_a_gesture(realizer, targets)
    realizer.env.process((lambda: (yield realizer.env.timeout(t)) or realizer.interrupt(
        "sync", exclude=["speech1"]))())
    realizer.run()
    syncs = realizer.feedback.sync_times()
    speech_end = syncs["sync:speech1:end"]
    assert speech_end > t + 1.0  # the speech goes on
    assert syncs[f"sync:g{k}:relax"] == t
    assert not [s for s in syncs if s.startswith("sync:g") and syncs[s] > t + BEAT_RETRACTION + 1e-9]
    cut = interrupted_ids(realizer)
    assert f"sync:g{k}" in cut and "sync:speech1" not in cut


def test_bad_targets_are_reported_and_the_rest_runs():
    realizer = Realizer()
    assert not realizer.interrupt("nobody") and not realizer.activate("nobody")
    realizer.submit(f'<bml {NS} id="b1" bmla:chunkAfter="ghost" bmla:onStart="ghost2">'
                    '<bmla:interrupt id="i" target="ghost3"/><bmla:activate id="a" target="ghost4"/>'
                    '<bmla:parametervaluechange id="p" target="g" paramId="volume">'
                    '<bmla:trajectory type="linear" initialValue="0" targetValue="1"/></bmla:parametervaluechange>'
                    '<bmla:parametervaluechange id="q" target="nobody" paramId="volume">'
                    '<bmla:trajectory type="instant" targetValue="1"/></bmla:parametervaluechange>'
                    '<gesture id="g" lexeme="BEAT"/></bml>')
    realizer.run()
    warnings = [(w["id"], w["warningType"]) for w in realizer.feedback.warnings()]
    assert ("nobody", "NO_SUCH_TARGET") in warnings and warnings.count(("nobody", "NO_SUCH_TARGET")) == 2
    assert ("b1", "NO_SUCH_TARGET") in warnings  # chunkAfter ghost, onStart ghost2
    for behaviour in ("i", "a", "p", "q"):
        assert (f"b1:{behaviour}", "NO_SUCH_TARGET") in warnings, behaviour
    described = " ".join(w["description"] for w in realizer.feedback.warnings())
    assert "ghost3" in described and "ghost4" in described and "has no parameter 'volume'" in described
    assert "b1:g:end" in realizer.feedback.sync_times()  # the gesture played


def test_the_interrupted_gesture_hands_its_arm_back_when_its_retraction_is_done():
    from agentsim.animation import evaluate_poses

    realizer, targets = talk()
    t, k = a_moment_inside_a_gesture(realizer, targets)
    realizer.env.process((lambda: (yield realizer.env.timeout(t)) or realizer.interrupt("sync"))())
    realizer.run()
    stream = evaluate_poses(realizer, fps=100)
    name = f"sync:g{k}"
    frame = lambda time: int(round(time * stream.fps))  # noqa: E731
    assert stream.writer(frame(t - 0.02), "r_shoulder.pitch") == name  # preparing when interrupted
    end = realizer.feedback.sync_times()[f"{name}:end"]
    after = [stream.writer(frame(end) + i, "r_shoulder.pitch") for i in range(1, 30)]
    assert name not in after  # handed back once its retraction is done
    unit = stream.unit(f"g{k}", "sync")
    assert unit["keys"]["relax"] == t and unit["keys"]["stroke"] == t  # the skipped stroke has no time of its own


def test_a_parameter_change_scales_the_gesture_it_targets():
    from agentsim.animation import evaluate_poses

    def travel(amplitude: str | None) -> float:
        change = ("" if amplitude is None else
                  f'<bmla:parametervaluechange id="p" target="g" paramId="amplitude" start="0" end="0.1">'
                  f'<bmla:trajectory type="instant" targetValue="{amplitude}"/></bmla:parametervaluechange>')
        realizer = Realizer()
        realizer.submit(f'<bml {NS} id="b"><gesture id="g" lexeme="BEAT" stroke="2"/>{change}</bml>')
        realizer.run()
        assert not realizer.feedback.warnings()
        syncs = realizer.feedback.sync_times()
        stream = evaluate_poses(realizer, fps=200)
        height = stream.position("r_wrist")[:, 1]
        at = lambda time: height[int(round(time * stream.fps))]  # noqa: E731
        return at(syncs["b:g:ready"]) - at(syncs["b:g:stroke"])

    normal, half = travel(None), travel("0.5")
    assert normal > 0.02 and half == pytest.approx(0.5 * normal, rel=0.15)


def test_circles_and_unreadable_sounds_are_reported(tmp_path):
    realizer = Realizer()
    realizer.submit(f'<bml {NS} id="a"><wait id="w" start="0" end="2"/></bml>')
    realizer.submit(f'<bml {NS} id="b" composition="APPEND-AFTER(a)"><wait id="w" start="0" end="1"/></bml>')
    # c waits for b, and asks b to wait for it: a circle
    realizer.submit(f'<bml {NS} id="c" bmla:appendAfter="b" bmla:prependBefore="b"><wait id="w" end="1"/></bml>')
    not_audio = tmp_path / "noise.wav"
    not_audio.write_text("this is not a sound")
    realizer.submit(f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmlt="http://hmi.ewi.utwente.nl/bmlt" '
                    f'id="d"><bmlt:audiofile id="s" fileName="{not_audio}"/><head id="n" lexeme="NOD"/></bml>')
    realizer.run()
    warnings = {w["id"]: w["description"] for w in realizer.feedback.warnings()}
    assert "waits for this one already" in warnings["c"]
    assert "not a sound file" in warnings["d:s"]
    blocks = {f["id"]: f["globalTime"] for f in realizer.feedback.items if f["type"] == "blockProgress"}
    assert blocks["b:start"] == blocks["a:end"] == 2.0 and blocks["c:start"] == blocks["b:end"] == 3.0
    assert "d:n:end" in realizer.feedback.sync_times()


def test_a_rate_change_before_the_speech_makes_it_faster():
    def spoken(rate: str | None) -> dict[str, float]:
        change = ("" if rate is None else
                  f'<bmla:parametervaluechange id="p" target="s" paramId="rate" start="0" end="0.5">'
                  f'<bmla:trajectory type="instant" targetValue="{rate}"/></bmla:parametervaluechange>')
        realizer = Realizer(tts=BuiltinBackend())  # its rate applies exactly
        realizer.submit(f'<bml {NS} id="b"><speech id="s" start="1"><text>one two <sync id="m"/>three four'
                        f'</text></speech><gesture id="g" lexeme="BEAT" stroke="s:m"/>{change}</bml>')
        realizer.run()
        assert not realizer.feedback.warnings()
        return realizer.feedback.sync_times()

    normal, fast = spoken(None), spoken("2")
    for sync in ("b:s:m", "b:s:end"):
        assert fast[sync] - 1.0 == pytest.approx((normal[sync] - 1.0) / 2, abs=1e-9)
    assert fast["b:g:stroke"] == fast["b:s:m"]  # what is tied to the speech follows the new timeline


def test_blocks_to_interrupt_and_activate_are_looked_up_when_the_block_starts():
    realizer = Realizer()
    # "late" starts when "first" ends; it names a preplanned block and a block to interrupt that are
    # submitted after it, before it starts
    realizer.submit(f'<bml {NS} id="first"><wait id="w" start="0" end="1"/></bml>')
    realizer.submit(f'<bml {NS} id="late" bmla:appendAfter="first" bmla:onStart="ready" bmla:interrupt="talk ghost">'
                    '<wait id="w" start="0" end="0.5"/></bml>')
    realizer.submit_at(0.2, f'<bml {NS} id="ready" bmla:preplan="true"><head id="n" lexeme="NOD"/></bml>')
    realizer.submit_at(0.5, f'<bml {NS} id="talk"><speech id="s"><text>On and on and on and on.</text></speech></bml>')
    realizer.submit_at(0.6, f'<bml {NS} id="x" bmla:appendAfter="late" bmla:onStart="ready">'
                            '<head id="n" lexeme="NOD"/></bml>')
    realizer.run()
    warnings = [(w["id"], w["description"]) for w in realizer.feedback.warnings()]
    assert warnings[0] == ("late", "interrupt: there is no block 'ghost'; ignored")
    assert warnings[1][0] == "x" and warnings[1][1].startswith("onStart: cannot activate block 'ready': it is ")
    assert len(warnings) == 2
    blocks = {f["id"]: f["globalTime"] for f in realizer.feedback.items if f["type"] == "blockProgress"}
    syncs = realizer.feedback.sync_times()
    assert blocks["talk:start"] == 0.5 and syncs["talk:s:end"] == 1.0  # cut short when "late" would start
    assert blocks["talk:end"] == blocks["late:start"] == blocks["ready:start"] == 1.0
    assert blocks["x:start"] == blocks["late:end"] == 1.5
    statuses = [(f["id"], f["globalTime"]) for f in realizer.feedback.items if f.get("status") == "INTERRUPTED"]
    assert statuses == [("talk:s:end", 1.0), ("talk:end", 1.0)]


def test_an_interruption_warns_only_of_what_nobody_asked_for():
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(f'<bml {NS} id="a"><head id="n" lexeme="NOD" start="2"/><head id="m" lexeme="NOD" start="0.5"/>'
                    '<required><head id="r" lexeme="SHAKE" start="3"/></required></bml>')
    # another block hangs a gesture from a:n's stroke, which the interruption means will never come
    realizer.submit(f'<bml {NS} id="b"><gesture id="g" lexeme="BEAT" stroke="a:n:stroke"/>'
                    '<wait id="w" start="0" end="4"/></bml>')
    realizer.env.process((lambda: (yield realizer.env.timeout(1.0)) or realizer.interrupt("a"))())
    realizer.run()
    warnings = [(w["id"], w["warningType"], w["description"], w["globalTime"]) for w in realizer.feedback.warnings()]
    assert warnings == [
        ("b:g", "INTERRUPTED", "g: interrupted: it was tied to a:n; behaviour removed before it started", 1.0),
        ("a:r", "INTERRUPTED", "r: required, but interrupted; behaviour removed before it started", 1.0)]
    # a:n went as asked, quietly; a:m was retracting already (relax at 0.9) and ends as planned
    ends = [(f["id"], f["globalTime"], f.get("status")) for f in realizer.feedback.items
            if f["type"] == "blockProgress" and f["id"].endswith(":end")]
    assert ends == [("a:end", 1.05, "INTERRUPTED"), ("b:end", 4.0, "INTERRUPTED")]
    assert realizer.feedback.sync_times()["a:m:end"] == 1.05
    assert not [s for s in realizer.feedback.sync_times() if s.startswith(("a:n:", "a:r:", "b:g:"))]


def test_a_pending_block_interrupted_whole_starts_and_ends_at_once_and_says_so():
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(f'<bml {NS} id="a"><wait id="w" start="0" end="2"/></bml>')
    realizer.submit(f'<bml {NS} id="b" composition="APPEND"><head id="n" lexeme="NOD"/></bml>')
    realizer.env.process((lambda: (yield realizer.env.timeout(0.5)) or realizer.interrupt("b"))())
    realizer.run()
    assert realizer.feedback.warnings() == []
    blocks = [(f["id"], f["globalTime"], f.get("status")) for f in realizer.feedback.items
              if f["type"] == "blockProgress"]
    assert blocks == [("a:start", 0.0, None), ("b:start", 0.5, None), ("b:end", 0.5, "INTERRUPTED"),
                      ("a:end", 2.0, None)]
