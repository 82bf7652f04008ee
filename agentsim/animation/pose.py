"""Held poses (face expressions, postures and their shifts), transitions, locomotion, and the jaw while
speaking."""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from agentsim.animation.drivers import PRIORITY
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.motion import EASE, STOP_HANDOVER, KeyTimes, MotionDriver, blend_in, frac


def face_values(behaviour_type: str, attrs: Mapping[str, str], lexicon: Lexicon) -> dict[str, float]:
    """DOF values of a face behaviour at full attack, as ``lexicon`` has its lexeme or FACS unit (scaled by
    ``amount``, one side if ``side`` says so)."""
    try:
        amount = float(attrs.get("amount", "1"))
    except ValueError:
        amount = 1.0
    values: dict[str, float] = {}
    if behaviour_type == "faceFacs":
        try:
            au = int(float(attrs.get("au", "0")))
        except ValueError:
            au = 0
        values = dict(lexicon.facs.get(au, {}))
    else:
        values = dict(lexicon.faces.get(attrs.get("lexeme", "").upper(), {}))
    side = attrs.get("side", "BOTH").upper()
    if behaviour_type == "faceFacs" and au == 46 and side == "RIGHT":  # the wink: its left eye's on the right
        values = {f"r_{k[2:]}" if k.startswith("l_") else k: v for k, v in values.items()}
    if side in ("LEFT", "RIGHT"):
        keep = "l_" if side == "LEFT" else "r_"
        values = {k: v for k, v in values.items() if not (k[:2] in ("l_", "r_") and not k.startswith(keep))}
    return {k: v * amount for k, v in values.items()}


class PoseDriver(MotionDriver):
    """Blends DOFs to fixed values and holds them: face expressions (attack to ``attackPeak``), postures
    (to ``ready``), and their shift variants (to ``end``; a shift holds its values afterwards: a face
    shift keeps its DOFs, a posture shift makes the values the rest pose)."""

    def __init__(self, name: str, keys: KeyTimes, values: Mapping[str, float], priority: int,
                 arrive: str, release: str | None = "relax", rest_after: bool = False, **kw):
        super().__init__(name, keys, priority, list(values), **kw)
        self.values = dict(values)
        self.arrive = arrive
        self.rest_after = rest_after
        self.hold_forever = release is None
        self.release_key = release or "end"

    def occupies_until(self) -> float:
        return math.inf if self.hold_forever else self.keys.end

    def setup(self) -> None:
        if not self.hold_forever:
            return super().setup()
        acquire = self.time_source.inverse(self.acquire)
        if self.stop_time is not None and self.stop_time < acquire:
            self.stopped = True
            return
        self.manager.at(acquire, self.begin_unit)
        if self.stop_time is not None:
            self.manager.at(self.stop_time, lambda t: self.stop(STOP_HANDOVER))

    def handover(self) -> float:
        return STOP_HANDOVER if self.rest_after else super().handover()

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if self.rest_after and idle is not None:
            for name, v in self.values.items():
                if name in idle.base:
                    idle.set_base(name, float(self.arbitrator.current[self.body.dof(name)]), t)

    def on_tick(self, t: np.ndarray) -> None:
        n = len(t)
        rest = self.body.rest_pose()
        target = {}
        for k, v in self.values.items():  # root translations are offsets from the rest position
            target[k] = np.full(n, v + (rest[self.body.dof(k)] if k.startswith("HumanoidRoot.t") else 0.0))
        self.write_held(blend_in(self, target, t, self.begun, self.keys.time(self.arrive)))


class TransitionDriver(MotionDriver):
    """BMLT's transition: the named joints move from the pose they are in at its start to the rest pose by
    its end (our motion units start from the pose they find, so the next behaviour takes over from there),
    then are handed over."""

    def __init__(self, name: str, keys: KeyTimes, dofs, **kw):
        self.moved = list(dofs)  # DOF names
        super().__init__(name, keys, PRIORITY["behaviour"], self.moved, **kw)
        self.release_key = "end"

    def handover(self) -> float:
        return STOP_HANDOVER

    def on_tick(self, t: np.ndarray) -> None:
        rest = self.body.rest_pose()
        target = {d: np.full(len(t), rest[self.body.dof(d)]) for d in self.moved}
        self.write_held(blend_in(self, target, t, self.begun, self.keys.end))


