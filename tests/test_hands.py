"""H-Anim level-of-articulation-2 hands: thumb and four fingers of three joints each, in the BVH (read and
composed here, by :class:`helpers.BvhFk`), every joint name of the body before hands kept."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from helpers import BvhFk

from agentsim.animation import write_bvh
from agentsim.animation.body import Body
from agentsim.animation.output import PoseStream

#: The joints of the body before it had hands: each is still there.
BEFORE_HANDS = ["HumanoidRoot", "sacroiliac", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle", "vl5",
                "vt10", "vc4", "skullbase", "temporomandibular", "lower_lip", "upper_lip", "l_lip_corner",
                "r_lip_corner", "l_eyeball", "l_eyelid", "l_eyebrow", "r_eyeball", "r_eyelid", "r_eyebrow",
                "l_sternoclavicular", "l_shoulder", "l_elbow", "l_wrist", "l_fingers", "r_sternoclavicular",
                "r_shoulder", "r_elbow", "r_wrist", "r_fingers"]
#: Their parents then.
PARENT_BEFORE_HANDS = {
    "sacroiliac": "HumanoidRoot", "l_hip": "sacroiliac", "l_knee": "l_hip", "l_ankle": "l_knee", "r_hip": "sacroiliac",
    "r_knee": "r_hip", "r_ankle": "r_knee", "vl5": "HumanoidRoot", "vt10": "vl5", "vc4": "vt10", "skullbase": "vc4",
    "temporomandibular": "skullbase", "lower_lip": "temporomandibular", "upper_lip": "skullbase",
    "l_lip_corner": "skullbase", "r_lip_corner": "skullbase", "l_eyeball": "skullbase", "l_eyelid": "skullbase",
    "l_eyebrow": "skullbase", "r_eyeball": "skullbase", "r_eyelid": "skullbase", "r_eyebrow": "skullbase",
    "l_sternoclavicular": "vt10", "l_shoulder": "l_sternoclavicular", "l_elbow": "l_shoulder", "l_wrist": "l_elbow",
    "l_fingers": "l_wrist", "r_sternoclavicular": "vt10", "r_shoulder": "r_sternoclavicular", "r_elbow": "r_shoulder",
    "r_wrist": "r_elbow", "r_fingers": "r_wrist"}
DIGITS = ("thumb", "index", "middle", "ring", "pinky")
CHANNEL_NAMES = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"}


def bvh_of(tmp_path, rows: list[dict[str, float]]) -> tuple[Body, BvhFk]:
    """A BVH of the rest pose with ``rows`` of DOF values set, one frame each, read back by the test's FK."""
    body = Body()
    values = np.tile(body.rest_pose(), (len(rows), 1))
    for k, row in enumerate(rows):
        for dof, v in row.items():
            values[k, body.dof(dof)] = v
    times = np.arange(len(rows)) / 10.0
    stream = PoseStream(times, list(body.dof_names), values, [], np.zeros((len(rows), 0, 3)), 10.0, body)
    write_bvh(tmp_path / "hands.bvh", stream)
    return body, BvhFk(tmp_path / "hands.bvh")


def test_the_bvh_has_h_anim_hands_and_every_joint_it_had(tmp_path):
    _, fk = bvh_of(tmp_path, [{}])
    assert [n for n in fk.names if n in BEFORE_HANDS] == [n for n in BEFORE_HANDS if n in fk.names]
    assert set(BEFORE_HANDS) <= set(fk.names)
    for side in "lr":
        hand = [f"{side}_{d}{k}" for d in DIGITS for k in (1, 2, 3)]
        assert set(hand) <= set(fk.names)
        assert all(fk.parent[f"{side}_{d}{k}"] == f"{side}_{d}{k - 1}" for d in DIGITS for k in (2, 3))
        assert fk.parent[f"{side}_thumb1"] == f"{side}_wrist"
        wrist = fk.position(f"{side}_wrist")[0]
        tips = {d: fk.position(f"{side}_{d}3.end")[0] for d in DIGITS}
        reach = {d: float(np.linalg.norm(p - wrist)) for d, p in tips.items()}
        # a hand of about 18 cm: the middle finger reaches furthest, the thumb least, all below the wrist
        assert 0.15 < reach["middle"] < 0.2 and reach["thumb"] < min(reach[d] for d in DIGITS[1:])
        assert all(p[1] < wrist[1] for p in tips.values())
        # hanging, the thumb is in front (+Z) and the index before the pinky
        assert tips["thumb"][2] > tips["index"][2] > tips["middle"][2] > tips["ring"][2] > tips["pinky"][2]


