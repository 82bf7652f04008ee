"""MURML gestures made from their form: AsapRealizer's five MURML test files realize without a warning, and
the motion (read from the BVH and composed by the test's own forward kinematics, :class:`helpers.BvhFk`)
puts the wrist where the symbols say, turns the palm, shapes the fingers, meets key frames and strokes
on their times."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from helpers import BvhFk, realize

from agentsim.animation import evaluate_poses, write_bvh
from speech_timing.builtin import BuiltinBackend

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


# --------------------------------------------------------------------------------------------- timing
def test_key_frames_are_met_at_their_times(tmp_path):
    result, fk = run(tmp_path, (ASAP / "murmlbodykeyframe.xml").read_text().split("id=\"bml1\">", 1)[1]
                     .rsplit("</bml>")[0])
    start = result.t("gesture1:start")
    column = fk.column[("l_shoulder", "Xrotation")]
    for ftime, value in ((0.5, 100.0), (1.0, 0.0), (1.5, 100.0), (2.0, 0.0)):
        assert abs(fk.data[fk.time(start + ftime), column] - value) < 0.01, ftime
    # between frames the value stays between them (no overshoot), and the elbow goes where the frame says
    assert fk.data[:, column].max() <= 100.0 + 1e-6
    k = fk.time(start + 0.5)
    elbow = fk.position("l_elbow")[k] - fk.position("l_shoulder")[k]
    assert elbow[2] < -0.25  # pitched 100 degrees about X: the upper arm points backwards


def test_asaps_face_key_frames_close_both_eyes_at_their_times(tmp_path):
    # its morph target is the eyes' closure of Asap's character: here both eyelids at CLOSE_EYES times weight/100
    from agentsim.animation.pose import FACE_LEXEMES

    result, fk = run(tmp_path, (ASAP / "murmlfacekeyframe.xml").read_text().split("id=\"bml1\">", 1)[1]
                     .rsplit("</bml>")[0])
    assert result.warnings == []
    start = result.t("face1:start")
    closed = FACE_LEXEMES["CLOSE_EYES"]["l_eyelid.pitch"]
    for side in "lr":
        column = fk.column[(f"{side}_eyelid", "Xrotation")]
        for ftime, weight in ((0.5, 100.0), (1.0, 0.0), (1.5, 100.0), (2.0, 0.0)):
            assert abs(fk.data[fk.time(start + ftime), column] - closed * weight / 100) < 0.01, (side, ftime)


def test_a_stroke_pegged_to_a_speech_mark_is_reported_there_and_reached_there(tmp_path):
    where = "LocChest LocCenterRight LocNorm"
    body = ('<speech id="s1"><text>Look at <sync id="m1"/>this tall tower over there</text></speech>'
            + gesture(f'<static slot="HandLocation" value="{where}"/>', stroke="s1:m1"))
    result, fk = run(tmp_path, body, tts=BuiltinBackend())
    assert result.warnings == []
    mark = result.t("s1:m1")
    assert result.t("g1:stroke") == pytest.approx(mark, abs=1e-9)
    got = body_point(fk, "r_wrist", fk.time(mark))
    assert np.linalg.norm(got - expected_location(*where.split(), fk)) < 0.01


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
