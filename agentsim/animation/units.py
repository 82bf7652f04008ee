"""Motion units: the preferred timing of each kind of motion (its keys and phases), and where a timed one is now.

A behaviour is bound to a :class:`MotionUnit` by its type and lexeme (:func:`motion_unit`); the
animation engine stretches the unit's keys between the constraints, and the motion drivers place their
motion between the keys by linear time warping.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass

from agentsim.animation.lexicon import Lexicon
from agentsim.core.block import Behaviour


@dataclass(frozen=True)
class MotionUnit:
    """A motion's preferred timing: seconds from its start to each sync point, and its duration limits.

    Phases lie between consecutive keys (for a gesture: preparation, pre-stroke hold, stroke, post-stroke
    hold, retraction). The canonical time of a key is its preferred time over the preferred duration.
    """

    name: str
    keys: tuple[float, ...]
    min_duration: float = 0.05
    max_duration: float = 3600.0
    #: index of the key range (start, end) that grows with ``repetition``
    repeat: tuple[int, int] | None = None

    def preferred(self, repetition: int = 1) -> list[float]:
        keys = list(self.keys)
        if self.repeat is not None and repetition > 1:
            a, b = self.repeat
            extra = (keys[b] - keys[a]) * (repetition - 1)
            keys = keys[:b] + [k + extra for k in keys[b:]]
        return keys

    def canonical(self, repetition: int = 1) -> list[float]:
        """Keys as canonical times 0 <= alpha <= 1."""
        keys = self.preferred(repetition)
        span = keys[-1] - keys[0]
        return [(k - keys[0]) / span if span > 0 else 0.0 for k in keys]


#                                 start ready sStart stroke sEnd relax  end
BEAT = MotionUnit("beat", (0.0, 0.30, 0.32, 0.45, 0.55, 0.65, 0.95), min_duration=0.1)
GESTURE = MotionUnit("gesture", (0.0, 0.40, 0.45, 0.65, 0.85, 1.00, 1.40), min_duration=0.15)
POINTING = MotionUnit("pointing", (0.0, 0.50, 0.55, 0.70, 0.85, 1.60, 2.00), min_duration=0.2)
NOD = MotionUnit("nod", (0.0, 0.10, 0.10, 0.25, 0.40, 0.40, 0.55), min_duration=0.1, repeat=(2, 4))
SHAKE = MotionUnit("shake", (0.0, 0.10, 0.10, 0.30, 0.50, 0.50, 0.65), min_duration=0.1, repeat=(2, 4))
#                                 start ready relax end
GAZE = MotionUnit("gaze", (0.0, 0.30, 1.80, 2.10), min_duration=0.05)
POSTURE = MotionUnit("posture", (0.0, 1.00, 3.00, 4.00), min_duration=0.3)
#                                 start attackPeak relax end
FACE = MotionUnit("face", (0.0, 0.20, 1.00, 1.30), min_duration=0.05)
#                                 start end
SHIFT = MotionUnit("shift", (0.0, 0.60), min_duration=0.05)
POSTURE_SHIFT = MotionUnit("postureShift", (0.0, 1.50), min_duration=0.2)
LOCOMOTION = MotionUnit("locomotion", (0.0, 2.00), min_duration=0.2)
#: BMLT's transition: named joints move from the pose they are in to the rest pose
TRANSITION = MotionUnit("transition", (0.0, 0.50), min_duration=0.0)

#: A viseme of lip sync (other realizers' ``<lips>``): the lips reach the shape at ready, hold it to relax
#                                 start ready relax end
LIPS = MotionUnit("lips", (0.0, 0.05, 0.12, 0.17), min_duration=0.0)
#: Keyframed face channels (other realizers' ``<curves>``); its keys give its duration
CURVES = MotionUnit("curves", (0.0, 1.00), min_duration=0.0)

_BY_TYPE = {
    "pointing": POINTING, "gaze": GAZE, "posture": POSTURE, "faceLexeme": FACE, "faceFacs": FACE,
    "face": FACE, "gazeShift": SHIFT, "headDirectionShift": SHIFT, "faceShift": SHIFT,
    "postureShift": POSTURE_SHIFT, "locomotion": LOCOMOTION, "transition": TRANSITION,
    "lips": LIPS, "curves": CURVES,
}


#: A MURML gesture made of static constraints: the hand reaches its form by ready and holds it through the
#: stroke; a dynamic one moves through the stroke (strokeStart to strokeEnd).
#                                 start ready sStart stroke sEnd relax  end
MURML_STATIC = MotionUnit("murml", (0.0, 0.50, 0.55, 0.60, 0.80, 1.00, 1.45), min_duration=0.15)
MURML_DYNAMIC = MotionUnit("murml", (0.0, 0.45, 0.45, 0.75, 1.05, 1.20, 1.65), min_duration=0.15)


@functools.lru_cache(maxsize=256)
def _murml_unit(kind: str, description: str) -> MotionUnit:
    form = json.loads(description) if description else {}
    frames = (form.get("keyframing") or {}).get("frames")
    if frames:
        # a key frame animation: its frames span start (at ftime 0) to end (at the last ftime)
        d = max(frames[-1]["ftime"], 0.1)
        keys = (0.0, 0.1 * d, 0.1 * d, 0.5 * d, 0.9 * d, 0.9 * d, d) if kind == "murmlgesture" else (
            0.0, 0.1 * d, 0.9 * d, d)
        return MotionUnit("murml keyframes", keys, min_duration=0.05)
    if kind == "murmlface":
        return FACE

    def dynamic(items) -> bool:
        return any(c["op"] == "dynamic" or dynamic(c.get("children", ())) for c in items)

    return MURML_DYNAMIC if dynamic(form.get("constraints", ())) else MURML_STATIC


def motion_unit(behaviour: Behaviour, lexicon: Lexicon | None = None) -> MotionUnit:
    """The motion unit a behaviour is bound to (the gesture binding): a gesture lexeme that is a MURML form in
    ``lexicon`` (default: the built-in one) is timed as that form."""
    if behaviour.type in ("murmlgesture", "murmlface"):
        return _murml_unit(behaviour.type, behaviour.params.get("murml", ""))
    lexeme = behaviour.attributes.get("lexeme", "").upper()
    if behaviour.type == "gesture":
        form = (lexicon if lexicon is not None else Lexicon.builtin()).form(lexeme) if lexeme else None
        if form is not None:  # a lexeme of the lexicon that is a MURML form
            return _murml_unit("murmlgesture", form)
        return BEAT if lexeme in ("", "BEAT") else GESTURE
    if behaviour.type == "head":
        return SHAKE if lexeme == "SHAKE" else NOD
    return _BY_TYPE[behaviour.type]


def curve_keys(behaviour: Behaviour) -> dict[str, list[tuple[float, float]]]:
    """The channels of a ``curves`` behaviour: name -> (seconds from its start, value) keys, in time order.

    The reader stores each channel as ``params["curve:<name>"] = "t1 v1 t2 v2 ..."``.
    """
    channels = {}
    for key, value in behaviour.params.items():
        if key.startswith("curve:"):
            numbers = [float(x) for x in value.split()]
            channels[key[6:]] = sorted(zip(numbers[0::2], numbers[1::2]))
    return channels


def curves_duration(behaviour: Behaviour) -> float:
    """How long a ``curves`` behaviour lasts: to its last key."""
    return max((keys[-1][0] for keys in curve_keys(behaviour).values() if keys), default=0.0)


#: The most repetitions a behaviour plays (``repetition="1000000"`` plays this many, with a warning).
MAX_REPETITION = 100


def read_repetition(text: str) -> tuple[int, str | None]:
    """The repetitions a ``repetition`` attribute asks for, and what is wrong with it (None: nothing).

    A whole number from 1 to :data:`MAX_REPETITION` is taken as it is; a larger one is clamped to
    :data:`MAX_REPETITION`; a fraction is rounded down; anything else (``inf``, ``nan``, ``-1``, ``abc``)
    is read as 1."""
    try:
        value = float(text)
    except ValueError:
        return 1, f"repetition={text!r} is not a number; played once"
    if value != value or value in (math.inf, -math.inf):
        return 1, f"repetition={text!r} is not a finite number; played once"
    if value < 1:
        return 1, f"repetition={text!r} is less than 1; played once"
    if value > MAX_REPETITION:
        return MAX_REPETITION, f"repetition={text!r} is more than the {MAX_REPETITION} repetitions played; " \
                               f"clamped to {MAX_REPETITION}"
    if not value.is_integer():
        return int(value), f"repetition={text!r} is not a whole number; {int(value)} repetitions played"
    return int(value), None


def repetition(behaviour: Behaviour) -> int:
    return read_repetition(behaviour.attributes.get("repetition", "1"))[0]


PHASE_NAMES = {
    ("start", "ready"): "preparation", ("ready", "strokeStart"): "pre-stroke hold",
    ("strokeStart", "stroke"): "stroke", ("stroke", "strokeEnd"): "stroke",
    ("strokeEnd", "relax"): "post-stroke hold", ("relax", "end"): "retraction",
    ("ready", "relax"): "hold", ("start", "attackPeak"): "attack", ("attackPeak", "relax"): "sustain",
    ("start", "end"): "transition",
}


def motion_state(timed, t: float, lexicon: Lexicon | None = None) -> tuple[str, float] | None:
    """Where a timed motion unit is at global time ``t``: its phase and canonical time alpha (0..1).

    Alpha is found by linear time warping between the keys around ``t`` (Elckerlyc's f^-1(t)); None
    before the start or after the end. ``lexicon``: as for :func:`motion_unit`.
    """
    times = timed.times()
    if t < times[0] or t > times[-1]:
        return None
    unit = motion_unit(timed.behaviour, lexicon)
    alphas = unit.canonical(repetition(timed.behaviour))
    syncs = timed.sync_ids
    for i in range(len(times) - 1):
        t0, t1 = times[i], times[i + 1]
        if t < t1 or i == len(times) - 2:
            frac = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
            alpha = alphas[i] + frac * (alphas[i + 1] - alphas[i])
            return PHASE_NAMES.get((syncs[i], syncs[i + 1]), f"{syncs[i]}-{syncs[i + 1]}"), alpha
    return None
