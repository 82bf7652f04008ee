"""``agentsim realize --physics``: the physical body under the animation, through the command line.

The BVH is read and its joints placed by this file's own reader and forward kinematics (not the project's);
``physics.csv`` is read as text. The runs longer than a few seconds are system tests.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmlt="http://hmi.ewi.utwente.nl/bmlt" '
       'id="b1">{}</bml>')
STANDING = '<head id="h1" lexeme="NOD" start="3" end="4"/><head id="h2" lexeme="NOD" start="6" end="6.5"/>'
HANG = ('<bmlt:controller id="c1" class="HangController" start="1" end="6.5">'
        '<bmlt:parameter name="part" value="left_arm"/></bmlt:controller>')
COLUMNS = ["time", "com_x", "com_y", "com_z", "support_min_x", "support_max_x", "support_min_z", "support_max_z",
           "com_inside", "pelvis_height", "fallen"]


def agentsim(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def realize(tmp: Path, name: str, body: str, *extra) -> tuple[subprocess.CompletedProcess, Path]:
    (tmp / f"{name}.xml").write_text(BML.format(body))
    proc = agentsim("realize", f"{name}.xml", "--tts", "builtin", "--bvh", f"{name}.bvh", *extra, cwd=tmp)
    assert proc.returncode == 0, proc.stderr
    return proc, tmp / f"{name}.bvh"


# ------------------------------------------------------------------ this file's own BVH reader and kinematics
def read_bvh(path: Path):
    """Joints (name, parent index, offset, channel names), frame time and the frames of a BVH file."""
    lines = path.read_text().splitlines()
    joints, stack, k = [], [], 0
    while lines[k].strip() != "MOTION":
        words = lines[k].split()
        if words and words[0] in ("ROOT", "JOINT"):
            joints.append([words[1], stack[-1] if stack else -1, None, []])
            stack.append(len(joints) - 1)
        elif words and words[0] == "End":
            stack.append(None)
        elif words and words[0] == "OFFSET" and stack[-1] is not None:
            joints[stack[-1]][2] = np.array([float(x) for x in words[1:4]])
        elif words and words[0] == "CHANNELS":
            joints[stack[-1]][3] = words[2:]
        elif words and words[0] == "}":
            stack.pop()
        k += 1
    frame_time = float(lines[k + 2].split(":")[1])
    frames = np.array([[float(x) for x in line.split()] for line in lines[k + 3:] if line.strip()])
    return joints, frame_time, frames


def _axis(name: str, degrees: np.ndarray) -> np.ndarray:
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    i = "XYZ".index(name)
    j, k = [x for x in range(3) if x != i]
    m[..., i, i] = 1.0
    m[..., j, j], m[..., k, k] = c, c
    sign = 1.0 if i != 1 else -1.0  # about Y the sine sits the other way round
    m[..., j, k], m[..., k, j] = -s * sign, s * sign
    return m


def world_positions(path: Path, wanted: list[str]) -> dict[str, np.ndarray]:
    """World positions (frames, 3) of joints of a BVH file: each joint turns by its channels in their order."""
    joints, _, frames = read_bvh(path)
    col, rot, pos = 0, {}, {}
    for i, (name, parent, offset, channels) in enumerate(joints):
        local = np.broadcast_to(np.eye(3), (len(frames), 3, 3))
        here = np.broadcast_to(offset, (len(frames), 3)).copy()
        for ch in channels:
            values = frames[:, col]
            col += 1
            if ch.endswith("position"):
                here[:, "XYZ".index(ch[0])] += values
            else:
                local = local @ _axis(ch[0], values)
        if parent < 0:
            rot[i], pos[i] = local, here
        else:
            rot[i] = rot[parent] @ local
            pos[i] = pos[parent] + np.einsum("nij,nj->ni", rot[parent], here)
    names = [j[0] for j in joints]
    return {w: pos[names.index(w)] for w in wanted}


def channels_of(path: Path) -> dict[str, int]:
    joints, _, _ = read_bvh(path)
    out, col = {}, 0
    for name, _, _, channels in joints:
        for ch in channels:
            out[f"{name}.{ch}"] = col
            col += 1
    return out


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(x) for x in r] for r in rows[1:]])


def feedback(proc) -> list[dict]:
    return [json.loads(line) for line in proc.stdout.splitlines()]


# ------------------------------------------------------------------ bad input (quick)
def test_a_malformed_push_is_a_usage_error_naming_push(tmp_path):
    (tmp_path / "a.xml").write_text(BML.format(STANDING))
    proc = agentsim("realize", "a.xml", "--tts", "builtin", "--physics", "--push", "2:0,150:0.2", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == ["agentsim: --push: the force needs three components FX,FY,FZ (newtons), "
                                        "got '0,150'"]


@pytest.mark.parametrize("push, message", [
    ("2:0,0,150", "expected TIME:FX,FY,FZ:DURATION"), ("two:0,0,150:0.2", "expected numbers"),
    ("2:0,0,150:-1", "the duration > 0"), ("2:0,0,nan:0.2", "finite"), ("-1:0,0,150:0.2", "time must be >= 0")])
def test_what_a_push_must_be(push, message):
    from agentsim.physics.run import parse_push

    with pytest.raises(ValueError, match=message):
        parse_push(push)
    assert parse_push("2:0,0,150:0.2") == parse_push(" 2 : 0, 0,150 :0.2")


@pytest.mark.parametrize("flag", [["--push", "2:0,0,150:0.2"], ["--physics-csv", "p.csv"]])
def test_push_and_the_physics_csv_need_physics(tmp_path, flag, capsys, monkeypatch):
    from agentsim.cli import main

    (tmp_path / "a.xml").write_text(BML.format(STANDING))
    monkeypatch.chdir(tmp_path)
    assert main(["realize", "a.xml", "--tts", "builtin", *flag]) == 2
    out = capsys.readouterr()
    assert out.err.strip() == f"agentsim: {flag[0]} needs --physics" and out.out == ""
    assert not (tmp_path / "p.csv").exists()


def test_an_unknown_controller_class_part_or_parameter_is_one_warning_each_and_the_rest_is_realized(tmp_path):
    body = (STANDING + '<bmlt:controller id="x1" class="Wobble" start="1" end="2"/>'
            '<bmlt:controller id="x2" class="HangController" start="1" end="2">'
            '<bmlt:parameter name="part" value="tail"/></bmlt:controller>'
            '<bmlt:controller id="x3" class="JointController" start="1" end="2">'
            '<bmlt:parameter name="l_elbow.twist" value="3"/></bmlt:controller>' + HANG)
    (tmp_path / "a.xml").write_text(BML.format(body))
    proc = agentsim("realize", "a.xml", "--tts", "builtin", cwd=tmp_path)
    assert proc.returncode == 0
    warnings = [f for f in feedback(proc) if f["type"] == "warningFeedback"]
    assert [(w["id"], w["warningType"]) for w in warnings] == [("b1:x1", "NO_SUCH_TARGET"), ("b1:x2", "NO_SUCH_TARGET"),
                                                               ("b1:x3", "NO_SUCH_TARGET")]
    assert "'Wobble'" in warnings[0]["description"] and "'tail'" in warnings[1]["description"]
    assert "'l_elbow.twist'" in warnings[2]["description"]
    passed = {f["id"] for f in feedback(proc) if f["type"] == "syncPointProgress"}
    assert {"b1:x1:start", "b1:x2:start", "b1:x3:start"}.isdisjoint(passed)
    assert {"b1:h2:end", "b1:c1:start", "b1:c1:end"} <= passed


# ------------------------------------------------------------------ what physics keeps, and what it moves
def in_process(tmp: Path, name: str, body: str, capsys, monkeypatch, *extra) -> tuple[list[dict], Path]:
    """``agentsim realize`` run in this process (a short run: no interpreter to start)."""
    from agentsim.cli import main

    (tmp / f"{name}.xml").write_text(BML.format(body))
    monkeypatch.chdir(tmp)
    capsys.readouterr()
    assert main(["realize", f"{name}.xml", "--tts", "builtin", "--bvh", f"{name}.bvh", *extra]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()], tmp / f"{name}.bvh"


def test_physics_keeps_every_sync_time_and_the_kinematic_joints_channels(tmp_path, capsys, monkeypatch):
    short = '<head id="h1" lexeme="NOD" start="0.5" end="1.3"/>'
    plain, plain_bvh = in_process(tmp_path, "plain", short, capsys, monkeypatch)
    phys, phys_bvh = in_process(tmp_path, "phys", short, capsys, monkeypatch, "--physics", "--physics-csv", "p.csv",
                                "--report", "r.html")
    assert phys == plain
    cols = channels_of(plain_bvh)
    _, frame_time, a = read_bvh(plain_bvh)
    _, _, b = read_bvh(phys_bvh)
    assert a.shape == b.shape and frame_time == pytest.approx(1 / 60)
    kinematic = [c for name, c in cols.items() if name.split(".")[0] in ("vc4", "skullbase", "l_shoulder",
                                                                          "r_elbow", "l_wrist", "r_index2")]
    assert np.abs(b[:, kinematic] - a[:, kinematic]).max() < 0.01
    nod = cols["skullbase.Xrotation"]
    assert np.ptp(b[:, nod]) > 5.0  # the nod is there, as animated
    header, rows = read_csv(tmp_path / "p.csv")
    assert header == COLUMNS and len(rows) == len(b)
    np.testing.assert_allclose(rows[:, 0], np.arange(len(b)) / 60, atol=1e-6)
    assert rows[:, 8].min() == 1 and rows[:, 10].max() == 0
    # the BVH's root is the simulated one: the pelvis (sacroiliac) is where the CSV says
    pelvis = world_positions(phys_bvh, ["sacroiliac"])["sacroiliac"]
    np.testing.assert_allclose(pelvis[:, 1], rows[:, 9], atol=2e-5)
    # the report plots the centre of mass against the support polygon
    svg = (tmp_path / "r_files" / "physics.svg").read_text()
    assert 'src="r_files/physics.svg"' in (tmp_path / "r.html").read_text()
    assert svg.count('class="com"') == 2 and svg.count('class="support"') == 2
    assert f"({int((rows[:, 8] == 0).sum())} of {len(rows)})" in svg


@pytest.mark.system
@pytest.mark.parametrize("axis, force", [(2, "0,0,150"), (0, "150,0,0")])
def test_a_push_moves_the_centre_of_mass_and_the_body_recovers(tmp_path, axis, force):
    proc, bvh = realize(tmp_path, "s", STANDING, "--physics", "--physics-csv", "p.csv", "--push", f"2:{force}:0.2")
    assert not [f for f in feedback(proc) if f["type"] == "warningFeedback"]
    _, rows = read_csv(tmp_path / "p.csv")
    t, com = rows[:, 0], rows[:, 1:4]
    stood = com[(t >= 1) & (t <= 2)].mean(axis=0)
    assert (com[:, axis] - stood[axis]).max() > 0.01  # moved more than 1 cm along the push
    assert rows[:, 10].max() == 0  # never fell
    late = com[t >= 5]
    assert t[-1] >= 7.0 and np.linalg.norm(late - stood, axis=1).max() < 0.02


@pytest.mark.system
def test_a_hanging_left_arm_hangs_and_swings_when_a_push_moves_the_trunk(tmp_path):
    still, still_bvh = realize(tmp_path, "still", STANDING + HANG, "--physics")
    pushed, pushed_bvh = realize(tmp_path, "pushed", STANDING + HANG, "--physics", "--push", "2:0,0,150:0.2")
    _, frame_time, frames = read_bvh(pushed_bvh)
    t = np.arange(len(frames)) * frame_time
    where = world_positions(pushed_bvh, ["l_wrist", "l_elbow"])
    during = (t >= 2.0 - 1e-9) & (t <= 6.5 + 1e-9)
    assert np.all(where["l_wrist"][during, 1] < where["l_elbow"][during, 1])
    shoulder = channels_of(pushed_bvh)["l_shoulder.Xrotation"]
    _, _, calm = read_bvh(still_bvh)
    swing = np.abs(frames[:, shoulder] - calm[:, shoulder])[(t > 2.0) & (t < 4.0)]
    assert swing.max() > 1.0  # degrees: the arm swings with the trunk


@pytest.mark.system
def test_the_same_command_twice_gives_the_same_files(tmp_path):
    args = ("--physics", "--physics-csv", "p.csv", "--push", "2:0,0,150:0.2")
    realize(tmp_path, "one", STANDING + HANG, *args)
    first = ((tmp_path / "p.csv").read_bytes(), (tmp_path / "one.bvh").read_bytes())
    realize(tmp_path, "one", STANDING + HANG, *args)
    assert ((tmp_path / "p.csv").read_bytes(), (tmp_path / "one.bvh").read_bytes()) == first


@pytest.mark.system
def test_a_body_that_falls_is_said_once_and_the_run_completes(tmp_path):
    proc, bvh = realize(tmp_path, "fall", STANDING, "--physics", "--physics-csv", "p.csv", "--push",
                        "2:0,0,900:0.4")
    fell = [f for f in feedback(proc) if f.get("warningType") == "BODY_FELL"]
    assert len(fell) == 1 and fell[0]["globalTime"] > 2.0
    _, rows = read_csv(tmp_path / "p.csv")
    first = int(np.argmax(rows[:, 10]))
    assert rows[first - 1, 10] == 0 and rows[first:, 10].min() == 1
    assert rows[first, 0] == pytest.approx(fell[0]["globalTime"], abs=1e-6)


@pytest.mark.parametrize("command", [["run", "conductor"], ["run", "storytelling"], ["demo"], ["serve", "--port", "0"]])
def test_every_command_with_physics_refuses_a_malformed_push_before_any_work(tmp_path, command, capsys, monkeypatch):
    from agentsim.cli import main

    monkeypatch.chdir(tmp_path)
    assert main([*command, "--physics", "--push", "1:0,0:0.2"]) == 2
    out = capsys.readouterr()
    assert out.err.strip() == ("agentsim: --push: the force needs three components FX,FY,FZ (newtons), got '0,0'")
    assert main([*command, "--push", "1:0,0,150:0.2"]) == 2
    assert capsys.readouterr().err.strip() == "agentsim: --push needs --physics"
    assert list(tmp_path.iterdir()) == []


def test_the_live_viewer_shows_the_physical_body_window_after_window():
    from agentsim.animation.output import records_of
    from agentsim.live.poses import evaluate_window
    from agentsim.physics.run import parse_push
    from agentsim.realizer import Realizer

    realizer = Realizer(tts=None)
    realizer.submit(BML.format('<head id="h1" lexeme="NOD" start="0.2" end="1.2"/>'))
    realizer.run()
    records = list(records_of(realizer.recording()))
    pushes = [parse_push("0.3:0,0,150:0.2")]  # as serve --physics --push 0.3:0,0,150:0.2 gives them
    animated = np.vstack([evaluate_window(records, k, k + 14, 30.0, 0)[0] for k in (0, 15, 30)])
    standing = np.vstack([evaluate_window(records, k, k + 14, 30.0, 0, None, [])[0] for k in (0, 15, 30)])
    pushed = np.vstack([evaluate_window(records, k, k + 14, 30.0, 0, None, pushes)[0] for k in (0, 15, 30)])
    assert np.abs(standing[:, 0:3] - animated[:, 0:3]).max() > 1e-3  # the first point drawn: the simulated root
    forward = pushed[:, 2] - standing[:, 2]
    assert np.abs(forward[:10]).max() < 1e-9 and forward[15:].max() > 0.01  # pushed forward from 0.3 s on
    assert np.abs(np.diff(pushed[:, 0:3], axis=0)).max() < 0.01  # no jump from one window to the next


@pytest.mark.parametrize("chosen, expected", [(None, "disable"), ("egl", "egl")])
def test_the_command_imports_mujoco_without_an_opengl_library_unless_a_backend_was_chosen(tmp_path, chosen,
                                                                                         expected):
    code = ("import os, sys\nfrom agentsim.cli import main\nsys.argv = ['agentsim', '--version']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\nimport mujoco\n"
            "print(os.environ['MUJOCO_GL'], 'glfw' in sys.modules)\n")
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    if chosen is not None:
        env["MUJOCO_GL"] = chosen
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == f"{expected} False"
