"""Gestures made from their form: MURML descriptions (read by :mod:`agentsim.animation.murml_form`) as procedural
motion units.

A form gives each arm it names four slots: the wrist's location, the palm's and the extended fingers'
directions and the hand's shape, each as a value through the stroke (a static constraint holds one; a
dynamic one moves from its start to its end, along a line or a curve; a sequence shares the stroke among
its parts, each moving on from where the one before left the hand; a symmetrical constraint mirrors the
dominant arm's onto the other). The symbols are those of ``data/murml_symbols.toml``, lengths scaled to
the body's arms. An arm a form names but leaves a slot of empty gets a default: the wrist in front of the
lower chest on its own side, the fingers pointing away from the body with the palm towards the middle, a
neutral hand.

The motion unit (:class:`MurmlDriver`) follows Kendon's phases on the unit's keys: the preparation
(start to ready) blends from the pose it finds into the form at the stroke's beginning; the pre-stroke
hold keeps it; the stroke (strokeStart to strokeEnd) moves through the form's values (u from 0 to 1, eased:
slow, fast, slow); the post-stroke hold keeps the end; the retraction hands the arm back. A static form is
where it says from ready to relax, so at ``stroke``. The wrist reaches its location by analytic two-link
inverse kinematics (:meth:`~agentsim.animation.body.Body.arm_ik`), computed every frame from the
shoulder's frame as the torso has it; the hand's orientation comes from the forearm's twist
(``elbow.yaw``) and the wrist's two angles, solved from the target orientation and the arm's pose (within
the joints' limits); the fingers take the shape's angles joint by joint. A gesture that takes over a hand
still in the previous one's post-stroke hold starts from where that one is (co-articulation, as for
every gesture).

A key frame animation (:class:`MurmlKeyframeDriver`) meets each frame's joint values at the frame's time
(ftime seconds after the start, warped with the unit's keys when the plan stretches it), interpolated
between frames by a monotone cubic (no overshoot).
"""

from __future__ import annotations

import functools
import json

import numpy as np

from agentsim.animation.arms import side_sign
from agentsim.animation.body import FINGERS, euler_matrix, matrix_euler
from agentsim.animation.drivers import PRIORITY
from agentsim.animation.motion import EASE, KeyTimes, MotionDriver, blend_in, frac
from agentsim.animation.murml_form import direction_letters, parse_shape, symbols

SLOT_NAMES = ("HandLocation", "PalmOrientation", "ExtFingerOrientation", "HandShape")


def form_of(behaviour) -> dict:
    return json.loads(behaviour.params.get("murml", "{}"))


# --------------------------------------------------------------------------------------------- symbols
def body_scale(body, side: str = "r") -> float:
    return body.arm_reach(side) / float(symbols()["body"]["arm"])


@functools.lru_cache(maxsize=8)
def _shoulder_height(body) -> float:
    """The shoulder joints' height above the root at rest (metres)."""
    rest = body.rest_pose()[None]
    fk = body.forward_kinematics(rest, ["r_shoulder", "HumanoidRoot"])
    return float(fk["r_shoulder"][1][0, 1] - fk["HumanoidRoot"][1][0, 1])


def location(value: str, body) -> np.ndarray:
    """The wrist position a hand location names, in the root's frame relative to the root joint (metres)."""
    words = value.split()
    table = symbols()
    if all(_is_number(w) for w in words):
        x, y, z = (float(w) for w in words)
        return np.array([x, y - body.hip_height, z])
    scale = body_scale(body)
    height, side, distance = words
    y = _shoulder_height(body) + table["heights"][height] * scale
    phi = np.radians(table["sides"][side])
    r = table["distances"][distance] * scale
    wide = r + table["body"]["half_breadth"] * scale
    d = 1.0 / np.sqrt((np.cos(phi) / r) ** 2 + (np.sin(phi) / wide) ** 2)
    return np.array([d * np.sin(phi), y, d * np.cos(phi)])


def _is_number(word: str) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def direction(value: str) -> np.ndarray:
    """A unit direction in the body's frame (X the character's left, Y up, Z forward)."""
    letters = direction_letters(value.strip())
    if letters is None:
        v = np.array([float(w) for w in value.split()])
    else:
        axes = symbols()["directions"]
        v = np.sum([np.asarray(axes[c], dtype=float) for c in letters], axis=0)
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])


