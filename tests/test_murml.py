"""MURML gestures made from their form: AsapRealizer's five MURML test files realize without a warning, and
the motion (read from the BVH and composed by the test's own forward kinematics, :class:`helpers.BvhFk`)
puts the wrist where the symbols say, turns the palm, shapes the fingers, meets key frames and strokes
on their times."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from helpers import BvhFk, realize

from agentsim.animation import evaluate_poses, write_bvh
from agentsim.animation.body import Body, default_joints
from agentsim.animation.murml import hand_matrix
from agentsim.realizer import Realizer
from anticipators.metronome import Metronome
from speech_timing.builtin import BuiltinBackend
from speech_timing.choice import named

ASAP = Path(__file__).resolve().parent / "bml-examples-asap" / "murml"
NS = "http://www.bml-initiative.org/bml/bml-1.0"
MURML = "http://www.techfak.uni-bielefeld.de/ags/soa/murml"
SYMBOLS = tomllib.loads((Path(__file__).resolve().parents[1] / "agentsim" / "animation" / "data" /
                         "murml_symbols.toml").read_text())
GESTURE_SYNCS = ["start", "ready", "strokeStart", "stroke", "strokeEnd", "relax", "end"]
FPS = 100
DIGITS = ("index", "middle", "ring", "pinky")


def gesture(description: str, gid: str = "g1", **syncs) -> str:
    attrs = "".join(f' {k}="{v}"' for k, v in syncs.items())
    return (f'<murmlgesture xmlns="{MURML}" id="{gid}"{attrs}><murml-description>{description}'
            f'</murml-description></murmlgesture>')


def run(tmp_path, body: str, **kw):
    result = realize(f'<bml xmlns="{NS}" id="b1">{body}</bml>'.encode(), **kw)
    stream = evaluate_poses(result.realizer.recording(), fps=FPS)
    write_bvh(tmp_path / "murml.bvh", stream)
    return result, BvhFk(tmp_path / "murml.bvh")


def body_point(fk: BvhFk, name: str, k: int) -> np.ndarray:
    """A joint's position in the root's frame (the root's rotation undone) at frame k."""
    rot, pos = fk.world["HumanoidRoot"]
    return rot[k].T @ (fk.position(name)[k] - pos[k])


def expected_location(height: str, side: str, distance: str, fk: BvhFk) -> np.ndarray:
    """Where the symbol table puts the wrist, in the root's frame: the height above the shoulder joints
    (as the BVH has them at rest), the angle about the vertical axis and the elliptic distance from it."""
    shoulder = body_point(fk, "r_shoulder", 0)[1]
    y = shoulder + SYMBOLS["heights"][height]
    phi = math.radians(SYMBOLS["sides"][side])
    r = SYMBOLS["distances"][distance]
    wide = r + SYMBOLS["body"]["half_breadth"]
    d = 1.0 / math.hypot(math.cos(phi) / r, math.sin(phi) / wide)
    return np.array([d * math.sin(phi), y, d * math.cos(phi)])


# --------------------------------------------------------------------------------------------- Asap's files
@pytest.mark.parametrize("strict", [False, True])
@pytest.mark.parametrize("name", sorted(p.name for p in ASAP.glob("*.xml")))
def test_asaps_murml_files_realize_without_a_warning(name, strict):
    result = realize((ASAP / name).read_bytes(), strict=strict)
    assert result.warnings == []
    assert [b["id"] for b in result.blocks] == ["bml1:start", "bml1:end"]
    syncs = [f["id"].split(":", 2) for f in result.syncs]
    behaviour = syncs[0][1]
    expected = GESTURE_SYNCS if behaviour.startswith("gesture") else ["start", "attackPeak", "relax", "end"]
    assert [s for _, b, s in syncs if b == behaviour] == expected
    times = [f["globalTime"] for f in result.syncs]
    assert times == sorted(times) and result.blocks[-1]["globalTime"] >= times[-1]


def test_there_are_five_asap_murml_files():
    assert len(list(ASAP.glob("*.xml"))) == 5


# --------------------------------------------------------------------------------------------- location
@pytest.mark.parametrize("where", ["LocShoulder LocCenterRight LocNorm", "LocChest LocCCenter LocFar",
                                   "LocStomach LocRight LocClose"])
def test_the_wrist_is_at_the_symbolic_location_at_the_stroke(tmp_path, where):
    result, fk = run(tmp_path, gesture(f'<static slot="HandLocation" value="{where}" scope="right_arm"/>',
                                       start="0.5"))
    assert result.warnings == []
    stroke = fk.time(result.t("g1:stroke"))
    want = expected_location(*where.split(), fk)
    got = body_point(fk, "r_wrist", stroke)
    assert np.linalg.norm(got - want) < 0.01, (got, want)
    # held from ready to relax
    for sync in ("ready", "strokeEnd"):
        assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(result.t(f"g1:{sync}"))) - want) < 0.01
    # and back down at the end
    assert body_point(fk, "r_wrist", fk.frames - 1)[1] < want[1] - 0.1


