"""H-Anim level-of-articulation-2 hands: thumb and four fingers of three joints each, in the BVH (read and
composed here, by :class:`helpers.BvhFk`), every joint name of the body before hands kept."""

from __future__ import annotations

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
DIGITS = ("thumb", "index", "middle", "ring", "pinky")


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