def shape_values(value: str, side: str) -> dict[str, float]:
    """The finger DOFs (degrees) of a hand shape with its modifiers, on one side."""
    name, modifiers = parse_shape(value)
    table = symbols()
    spec = {"fingers": {}, "spread": {}, "thumb": [0, 0, 0], "thumb_spread": 0.0, "thumb_oppose": 0.0}
    for part in [table["shapes"][name], *(table["modifiers"][m] for m in modifiers)]:
        for key, v in part.items():
            if isinstance(v, dict):
                spec[key] = {**spec[key], **v}
            else:
                spec[key] = v
    s = side_sign(side)
    out = {f"{side}_fingers.roll": 0.0}
    for finger in FINGERS:
        flex = spec["fingers"].get(finger, [0, 0, 0])
        for k in range(3):
            out[f"{side}_{finger}{k + 1}.roll"] = -s * float(flex[k])
        out[f"{side}_{finger}1.pitch"] = -float(spec["spread"].get(finger, 0.0))
    for k in range(3):
        out[f"{side}_thumb{k + 1}.roll"] = -s * float(spec["thumb"][k])
    out[f"{side}_thumb1.pitch"] = float(spec["thumb_spread"])
    out[f"{side}_thumb1.yaw"] = s * float(spec["thumb_oppose"])
    return out


def hand_dofs(side: str) -> list[str]:
    """Every DOF a form moves on one arm: the arm's, the wrist's and the fingers'."""
    dofs = [f"{side}_shoulder.roll", f"{side}_shoulder.pitch", f"{side}_shoulder.yaw", f"{side}_elbow.pitch",
            f"{side}_elbow.yaw", f"{side}_wrist.roll", f"{side}_wrist.pitch", f"{side}_fingers.roll"]
    for finger in FINGERS:
        dofs += [f"{side}_{finger}1.roll", f"{side}_{finger}1.pitch", f"{side}_{finger}2.roll",
                 f"{side}_{finger}3.roll"]
    return dofs + [f"{side}_thumb1.roll", f"{side}_thumb1.pitch", f"{side}_thumb1.yaw", f"{side}_thumb2.roll",
                   f"{side}_thumb3.roll"]


# --------------------------------------------------------------------------------------------- the form
class Track:
    """One slot of one arm through the stroke: segments (u0, u1, start, end, curve) over u in [0, 1]. A
    segment that begins where an earlier one has ended starts from that one's end and comes to its own
    path by its end (a static value is moved to, a dynamic path joined), as AsapRealizer prepares each
    part of a sequence from where the hand is: the hand never jumps between the parts of a sequence."""

    def __init__(self):
        self.segments: list[tuple[float, float, object, object, tuple | None]] = []

    def add(self, u0: float, u1: float, a, b, curve=None) -> None:
        self.segments.append((u0, u1, a, b, curve))

    def _ordered(self):
        """The segments by their beginning, each with the end value of the latest one ended by then (None
        for a segment at the stroke's beginning or with none before it)."""
        segments = sorted(self.segments, key=lambda s: s[0])
        out = []
        for k, (u0, u1, a, b, curve) in enumerate(segments):
            before = [s for s in segments[:k] if s[1] <= u0 + 1e-9]
            prev = max(before, key=lambda s: s[1])[3] if before and u0 > 1e-9 else None
            out.append((u0, u1, a, b, curve, prev))
        return out

    def at(self, u: np.ndarray):
        """The slot's values at stroke fractions ``u`` (n,): an array (n, 3) for vectors, a dict of arrays
        for a hand shape."""
        segments = self._ordered()
        first = segments[0]
        if isinstance(first[2], dict):
            names = list(first[2])
            out = {k: np.full(len(u), float(first[2][k])) for k in names}
            for u0, u1, a, b, _, prev in segments:
                w = EASE(frac(u, u0, u1)) if u1 > u0 else (u >= u0).astype(float)
                inside = u >= u0
                for k in names:
                    v = a.get(k, 0.0) + (b.get(k, 0.0) - a.get(k, 0.0)) * w
                    if prev is not None:
                        v = v + (prev.get(k, 0.0) - a.get(k, 0.0)) * (1.0 - w)
                    out[k] = np.where(inside, v, out[k])
            return out
        out = np.tile(np.asarray(first[2], dtype=float), (len(u), 1))
        for u0, u1, a, b, curve, prev in segments:
            a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
            f = frac(u, u0, u1) if u1 > u0 else (u >= u0).astype(float)
            w = EASE(f)
            p = a + np.multiply.outer(w, b - a)
            if curve is not None:
                normal, shape, extension = curve
                chord = b - a
                side = np.cross(normal, chord)
                n = np.linalg.norm(side)
                if n > 1e-9:
                    side = side / n * (0.5 * extension * np.linalg.norm(chord))
                    if shape.startswith("Right"):
                        side = -side
                    bulge = np.sin(np.pi * w) if shape.endswith("C") else np.sin(2 * np.pi * w)
                    if shape in ("UpC", "DownC"):
                        side = normal * (0.5 * extension * np.linalg.norm(chord)) * (1 if shape == "UpC" else -1)
                    p = p + np.multiply.outer(bulge, side)
            if prev is not None:
                p = p + np.multiply.outer(1.0 - w, np.asarray(prev, dtype=float) - a)
            out = np.where((u >= u0)[:, None], p, out)
        return out