def test_a_dynamic_location_moves_the_hand_in_its_direction(tmp_path):
    body = gesture('<dynamic slot="HandLocation" scope="right_arm"><dynamicElement type="linear">'
                   '<value type="start" name="LocLowerChest LocCenterRight LocFar"/>'
                   '<value type="end" name="LocShoulder LocCenterRight LocClose"/></dynamicElement></dynamic>')
    result, fk = run(tmp_path, body)
    a, b = fk.time(result.t("g1:strokeStart")), fk.time(result.t("g1:strokeEnd"))
    start, end = body_point(fk, "r_wrist", a), body_point(fk, "r_wrist", b)
    assert np.linalg.norm(start - expected_location("LocLowerChest", "LocCenterRight", "LocFar", fk)) < 0.01
    assert np.linalg.norm(end - expected_location("LocShoulder", "LocCenterRight", "LocClose", fk)) < 0.01
    path = np.array([body_point(fk, "r_wrist", k) for k in range(a, b + 1)])
    assert np.all(np.diff(path[:, 1]) > -1e-4) and np.all(np.diff(path[:, 2]) < 1e-4)  # up and in, all along
    assert end[1] - start[1] > 0.15 and start[2] - end[2] > 0.1


def test_a_curve_bulges_to_its_side(tmp_path):
    def middle_x(shape):
        body = gesture('<dynamic slot="HandLocation" scope="right_arm"><dynamicElement type="curve">'
                       '<value type="start" name="LocChest LocCenterRight LocFar"/>'
                       '<value type="end" name="LocChest LocCenterRight LocClose"/>'
                       f'<value type="normal" name="DirU"/><value type="shape" name="{shape}"/>'
                       '<value type="extension" name="0.6"/></dynamicElement></dynamic>')
        result, fk = run(tmp_path, body)
        mid = fk.time(0.5 * (result.t("g1:strokeStart") + result.t("g1:strokeEnd")))
        ends = [body_point(fk, "r_wrist", fk.time(result.t(f"g1:{s}"))) for s in ("strokeStart", "strokeEnd")]
        return body_point(fk, "r_wrist", mid)[0] - 0.5 * (ends[0][0] + ends[1][0])

    # moving towards the body with the normal up: the left of the movement is the character's right (-X)
    left, right = middle_x("LeftC"), middle_x("RightC")
    assert left < -0.015 and right > 0.015


def test_symmetrical_mirrors_the_dominant_arm(tmp_path):
    body = gesture('<symmetrical dominant="right_arm" symmetry="SymMS">'
                   '<static slot="HandLocation" value="LocChest LocCenterRight LocNorm"/></symmetrical>')
    result, fk = run(tmp_path, body)
    k = fk.time(result.t("g1:stroke"))
    right, left = body_point(fk, "r_wrist", k), body_point(fk, "l_wrist", k)
    assert abs(right[0] + left[0]) < 0.01 and abs(right[1] - left[1]) < 0.01 and abs(right[2] - left[2]) < 0.01
    assert right[0] < -0.1


def test_absolute_coordinates_put_the_wrist_at_that_point_of_the_body(tmp_path):
    # three numbers: X the character's left, Y up from the floor, Z forward (metres)
    result, fk = run(tmp_path, gesture('<static slot="HandLocation" value="-0.25 1.30 0.35"/>'))
    assert result.warnings == []
    floor = -fk.position("HumanoidRoot")[0][1]  # the root's height at rest, below it in the root's frame
    got = body_point(fk, "r_wrist", fk.time(result.t("g1:stroke")))
    assert np.linalg.norm(got - np.array([-0.25, 1.30 + floor, 0.35])) < 0.01, got