# --------------------------------------------------------------------------------------------- locomotion, speech
class LocomotionDriver(MotionDriver):
    """Walks the root to a goal (a point short of the target) between start and end, legs swinging;
    the goal becomes the rest position of the root."""

    STEP_RATE = 1.8  # steps per second

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, **kw):
        dofs = ["HumanoidRoot.tx", "HumanoidRoot.tz", "HumanoidRoot.yaw", "l_hip.pitch", "r_hip.pitch",
                "l_knee.pitch", "r_knee.pitch"]
        super().__init__(name, keys, PRIORITY["shift"], dofs, **kw)
        self.release_key = "end"
        self.target = np.asarray(target, dtype=float)
        self.goal: np.ndarray | None = None

    def handover(self) -> float:
        return STOP_HANDOVER

    def on_dof_grant(self, dofs, t, current, blend) -> None:
        super().on_dof_grant(dofs, t, current, blend)
        if self.goal is None:
            here = np.array([self.start_value("HumanoidRoot.tx"), self.start_value("HumanoidRoot.tz")])
            there = self.target[[0, 2]]
            d = there - here
            dist = float(np.linalg.norm(d))
            self.goal = here if dist < 0.7 else here + d * (dist - 0.6) / dist

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if idle is not None:
            for name in ("HumanoidRoot.tx", "HumanoidRoot.tz"):
                idle.set_base(name, float(self.arbitrator.current[self.body.dof(name)]), t)

    def on_tick(self, t: np.ndarray) -> None:
        t0, t1 = self.begun, self.keys.end
        here = np.array([self.start_value("HumanoidRoot.tx"), self.start_value("HumanoidRoot.tz")])
        f = EASE(frac(t, t0, t1))
        pos = here + np.multiply.outer(f, self.goal - here)
        d = self.goal - here
        heading = math.degrees(math.atan2(d[0], d[1])) if np.linalg.norm(d) > 1e-6 else 0.0
        turn = np.sin(np.pi * frac(t, t0, t1)) ** 0.5
        walking = np.sin(np.pi * frac(t, t0, t1))
        phase = 2 * np.pi * self.STEP_RATE / 2 * (t - t0)
        values = {"HumanoidRoot.tx": pos[:, 0], "HumanoidRoot.tz": pos[:, 1],
                  "HumanoidRoot.yaw": heading * turn,
                  "l_hip.pitch": -20 * walking * np.sin(phase), "r_hip.pitch": 20 * walking * np.sin(phase),
                  "l_knee.pitch": 30 * walking * np.maximum(0, np.sin(phase + np.pi / 2)),
                  "r_knee.pitch": 30 * walking * np.maximum(0, -np.sin(phase + np.pi / 2))}
        self.write_held(values)


class SpeechJawDriver(MotionDriver):
    """The jaw opening and closing at syllable rate while speech plays (start to end)."""

    SYLLABLE_RATE = 4.3

    def __init__(self, name: str, keys: KeyTimes, **kw):
        super().__init__(name, keys, PRIORITY["speech"], ["temporomandibular.pitch"], **kw)
        self.release_key = keys.sync_ids[-1]

    def release_time(self) -> float:
        return self.keys.end

    def on_tick(self, t: np.ndarray) -> None:
        t0, t1 = self.keys.start, self.keys.end
        env = np.clip(np.minimum(t - t0, t1 - t) / 0.1, 0, 1)
        jaw = 9.0 * (0.5 - 0.5 * np.cos(2 * np.pi * self.SYLLABLE_RATE * (t - t0)))
        self.write_held({"temporomandibular.pitch": self.start_value("temporomandibular.pitch") * (1 - env) + jaw * env})