class Form:
    """A MURML form as tracks per arm (``l``, ``r``) and slot, evaluated on a body."""

    def __init__(self, form: dict, body, hand: str | None = None):
        """``hand`` (``l`` or ``r``, for a lexicon's form played with a mode): a form of the other arm alone
        is mirrored onto that one."""
        self.body = body
        self.tracks: dict[str, dict[str, Track]] = {}
        for c in form.get("constraints", ()):
            self._add(c, 0.0, 1.0, None)
        if hand is not None and set(self.tracks) == {"l" if hand == "r" else "r"}:
            self.tracks = {}
            for c in form.get("constraints", ()):
                self._add(c, 0.0, 1.0, (hand, "x"))
        for side, slots in self.tracks.items():
            self._defaults(side, slots)

    @property
    def sides(self) -> list[str]:
        return sorted(self.tracks, key=lambda s: s != "r")

    def _value(self, slot: str, value: str, side: str, mirror: str):
        if slot == "HandShape":
            return shape_values(value, side)
        v = location(value, self.body) if slot == "HandLocation" else direction(value)
        for axis in mirror:
            v = v * np.array([-1.0 if axis == a else 1.0 for a in "xyz"])
        return v

    def _add(self, c: dict, u0: float, u1: float, mirror_to: tuple[str, str] | None) -> None:
        op = c["op"]
        if op == "parallel":
            for child in c["children"]:
                self._add(child, u0, u1, mirror_to)
        elif op == "sequence":
            n = len(c["children"])
            for k, child in enumerate(c["children"]):
                self._add(child, u0 + (u1 - u0) * k / n, u0 + (u1 - u0) * (k + 1) / n, mirror_to)
        elif op == "symmetrical":
            other = "l" if c["dominant"] == "r" else "r"
            for child in c["children"]:
                self._add(child, u0, u1, None)
                self._add(child, u0, u1, (other, c["mirror"]))
        else:
            side = c["side"] if mirror_to is None else mirror_to[0]
            mirror = "" if mirror_to is None else mirror_to[1]
            track = self.tracks.setdefault(side, {}).setdefault(c["slot"], Track())
            if op == "static":
                v = self._value(c["slot"], c["value"], side, mirror)
                track.add(u0, u1, v, v)
            else:
                n = len(c["elements"])
                for k, e in enumerate(c["elements"]):
                    a = self._value(c["slot"], e["values"]["start"], side, mirror)
                    b = self._value(c["slot"], e["values"]["end"], side, mirror)
                    curve = None
                    if e["type"] == "curve":
                        normal = self._value("PalmOrientation", e["values"].get("normal", "DirU"), side, mirror)
                        shape = e["values"].get("shape", "LeftC")
                        if "x" in mirror and shape.startswith(("Left", "Right")):
                            shape = ("Right" + shape[4:]) if shape.startswith("Left") else ("Left" + shape[5:])
                        curve = (normal, shape, float(e["values"].get("extension", "0.5")))
                    track.add(u0 + (u1 - u0) * k / n, u0 + (u1 - u0) * (k + 1) / n, a, b, curve)

    def _defaults(self, side: str, slots: dict[str, Track]) -> None:
        def fixed(slot, v):
            if slot not in slots:
                slots[slot] = Track()
                slots[slot].add(0.0, 1.0, v, v)

        here = "LocCenterLeft" if side == "l" else "LocCenterRight"
        fixed("HandLocation", location(f"LocLowerChest {here} LocNorm", self.body))
        fixed("ExtFingerOrientation", direction("DirAU"))
        fixed("PalmOrientation", direction("DirR" if side == "l" else "DirL"))
        fixed("HandShape", shape_values("BSneutral", side))