def scaled_body(factor: float) -> Body:
    """The default figure with every length times ``factor``."""
    joints = [dataclasses.replace(j, offset=tuple(factor * x for x in j.offset),
                                  end_site=None if j.end_site is None else tuple(factor * x for x in j.end_site))
              for j in default_joints()]
    return Body(joints, hip_height=0.95 * factor)


def test_the_symbols_are_scaled_to_the_body(tmp_path):
    # the same gesture on a figure 1.2 times and 0.8 times as big: the wrist's height below the shoulders and
    # its distance from the body's axis scale with it
    form = gesture('<static slot="HandLocation" value="LocStomach LocCenterRight LocFar"/>')
    result = realize(f'<bml xmlns="{NS}" id="b1">{form}</bml>'.encode())
    placed = {}
    for factor in (1.0, 1.2, 0.8):
        write_bvh(tmp_path / "scaled.bvh", evaluate_poses(result.realizer.recording(), fps=FPS, body=scaled_body(factor)))
        fk = BvhFk(tmp_path / "scaled.bvh")
        wrist = body_point(fk, "r_wrist", fk.time(result.t("g1:stroke")))
        placed[factor] = np.array([wrist[1] - body_point(fk, "r_shoulder", 0)[1], math.hypot(wrist[0], wrist[2])])
    drop, reach = placed[1.0]
    assert drop == pytest.approx(SYMBOLS["heights"]["LocStomach"], abs=0.005) and reach > 0.4
    for factor in (1.2, 0.8):
        assert np.abs(placed[factor] - factor * placed[1.0]).max() < 0.003, (factor, placed)


def test_a_sequence_moves_the_hand_from_one_location_to_the_next(tmp_path):
    # as Asap prepares each part of a sequence from where the hand is: no jump between the parts
    a, b = "LocChest LocCenterRight LocFar", "LocShoulder LocRight LocClose"
    result, fk = run(tmp_path, gesture(f'<sequence><static slot="HandLocation" value="{a}"/>'
                                       f'<static slot="HandLocation" value="{b}"/></sequence>'))
    assert result.warnings == []
    at = {s: fk.time(result.t(f"g1:{s}")) for s in ("ready", "strokeStart", "strokeEnd", "relax")}
    want_a, want_b = expected_location(*a.split(), fk), expected_location(*b.split(), fk)
    gap = float(np.linalg.norm(want_b - want_a))
    assert gap > 0.2
    for sync in ("ready", "strokeStart"):
        assert np.linalg.norm(body_point(fk, "r_wrist", at[sync]) - want_a) < 0.01, sync
    for sync in ("strokeEnd", "relax"):
        assert np.linalg.norm(body_point(fk, "r_wrist", at[sync]) - want_b) < 0.01, sync
    path = np.array([body_point(fk, "r_wrist", k) for k in range(at["ready"], at["relax"] + 1)])
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert steps.max() < 0.25 * gap, steps.max()  # a 10 ms frame moves it a fraction of the way, never all of it
    to_b = np.linalg.norm(path - want_b, axis=1)
    assert np.all(np.diff(to_b) < 1e-3)  # and it only ever comes nearer the second location


def test_a_sequence_of_hand_shapes_closes_the_hand_gradually(tmp_path):
    result, fk = run(tmp_path, gesture('<sequence><static slot="HandShape" value="BSflat"/>'
                                       '<static slot="HandShape" value="BSfist"/></sequence>'))
    a, b = fk.time(result.t("g1:strokeStart")), fk.time(result.t("g1:strokeEnd"))
    reach = np.mean([np.linalg.norm(fk.position(f"r_{d}3.end") - fk.position("r_wrist"), axis=1) for d in DIGITS],
                    axis=0)
    closing = reach[a:b + 1]
    assert closing[0] - closing[-1] > 0.07  # flat at the stroke's start, a fist at its end
    assert np.abs(np.diff(closing)).max() < 0.25 * (closing[0] - closing[-1])
    assert np.all(np.diff(closing) < 1e-4)


