"""The body side of agentsim: what moves, when, and which driver owns each joint.

A timed BML plan says *when* things happen; this package says *what the body does* then, in the
manner of Chang's Pantomime (drivers, a priority Arbitrator over degrees of freedom, a Driver Manager
with motor functions) and Elckerlyc's Animation Player (motion units whose keys are placed by linear
time warping, transition units, replacement groups):

===============  ========================================================================================
module           what lives there
===============  ========================================================================================
``body``         the H-Anim style skeleton: joints (a jaw and four lip joints in the face), offsets,
                 Euler channels (BVH order ZXY), joint limits, degrees of freedom by name
                 (``"skullbase.pitch"``), forward kinematics and the analytic two-link arm inverse
                 kinematics.
``units``        motion units: the preferred key times and phases of every kind of motion, the binding
                 of a behaviour to its unit, and where a timed unit is at a given time.
``time_source``  TimeSource: the time a driver is advanced by (the clock, or animator time that
                 follows the speech).
``drivers``      Driver and SlaveDriver (one motor skill each, master and slave) and the priorities.
``arbitrator``   the Arbitrator: one writer per DOF and frame, granted by priority.
``background``   the background drivers: idle sway, breathing, eye fixation and the eye-blink reflex.
``scene``        named points of the world that behaviours aim at.
``motion``       the MotionDriver base of the motion units: key times and linear time warping,
                 blending curves and the hold interpolator, replacement groups.
``arms``         gesture strokes (the ictus of beats and conducting patterns at the stroke key),
                 pointing by inverse kinematics, hand shapes and key frame sequences.
``head``         nods, shakes and tilts, head turns, gaze with its eyes, saccades and held eyelids.
``pose``         face expressions and postures blended to and held, locomotion, the jaw during speech.
``lexicon``      the Lexicon: what gesture, face and posture lexemes, FACS units and visemes play, read
                 from the data files beside it and from users' lexicon files (no numpy); one a realizer.
``lips``         lip sync: mouth shapes (jaw, lip spread and rounding, lip closure), the drivers of
                 visemes and of keyframed face channels, and the monotone cubic their keys follow.
``functions``    motor functions by name with default parameters (background drivers, motion units).
``manager``      the DriverManager: drivers, Arbitrator and motor functions of one body, and the event
                 sweep that evaluates poses.
``behaviours``   ``build_drivers``: the motion drivers that play a list of timed BML behaviours.
``output``       ``evaluate_poses`` (a PoseStream of joint angles and joint positions per frame),
                 ``write_bvh`` and ``write_npz``.
``timeline``     ``plot_timeline``: behaviours, phases, pegs, feedback and the words heard on one time
                 axis, for a run or a window of it, and a long run's overview.
``pictures``     ``plot_timelines``: a long run as an overview plus one picture per window, drawn side by
                 side by worker processes.
``analysis``     measuring where the motion really has its stroke (ictus, nod bottom, pointing arrival)
                 against the stroke feedback.
===============  ========================================================================================

Times are seconds, lengths metres, joint angles degrees.
"""

import importlib

#: What the package offers, and the module it comes from: imported on first use, so that the modules that
#: need only a part (the units, when planning) do not load the body, numpy and the plots with it.
_EXPORTS = {
    "Arbitrator": "arbitrator", "Body": "body", "Driver": "drivers", "DriverManager": "manager", "Lexicon": "lexicon",
    "PoseStream": "output", "evaluate_poses": "output", "write_bvh": "output", "write_npz": "output",
    "TimeSource": "time_source", "plot_timeline": "timeline", "plot_timelines": "pictures",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
