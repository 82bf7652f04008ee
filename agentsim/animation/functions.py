"""Motor functions: named motions with default parameters, of the background drivers and of the motion units.

A :class:`MotorFunctionExporter` offers motor functions and runs them (Pantomime); the
:class:`~agentsim.animation.manager.DriverManager` that registered it hands itself in when one is run.
"""

from __future__ import annotations

import math

import numpy as np

from agentsim.animation.arms import (
    KEYFRAMES, GestureDriver, HandShapeDriver, KeyframeDriver, PointingDriver, conducting_path, stroke_path,
)
from agentsim.animation.background import Breathing, EyeBlinkReflex
from agentsim.animation.drivers import Driver
from agentsim.animation.head import EyelidDriver, GazeDriver, HeadDriver, HeadTurnDriver, SaccadeDriver
from agentsim.animation.motion import KeyTimes
from agentsim.animation.units import BEAT, NOD, SHAKE
from agentsim.core.block import GESTURE_SYNCS


class MotorFunctionExporter:
    """Something that offers motor functions: names with default parameters, and a way to run them."""

    def list_interface(self) -> dict[str, dict[str, object]]:
        """Motor function name -> default parameters."""
        raise NotImplementedError

    def execute(self, name: str, at: float, args: dict[str, object], manager) -> Driver | None:
        """Run motor function ``name`` at time ``at`` with ``args`` (every parameter given) on ``manager``, the
        DriverManager that registered this exporter; returns the driver that plays (or changed) it."""
        raise NotImplementedError


class BackgroundFunctions(MotorFunctionExporter):
    """Motor functions of the background drivers: blink reflex on/off, a forced blink, breathing."""

    def __init__(self, blink: EyeBlinkReflex, breathing: Breathing):
        self.blink, self.breathing = blink, breathing

    def list_interface(self):
        return {"blinkreflex": {"msg": "on"}, "eyeblink": {"which": "both"},
                "breathing": {"rate": 15.0, "depth": 1.0}}

    def execute(self, name, at, args, manager):
        if name == "blinkreflex":
            self.blink.turn(str(args["msg"]).lower() != "off", at)
            return self.blink
        if name == "eyeblink":
            self.blink.force(at)
            return self.blink
        self.breathing.set_rate(at, float(args["rate"]), float(args["depth"]))
        return self.breathing


def _side(hand: str, default: str = "r") -> str:
    h = (hand or "").lower()
    if h.startswith("l"):
        return "l"
    if h.startswith("r"):
        return "r"
    return default