# --------------------------------------------------------------------------------------------- hand
def palm_normal(fk: BvhFk, side: str, k: int) -> np.ndarray:
    """The palm's normal from the hand's points: the fingers' direction crossed with the knuckle line
    (the right hand is the left's mirror image)."""
    along = fk.position(f"{side}_middle1")[k] - fk.position(f"{side}_wrist")[k]
    across = fk.position(f"{side}_index1")[k] - fk.position(f"{side}_pinky1")[k]
    n = np.cross(along, across) * (1.0 if side == "l" else -1.0)
    return n / np.linalg.norm(n)


def test_palm_up_and_palm_down_differ_by_a_turn_of_the_hand(tmp_path):
    normals = {}
    for palm in ("PalmU", "PalmD"):
        body = gesture('<parallel><static slot="HandLocation" value="LocStomach LocCenterRight LocNorm"/>'
                       f'<static slot="PalmOrientation" value="{palm}"/>'
                       '<static slot="ExtFingerOrientation" value="DirA"/></parallel>')
        result, fk = run(tmp_path, body)
        normals[palm] = palm_normal(fk, "r", fk.time(result.t("g1:stroke")))
    up = np.array([0.0, 1.0, 0.0])
    assert normals["PalmU"] @ up > 0.8 and normals["PalmD"] @ up < -0.8
    assert math.degrees(math.acos(np.clip(normals["PalmU"] @ normals["PalmD"], -1, 1))) > 150


def test_a_dynamic_palm_orientation_turns_the_palm(tmp_path):
    result, fk = run(tmp_path, (ASAP / "murmlpalmorientation.xml").read_text().split(">", 1)[1].rsplit("</bml>")[0])
    a, b = (fk.time(result.t(f"gesture1:{s}")) for s in ("strokeStart", "strokeEnd"))
    for k, target in ((a, np.array([1.0, 1.0, 0.0])), (b, np.array([0.0, 1.0, 0.0]))):
        # the palm faces the target direction as far as the fingers' direction (the default: away and up)
        # lets it: the target's part across the fingers
        along = fk.position("r_middle1")[k] - fk.position("r_wrist")[k]
        along /= np.linalg.norm(along)
        across = target - (target @ along) * along
        assert palm_normal(fk, "r", k) @ (across / np.linalg.norm(across)) > 0.97
    assert palm_normal(fk, "r", a)[0] - palm_normal(fk, "r", b)[0] > 0.6  # it turned from the left to up


def test_a_fist_brings_the_finger_tips_much_closer_to_the_wrist_than_a_flat_hand(tmp_path):
    reach = {}
    for shape in ("BSflat", "BSfist", "BSifinger"):
        result, fk = run(tmp_path, gesture(f'<static slot="HandShape" value="{shape}"/>'))
        k = fk.time(result.t("g1:stroke"))
        wrist = fk.position("r_wrist")[k]
        reach[shape] = {d: float(np.linalg.norm(fk.position(f"r_{d}3.end")[k] - wrist)) for d in DIGITS}
    flat, fist = np.mean(list(reach["BSflat"].values())), np.mean(list(reach["BSfist"].values()))
    assert fist < 0.6 * flat and flat > 0.15
    # the index finger: out, the others closed
    assert reach["BSifinger"]["index"] > 0.95 * reach["BSflat"]["index"]
    assert all(reach["BSifinger"][d] < 0.7 * reach["BSflat"][d] for d in DIGITS[1:])


@pytest.mark.parametrize("direction, want", [("DirA", (0, 0, 1)), ("DirU", (0, 1, 0)), ("DirAU", (0, 1, 1)),
                                             ("DirL", (1, 0, 0))])
def test_the_extended_fingers_point_where_ext_finger_orientation_says(tmp_path, direction, want):
    # DirL on the right hand: the fingers across the body, along the palm's default direction (towards the
    # middle), which then faces down
    result, fk = run(tmp_path, gesture('<parallel><static slot="HandLocation" value="LocChest LocCenterRight LocNorm"/>'
                                       f'<static slot="ExtFingerOrientation" value="{direction}"/>'
                                       '<static slot="HandShape" value="BSflat"/></parallel>'))
    assert result.warnings == []
    k = fk.time(result.t("g1:stroke"))
    fingers = body_point(fk, "r_middle3.end", k) - body_point(fk, "r_wrist", k)
    want = np.array(want, dtype=float)
    assert fingers @ want / np.linalg.norm(fingers) / np.linalg.norm(want) > 0.99


