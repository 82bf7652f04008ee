"""Arm motion: gesture strokes and conducting patterns, pointing, hand shapes and key frame sequences.

Gestures follow Kendon's phases as Kallmann & Marsella schedule them: *preparation* (start to ready) is
a transition from whatever pose the arm is in; the *pre-stroke hold* (ready to strokeStart) and the
*post-stroke hold* (strokeEnd to relax) are filled by an interpolator with a blending curve, so slow
speech gives long holds; the *stroke* runs strokeStart to strokeEnd; the *retraction* (relax to end)
hands the arm back to the driver below, which blends from the current pose to its own (a transition
unit). When speech is fast and keys are squeezed the preparation and retraction shrink; when the next
gesture of the same hand starts before this one has retracted, this one's retraction and that one's
preparation are dropped (coarticulation): the hand goes straight from one stroke to the next.

**The stroke.** For beats, conducting beats and the other gesture lexemes the ``stroke`` key is the
*ictus*: the moment the wrist reaches the bottom of the stroke, where its vertical velocity changes sign
from down to up. The wrist accelerates into the ictus and rebounds out of it (a bounce, not a rounded
turn), so the lowest point is exactly at the key even with breathing and sway moving the shoulders. For
pointing the stroke is the moment the arm reaches the target (two-link inverse kinematics puts the
wrist on the target, or on the line to it at arm's length).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim.animation.drivers import EPSILON, PRIORITY
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.motion import EASE, HOLD, MIN_PREP, KeyTimes, MotionDriver, blend_in, frac


def arm_dofs(side: str) -> list[str]:
    return [f"{side}_shoulder.roll", f"{side}_shoulder.pitch", f"{side}_shoulder.yaw", f"{side}_elbow.pitch",
            f"{side}_elbow.yaw", f"{side}_wrist.roll", f"{side}_wrist.pitch", f"{side}_fingers.roll"]


def side_sign(side: str) -> float:
    return 1.0 if side == "l" else -1.0


def outward(side: str, v) -> np.ndarray:
    """A point given as (outward, up, forward) relative to a shoulder, in the clavicle frame (+X left)."""
    v = np.asarray(v, dtype=float)
    return v * np.array([side_sign(side), 1.0, 1.0])


# --------------------------------------------------------------------------------------------- strokes
@dataclass(frozen=True)
class StrokePath:
    """The wrist's path through a stroke, relative to the shoulder as (outward, up, forward) metres:
    from ``top`` down into the ictus at ``bottom`` and up to ``rebound``; the hand's wrist pitch, the
    flick of the wrist at the ictus, the finger curl and the forearm twist (degrees)."""

    top: tuple[float, float, float]
    bottom: tuple[float, float, float]
    rebound: tuple[float, float, float]
    wrist: float = -8.0
    flick: float = 12.0
    curl: float = 30.0
    twist: float = 0.0

    def scaled(self, amount: float) -> "StrokePath":
        """The same stroke with its drop and rebound scaled by ``amount`` (about the ictus)."""
        if amount == 1.0:
            return self
        b = np.asarray(self.bottom)
        top = b + (np.asarray(self.top) - b) * amount
        reb = b + (np.asarray(self.rebound) - b) * amount
        return StrokePath(tuple(top), self.bottom, tuple(reb), self.wrist, self.flick * amount, self.curl,
                          self.twist)


def stroke_path(lexicon: Lexicon, lexeme: str) -> StrokePath:
    """The stroke of a gesture lexeme in ``lexicon`` (of its ``DEFAULT`` for a lexeme it has no stroke for)."""
    strokes = lexicon.strokes
    return StrokePath(**strokes.get(lexeme.upper(), strokes["DEFAULT"]))


# --------------------------------------------------------------------------------------------- conducting
def conducting_path(lexicon: Lexicon, beats_per_bar: int, beat: int, amount: float = 1.0) -> StrokePath:
    """The stroke of beat ``beat`` (1-based) of a conducting pattern of ``lexicon``: down into the beat's
    ictus from above (arriving from the side of the previous beat) and rebounding towards the next. The
    lexicon's ``conducting`` says where the pattern's centre is (relative to the shoulder) and, for each
    meter it knows, each beat's ictus offset from the centre, the height the hand falls from into it and
    how high it rebounds."""
    pattern = lexicon.conducting["patterns"].get(beats_per_bar)
    if pattern is None:  # other meters: one down-beat, then alternating inside and outside
        pattern = [((0.0, 0.0, 0.0), 0.20, 0.10)] + [
            (((-0.12 if k % 2 else 0.14), 0.03, 0.0), 0.12, 0.08) for k in range(1, max(beats_per_bar, 1))]
    n = len(pattern)
    k = (beat - 1) % n
    ictus, fall, rise = pattern[k]
    prev = pattern[(k - 1) % n][0]
    nxt = pattern[(k + 1) % n][0]
    center = np.asarray(lexicon.conducting["center"])
    bottom = center + np.asarray(ictus)
    top = bottom + np.array([0.35 * (prev[0] - ictus[0]), fall * amount, 0.0])
    rebound = bottom + np.array([0.25 * (nxt[0] - ictus[0]), rise * amount, 0.0])
    return StrokePath(tuple(top), tuple(bottom), tuple(rebound), wrist=-5.0, flick=18.0 * amount, curl=20.0)


# --------------------------------------------------------------------------------------------- gesture, pointing
class GestureDriver(MotionDriver):
    """A gesture on one arm: preparation from the current pose, holds, a stroke whose ictus (the
    wrist's lowest point) is exactly at the ``stroke`` key, post-stroke hold, retraction by handover.

    The wrist follows a Cartesian path (:class:`StrokePath`) in the clavicle frame, turned into shoulder
    and elbow angles by analytic inverse kinematics every frame: down into the ictus accelerating
    (height ~ 1 - s^2), out of it decelerating (~ 2s - s^2).
    """

    def __init__(self, name: str, keys: KeyTimes, side: str, path: StrokePath, **kw):
        kw.setdefault("info", {})
        super().__init__(name, keys, PRIORITY["behaviour"], arm_dofs(side), **kw)
        self.side = side
        self.path = path
        self.top = outward(side, path.top)
        self.bottom = outward(side, path.bottom)
        self.rebound = outward(side, path.rebound)
        self._from_wrist: np.ndarray | None = None

    def on_dof_grant(self, dofs, t, current, blend) -> None:
        super().on_dof_grant(dofs, t, current, blend)
        angles = {self.body.dof_names[d]: self.start_value(d) for d in self.dofs}
        self._from_wrist = self.body.arm_fk(self.side, angles)[0]

    def on_dof_loss(self, dofs, t) -> None:
        # Losing the arm after the stroke leaves nothing worth coming back for (losing only the fingers,
        # say to a hand shape, is no reason to stop).
        if t >= self.keys.time("stroke") - EPSILON and any(
                self.body.dof_names[d].startswith(f"{self.side}_shoulder") for d in dofs):
            self.stop()

    def phases(self) -> tuple[float, float, float, np.ndarray]:
        """(end of preparation, start of the down stroke, the ictus, the top the stroke falls from)."""
        k = self.keys
        t_acq = self.begun
        s_start, stroke = k.time("strokeStart"), k.time("stroke")
        prep_end = min(max(k.time("ready"), t_acq + MIN_PREP), s_start)
        down = max(s_start, t_acq)
        top = self.top
        if prep_end <= t_acq + EPSILON:  # no time left to prepare
            here = self._from_wrist if self._from_wrist is not None else self.top
            if here[1] >= self.bottom[1] + 0.5 * (self.top[1] - self.bottom[1]):
                # the hand is up (coarticulation): the stroke falls from where it is
                prep_end = t_acq
                top = here.copy()
            else:
                # the hand is down: half of the way into the ictus goes to getting the hand up
                prep_end = down = t_acq + 0.5 * max(stroke - t_acq, 0.0)
        return prep_end, min(down, stroke), stroke, top

    def wrist_path(self, t: np.ndarray) -> np.ndarray:
        """Target wrist positions (n, 3) relative to the shoulder in the clavicle frame."""
        k = self.keys
        prep_end, down, stroke, top = self.phases()
        s_end, relax = k.time("strokeEnd"), k.time("relax")
        settle = self.rebound + (self.bottom - self.rebound) * 0.3 * min(1.0, (relax - s_end) / 0.5)
        f_down = frac(t, down, stroke)[:, None]
        f_up = frac(t, stroke, s_end)[:, None]
        p = np.where((t < down)[:, None], top, top + (self.bottom - top) * f_down ** 2)
        p = np.where((t >= stroke)[:, None], self.bottom + (self.rebound - self.bottom) * (2 * f_up - f_up ** 2), p)
        if relax > s_end:
            hold = HOLD(t, s_end, relax, self.rebound, settle)
            p = np.where((t >= s_end)[:, None], hold, p)
        elif s_end <= stroke:  # no rebound phase: stay in the ictus
            p = np.where((t >= stroke)[:, None], self.bottom, p)
        return p

    def on_tick(self, t: np.ndarray) -> None:
        side, path = self.side, self.path
        prep_end, down, stroke, _ = self.phases()
        p = self.wrist_path(t)
        values = self.body.arm_ik(side, p)
        f_down = frac(t, down, stroke)
        f_up = frac(t, stroke, self.keys.time("strokeEnd"))
        flick = np.where(t < stroke, path.flick * f_down ** 2, path.flick * (1 - (2 * f_up - f_up ** 2)))
        values[f"{side}_wrist.pitch"] = path.wrist + flick
        values[f"{side}_wrist.roll"] = np.zeros(len(t))
        values[f"{side}_elbow.yaw"] = np.full(len(t), path.twist * side_sign(side))
        values[f"{side}_fingers.roll"] = np.full(len(t), -side_sign(side) * path.curl)
        self.write_held(blend_in(self, values, t, self.begun, prep_end))


class PointingDriver(MotionDriver):
    """Pointing with one arm: the wrist reaches the target at the ``stroke`` key (two-link IK in the
    world: on the target when it is within reach, otherwise on the line from the shoulder to it at
    :attr:`REACH` metres) and stays on it until relax."""

    REACH = 0.5
    HOME = (0.05, -0.28, 0.28)

    def __init__(self, name: str, keys: KeyTimes, side: str, target: np.ndarray, **kw):
        super().__init__(name, keys, PRIORITY["behaviour"], arm_dofs(side), **kw)
        self.side = side
        self.target = np.asarray(target, dtype=float)

    def on_dof_loss(self, dofs, t) -> None:
        if t >= self.keys.time("stroke") - EPSILON and any(
                self.body.dof_names[d].startswith(f"{self.side}_shoulder") for d in dofs):
            self.stop()

    def aim(self) -> tuple[np.ndarray, np.ndarray]:
        """Aim point relative to the shoulder in the clavicle frame for the frames being ticked, and the
        world aim point."""
        rot, shoulder = self.parent_frame(f"{self.side}_shoulder")
        d = self.target - shoulder
        dist = np.linalg.norm(d, axis=1)
        aim_world = shoulder + d / np.maximum(dist, 1e-9)[:, None] * np.minimum(dist, self.REACH)[:, None]
        return np.einsum("nji,nj->ni", rot, aim_world - shoulder), aim_world

    def on_tick(self, t: np.ndarray) -> None:
        k = self.keys
        side = self.side
        s_start, stroke = k.time("strokeStart"), k.time("stroke")
        t_acq = self.begun
        prep_end = min(max(k.time("ready"), t_acq + MIN_PREP), s_start)
        aim, _ = self.aim()
        home = outward(side, self.HOME)
        ready = home + 0.5 * (aim - home)
        if prep_end <= t_acq + EPSILON:
            prep_end = t_acq
        go = max(s_start, t_acq)
        f = EASE(frac(t, go, stroke))[:, None]
        p = np.where((t < go)[:, None], ready, ready + (aim - ready) * f)
        p = np.where((t >= stroke)[:, None], aim, p)
        values = self.body.arm_ik(side, p)
        n = len(t)
        values[f"{side}_wrist.pitch"] = np.zeros(n)
        values[f"{side}_wrist.roll"] = np.zeros(n)
        values[f"{side}_elbow.yaw"] = np.zeros(n)
        values[f"{side}_fingers.roll"] = np.full(n, -side_sign(side) * 12.0)
        self.write_held(blend_in(self, values, t, t_acq, prep_end))


# --------------------------------------------------------------------------------------------- hands, key frames
HAND_SHAPES = {"relaxed": 25.0, "flat": 0.0, "open": 0.0, "fist": 95.0, "point": 70.0, "cup": 40.0, "claw": 60.0}


class HandShapeDriver(MotionDriver):
    """Forms a named hand shape (the fingers' curl), holds it, and hands the fingers back."""

    def __init__(self, name: str, keys: KeyTimes, side: str, shape: str, **kw):
        super().__init__(name, keys, PRIORITY["command"], [f"{side}_fingers.roll"], **kw)
        self.release_key = "end"
        self.side = side
        self.curl = HAND_SHAPES.get(shape.lower(), HAND_SHAPES["relaxed"])

    def handover(self) -> float:
        return 0.3

    def on_tick(self, t: np.ndarray) -> None:
        v = {f"{self.side}_fingers.roll": np.full(len(t), -side_sign(self.side) * self.curl)}
        self.write_held(blend_in(self, v, t, self.begun, self.keys.time("ready")))


#: Key frame sequences for the right arm: (approach seconds, hold seconds, DOF values). For the left arm
#: the DOF names swap side and the roll and yaw values change sign.
KEYFRAMES: dict[str, list[tuple[float, float, dict[str, float]]]] = {
    "wave": [
        (0.5, 0.1, {"shoulder.roll": -70.0, "shoulder.pitch": -30.0, "shoulder.yaw": -80.0, "elbow.pitch": -110.0,
                    "wrist.roll": 0.0, "fingers.roll": 5.0}),
        (0.25, 0.0, {"wrist.roll": 25.0}),
        (0.25, 0.0, {"wrist.roll": -25.0}),
        (0.25, 0.0, {"wrist.roll": 25.0}),
        (0.25, 0.1, {"wrist.roll": 0.0}),
    ],
    "shrug": [
        (0.3, 0.3, {"shoulder.roll": -25.0, "shoulder.pitch": -20.0, "elbow.pitch": -90.0, "elbow.yaw": -60.0,
                    "fingers.roll": 0.0}),
    ],
}


class KeyframeDriver(MotionDriver):
    """Plays a named key frame sequence on one arm (Pantomime's ArmKFMotionDriver): each key frame is
    approached from the previous one and held, the whole sequence ``repeat`` times; then hands back."""

    def __init__(self, name: str, start: float, side: str, sequence: str, repeat: int = 1, **kw):
        frames = KEYFRAMES[sequence]
        s = side_sign(side)
        flip = -s  # the library is written for the right arm (s = -1)
        poses: list[dict[str, float]] = []
        current: dict[str, float] = {}
        times = [0.0]
        for _ in range(max(1, repeat)):
            for approach, hold, vals in frames:
                for k, v in vals.items():
                    current[f"{side}_{k}"] = v * (flip if k.endswith(("roll", "yaw")) else 1.0)
                poses.append(dict(current))
                times.append(times[-1] + approach)
                times.append(times[-1] + hold)
        dofs = sorted(poses[-1])
        keys = KeyTimes(("start", "end"), np.array([start, start + times[-1]]), np.array([0.0, times[-1]]))
        super().__init__(name, keys, PRIORITY["command"], dofs, **kw)
        self.release_key = "end"
        self.poses = poses
        self.frame_times = start + np.asarray(times)

    def handover(self) -> float:
        return 0.4

    def on_tick(self, t: np.ndarray) -> None:
        n = len(t)
        out = {}
        for name in self.dof_names:
            a = np.full(n, self.start_value(name))
            prev = self.start_value(name)
            for k, pose in enumerate(self.poses):
                t0, t1 = self.frame_times[2 * k], self.frame_times[2 * k + 1]
                v = pose.get(name, prev)
                a = np.where(t >= t0, HOLD(t, t0, t1, prev, v, angular=True), a)
                prev = v
            out[name] = a
        self.write_held(out)
