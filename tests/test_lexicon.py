"""The lexicon as data: the built-in entries come from the files in ``agentsim/animation/data``, ``agentsim
lexicon list`` shows them, and ``--lexicon FILE`` (``Realizer(lexicon=...)``) adds or replaces entries without
Python (a stroke, a MURML form, a face, a FACS unit, a posture, a viseme), read back from the BVH by the test's
own forward kinematics. A lexicon is its realizer's: two realizers in one process play their own."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from helpers import BvhFk

from agentsim.animation import evaluate_poses
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.lips import lips_values
from agentsim.animation.units import GESTURE, MURML_STATIC
from agentsim.errors import UsageError
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = "http://www.bml-initiative.org/bml/bml-1.0"
PRESENT = '''
[gesture.PRESENT]
murml = """
<murml-description><parallel>
  <static slot="HandLocation" value="LocStomach LocCenterRight LocNorm"/>
  <static slot="PalmOrientation" value="PalmU"/>
  <static slot="ExtFingerOrientation" value="DirA"/>
  <static slot="HandShape" value="ASL5"/>
</parallel></murml-description>
"""
'''
HIGH_BEAT = '''
[gesture.BEAT]
top = [-0.04, -0.12, 0.33]
bottom = [-0.03, -0.37, 0.35]
rebound = [-0.03, -0.335, 0.35]
'''


def agentsim(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


WIDE_SMILE = '''
[face.SMILE]
l_lip_corner.roll = 20.0
r_lip_corner.roll = -20.0
'''
MORE = '''
[face.GRIN]
"l_lip_corner.yaw" = 14.0
"r_lip_corner.yaw" = -14.0

[facs.12]
"l_lip_corner.roll" = 4.0

[posture.SLOUCH]
"vl5.pitch" = 14.0

[viseme]
aa = { jaw = 20.0 }
'''


def test_lexicon_list_shows_the_built_in_entries():
    run = agentsim("lexicon", "list")
    assert run.returncode == 0, run.stderr
    rows = [line.split(None, 1) for line in run.stdout.splitlines()]
    names = [r[0] for r in rows]
    assert {"BEAT", "CHOP", "OFFER", "POINT_DOWN", "DEFAULT", "CONDUCT_<beats>_<unit>[_<beat>]"} <= set(names)
    assert {"SMILE", "RAISE_BROWS", "AU12", "AU46", "LEAN_BACK", "WEIGHT_SHIFT", "aa", "pbm", "open"} <= set(names)
    assert all(line.rstrip().endswith("built in") for line in run.stdout.splitlines())
    kinds = {line.split()[0]: line.split(None, 1)[1].rsplit("built in", 1)[0].strip()
             for line in run.stdout.splitlines()}
    assert (kinds["SMILE"], kinds["AU12"], kinds["LEAN_BACK"], kinds["aa"], kinds["open"]) == (
        "face lexeme", "FACS unit", "posture", "viseme", "face channel")
    # every table of the built-in lexicon is listed, one line an entry
    builtin = Lexicon.builtin()
    assert len(rows) == (len(builtin.strokes) + len(builtin.forms) + 1 + len(builtin.faces) + len(builtin.facs)
                         + len(builtin.postures) + len(builtin.visemes) + len(builtin.channels))


def test_agentsim_lexicon_alone_lists_as_lexicon_list_does_the_files_given_before_or_after_list(tmp_path):
    (tmp_path / "mine.toml").write_text(PRESENT + HIGH_BEAT)
    listed = agentsim("lexicon", "list", "--lexicon", tmp_path / "mine.toml")
    assert listed.returncode == 0 and "mine.toml" in listed.stdout, listed.stderr
    for args in (("lexicon", "--lexicon", tmp_path / "mine.toml"), ("lexicon", "--lexicon", tmp_path / "mine.toml",
                                                                   "list")):
        run = agentsim(*args)
        assert (run.returncode, run.stdout) == (0, listed.stdout), (args, run.stderr)
    bare = agentsim("lexicon")
    assert bare.returncode == 0 and bare.stdout == agentsim("lexicon", "list").stdout
    assert "mine.toml" not in bare.stdout


def test_a_lexicon_file_adds_a_form_and_replaces_a_stroke(tmp_path):
    (tmp_path / "mine.toml").write_text(PRESENT + HIGH_BEAT + WIDE_SMILE + MORE)
    run = agentsim("lexicon", "list", "--lexicon", tmp_path / "mine.toml")
    assert run.returncode == 0, run.stderr
    by_name = {line.split()[0]: line for line in run.stdout.splitlines()}
    assert "form (MURML)" in by_name["PRESENT"] and by_name["PRESENT"].endswith("mine.toml")
    assert by_name["BEAT"].endswith("mine.toml") and by_name["CHOP"].endswith("built in")
    for name in ("SMILE", "GRIN", "AU12", "SLOUCH", "aa"):
        assert by_name[name].endswith("mine.toml"), name
    for name in ("FROWN", "AU15", "LEAN_BACK", "uw", "open"):
        assert by_name[name].endswith("built in"), name


def test_a_loaded_lexicon_extends_the_built_in_one_and_wins_on_equal_names(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(HIGH_BEAT + WIDE_SMILE + MORE)
    builtin, mine = Lexicon.builtin(), Lexicon.load(path)
    assert Lexicon.load(str(path)).rows() == mine.rows()
    # the file's entries win (dotted keys and quoted ones name the same degrees of freedom)
    assert mine.strokes["BEAT"]["top"] == (-0.04, -0.12, 0.33) and builtin.strokes["BEAT"]["top"] == (-0.04, -0.27, 0.33)
    assert dict(mine.faces["SMILE"]) == {"l_lip_corner.roll": 20.0, "r_lip_corner.roll": -20.0}
    assert dict(mine.facs[12]) == {"l_lip_corner.roll": 4.0} and dict(mine.postures["SLOUCH"]) == {"vl5.pitch": 14.0}
    assert dict(mine.visemes["aa"]) == {"jaw": 20.0, "spread": 0.0, "upper": 0.0, "lower": 0.0}
    assert mine.source("face", "SMILE") == str(path) and mine.source("face", "FROWN") == "built in"
    # the rest is the built-in lexicon's, and the built-in lexicon is unchanged
    assert mine.faces["FROWN"] == builtin.faces["FROWN"] and mine.strokes["CHOP"] == builtin.strokes["CHOP"]
    assert builtin.faces["SMILE"]["l_lip_corner.roll"] == 10.0 and "GRIN" not in builtin.faces
    assert lips_values({"viseme": "AA"}, mine)[0]["temporomandibular.pitch"] == 20.0
    assert lips_values({"viseme": "AA"}, builtin)[0]["temporomandibular.pitch"] == 16.0
    with pytest.raises(TypeError):
        mine.faces["SMILE"] = {}  # a lexicon is never changed: extended() makes another
    assert Lexicon.builtin() is builtin


@pytest.mark.parametrize("text, said", [
    ('[face.GRIN]\n"l_lip_corner.rol" = 3.0\n', "[face.GRIN] 'l_lip_corner.rol' is not a degree of freedom"),
    ('[face.GRIN]\n"l_lipcorner.roll" = 3.0\n', "[face.GRIN] moves l_lipcorner.roll, which the body has not"),
    ('[face.GRIN]\n"l_lip_corner.roll" = "wide"\n', "[face.GRIN] l_lip_corner.roll must be a finite number"),
    ('[facs.twelve]\n"l_lip_corner.roll" = 3.0\n', "[facs.twelve] a FACS action unit is named by its number"),
    ('[posture.SLOUCH]\n"vl5.pitch" = nan\n', "[posture.SLOUCH] vl5.pitch must be a finite number"),
    ("[posture]\nSLOUCH = 3\n", "[posture.SLOUCH] must be a table of degrees of freedom"),
    ("[viseme]\naa = { jaw = 20.0, round = 3.0 }\n", "[viseme.aa] is a mouth shape: jaw, spread, upper, lower"),
    ("[smile]\nx = 1\n", "has [smile]; a lexicon has the tables [gesture], [conducting], [face]"),
    ("[conducting]\ncenter = [0.0, 1.0]\n", "[conducting] needs center = [outward, up, forward]"),
])
def test_a_bad_entry_is_one_line_naming_the_file_and_the_entry(tmp_path, text, said):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(UsageError) as caught:
        Lexicon.load(path)
    message = str(caught.value)
    assert message.startswith(f"lexicon {path}: ") and said in message and "\n" not in message


def realize(tmp_path, body: str, *extra):
    doc = tmp_path / "doc.xml"
    doc.write_text(f'<bml xmlns="{NS}" id="b1">{body}</bml>')
    run = agentsim("realize", doc, "--tts", "builtin", "--bvh", tmp_path / "run.bvh", "--fps", "100", *extra)
    assert run.returncode == 0, run.stderr
    feedback = [json.loads(line) for line in run.stdout.splitlines()]
    return feedback, BvhFk(tmp_path / "run.bvh")


def test_a_form_of_the_lexicon_plays_as_a_gesture_lexeme(tmp_path):
    (tmp_path / "mine.toml").write_text(PRESENT)
    for mode, side in (("RIGHT_HAND", "r"), ("LEFT_HAND", "l")):
        feedback, fk = realize(tmp_path, f'<gesture id="g1" lexeme="PRESENT" mode="{mode}" start="0.2"/>',
                               "--lexicon", tmp_path / "mine.toml")
        assert [f for f in feedback if f["type"] == "warningFeedback"] == []
        stroke = next(f["globalTime"] for f in feedback if f["id"] == "b1:g1:stroke")
        k = fk.time(stroke)
        wrist = fk.position(f"{side}_wrist")[k] - fk.position("HumanoidRoot")[k]
        assert (wrist[0] < -0.1) if side == "r" else (wrist[0] > 0.1)  # on its own side, mirrored for the left
        along = fk.position(f"{side}_middle1")[k] - fk.position(f"{side}_wrist")[k]
        across = fk.position(f"{side}_index1")[k] - fk.position(f"{side}_pinky1")[k]
        palm = np.cross(along, across) * (1.0 if side == "l" else -1.0)
        assert palm[1] / np.linalg.norm(palm) > 0.8  # palm up
    # without the file the lexeme is unknown: a generic gesture, and a warning says so
    feedback, _ = realize(tmp_path, '<gesture id="g1" lexeme="PRESENT" start="0.2"/>')
    assert any("PRESENT" in f["description"] for f in feedback if f["type"] == "warningFeedback")


def test_a_stroke_of_the_lexicon_replaces_the_built_in_one(tmp_path):
    (tmp_path / "mine.toml").write_text(HIGH_BEAT)
    tops = []
    for extra in ((), ("--lexicon", tmp_path / "mine.toml")):
        feedback, fk = realize(tmp_path, '<gesture id="g1" lexeme="BEAT" start="0.2"/>', *extra)
        t = {f["id"].split(":")[-1]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
        a, b = fk.time(t["strokeStart"]), fk.time(t["stroke"])
        tops.append(float((fk.position("r_wrist")[a:b, 1] - fk.position("r_shoulder")[a:b, 1]).max()))
    assert tops[1] - tops[0] > 0.1  # the stroke falls from 0.15 m higher


def test_a_bad_lexicon_file_is_one_line_and_nothing_runs(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[gesture.WIGGLE]\ntop = [0, 1]\n')
    run = agentsim("lexicon", "list", "--lexicon", bad)
    assert run.returncode == 2 and run.stdout == ""
    assert run.stderr.strip().count("\n") == 0 and "[gesture.WIGGLE] needs top" in run.stderr
    run = agentsim("lexicon", "list", "--lexicon", tmp_path / "missing.toml")
    assert run.returncode == 2 and "cannot read the lexicon" in run.stderr


def test_a_realizer_is_given_a_lexicon_or_the_path_of_one(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(WIDE_SMILE)
    assert Realizer(tts=BuiltinBackend()).lexicon is Lexicon.builtin()
    given = Lexicon.load(path)
    assert Realizer(tts=BuiltinBackend(), lexicon=given).lexicon is given
    loaded = Realizer(tts=BuiltinBackend(), lexicon=path).lexicon
    assert loaded.rows() == given.rows() and loaded.faces["SMILE"] == given.faces["SMILE"]
    with pytest.raises(UsageError, match="cannot read the lexicon"):
        Realizer(tts=BuiltinBackend(), lexicon=str(tmp_path / "missing.toml"))
    with pytest.raises(TypeError, match="a lexicon is a Lexicon or the path of a lexicon file"):
        Realizer(tts=BuiltinBackend(), lexicon=3)


TWO = (f'<bml xmlns="{NS}" id="b1"><gesture id="g1" lexeme="BEAT" start="0.2"/>'
       '<faceLexeme id="f1" lexeme="SMILE" start="0.2" end="2.0"/>'
       '<gesture id="g2" lexeme="PRESENT" start="2.5"/></bml>')


def _played(realizer: Realizer):
    """The run's feedback as (type, id, time) and its poses at 50 frames a second, with the frames' times."""
    feedback = [(f["type"], f.get("id"), f.get("globalTime")) for f in realizer.feedback.items]
    return feedback, evaluate_poses(realizer, fps=50.0)


def test_two_realizers_in_one_process_play_their_own_lexicons_interleaved(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(HIGH_BEAT + WIDE_SMILE + PRESENT)
    mine, plain = Realizer(tts=BuiltinBackend(), lexicon=path), Realizer(tts=BuiltinBackend())
    mine.submit(TWO)
    plain.submit(TWO)
    for k in range(1, 13):  # their clocks advanced in turns
        mine.run(until=0.5 * k)
        plain.run(until=0.5 * k)
    mine.run()
    plain.run()
    assert mine.recording().lexicon is mine.lexicon and plain.recording().lexicon is Lexicon.builtin()
    # each played as a realizer alone in the process plays with the same lexicon
    for realizer, lexicon in ((mine, Lexicon.load(path)), (plain, None)):
        alone = Realizer(tts=BuiltinBackend(), lexicon=lexicon)
        alone.submit(TWO)
        alone.run()
        (together, poses), (by_itself, poses_alone) = _played(realizer), _played(alone)
        assert together == by_itself
        assert np.array_equal(poses.values, poses_alone.values)
        # the numbers a run gives its behaviours and drivers are its own, whatever ran beside it
        assert [r.order for r in realizer.recording()] == [r.order for r in alone.recording()] == [0, 1, 2]
        assert poses.driver_names == poses_alone.driver_names and np.array_equal(poses.writers, poses_alone.writers)
    (feedback_mine, poses_mine), (feedback_plain, poses_plain) = _played(mine), _played(plain)
    # PRESENT is a form of the one lexicon, timed as one; the other plays it as a generic gesture, and says so
    warned = [f for f in plain.feedback.items if f["type"] == "warningFeedback"]
    assert [w for w in mine.feedback.items if w["type"] == "warningFeedback"] == []
    assert len(warned) == 1 and "PRESENT (g2)" in warned[0]["description"]
    stroke = {name: {f[1]: f[2] for f in fb if f[0] == "syncPointProgress"}
              for name, fb in (("mine", feedback_mine), ("plain", feedback_plain))}
    assert stroke["mine"]["b1:g2:stroke"] != stroke["plain"]["b1:g2:stroke"]
    assert stroke["mine"]["b1:g1:stroke"] == stroke["plain"]["b1:g1:stroke"]  # the BEAT's timing is the same
    # the smile: the file's mouth corners in the one, the built-in ones in the other
    k = int(np.searchsorted(poses_mine.times, 1.5))
    assert poses_mine.channel("l_lip_corner.roll")[k] == pytest.approx(20.0, abs=1e-9)
    assert poses_plain.channel("l_lip_corner.roll")[k] == pytest.approx(10.0, abs=1e-9)
    # the beat falls from higher in the one whose lexicon raises its top (the same keys, other angles)
    a, b = (int(np.searchsorted(poses_mine.times, stroke["mine"][f"b1:g1:{s}"])) for s in ("strokeStart", "stroke"))
    tops = [float((p.position("r_wrist")[a:b, 1] - p.position("r_shoulder")[a:b, 1]).max())
            for p in (poses_mine, poses_plain)]
    assert tops[0] - tops[1] > 0.1
    assert not np.array_equal(poses_mine.channel("r_shoulder.pitch")[a:b], poses_plain.channel("r_shoulder.pitch")[a:b])


def test_the_live_service_reads_and_plays_with_its_lexicon(tmp_path):
    from websockets.sync.client import connect

    from agentsim.core.gcpause import CollectionPause
    from agentsim.live.service import Background, Service

    path = tmp_path / "mine.toml"
    path.write_text(PRESENT)
    block = f'<bml xmlns="{NS}" id="b1"><gesture id="g1" lexeme="PRESENT" start="0"/></bml>'
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend(), lexicon=path)) as running:
        realizer = running.service.live.realizer
        assert realizer.lexicon.form("PRESENT") is not None and Lexicon.builtin().form("PRESENT") is None
        assert isinstance(realizer.gc_pause, CollectionPause)  # the service's pause, shared by its two threads
        got = []
        with connect(running.url) as ws:
            ws.send(block)
            while not got or got[-1]["id"] != "b1:end":
                got.append(json.loads(ws.recv(timeout=20.0)))
    assert [f for f in got if f["type"] == "warningFeedback"] == []  # read with the service's lexicon
    # and planned with it: timed as a static MURML form, not as the generic gesture
    assert list(realizer.recording().behaviour("b1:g1").preferred) == MURML_STATIC.preferred() != GESTURE.preferred()


def test_serve_with_a_bad_lexicon_is_one_line_before_anything_starts(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[posture.SLOUCH]\n"vl5.pitch" = "far"\n')
    run = agentsim("serve", "--port", "0", "--audio", "none", "--fps", "0", "--tts", "builtin", "--lexicon", bad)
    assert run.returncode == 2 and run.stdout == ""
    assert run.stderr.strip().count("\n") == 0
    assert f"lexicon {bad}: [posture.SLOUCH] vl5.pitch must be a finite number" in run.stderr