def test_a_hand_of_fingers_without_a_direction_or_a_palm_along_them_is_still_a_hand():
    # what a movement between opposite directions passes through, or a palm given along the fingers: a
    # rotation all the same (the fingers away from the body; the palm towards the middle, or down)
    fingers = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    palm = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    for side, middle in (("r", (1.0, 0.0, 0.0)), ("l", (-1.0, 0.0, 0.0))):
        m = hand_matrix(side, fingers, palm)
        assert np.allclose(m @ np.transpose(m, (0, 2, 1)), np.eye(3), atol=1e-9)
        assert np.allclose(np.linalg.det(m), 1.0)
        pointing = -m[:, :, 1]  # the fingers point along the hand's -Y
        assert np.allclose(pointing, [[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0]])
        facing = -m[:, :, 0] * (1.0 if side == "l" else -1.0)  # the palm: the left hand's -X
        assert np.allclose(facing[2], middle) and np.allclose(facing[1], [0, -1, 0]) and np.allclose(facing[3], [0, -1, 0])


def test_a_thumb_modifier_stretches_the_thumb_of_a_fist(tmp_path):
    tips = {}
    for shape in ("BSfist", "BSfist (ThExt)"):
        result, fk = run(tmp_path, gesture(f'<static slot="HandShape" value="{shape}"/>'))
        assert result.warnings == []
        k = fk.time(result.t("g1:stroke"))
        tips[shape] = {d: fk.position(f"r_{d}3.end")[k] - fk.position("r_wrist")[k] for d in ("thumb", *DIGITS)}
    fist, stretched = tips["BSfist"], tips["BSfist (ThExt)"]
    apart = {name: float(np.linalg.norm(t["thumb"] - t["index"])) for name, t in tips.items()}
    assert apart["BSfist (ThExt)"] - apart["BSfist"] > 0.015, apart
    assert all(np.linalg.norm(fist[d] - stretched[d]) < 1e-4 for d in DIGITS)  # the fingers stay closed


# --------------------------------------------------------------------------------------------- timing
def test_key_frames_are_met_at_their_times(tmp_path):
    # (l_shoulder 3 100 0 0): as AsapRealizer reads a posture, roll 100 degrees about the joint's Z axis
    result, fk = run(tmp_path, (ASAP / "murmlbodykeyframe.xml").read_text().split("id=\"bml1\">", 1)[1]
                     .rsplit("</bml>")[0])
    start = result.t("gesture1:start")
    column = fk.column[("l_shoulder", "Zrotation")]
    for ftime, value in ((0.5, 100.0), (1.0, 0.0), (1.5, 100.0), (2.0, 0.0)):
        assert abs(fk.data[fk.time(start + ftime), column] - value) < 0.01, ftime
        for axis in ("Xrotation", "Yrotation"):
            assert abs(fk.data[fk.time(start + ftime), fk.column[("l_shoulder", axis)]]) < 0.01, (ftime, axis)
    # between frames the value stays between them (no overshoot), and the elbow goes where the frame says
    assert fk.data[:, column].max() <= 100.0 + 1e-6
    k = fk.time(start + 0.5)
    elbow = body_point(fk, "l_elbow", k) - body_point(fk, "l_shoulder", k)
    assert elbow[0] > 0.25 and elbow[1] > 0.0  # turned 100 degrees about the forward axis: out to the side, up


