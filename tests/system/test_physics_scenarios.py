"""The scenarios with ``--physics``: the conductor (seed 0) once with it and once without, the storyteller on
the physical body, through the command line.

The BVH is read and its joints placed by the reader and forward kinematics of ``tests/test_physics_cli.py``
(the tests' own, not the project's); ``physics.csv`` is read as text.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import base64
import json

from tests.test_physics_cli import COLUMNS, channels_of, read_bvh, read_csv, world_positions

pytestmark = pytest.mark.system

#: The conductor's physical joints (the balance's, and the hanging left arm's): their channels may differ
#: from the run without physics; every other channel may not.
BALANCE = ("HumanoidRoot", "sacroiliac", "vl5", "vt10", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")
LEFT_ARM = ("l_shoulder", "l_elbow", "l_wrist")
#: How long before a gesture with the left hand the hanging arm is given back to the animation (s).
RELEASE = 0.3


def agentsim(*args, cwd) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=cwd)
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture(scope="session")
def conductor(tmp_path_factory) -> dict[str, Path]:
    """The conductor (seed 0, no pictures) without and with ``--physics``: each run's folder."""
    tmp = tmp_path_factory.mktemp("conductor")
    agentsim("run", "conductor", "--out", "plain", "--no-pictures", cwd=tmp)
    agentsim("run", "conductor", "--out", "physical", "--no-pictures", "--physics", cwd=tmp)
    return {"plain": tmp / "plain", "physical": tmp / "physical"}


def test_the_conductor_on_the_physical_body_keeps_its_feedback_and_writes_physics_csv(conductor):
    plain, physical = conductor["plain"], conductor["physical"]
    assert (physical / "feedback.jsonl").read_bytes() == (plain / "feedback.jsonl").read_bytes()
    assert not (plain / "physics.csv").exists()
    header, rows = read_csv(physical / "physics.csv")
    _, frame_time, frames = read_bvh(physical / "conductor.bvh")
    assert header == COLUMNS and len(rows) == len(frames) > 1000
    np.testing.assert_allclose(rows[:, 0], np.arange(len(frames)) * frame_time, atol=1e-6)


def _left_hand_gestures(folder: Path) -> list[tuple[float, float]]:
    """(start, end) of the conductor's gestures with the left hand ("play louder", stop), from its feedback."""
    times: dict[str, dict[str, float]] = {}
    for line in (folder / "feedback.jsonl").read_text().splitlines():
        f = json.loads(line)
        if f.get("type") == "syncPointProgress" and f["id"].split(":")[1].startswith(("louder", "stop")):
            block, behaviour, sync = f["id"].split(":")
            times.setdefault(behaviour, {})[sync] = f["globalTime"]
    return sorted((t["start"], t["end"]) for t in times.values() if "start" in t and "end" in t)


def test_the_conductor_keeps_its_balance_while_its_strokes_move_its_trunk(conductor):
    plain, physical = conductor["plain"], conductor["physical"]
    _, rows = read_csv(physical / "physics.csv")
    assert rows[:, 10].max() == 0  # never fell
    inside = rows[:, 8].mean()
    assert inside >= 0.99, inside
    cols = channels_of(physical / "conductor.bvh")
    _, _, a = read_bvh(plain / "conductor.bvh")
    _, _, b = read_bvh(physical / "conductor.bvh")
    vl5 = [cols[f"vl5.{axis}rotation"] for axis in "ZXY"]
    assert b[:, vl5].std(axis=0).max() > 0.2  # degrees, over the run
    moved = (b[:, vl5] - a[:, vl5]).std(axis=0)
    assert moved.max() > 0.2, moved  # and the part of it that physics adds (the strokes' reaction) too
    right = [c for name, c in cols.items() if name.split(".")[0] in ("r_shoulder", "r_elbow", "r_wrist")]
    assert np.abs(b[:, right] - a[:, right]).max() < 0.01  # the conducting arm as animated
    kinematic = [c for name, c in cols.items() if name.split(".")[0] not in BALANCE + LEFT_ARM]
    assert len(kinematic) > 100 and np.abs(b[:, kinematic] - a[:, kinematic]).max() < 0.01