class MotionFunctions(MotorFunctionExporter):
    """The motor functions of the motion units (names and defaults after Pantomime's table 4; times in
    seconds, angles in degrees unless noted)."""

    def list_interface(self):
        return {
            "beat": {"hand": "right", "approach": 0.3, "retract": 0.3, "amount": 1.0, "lexeme": "BEAT"},
            "conduct": {"hand": "right", "meter": 4, "beat": 1, "approach": 0.3, "retract": 0.3, "amount": 1.0},
            "point": {"target": "", "x": 0.0, "y": 1.3, "z": 2.0, "hand": "", "approach": 0.5, "hold": 1.0,
                      "retract": 0.4},
            "nod": {"amt": 0.3, "duration": 1.0, "repeat": 1},
            "shake": {"amt": 0.3, "duration": 1.0, "repeat": 1},
            "tilt": {"amt": 0.3, "duration": 1.0},
            "headtowards": {"object": "", "x": 0.0, "y": 1.6, "z": 2.0, "approach": 0.5, "hold": 2.0,
                            "retract": 0.5},
            "saccade": {"target": "", "coord": "eyespace", "x": 0.0, "y": 0.0, "z": 0.5, "hold": 0.5,
                        "dYRot": 0.0, "dXRot": 0.0},
            "eyetrack": {"target": "", "tol": 0.1, "approach": 0.3, "duration": 2.0},
            "gaze track": {"target": "", "tol": 0.1, "approach": 0.3, "duration": 2.0},
            "handshape": {"shape": "relaxed", "hand": "right", "approach": 0.3, "duration": 1.0},
            "keyframe": {"name": "wave", "hand": "right", "repeat": 1},
            "eyelids": {"amount": 0.0, "approach": 0.1, "duration": 1.0},
        }

    def execute(self, name, at, a, manager):
        scene = manager.scene
        label = f"{name}@{at:g}"
        if name in ("beat", "conduct"):
            side = _side(str(a["hand"]))
            keys = KeyTimes.scaled(GESTURE_SYNCS, BEAT.preferred(), at, "stroke", float(a["approach"]),
                                   float(a["retract"]) + 0.2)
            if name == "beat":
                path = stroke_path(manager.lexicon, str(a["lexeme"])).scaled(float(a["amount"]))
            else:
                path = conducting_path(manager.lexicon, int(a["meter"]), int(a["beat"]), float(a["amount"]))
            return manager.add(GestureDriver(label, keys, side, path))
        if name == "point":
            target = scene.point(str(a["target"])) if a["target"] else np.array([a["x"], a["y"], a["z"]], float)
            side = _side(str(a["hand"]), "l" if target[0] > 0 else "r")
            ap, hold, rt = float(a["approach"]), float(a["hold"]), float(a["retract"])
            times = at + np.array([0.0, 0.6 * ap, 0.65 * ap, ap, ap + 0.15, ap + hold, ap + hold + rt])
            keys = KeyTimes(GESTURE_SYNCS, times, times - at)
            return manager.add(PointingDriver(label, keys, side, target))
        if name in ("nod", "shake", "tilt"):
            unit = SHAKE if name == "shake" else NOD
            rep = int(a.get("repeat", 1))
            keys = KeyTimes.scaled(GESTURE_SYNCS, unit.preferred(rep), at, duration=float(a["duration"]))
            return manager.add(HeadDriver(label, keys, name.upper(), 40.0 * float(a["amt"]), rep))
        if name == "headtowards":
            target = scene.point(str(a["object"])) if a["object"] else np.array([a["x"], a["y"], a["z"]], float)
            ap, hold, rt = float(a["approach"]), float(a["hold"]), float(a["retract"])
            times = at + np.array([0.0, ap, ap + hold, ap + hold + rt])
            keys = KeyTimes(("start", "ready", "relax", "end"), times, times - at)
            return manager.add(HeadTurnDriver(label, keys, target, arrive="ready"))
        if name == "saccade":
            hold = float(a["hold"])
            times = at + np.array([0.0, 0.05, 0.05 + hold])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            if a["target"]:
                return manager.add(SaccadeDriver(label, keys, scene.point(str(a["target"]))))
            if a["dXRot"] or a["dYRot"]:
                return manager.add(SaccadeDriver(label, keys, offset=(float(a["dXRot"]), float(a["dYRot"]))))
            p = np.array([a["x"], a["y"], a["z"]], dtype=float)
            if str(a["coord"]).lower() == "eyespace":  # origin between the eyes, z along the nose, at rest
                p = p + np.array([0.0, 1.665, 0.085])
            return manager.add(SaccadeDriver(label, keys, p))
        if name in ("eyetrack", "gaze track"):
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur, ap + dur + 0.3])
            keys = KeyTimes(("start", "ready", "relax", "end"), times, times - at)
            return manager.add(GazeDriver(label, keys, scene.point(str(a["target"])),
                                          tolerance=math.degrees(float(a["tol"]))))
        if name == "handshape":
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            return manager.add(HandShapeDriver(label, keys, _side(str(a["hand"])), str(a["shape"])))
        if name == "keyframe":
            if str(a["name"]) not in KEYFRAMES:
                raise KeyError(f"no key frame sequence {a['name']!r} (known: {', '.join(sorted(KEYFRAMES))})")
            return manager.add(KeyframeDriver(label, at, _side(str(a["hand"])), str(a["name"]), int(a["repeat"])))
        if name == "eyelids":
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            return manager.add(EyelidDriver(label, keys, float(a["amount"])))
        raise KeyError(name)