def rotation(axis: str, degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    i, j = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def test_a_posture_of_three_values_turns_the_joint_as_asap_reads_it(tmp_path):
    # AsapRealizer: Quat4f.setFromRollPitchYawDegrees(q, v1, v2, v3), the rotation Ry(v3) Rx(v2) Rz(v1); the
    # joint's rotation relative to its parent, composed here from the BVH's channels, is that one
    frames = "".join(f'<frame ftime="{t}"><posture>Humanoid (r_shoulder 3 {r} {p} {y}) (l_elbow 3 0 -60 0)'
                     '</posture></frame>' for t, (r, p, y) in ((0.5, (-40, -30, 20)), (1.0, (-70, 25, -35))))
    body = ('<murmlgesture xmlns="' + MURML + '" id="k1" start="0.2"><murml-description><dynamic><keyframing>'
            f'<phase>{frames}</phase></keyframing></dynamic></murml-description></murmlgesture>')
    result, fk = run(tmp_path, body)
    assert result.warnings == []
    start = result.t("k1:start")
    for ftime, (r, p, y) in ((0.5, (-40, -30, 20)), (1.0, (-70, 25, -35))):
        k = fk.time(start + ftime)
        parent = fk.world["r_sternoclavicular"][0][k]
        local = parent.T @ fk.world["r_shoulder"][0][k]
        want = rotation("Y", y) @ rotation("X", p) @ rotation("Z", r)
        assert np.abs(local - want).max() < 1e-4, (ftime, local, want)
        assert abs(fk.data[k, fk.column[("l_elbow", "Xrotation")]] + 60.0) < 0.01


def test_asaps_face_key_frames_close_both_eyes_at_their_times(tmp_path):
    # its morph target is the eyes' closure of Asap's character: here both eyelids at CLOSE_EYES times weight/100
    from agentsim.animation.lexicon import Lexicon

    result, fk = run(tmp_path, (ASAP / "murmlfacekeyframe.xml").read_text().split("id=\"bml1\">", 1)[1]
                     .rsplit("</bml>")[0])
    assert result.warnings == []
    start = result.t("face1:start")
    closed = Lexicon.builtin().faces["CLOSE_EYES"]["l_eyelid.pitch"]
    for side in "lr":
        column = fk.column[(f"{side}_eyelid", "Xrotation")]
        for ftime, weight in ((0.5, 100.0), (1.0, 0.0), (1.5, 100.0), (2.0, 0.0)):
            assert abs(fk.data[fk.time(start + ftime), column] - closed * weight / 100) < 0.01, (side, ftime)


@pytest.mark.parametrize("tts", ["builtin", "espeak"])
def test_a_stroke_pegged_to_a_speech_mark_is_reported_there_and_reached_there(tmp_path, tts):
    where = "LocChest LocCenterRight LocNorm"
    body = ('<speech id="s1"><text>Look at <sync id="m1"/>this tall tower over there</text></speech>'
            + gesture(f'<static slot="HandLocation" value="{where}"/>', stroke="s1:m1"))
    result, fk = run(tmp_path, body, tts=named(tts))
    assert result.warnings == []
    mark = result.t("s1:m1")
    assert mark > 0.2 and result.t("g1:stroke") == pytest.approx(mark, abs=1e-9)
    got = body_point(fk, "r_wrist", fk.time(mark))
    assert np.linalg.norm(got - expected_location(*where.split(), fk)) < 0.01


def test_sync_points_tied_to_other_behaviours_are_met(tmp_path):
    # start at the end of a nod, stroke on a word of the speech that follows it, relax at the speech's end:
    # the hand is at its location from ready to relax and back down after the end
    where = "LocChest LocCenterRight LocNorm"
    body = ('<head id="h1" lexeme="NOD" start="0.1"/>'
            '<speech id="s1" start="h1:end"><text>Look at <sync id="m1"/>this tall tower over there, it is very old'
            '</text></speech>'
            + gesture(f'<static slot="HandLocation" value="{where}"/>', start="h1:end", stroke="s1:m1",
                      relax="s1:end"))
    result, fk = run(tmp_path, body, tts=named("espeak"))
    assert result.warnings == []
    t = result.t
    assert t("g1:start") == pytest.approx(t("h1:end"), abs=1e-9)
    assert t("g1:stroke") == pytest.approx(t("s1:m1"), abs=1e-9)
    assert t("g1:relax") == pytest.approx(t("s1:end"), abs=1e-9)
    order = [t(f"g1:{s}") for s in GESTURE_SYNCS]
    assert order == sorted(order) and t("g1:relax") - t("g1:stroke") > 1.0
    want = expected_location(*where.split(), fk)
    for sync in ("ready", "stroke", "strokeEnd", "relax"):
        assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(t(f"g1:{sync}"))) - want) < 0.01, sync
    for sync in ("start", "end"):
        assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(t(f"g1:{sync}"))) - want) > 0.3, sync


