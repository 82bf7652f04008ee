"""Head and eyes: nods, shakes and tilts, head turns, gaze with its eyes, saccades and held eyelids.

For a head nod the stroke is the lowest head pitch (the first one, with repetitions); for a shake or a
tilt the first extreme; for gaze the eyes (and neck) reach the target at ``ready``.
"""

from __future__ import annotations

import numpy as np

from agentsim.animation.background import eye_angles
from agentsim.animation.drivers import PRIORITY, Driver
from agentsim.animation.motion import EASE, STOP_HANDOVER, KeyTimes, MotionDriver, blend_in

NECK_SHARE = (("vc4", 0.4), ("skullbase", 0.6))


class HeadDriver(MotionDriver):
    """A head movement on top of the current head pose: NOD (pitch), SHAKE (yaw) or TILT (roll),
    ``repeats`` times. The stroke key is the lowest point of the first nod (the head bounces there) or
    the first extreme of a shake or tilt. The neck (vc4) takes 40 % of the angle, the skull base 60 %."""

    AXES = {"NOD": "pitch", "SHAKE": "yaw", "TILT": "roll"}

    def __init__(self, name: str, keys: KeyTimes, lexeme: str = "NOD", amplitude: float = 14.0,
                 repeats: int = 1, **kw):
        lexeme = lexeme.upper() if lexeme.upper() in self.AXES else "NOD"
        self.axis = self.AXES[lexeme]
        super().__init__(name, keys, PRIORITY["head"], [f"{j}.{self.axis}" for j, _ in NECK_SHARE], **kw)
        self.lexeme = lexeme
        self.amplitude = float(amplitude)
        self.repeats = max(1, int(repeats))

    def curve(self, u: np.ndarray) -> np.ndarray:
        """The head angle (degrees, relative to where it started) on the preferred-time axis ``u``."""
        k, a = self.keys, self.amplitude
        ready = k.pref("ready")
        s0, s1 = k.pref("strokeStart"), k.pref("strokeEnd")
        n = self.repeats
        period = (s1 - s0) / n if s1 > s0 else 1.0
        x = (u - s0) / period
        cyc = np.clip(np.floor(x), 0, n - 1)
        phi = np.clip(x - cyc, 0.0, 1.0)
        first = cyc == 0
        if self.lexeme == "NOD":
            lift = -0.15 * a
            pre = lift * EASE(u / ready) if ready > 0 else np.full(u.shape, lift)
            level = np.where(first, lift, 0.0)
            d = np.clip(2 * phi, 0, 1)
            r = np.clip(2 * phi - 1, 0, 1)
            during = np.where(phi < 0.5, level + (a - level) * d * d, a * (1 - (2 * r - r * r)))
            after = np.zeros(u.shape)
        elif self.lexeme == "SHAKE":
            pre = np.zeros(u.shape)
            level = np.where(first, 0.0, -a)
            during = np.where(phi < 0.5, level + (a - level) * EASE(2 * phi), a - 2 * a * EASE(2 * phi - 1))
            after = np.full(u.shape, -a)
        else:  # TILT
            pre = np.zeros(u.shape)
            during = np.where(phi < 0.5, a * EASE(2 * phi), a * (1 - EASE(2 * phi - 1)))
            after = np.zeros(u.shape)
        return np.where(u < s0, pre, np.where(u >= s1, after, during))

    def on_tick(self, t: np.ndarray) -> None:
        c = self.curve(self.keys.warp(t))
        for joint, share in NECK_SHARE:
            dof = f"{joint}.{self.axis}"
            if self.holds(dof):
                self.write(dof, self.start_value(dof) + share * c)


