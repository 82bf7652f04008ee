"""de Melo's Expression Markup Language through ``agentsim realize FILE.eml``: the thesis's Hello World (its
second gesture key strokes on the onset of "world", and the only warning lists the adaptations), EML's time
expressions and containers (the times events are realized at), the Portuguese Sign Language hand shapes
(the finger angles of the poses), and bad input (one warning each, the rest realized)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agentsim.animation.murml import shape_values
from agentsim.cli import main

HELLO = Path(__file__).resolve().parents[1] / "agentsim" / "examples" / "dialects" / "hello_world.eml"


def realize(tmp_path, capsys, text: str | None = None, *options: str) -> list[dict]:
    """The feedback of ``agentsim realize`` on an EML document (``text``; None: the Hello World)."""
    path = HELLO
    if text is not None:
        path = tmp_path / "doc.eml"
        path.write_text(text)
    assert main(["realize", str(path), *options]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


def syncs(feedback: list[dict]) -> dict[str, float]:
    return {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}


def warnings(feedback: list[dict]) -> list[dict]:
    return [f for f in feedback if f["type"] == "warningFeedback"]


@pytest.mark.parametrize("tts", ["builtin", "espeak"])
def test_hello_world_strokes_on_world_with_one_warning_listing_its_adaptations(tmp_path, capsys, tts):
    feedback = realize(tmp_path, capsys, None, "--tts", tts)
    got = syncs(feedback)
    # the beat's stroke is the onset of "world" (the time marker t2 of the speech t1), exactly
    assert got["helloWorld:key2:stroke"] == got["helloWorld:t1:t2"] > 0.2
    # the salutation, due 0.1 s before the block, starts with it and strokes 0.15 s later, before the beat
    assert got["helloWorld:key1:start"] == 0.0 and got["helloWorld:key1:stroke"] == 0.15
    assert got["helloWorld:key1:end"] > got["helloWorld:key2:start"]
    [warning] = warnings(feedback)
    assert warning["warningType"] == "NONSTANDARD_BML"
    assert warning["modifiedBehaviours"] == ["t1", "key1", "key2"]
    adaptations = warning["adaptations"]
    for phrase in ("EML document read as one BML block", "gestures are always on here",
                   "VEML <voice-text> read as a speech", "VEML <div>", "VEML <emph> read as SSML <emphasis>",
                   "VEML <tm> read as sync points", "hand shape 7 (open claw) played as MURML's ASL5 (Claw) (2 times)",
                   "GEML <gesture-key> played as a MURML gesture: its stroke at its time",
                   "gesture-key key1 would start 0.540 s before the block: clamped to the block's start, its stroke "
                   "at 0.150 s"):
        assert any(phrase in line for line in adaptations), phrase
    assert [f["id"] for f in feedback if f["type"] == "blockProgress"] == ["helloWorld:start", "helloWorld:end"]


TIMES = """<eml name="times"><body>
  <event time="5.0" timeId="c1"/> <event time="c1+1s" timeId="c2"/> <event time="c1+4s-1s" timeId="c3"/>
  <event time="5+c1" timeId="c4"/> <event time="0.05m+250ms" timeId="c5"/>
  <seq time="1.0"><event time="0" timeId="q1"/><null time="0.5"/><event time="1" timeId="q2"/></seq>
  <par time="1.0"><null time="3"/><event time="1" timeId="p1"/></par>
  <seq time="20" repetitionCount="2" duration="2"><event time="0" timeId="r1"/><event time="1" timeId="r2"/></seq>
  <seq time="30" repetitionCount="3"><event time="0.5" timeId="n1"/></seq>
  <event time="n1+0.25" timeId="after"/>
  <seq time="40"><voice-text timeId="v">Good <tm name="m1"/>evening, <tm name="m2" event="onEnd"/>dear
    friends.</voice-text><event time="0.5" timeId="s1"/><event time="m1-0.1" timeId="s2"/></seq>
</body></eml>"""


def test_time_expressions_seq_par_and_repetitions_place_clauses_where_eml_says(tmp_path, capsys):
    feedback = realize(tmp_path, capsys, TIMES, "--tts", "builtin")
    got = syncs(feedback)

    def at(name):
        return got[f"times:{name}:start"]

    # Appendix D.2.3's examples: 5, 6, 8, 10 seconds; minutes and milliseconds
    assert [at(c) for c in ("c1", "c2", "c3", "c4", "c5")] == [5.0, 6.0, 8.0, 10.0, 3.25]
    # a seq counts each clause from the end of the one before (the null at 1.5 ends when it begins)
    assert (at("q1"), at("q2")) == (1.0, 2.5)
    # a par counts each from its own beginning
    assert at("p1") == 2.0
    # repetitionCount with duration: each iteration 2 s after the one before; names inside mean their own
    assert [at(n) for n in ("r1", "r2", "r1_2", "r2_2")] == [20.0, 21.0, 22.0, 23.0]
    # without duration: each iteration after the one before ends; from outside, a name means the first's
    assert [at(n) for n in ("n1", "n1_2", "n1_3")] == [30.5, 31.0, 31.5]
    assert at("after") == 30.75
    # a speech in a seq: the clause after it counts from its end; a time marker is its word's onset
    assert got["times:v:start"] == 40.0
    assert at("s1") == pytest.approx(got["times:v:end"] + 0.5, abs=1e-9)
    assert at("s2") == pytest.approx(got["times:v:m1"] - 0.1, abs=1e-9)
    assert got["times:v:m1"] > 40.0 and got["times:v:m2"] > got["times:v:m1"]
    [warning] = warnings(feedback)
    assert any("onEnd" in line for line in warning["adaptations"])


SHAPES = """<eml name="shapes"><body>
  <gesture-key time="1" duration="0.4" handedness="right" timeId="claw">
    <hand-shapes><key id="7"/></hand-shapes></gesture-key>
  <gesture-key time="1" duration="0.4" handedness="left" timeId="unknown">
    <hand-shapes><key id="24"/></hand-shapes>
    <motion><key x="7" y="10" z="-8"/></motion></gesture-key>