def test_a_tempo_change_while_the_gesture_plays_warps_its_phases(tmp_path):
    # the stroke on the metronome's fourth beat (1.5 s at 120 BPM); at 1.1 s, in the gesture's preparation,
    # the tempo drops to 60 BPM: 20 % of the beat after beat 3 (1.0 s) has gone, the rest of the new 1 s
    # beat brings beat 4 to 1.9 s. The stroke is reported there and the wrist reaches its location there.
    where = "LocChest LocCenterRight LocNorm"
    metronome = Metronome("metronome", bpm=120)
    realizer = Realizer(anticipators=[metronome], tts=BuiltinBackend())
    realizer.submit(f'<bml xmlns="{NS}" id="b1">'
                    + gesture(f'<static slot="HandLocation" value="{where}"/>', stroke="anticipators:metronome:beat4")
                    + '</bml>')

    def change():
        yield realizer.env.timeout(1.1)
        metronome.set_tempo(60)

    realizer.env.process(change())
    realizer.run()
    assert realizer.feedback.warnings() == []
    t = {k.split(":", 1)[1]: v for k, v in realizer.feedback.sync_times().items()}
    assert t["g1:start"] == pytest.approx(0.9, abs=1e-9)  # passed before the change: kept
    assert t["g1:stroke"] == pytest.approx(1.9, abs=1e-9)
    assert 1.1 < t["g1:ready"] < t["g1:strokeStart"] < t["g1:stroke"]
    write_bvh(tmp_path / "warped.bvh", evaluate_poses(realizer.recording(), fps=FPS))
    fk = BvhFk(tmp_path / "warped.bvh")
    want = expected_location(*where.split(), fk)
    assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(1.9)) - want) < 0.01
    assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(t["g1:ready"])) - want) < 0.01
    assert np.linalg.norm(body_point(fk, "r_wrist", fk.time(1.5)) - want) > 0.05  # the old stroke: still on its way


def test_a_gesture_co_articulates_into_the_next_one(tmp_path):
    # the second gesture begins in the first one's post-stroke hold: the hand goes from the first location
    # straight to the second, at shoulder height, without going down to rest between them
    a, b = "LocShoulder LocCenterRight LocNorm", "LocShoulder LocRight LocFar"
    body = (gesture(f'<static slot="HandLocation" value="{a}"/>', gid="g1", start="0.2")
            + gesture(f'<static slot="HandLocation" value="{b}"/>', gid="g2", start="g1:strokeEnd+0.05"))
    result, fk = run(tmp_path, body)
    assert result.warnings == []
    want_a, want_b = expected_location(*a.split(), fk), expected_location(*b.split(), fk)
    first, second = fk.time(result.t("g1:strokeEnd")), fk.time(result.t("g2:ready"))
    assert np.linalg.norm(body_point(fk, "r_wrist", first) - want_a) < 0.01
    assert np.linalg.norm(body_point(fk, "r_wrist", second) - want_b) < 0.01
    path = np.array([body_point(fk, "r_wrist", k) for k in range(first, second + 1)])
    chord = (want_b - want_a) / np.linalg.norm(want_b - want_a)
    off = path - want_a - np.outer((path - want_a) @ chord, chord)
    assert np.linalg.norm(off, axis=1).max() < 0.03  # within 3 cm of the straight line between them
    assert path[:, 1].min() > min(want_a[1], want_b[1]) - 0.03
    assert fk.time(result.t("g1:end")) > second  # the first gesture's own retraction would still be under way


# --------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("description, reason", [
    ('<static slot="HandLocation" value="LocNowhere LocCenterRight LocNorm"/>', "no height 'LocNowhere'"),
    ('<static slot="HandShape" value="BSsquiggle"/>', "hand shape 'BSsquiggle'"),
    ('<static slot="Wiggle" value="x"/>', "slot 'Wiggle'"),
])
def test_a_bad_form_loses_only_its_gesture_with_a_one_line_warning(description, reason):
    fist = gesture('<static slot="HandShape" value="BSfist"/>', gid="g2")
    doc = f'<bml xmlns="{NS}" id="b1">{gesture(description)}{fist}</bml>'
    result = realize(doc.encode())
    assert len(result.warnings) == 1
    text = result.warnings[0]["description"]
    assert reason in text and "g1" in text and "\n" not in text
    assert {f["id"].split(":")[1] for f in result.syncs} == {"g2"}