def head_angles_to(driver: Driver, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pitch, yaw) degrees that would face the head towards ``target`` from the torso as it is in the
    frames being ticked (pitch positive downwards)."""
    rot, neck = driver.parent_frame("vc4")
    eyes = neck + np.einsum("nij,j->ni", rot, np.array([0.0, 0.155, 0.095]))
    d = np.einsum("nji,nj->ni", rot, target - eyes)
    yaw = np.degrees(np.arctan2(d[:, 0], d[:, 2]))
    pitch = np.degrees(np.arctan2(-d[:, 1], np.hypot(d[:, 0], d[:, 2])))
    return pitch, yaw


class HeadTurnDriver(MotionDriver):
    """Turns the head (neck and skull base, pitch and yaw) towards a point, arriving at ``arrive``.

    ``shift=True`` (headDirectionShift) makes the new direction the head's rest direction when the unit
    ends; otherwise it holds until its release and hands the neck back.
    """

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, arrive: str = "end",
                 share: float = 1.0, shift: bool = False, priority: int | None = None, **kw):
        dofs = [f"{j}.{a}" for j, _ in NECK_SHARE for a in ("pitch", "yaw")]
        super().__init__(name, keys, PRIORITY["shift" if shift else "behaviour"] if priority is None else priority,
                         dofs, **kw)
        self.target = np.asarray(target, dtype=float)
        self.arrive = arrive
        self.share = share
        self.shift = shift
        if shift:
            self.release_key = "end"

    def handover(self) -> float:
        return STOP_HANDOVER if self.shift else super().handover()

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if self.shift and idle is not None:
            for d in self.dofs:
                idle.set_base(self.body.dof_names[d], float(self.arbitrator.current[d]), t)

    def on_tick(self, t: np.ndarray) -> None:
        pitch, yaw = head_angles_to(self, self.target)
        values = {}
        for joint, share in NECK_SHARE:
            values[f"{joint}.pitch"] = share * self.share * pitch
            values[f"{joint}.yaw"] = share * self.share * yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(self.arrive)))


# --------------------------------------------------------------------------------------------- gaze
#: Share of the gaze angle taken by the head, by BML ``influence``; the torso joints that join in.
GAZE_INFLUENCE = {
    "EYES": (0.0, ()), "NECK": (0.5, ()), "HEAD": (0.6, ()), "SHOULDER": (0.65, ("vt10",)),
    "WAIST": (0.7, ("vt10", "vl5")), "WHOLE": (0.7, ("vt10", "vl5")),
}


class GazeDriver(MotionDriver):
    """Gaze at a target: the neck (and torso, by ``influence``) turn part of the way, the eyes (a slave,
    :class:`GazeEyes`) the rest, both arriving at ``arrive`` (``ready`` for gaze) and tracking the target
    until the release. A gaze shift (``shift=True``) arrives at its end and leaves the eyes and head
    resting on the target."""

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, influence: str = "HEAD",
                 arrive: str = "ready", shift: bool = False, tolerance: float | None = None, **kw):
        share, torso = GAZE_INFLUENCE.get((influence or "HEAD").upper(), GAZE_INFLUENCE["HEAD"])
        if tolerance is not None:
            share = 1.0
        dofs = []
        if share > 0:
            dofs = [f"{j}.{a}" for j, _ in NECK_SHARE for a in ("pitch", "yaw")] + [f"{j}.yaw" for j in torso]
        super().__init__(name, keys, PRIORITY["shift" if shift else "behaviour"], dofs, **kw)
        self.target = np.asarray(target, dtype=float)
        self.share = share
        self.torso = torso
        self.arrive = arrive
        self.shift = shift
        self.tolerance = tolerance  # degrees the eyes may take before the head follows (eye tracking)
        if shift:
            self.release_key = "end"
        self.eyes = GazeEyes(self)

    def attach(self, manager) -> None:
        super().attach(manager)
        manager.add(self.eyes)

    def handover(self) -> float:
        return STOP_HANDOVER if self.shift else super().handover()

    def finish_unit(self, t: float) -> None:
        if not self.shift:
            return
        mgr = self.manager
        if mgr.eyes is not None:
            mgr.eyes.set_target(t, self.target)
        if mgr.idle is not None:
            for d in self.dofs:
                name = self.body.dof_names[d]
                if name in mgr.idle.base:
                    mgr.idle.set_base(name, float(self.arbitrator.current[d]), t)

    def on_tick(self, t: np.ndarray) -> None:
        if not self.owned:
            return
        pitch, yaw = head_angles_to(self, self.target)
        if self.tolerance is not None:
            pitch = pitch - np.clip(pitch, -self.tolerance, self.tolerance)
            yaw = yaw - np.clip(yaw, -self.tolerance, self.tolerance)
        torso_yaw = {"vt10": 0.15, "vl5": 0.1}
        head_yaw_share = 1.0 - sum(torso_yaw[j] for j in self.torso)
        values = {}
        for joint, share in NECK_SHARE:
            values[f"{joint}.pitch"] = share * self.share * pitch
            values[f"{joint}.yaw"] = share * self.share * head_yaw_share * yaw
        for j in self.torso:
            values[f"{j}.yaw"] = torso_yaw[j] * self.share * yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(self.arrive)))


class GazeEyes(MotionDriver):
    """The eyes of a gaze (a slave of :class:`GazeDriver`, with its priority and keys): each eye turns
    onto the target from where the head really is, arriving at the master's arrival key."""

    def __init__(self, master: GazeDriver):
        dofs = ["l_eyeball.pitch", "l_eyeball.yaw", "r_eyeball.pitch", "r_eyeball.yaw"]
        super().__init__(f"{master.name} (eyes)", master.keys, None, dofs, acquire=master.acquire,
                         stop=master.stop_time, time_source=master.time_source)
        master.add_slave(self)
        self.release_key = master.release_key

    def handover(self) -> float:
        return self.master.handover()

    def on_tick(self, t: np.ndarray) -> None:
        m = self.master
        values = {}
        for side in "lr":
            rot, pos = self.parent_frame(f"{side}_eyeball")
            local = np.einsum("nji,nj->ni", rot, m.target - pos)
            pitch, yaw = eye_angles(local)
            values[f"{side}_eyeball.pitch"] = pitch
            values[f"{side}_eyeball.yaw"] = yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(m.arrive)))