</body></eml>"""


def test_hand_shapes_come_from_the_sign_language_table_and_an_unknown_one_is_the_neutral_hand(tmp_path, capsys):
    poses = tmp_path / "poses.npz"
    feedback = realize(tmp_path, capsys, SHAPES, "--tts", "builtin", "--poses", str(poses), "--fps", "100")
    got = syncs(feedback)
    assert got["shapes:claw:stroke"] == got["shapes:unknown:stroke"] == 1.0
    data = np.load(poses)
    channels = [str(c) for c in data["channels"]]
    frame = int(np.argmin(np.abs(data["times"] - 1.2)))  # in the stroke of both keys
    for side, shape in (("r", "ASL5 (Claw)"), ("l", "BSneutral")):
        for dof, value in shape_values(shape, side).items():
            if dof in channels:
                assert data["values"][frame, channels.index(dof)] == pytest.approx(value, abs=1e-6), dof
    other = [w for w in warnings(feedback) if w["warningType"] != "NONSTANDARD_BML"]
    assert [(w["warningType"], w["description"].split(" (line")[0]) for w in other] == [
        ("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", "hand shape id '24' is not one of the Portuguese Sign Language shapes "
         "described here (7): the neutral hand (BSneutral) instead")]


@pytest.mark.parametrize("clause, named", [
    ('<event time="t1+" timeId="bad"/>', "time 't1+'"),
    ('<event time="2x" timeId="bad"/>', "time '2x'"),
    ('<event time="nowhere+1" timeId="bad"/>', "'nowhere' is no timeId"),
    ('<event time="m1+m1" timeId="bad"/>', "adds two points of speech"),
    ('<wave time="1" hand="right"/>', "<wave>: not an EML element"),
    ('<body-player-add time="1"/>', "<body-player-add>: BEML's keyframe animation players"),
])
def test_a_bad_time_or_an_unknown_element_gives_one_warning_and_the_rest_is_realized(tmp_path, capsys, clause,
                                                                                      named):
    text = (f'<eml name="doc"><body><voice-text timeId="v">Hello <tm name="m1"/>there.</voice-text>{clause}'
            '<event time="m1" timeId="ok"/></body></eml>')
    feedback = realize(tmp_path, capsys, text, "--tts", "builtin")
    other = [w for w in warnings(feedback) if w["warningType"] != "NONSTANDARD_BML"]
    assert len(other) == 1 and named in other[0]["description"], other
    got = syncs(feedback)
    assert got["doc:ok:start"] == got["doc:v:m1"] and "doc:v:end" in got
    assert "doc:bad:start" not in got


def test_motion_keys_put_the_wrist_where_speaker_coordinates_say_and_both_hands_mirror(tmp_path, capsys):
    from agentsim.bml.eml_gestures import location

    poses = tmp_path / "poses.npz"
    got = syncs(realize(tmp_path, capsys, None, "--tts", "builtin", "--poses", str(poses), "--fps", "100"))
    data = np.load(poses)
    joints = [str(j) for j in data["joints"]]

    def wrist(side, t):
        return data["positions"][int(round(t * 100)), joints.index(f"{side}_wrist")]

    head = data["positions"][0, joints.index("skullbase")][1]
    # the salutation: above the head, where (-7, 45, 3) is; the beat: (-15, 40, 3) 0.1 s after "world"
    raised = wrist("r", got["helloWorld:key1:strokeEnd"])
    assert raised[1] > head + 0.3
    assert np.allclose(raised, location(-7.0, 45.0, 3.0), atol=0.01)
    assert np.allclose(wrist("r", got["helloWorld:t1:t2"] + 0.12), location(-15.0, 40.0, 3.0), atol=0.01)
    # both hands: the left one mirrors the right on the sagittal plane
    text = ('<eml name="both"><body><gesture-key time="1" duration="0.4" handedness="both"><motion>'
            '<key time="0" x="-10" y="20" z="-10"/><key time="0.2" x="-14" y="22" z="-12"/></motion>'
            '</gesture-key></body></eml>')
    realize(tmp_path, capsys, text, "--tts", "builtin", "--poses", str(poses), "--fps", "100")
    data = np.load(poses)
    right, left = wrist("r", 1.3), wrist("l", 1.3)
    root = data["positions"][130, joints.index("HumanoidRoot")] * np.array([1.0, 0.0, 1.0])  # (its sway)
    assert np.allclose(right, location(-14.0, 22.0, -12.0), atol=0.01)
    assert np.allclose(left - root, (right - root) * np.array([-1.0, 1.0, 1.0]), atol=0.002)