def test_the_conductors_left_arm_hangs_while_the_right_conducts_alone_and_gestures_when_asked(conductor):
    plain, physical = conductor["plain"], conductor["physical"]
    gestures = _left_hand_gestures(physical)
    assert len(gestures) >= 2  # the 'play louder' gestures of seed 0
    _, frame_time, b = read_bvh(physical / "conductor.bvh")
    _, _, a = read_bvh(plain / "conductor.bvh")
    t = np.arange(len(b)) * frame_time
    where = world_positions(physical / "conductor.bvh", ["l_wrist", "l_elbow"])
    cols = channels_of(physical / "conductor.bvh")
    arm = [c for name, c in cols.items() if name.split(".")[0] in LEFT_ARM]
    hanging_from = 0.0
    for start, end in [*gestures, (t[-1] + RELEASE, t[-1])]:
        hangs = (t >= hanging_from + 1.0) & (t < start - RELEASE)  # from 1 s after it started hanging
        assert hangs.sum() > 30
        assert np.all(where["l_wrist"][hangs, 1] < where["l_elbow"][hangs, 1])
        assert np.abs(b[hangs][:, arm] - a[hangs][:, arm]).max() > 1.0  # degrees: it swings as it hangs
        gesturing = (t >= start) & (t < end - frame_time / 2)  # taken back: exactly as animated
        if start < t[-1]:
            assert gesturing.sum() > 10 and np.abs(b[gesturing][:, arm] - a[gesturing][:, arm]).max() < 0.01
        hanging_from = end


def test_the_storyteller_on_the_physical_body_keeps_its_balance(tmp_path):
    agentsim("run", "storytelling", "--story", "the_north_wind_and_the_sun", "--tts", "builtin", "--no-pictures",
             "--out", "story", "--physics", cwd=tmp_path)
    _, rows = read_csv(tmp_path / "story" / "physics.csv")
    _, _, frames = read_bvh(tmp_path / "story" / "story.bvh")
    assert len(rows) == len(frames) > 2000
    assert rows[:, 10].max() == 0 and rows[:, 8].mean() >= 0.99


def _report_points(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """The frames and joint positions (frames, points, 3) the report's 3-D view draws, read from poses.js."""
    text = (folder / "report_files" / "poses.js").read_text()
    payload = json.loads(text[text.index("= ") + 2:text.rindex(";")])
    frames = np.frombuffer(base64.b64decode(payload["frames"]), "<u4")
    q = np.frombuffer(base64.b64decode(payload["xyz"]), "<i2").reshape(payload["count"], payload["points"], 3)
    return frames, q * float(payload["scale"]) + np.asarray(payload["origin"], dtype=float)


def test_the_conductors_report_shows_the_physical_body_and_its_centre_of_mass(conductor):
    plain, physical = conductor["plain"], conductor["physical"]
    assert 'src="report_files/physics.svg"' in (physical / "report.html").read_text()
    assert not (plain / "report_files" / "physics.svg").exists() and "physics" not in (plain / "report.html").read_text()
    _, rows = read_csv(physical / "physics.csv")
    svg = (physical / "report_files" / "physics.svg").read_text()
    assert svg.count('class="com"') == 2 and f"({int((rows[:, 8] == 0).sum())} of {len(rows)})" in svg
    root = world_positions(physical / "conductor.bvh", ["HumanoidRoot"])["HumanoidRoot"]
    frames, points = _report_points(physical)
    assert len(frames) > 100
    np.testing.assert_allclose(points[:, 0], root[frames], atol=2e-3)  # the 3-D view's root is the BVH's
    animated = world_positions(plain / "conductor.bvh", ["HumanoidRoot"])["HumanoidRoot"]
    assert np.abs(root - animated).max() > 0.002  # the simulated root, not the animation's