def hand_matrix(side: str, fingers: np.ndarray, palm: np.ndarray, frame: np.ndarray | None = None) -> np.ndarray:
    """World rotations (n, 3, 3) of a hand whose extended fingers point along ``fingers`` and whose palm
    faces ``palm`` (n, 3 each; the palm is made perpendicular to the fingers). Fingers of no direction (a
    movement between opposite directions passes through none) point away from the body; a palm along the
    fingers faces the middle of the body instead or, fingers pointing across the body, down. ``frame``
    (n, 3, 3) is the body's rotation, in which these directions are meant (none: the world's axes)."""
    rot = np.tile(np.eye(3), (len(fingers), 1, 1)) if frame is None else frame

    def unit(v):
        return v / np.maximum(np.linalg.norm(v, axis=1), 1e-12)[:, None]

    def body_axis(v):
        return rot @ np.asarray(v, dtype=float)

    def across(v, f):
        return v - np.sum(v * f, axis=1)[:, None] * f

    f = np.where(np.linalg.norm(fingers, axis=1)[:, None] > 1e-6, unit(fingers), body_axis([0.0, 0.0, 1.0]))
    n = across(palm, f)
    for fallback in ([-side_sign(side), 0.0, 0.0], [0.0, -1.0, 0.0]):
        n = np.where(np.linalg.norm(n, axis=1)[:, None] > 1e-6, n, across(body_axis(fallback), f))
    n = unit(n)
    s = side_sign(side)
    col0, col1 = -s * n, -f  # the hand's X axis and Y axis (its fingers point along -Y, the left palm -X)
    return np.stack([col0, col1, np.cross(col0, col1)], axis=2)


class MurmlDriver(MotionDriver):
    """A MURML form on one arm: the phases meet the unit's keys; see the module's description."""

    def __init__(self, name: str, keys: KeyTimes, side: str, form: Form, **kw):
        super().__init__(name, keys, PRIORITY["behaviour"], hand_dofs(side), **kw)
        self.side = side
        self.slots = form.tracks[side]

    def stroke_fraction(self, t: np.ndarray) -> np.ndarray:
        k = self.keys
        return frac(t, k.time("strokeStart"), k.time("strokeEnd"))

    def targets(self, t: np.ndarray):
        """Wrist position (n, 3) in the root's frame, finger and palm directions, finger DOFs."""
        u = self.stroke_fraction(t)
        return (self.slots["HandLocation"].at(u), self.slots["ExtFingerOrientation"].at(u),
                self.slots["PalmOrientation"].at(u), self.slots["HandShape"].at(u))

    def on_tick(self, t: np.ndarray) -> None:
        side, body = self.side, self.body
        where, fingers, palm, shape = self.targets(t)
        root_rot, root_pos = self.parent_frame("sacroiliac")  # the root's rotation, and (near) its position
        root_pos = root_pos - np.einsum("nij,j->ni", root_rot, body.offsets[body.joint_index["sacroiliac"]])
        wrist_world = root_pos + np.einsum("nij,nj->ni", root_rot, where)
        sc_rot, shoulder = self.parent_frame(f"{side}_shoulder")
        aim = np.einsum("nji,nj->ni", sc_rot, wrist_world - shoulder)
        values = body.arm_ik(side, aim)
        # the hand's orientation: what is left after the upper arm and the elbow's bend, as a twist of the
        # forearm (elbow yaw, about its own axis) and the wrist's roll and pitch
        target = hand_matrix(side, np.einsum("nij,nj->ni", root_rot, fingers), np.einsum("nij,nj->ni", root_rot, palm),
                             root_rot)
        upper = sc_rot @ euler_matrix(values[f"{side}_shoulder.roll"], values[f"{side}_shoulder.pitch"],
                                      values[f"{side}_shoulder.yaw"])
        bent = upper @ euler_matrix(np.zeros(len(t)), values[f"{side}_elbow.pitch"], np.zeros(len(t)))
        local = np.transpose(bent, (0, 2, 1)) @ target
        from scipy.spatial.transform import Rotation  # (scipy.spatial: a third of a second, for MURML only)

        twist, roll, pitch = Rotation.from_matrix(local).as_euler("YZX", degrees=True).T
        lo, hi = body.lower, body.upper
        clip = lambda name, v: np.clip(v, lo[body.dof(name)], hi[body.dof(name)])  # noqa: E731
        values[f"{side}_elbow.yaw"] = clip(f"{side}_elbow.yaw", twist)
        values[f"{side}_wrist.roll"] = clip(f"{side}_wrist.roll", roll)
        values[f"{side}_wrist.pitch"] = clip(f"{side}_wrist.pitch", pitch)
        values.update(shape)
        k = self.keys
        self.write_held(blend_in(self, values, t, self.begun, max(k.time("ready"), self.begun)))


