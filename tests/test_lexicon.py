"""The gesture lexicon as data: the built-in lexemes come from ``data/lexicon.toml``, ``agentsim lexicon list``
shows them, and ``--lexicon FILE`` adds lexemes without Python (a stroke, or a MURML form), read back from
the BVH by the test's own forward kinematics. Each run is a process of its own: a lexicon is for the rest of
its process."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from helpers import BvhFk

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


def test_lexicon_list_shows_the_built_in_lexemes_and_a_files():
    run = agentsim("lexicon", "list")
    assert run.returncode == 0, run.stderr
    rows = [line.split(None, 1) for line in run.stdout.splitlines()]
    names = [r[0] for r in rows]
    assert {"BEAT", "CHOP", "OFFER", "POINT_DOWN", "DEFAULT", "CONDUCT_<beats>_<unit>[_<beat>]"} <= set(names)
    assert all(line.rstrip().endswith("built in") for line in run.stdout.splitlines())


def test_a_lexicon_file_adds_a_form_and_replaces_a_stroke(tmp_path):
    (tmp_path / "mine.toml").write_text(PRESENT + HIGH_BEAT)
    run = agentsim("lexicon", "list", "--lexicon", tmp_path / "mine.toml")
    assert run.returncode == 0, run.stderr
    by_name = {line.split()[0]: line for line in run.stdout.splitlines()}
    assert "form (MURML)" in by_name["PRESENT"] and by_name["PRESENT"].endswith("mine.toml")
    assert by_name["BEAT"].endswith("mine.toml") and by_name["CHOP"].endswith("built in")


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