def test_each_finger_joint_bends_its_own_finger_towards_the_palm(tmp_path):
    rows = [{}]
    for side, s in (("l", 1.0), ("r", -1.0)):
        for d in DIGITS:
            rows.append({f"{side}_{d}{k}.roll": -60.0 * s for k in (1, 2, 3)})
    _, fk = bvh_of(tmp_path, rows)
    k = 1
    for side, s in (("l", 1.0), ("r", -1.0)):
        palm = np.array([-s, 0.0, 0.0])  # the palm faces the thigh
        for d in DIGITS:
            moved = {e: float(np.linalg.norm(fk.position(f"{side}_{e}3.end")[k] - fk.position(f"{side}_{e}3.end")[0]))
                     for e in DIGITS}
            tip = fk.position(f"{side}_{d}3.end")
            towards = float((tip[k] - tip[0]) @ palm)
            assert moved[d] > 0.03 and towards > 0.015, (side, d, moved[d], towards)
            assert all(moved[e] < 1e-9 for e in DIGITS if e != d), (side, d, moved)
            k += 1
    # the wrist and the rest of the body do not move
    assert np.abs(fk.position("l_wrist") - fk.position("l_wrist")[0]).max() < 1e-9


def read_bvh_strictly(text: str) -> tuple[list[str], dict, dict, int, float, list[list[float]]]:
    """A BVH file read line by line as an importer such as Blender's reads it, every rule checked: HIERARCHY;
    ROOT, then JOINTs, each a name, a brace, an OFFSET of three numbers and CHANNELS n with n channel names;
    an End Site (brace, OFFSET, brace) at every leaf; braces balanced; MOTION, Frames: N, Frame Time: t and N
    lines of exactly as many numbers as there are channels. Returns the joints, their parents and channels,
    N, t and the frames."""
    lines = text.split("\n")
    assert lines[0] == "HIERARCHY"
    names, parent, channels, leaves, stack, i = [], {}, {}, set(), [], 1
    while True:
        words = lines[i].split()
        i += 1
        if words[0] in ("ROOT", "JOINT"):
            assert len(words) == 2 and (words[0] == "ROOT") == (not stack) and words[1] not in parent, lines[i - 1]
            name = words[1]
            assert lines[i].split() == ["{"], lines[i]
            offset, chan = lines[i + 1].split(), lines[i + 2].split()
            assert offset[0] == "OFFSET" and len(offset) == 4 and all(math.isfinite(float(x)) for x in offset[1:])
            assert chan[0] == "CHANNELS" and len(chan) == 2 + int(chan[1]), chan
            assert set(chan[2:]) <= CHANNEL_NAMES and len(set(chan[2:])) == len(chan) - 2, chan
            names.append(name)
            parent[name], channels[name] = (stack[-1] if stack else None), chan[2:]
            stack.append(name)
            i += 3
        elif words == ["End", "Site"]:
            assert lines[i].split() == ["{"] and lines[i + 2].split() == ["}"], lines[i:i + 3]
            site = lines[i + 1].split()
            assert site[0] == "OFFSET" and len(site) == 4 and all(math.isfinite(float(x)) for x in site[1:])
            leaves.add(stack[-1])
            i += 3
        elif words == ["}"]:
            stack.pop()
            if not stack:
                break
        else:
            raise AssertionError(f"line {i}: {lines[i - 1]!r}")
    assert {n for n in names if n not in parent.values()} == leaves  # an End Site at every leaf and only there
    assert lines[i] == "MOTION", lines[i]
    frames = int(re.fullmatch(r"Frames: (\d+)", lines[i + 1]).group(1))
    frame_time = float(re.fullmatch(r"Frame Time: (\S+)", lines[i + 2]).group(1))
    rows = [line.split() for line in lines[i + 3:] if line.strip()]
    width = sum(len(c) for c in channels.values())
    assert len(rows) == frames and all(len(r) == width for r in rows), (len(rows), frames, width)
    values = [[float(x) for x in r] for r in rows]
    assert all(math.isfinite(x) for r in values for x in r)
    return names, parent, channels, frames, frame_time, values


def test_realize_writes_a_strict_bvh_that_keeps_every_joint_of_the_body_before_hands(tmp_path):
    form = Path(__file__).resolve().parent / "bml-examples-asap" / "murml" / "murmlhandlocation.xml"
    run = subprocess.run([sys.executable, "-m", "agentsim", "realize", str(form), "--tts", "builtin", "--bvh",
                          str(tmp_path / "hands.bvh"), "--fps", "30"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    names, parent, channels, frames, frame_time, values = read_bvh_strictly((tmp_path / "hands.bvh").read_text())
    assert [n for n in names if n in BEFORE_HANDS] == BEFORE_HANDS  # every one, in the order it had
    assert {n: parent[n] for n in PARENT_BEFORE_HANDS} == PARENT_BEFORE_HANDS
    assert len(names) == len(BEFORE_HANDS) + 2 * 15
    # the root: its position and three rotations; every other joint three rotations (an importer's Euler order)
    assert channels["HumanoidRoot"] == ["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]
    assert all(channels[n] == ["Zrotation", "Xrotation", "Yrotation"] for n in names[1:])
    assert frame_time == 0.03333333 and frames == len(values) > 30
    # the right hand moves in it (the gesture's wrist, the fingers of its neutral hand)
    column = {(n, c): k for k, (n, c) in enumerate((n, c) for n in names for c in channels[n])}
    data = np.array(values)
    for joint in ("r_shoulder", "r_elbow", "r_index2"):
        assert np.ptp(data[:, [column[(joint, c)] for c in channels[joint]]], axis=0).max() > 5.0, joint
