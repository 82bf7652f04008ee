"""Physical controllers: what a ``<bmlt:controller class="...">`` behaviour asks of the physical body.

Three classes, after AsapRealizer's: ``BalanceController`` keeps the centre of mass over the support polygon
(PD servos on the pelvis, legs and spine, and ankle and hip corrections from the centre of mass's offset and
velocity), ``HangController`` lets the joints of a part hang in gravity, damped, and ``JointController``
drives named joints to target angles with PD servos. Each is read from a behaviour's ``class`` attribute and
its ``<bmlt:parameter name= value=>`` children by :func:`controller_spec`, which refuses (ValueError, naming
it) an unknown class, part or parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

#: The joints of each part a HangController can take.
PARTS = {
    "left_arm": ("l_shoulder", "l_elbow", "l_wrist"),
    "right_arm": ("r_shoulder", "r_elbow", "r_wrist"),
    "head": ("vc4", "skullbase"),
}
#: The joints a BalanceController holds (with the root): the pelvis, the legs, the lumbar and thoracic spine.
LEGS = tuple(f"{s}_{j}" for s in ("l", "r") for j in ("hip", "knee", "ankle"))
BALANCE_JOINTS = ("sacroiliac", *LEGS, "vl5", "vt10")
#: The joints JointController may name (those the model simulates, but the root).
JOINTABLE = (*BALANCE_JOINTS, "vc4", "skullbase", *(f"{s}_{j}" for s in ("l", "r")
                                                   for j in ("shoulder", "elbow", "wrist")))

#: The joints of the spine a BalanceController holds with its own (softer) gains, and those gains' defaults.
SPINE = ("vl5", "vt10")
SPINE_KP, SPINE_KD = 300.0, 30.0

#: Each class's parameters and their defaults (None: required or free-form).
DEFAULTS = {
    # kp, kd: the servos' stiffness (N m/rad) and damping (N m s/rad) on the pelvis and legs; spine_kp,
    # spine_kd: those of the lumbar and thoracic spine (vl5, vt10: softer, so that the arms' strokes move the
    # trunk); com_kp, com_kd: degrees of ankle and hip correction per centimetre of centre-of-mass offset and
    # per cm/s of its speed; pelvis_height: the pelvis's height to hold (m; default: as the animation stands)
    "BalanceController": {"kp": 1500.0, "kd": 150.0, "spine_kp": SPINE_KP, "spine_kd": SPINE_KD, "com_kp": 0.3,
                          "com_kd": 0.25, "pelvis_height": None},
    # damping (N m s/rad) of the hanging joints
    "HangController": {"part": None, "damping": 0.8},
    # kp, kd as the balance's; every other parameter names a DOF ("l_elbow.pitch") and its target (degrees)
    "JointController": {"kp": 300.0, "kd": 30.0},
}
CLASSES = tuple(DEFAULTS)


@dataclass
class ControllerSpec:
    """One controller: its class, the joints it makes physical, its parameters and (for JointController) its
    target angles (DOF name -> degrees)."""

    kind: str
    joints: tuple[str, ...]
    params: dict[str, float] = field(default_factory=dict)
    targets: dict[str, float] = field(default_factory=dict)
    start: float = 0.0
    end: float = math.inf
    name: str = ""


def _number(cls: str, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{cls} parameter {name!r} is not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{cls} parameter {name!r} is not finite: {text!r}")
    return value


def controller_spec(cls: str, params: dict[str, str]) -> ControllerSpec:
    """The controller a behaviour of class ``cls`` with parameters ``params`` (name -> text) asks for;
    ValueError (naming the unknown class, part or parameter) if it is not one this body has."""
    if cls not in DEFAULTS:
        raise ValueError(f"unknown controller class {cls!r} (known: {', '.join(CLASSES)})")
    defaults = DEFAULTS[cls]
    values: dict[str, float] = {k: v for k, v in defaults.items() if v is not None}
    targets: dict[str, float] = {}
    joints: tuple[str, ...] = ()
    for name, text in params.items():
        if cls == "HangController" and name == "part":
            if text not in PARTS:
                raise ValueError(f"unknown part {text!r} for HangController (known: {', '.join(PARTS)})")
            joints = PARTS[text]
        elif name in defaults:
            values[name] = _number(cls, name, text)
        elif cls == "JointController" and name.count(".") == 1 and name.split(".")[0] in JOINTABLE \
                and name.split(".")[1] in ("roll", "pitch", "yaw"):
            targets[name] = _number(cls, name, text)
        else:
            raise ValueError(f"unknown parameter {name!r} of {cls}")
    if cls == "HangController" and not joints:
        raise ValueError("HangController needs a parameter 'part' (left_arm, right_arm or head)")
    if cls == "BalanceController":
        joints = BALANCE_JOINTS
    if cls == "JointController":
        if not targets:
            raise ValueError("JointController needs a target angle, as <bmlt:parameter name=\"l_elbow.pitch\" "
                             "value=\"-90\"/>")
        joints = tuple(dict.fromkeys(n.split(".")[0] for n in targets))
    for key in ("kp", "kd", "spine_kp", "spine_kd", "damping", "com_kp", "com_kd"):
        if key in values and values[key] < 0:
            raise ValueError(f"{cls} parameter {key!r} must not be negative")
    if "pelvis_height" in values and not 0.3 <= values["pelvis_height"] <= 1.2:
        raise ValueError(f"{cls} parameter 'pelvis_height' must be between 0.3 and 1.2 m")
    return ControllerSpec(cls, joints, values, targets)


def default_balance(end: float = math.inf) -> ControllerSpec:
    """The BalanceController ``--physics`` runs for the whole run when the BML has none."""
    spec = controller_spec("BalanceController", {})
    spec.end, spec.name = end, "balance"
    return spec
