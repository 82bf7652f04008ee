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

from tests.test_physics_cli import COLUMNS, channels_of, read_bvh, read_csv

pytestmark = pytest.mark.system

#: The joints the conductor's physical body simulates (their channels may differ from the run without).
SIMULATED = ("HumanoidRoot", "sacroiliac", "vl5", "vt10", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee",
             "r_ankle", "l_sternoclavicular", "l_shoulder", "l_elbow", "l_wrist")


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