# --------------------------------------------------------------------------------------------- key frames
def posture_angles(values) -> tuple[float, float, float]:
    """A joint's three values of a MURML posture as AsapRealizer reads them (roll about Z, pitch about X, yaw
    about Y, in degrees; the joint turned by Ry(yaw) Rx(pitch) Rz(roll), as its Quat4f.setFromRollPitchYaw
    makes it) as this body's (roll, pitch, yaw), which turn a joint by Rz(roll) Rx(pitch) Ry(yaw). A turn
    about one axis keeps its value exactly."""
    roll, pitch, yaw = (float(v) for v in values)
    if sum(v != 0.0 for v in (roll, pitch, yaw)) <= 1:
        return roll, pitch, yaw
    zero = np.zeros(1)
    m = (euler_matrix(zero, zero, zero + yaw) @ euler_matrix(zero, zero + pitch, zero)
         @ euler_matrix(zero + roll, zero, zero))
    r, p, y = matrix_euler(m[0])
    return float(r), float(p), float(y)


def keyframe_channels(form: dict, body, lexicon) -> tuple[dict[str, list[tuple[float, float]]], list[str]]:
    """DOF name -> [(ftime, degrees)] of a key frame animation, and the names it has that this body has
    not. Three values of a joint are its rotation as AsapRealizer reads them: roll about Z, pitch about X,
    yaw about Y (:func:`posture_angles`); one value is a DOF (``l_eyebrow.pitch``), a viseme or face channel of
    ``lexicon`` (:func:`agentsim.animation.lips.channel_shape`) or a morph target of the symbol table's
    ``morph_targets`` (weight 0..100: that face lexeme's values in ``lexicon`` times weight / 100)."""
    from agentsim.animation.lips import channel_shape
    from agentsim.animation.murml_form import symbols

    morphs = {name: lexicon.faces[lexeme] for name, lexeme in symbols().get("morph_targets", {}).items()}

    channels: dict[str, list[tuple[float, float]]] = {}
    unknown: list[str] = []
    names = set(body.dof_names)
    for frame in form["keyframing"]["frames"]:
        for joint, v in frame["values"].items():
            if len(v) == 3 and joint in body.joint:
                for axis, x in zip(("roll", "pitch", "yaw"), posture_angles(v)):
                    channels.setdefault(f"{joint}.{axis}", []).append((frame["ftime"], x))
            elif len(v) == 1 and joint in names:
                channels.setdefault(joint, []).append((frame["ftime"], float(v[0])))
            elif len(v) == 1 and channel_shape(joint, lexicon) is not None:
                for dof, x in channel_shape(joint, lexicon).dofs(v[0] / 100.0).items():
                    channels.setdefault(dof, []).append((frame["ftime"], x))
            elif len(v) == 1 and joint in morphs:
                for dof, x in morphs[joint].items():
                    channels.setdefault(dof, []).append((frame["ftime"], x * float(v[0]) / 100.0))
            elif joint not in unknown:
                unknown.append(joint)
    return channels, unknown


class MurmlKeyframeDriver(MotionDriver):
    """A MURML key frame animation: each frame's values at its (warped) time; hands back at the end."""

    release_key = "end"

    def __init__(self, name: str, keys: KeyTimes, channels: dict[str, list[tuple[float, float]]], **kw):
        super().__init__(name, keys, PRIORITY["behaviour"], sorted(channels), **kw)
        self.channels = channels

    def handover(self) -> float:
        return 0.3

    def release_time(self) -> float:
        """Just after the end, so that a frame at the end is met there (then the handover begins)."""
        return self.keys.end + 1e-4

    def frame_time(self, ftime: float) -> float:
        """When a frame is met: its ftime on the unit's preferred axis, warped to the keys' times."""
        return float(np.interp(ftime, self.keys.preferred, self.keys.times))

    def on_tick(self, t: np.ndarray) -> None:
        from agentsim.animation.lips import monotone_cubic

        out = {}
        for dof, frames in self.channels.items():
            times = [self.frame_time(f) for f, _ in frames]
            values = [v for _, v in frames]
            if times[0] > self.keys.start + 1e-9:  # from the pose found at the start to the first frame
                times, values = [self.keys.start, *times], [self.start_value(dof), *values]
            if len(times) == 1:
                out[dof] = np.full(len(t), values[0])
            else:
                out[dof] = monotone_cubic(times, values, t)
        self.write_held(out)