class SaccadeDriver(MotionDriver):
    """Eyes thrown onto a point (Pantomime's saccade): a fast ballistic move, then a hold."""

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray | None = None,
                 offset: tuple[float, float] = (0.0, 0.0), **kw):
        dofs = ["l_eyeball.pitch", "l_eyeball.yaw", "r_eyeball.pitch", "r_eyeball.yaw"]
        super().__init__(name, keys, PRIORITY["behaviour"], dofs, **kw)
        self.release_key = "end"
        self.target = None if target is None else np.asarray(target, dtype=float)
        self.offset = offset  # (pitch, yaw) degrees from the current direction when no target

    def handover(self) -> float:
        return 0.06

    def on_tick(self, t: np.ndarray) -> None:
        values = {}
        for side in "lr":
            if self.target is not None:
                rot, pos = self.parent_frame(f"{side}_eyeball")
                pitch, yaw = eye_angles(np.einsum("nji,nj->ni", rot, self.target - pos))
            else:
                pitch = np.full(len(t), self.start_value(f"{side}_eyeball.pitch") + self.offset[0])
                yaw = np.full(len(t), self.start_value(f"{side}_eyeball.yaw") + self.offset[1])
            values[f"{side}_eyeball.pitch"] = pitch
            values[f"{side}_eyeball.yaw"] = yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time("ready")))


# --------------------------------------------------------------------------------------------- eyelids
class EyelidDriver(MotionDriver):
    """Holds the eyelids (0 open, 1 closed, negative wide open): a staring contest suppresses blinks."""

    def __init__(self, name: str, keys: KeyTimes, amount: float, **kw):
        super().__init__(name, keys, PRIORITY["command"], ["l_eyelid.pitch", "r_eyelid.pitch"], **kw)
        self.release_key = "end"
        self.value = 72.0 * amount if amount >= 0 else 18.0 * amount

    def handover(self) -> float:
        return 0.1

    def on_tick(self, t: np.ndarray) -> None:
        v = np.full(len(t), self.value)
        self.write_held(blend_in(self, {"l_eyelid.pitch": v, "r_eyelid.pitch": v}, t, self.begun,
                                 self.keys.time("ready")))
