"""The physical body: a MuJoCo model generated from agentsim's skeleton.

Every simulated joint of :class:`~agentsim.animation.body.Body` becomes a MuJoCo body at the same offset
from its parent, turning about three hinges in the BVH channel order (``roll`` about z, ``pitch`` about x,
``yaw`` about y; MuJoCo composes a body's joints in the order they are declared, so the body's rotation is
``Rz(roll) @ Rx(pitch) @ Ry(yaw)``, the skeleton's own). The root (``HumanoidRoot``) has a free joint. The
world is the BVH's: +Y up (gravity -9.81 m/s^2 along Y), the character facing +Z, +X its left; the floor is
the plane y = 0 (friction 1).

The clavicles (:data:`WELDED`) have no hinges: they turn as animated. Not simulated: the fingers and the thumb (each hand is one rigid body on the wrist), the jaw, lips, eyes,
eyelids and brows (part of the head). Those joints stay kinematic whatever happens.

Masses, centres of mass and radii of gyration are de Leva's adjustments of Zatsiorsky and Seluyanov's
segment parameters for men (P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
Journal of Biomechanics 29(9), 1223-1230, 1996, table 4), for a body of :data:`MASS` kg. A segment's centre
of mass lies on the line from its proximal joint to its distal one at de Leva's fraction of that line; its
radii of gyration are de Leva's fractions of de Leva's mean segment length (table 1, scaled to a stature of
1.70 m). De Leva's middle trunk is split between the lumbar body (``HumanoidRoot``, below ``vl5``) and
``vl5`` by their lengths, his head-and-neck between ``vc4`` and ``skullbase`` by their lengths, and each
clavicle (``sternoclavicular``) takes 1 % of the body mass from his upper trunk (his table has no shoulder
girdle of its own). Capsules along the segments (a box for each foot) are the collision geometry only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim.animation.body import Body

#: Body mass (kg) and stature (m) of the simulated figure.
MASS = 73.0
STATURE = 1.70
#: de Leva (1996) male mean stature (m), which his segment lengths belong to.
DE_LEVA_STATURE = 1.741

#: de Leva 1996 table 4 (males): segment -> (mass % of body, centre of mass % from the proximal end,
#: radii of gyration % of the length about the sagittal (x), longitudinal and transverse (z) axes,
#: mean length in metres from table 1).
DE_LEVA = {
    "head": (6.94, 50.02, (30.3, 26.1, 31.5), 0.2033),
    "upper_trunk": (15.96, 50.66, (50.5, 46.5, 32.0), 0.1707),
    "middle_trunk": (16.33, 45.02, (48.2, 46.8, 38.3), 0.2155),
    "lower_trunk": (11.17, 61.15, (61.5, 58.7, 55.1), 0.1457),
    "upper_arm": (2.71, 57.72, (28.5, 15.8, 26.9), 0.2817),
    "forearm": (1.62, 45.74, (27.6, 12.1, 26.5), 0.2689),
    "hand": (0.61, 79.00, (62.8, 40.1, 51.3), 0.0862),
    "thigh": (14.16, 40.95, (32.9, 14.9, 32.9), 0.4222),
    "shank": (4.33, 44.59, (25.5, 10.3, 24.9), 0.4340),
    "foot": (1.37, 44.15, (25.7, 12.4, 24.5), 0.2581),
}

#: The joints that are simulated, each with its de Leva segment, the share of that segment's mass it
#: takes, the point its segment runs to (its distal end, in its own frame; proximal end: the joint) and
#: its collision capsule's radius.
TRUNK = ("HumanoidRoot", "sacroiliac", "vl5", "vt10")
NECK = ("vc4", "skullbase")
SIDES = ("l", "r")
#: Joints simulated without hinges: their segment turns as the animation turns it (the simulation sets the
#: body's orientation a frame at a time) and no controller takes it. The clavicles move little, and their six
#: hinges would cost a quarter of a step (a step's constraint solver grows with the cube of the hinges).
WELDED = ("l_sternoclavicular", "r_sternoclavicular")
#: The foot box: from the heel to the toes (z), its sole on the floor at rest (y), relative to the ankle.
FOOT_HEEL, FOOT_TOE, FOOT_HALF_WIDTH, FOOT_SOLE = -0.07, 0.18, 0.05, -0.04


def _segments(body: Body) -> dict[str, tuple[str, float, tuple[float, float, float], float]]:
    off = {j.name: np.asarray(j.offset) for j in body.joints}
    root_len, vl5_len = float(np.linalg.norm(off["vl5"])), float(np.linalg.norm(off["vt10"]))
    neck_len, head_len = float(np.linalg.norm(off["skullbase"])), 0.18
    seg = {
        "HumanoidRoot": ("middle_trunk", root_len / (root_len + vl5_len), tuple(off["vl5"]), 0.10),
        "sacroiliac": ("lower_trunk", 1.0, (0.0, -0.06, 0.0), 0.09),
        "vl5": ("middle_trunk", vl5_len / (root_len + vl5_len), tuple(off["vt10"]), 0.11),
        "vt10": ("upper_trunk", 1.0 - 2 * 1.0 / 15.96, tuple(off["vc4"]), 0.12),
        "vc4": ("head", neck_len / (neck_len + head_len), tuple(off["skullbase"]), 0.05),
        "skullbase": ("head", head_len / (neck_len + head_len), (0.0, head_len, 0.02), 0.095),
    }
    for s in SIDES:
        seg[f"{s}_sternoclavicular"] = ("upper_trunk", 1.0 / 15.96, tuple(off[f"{s}_shoulder"]), 0.04)
        seg[f"{s}_shoulder"] = ("upper_arm", 1.0, tuple(off[f"{s}_elbow"]), 0.045)
        seg[f"{s}_elbow"] = ("forearm", 1.0, tuple(off[f"{s}_wrist"]), 0.038)
        seg[f"{s}_wrist"] = ("hand", 1.0, tuple(off[f"{s}_fingers"]), 0.035)
        seg[f"{s}_hip"] = ("thigh", 1.0, tuple(off[f"{s}_knee"]), 0.07)
        seg[f"{s}_knee"] = ("shank", 1.0, tuple(off[f"{s}_ankle"]), 0.05)
        seg[f"{s}_ankle"] = ("foot", 1.0, (0.0, FOOT_SOLE / 2, FOOT_TOE), 0.0)
    return seg


def segment_radii(body: Body) -> dict[str, float]:
    """The radius (m) of each simulated joint's segment, the capsule from the joint towards its child (the
    head's sphere for ``skullbase``; the feet, boxes in the model, half their height)."""
    return {name: (-FOOT_SOLE if name.endswith("_ankle") else radius)
            for name, (_, _, _, radius) in _segments(body).items()}


#: Names of the simulated joints (every other joint of the skeleton is kinematic, always).
def simulated_joints(body: Body) -> list[str]:
    """The skeleton's joints that the model simulates, in the skeleton's (BVH) order."""
    names = set(_segments(body))
    return [j.name for j in body.joints if j.name in names]


@dataclass
class Layout:
    """Where each simulated joint's three hinges are in the model: ``qpos``/``qvel`` addresses (roll, pitch,
    yaw; -1 for an axis the skeleton never turns, which has no hinge), and the MuJoCo body id of each joint."""

    joints: list[str]
    qpos: dict[str, tuple[int, int, int]]
    dof: dict[str, tuple[int, int, int]]
    body_id: dict[str, int]
    foot_geoms: frozenset[int]
    floor_geom: int
    actuator: dict[str, tuple[int, int, int]]


def _fmt(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in v)


def inertial(body: Body, joint: str) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre of mass (in the joint's frame) and diagonal inertia (kg m^2) of a simulated joint's
    segment, from de Leva's table."""
    segment, share, distal, _ = _segments(body)[joint]
    mass_pct, com_pct, radii, length = DE_LEVA[segment]
    mass = MASS * mass_pct / 100.0 * share
    distal = np.asarray(distal, dtype=float)
    if joint.endswith("_ankle"):  # from the heel to the toes
        heel = np.array([0.0, FOOT_SOLE / 2, FOOT_HEEL])
        com = heel + com_pct / 100.0 * (distal - heel)
        length_axis = 2
    else:
        com = com_pct / 100.0 * distal
        if joint in ("vl5", "vt10", "HumanoidRoot", "vc4", "skullbase", "sacroiliac"):
            com = (1 - com_pct / 100.0) * distal if joint != "sacroiliac" else com  # de Leva measures from the top
        length_axis = 1
    scale = length * STATURE / DE_LEVA_STATURE
    r_sag, r_long, r_trans = (scale * r / 100.0 for r in radii)
    inertia = np.array([r_sag, r_long, r_trans]) ** 2 * mass
    if length_axis == 2:
        inertia = np.array([r_sag, r_trans, r_long]) ** 2 * mass
    return mass, com, inertia


def build_xml(body: Body, timestep: float) -> str:
    """The MJCF text of the physical body (every simulated joint with three hinges and a servo on each
    hinge, gains zero until the simulation sets them; the servo's target is its activation, which moves at
    the rate its control says, so that a target can glide within a call of ``mj_step``)."""
    seg = _segments(body)
    names = simulated_joints(body)
    children: dict[str, list[str]] = {}
    for j in body.joints:
        if j.name in seg and j.parent:
            children.setdefault(j.parent, []).append(j.name)
    out: list[str] = []
    actuators: list[str] = []

    def geom(name: str) -> str:
        segment_, _, distal, radius = seg[name]
        if name.endswith("_ankle"):
            centre = (0.0, FOOT_SOLE / 2, (FOOT_HEEL + FOOT_TOE) / 2)
            half = (FOOT_HALF_WIDTH, -FOOT_SOLE / 2, (FOOT_TOE - FOOT_HEEL) / 2)
            return f'<geom name="{name}" type="box" pos="{_fmt(centre)}" size="{_fmt(half)}"/>'
        if name == "sacroiliac":
            return f'<geom name="{name}" type="capsule" fromto="-0.08 -0.05 0 0.08 -0.05 0" size="{radius}"/>'
        if name == "skullbase":
            return f'<geom name="{name}" type="sphere" pos="0 0.09 0.02" size="{radius}"/>'
        d = np.asarray(distal, dtype=float)
        length = float(np.linalg.norm(d))
        u = d / length
        a, b = u * min(radius, length / 2 - 1e-3), d - u * min(radius, length / 2 - 1e-3)
        return f'<geom name="{name}" type="capsule" fromto="{_fmt(a)} {_fmt(b)}" size="{radius}"/>'

    def visit(name: str, depth: int) -> None:
        j = body.joint[name]
        pad = "  " * depth
        mass, com, inertia = inertial(body, name)
        pos = (0.0, body.hip_height, 0.0) if j.parent is None else j.offset
        out.append(f'{pad}<body name="{name}" pos="{_fmt(pos)}">')
        out.append(f'{pad}  <inertial pos="{_fmt(com)}" mass="{mass:.6g}" diaginertia="{_fmt(inertia)}"/>')
        if j.parent is None:
            out.append(f'{pad}  <freejoint name="{name}"/>')
        elif name not in WELDED:
            for axis, vec in (("roll", "0 0 1"), ("pitch", "1 0 0"), ("yaw", "0 1 0")):
                lo, hi = j.limit(axis)
                if lo == hi == 0:
                    continue  # an axis the skeleton never turns (the knee's and elbow's roll, the wrist's yaw)
                if hi - lo < 2.0:
                    lo, hi = lo - 2.0, hi + 2.0
                if hi - lo >= 360.0:  # a whole turn (the shoulder): no limit, its angle may wrap
                    out.append(f'{pad}  <joint name="{name}.{axis}" type="hinge" axis="{vec}" limited="false"/>')
                else:
                    out.append(f'{pad}  <joint name="{name}.{axis}" type="hinge" axis="{vec}" limited="true" '
                               f'range="{lo - 3.0:g} {hi + 3.0:g}"/>')
                actuators.append(f'<general name="{name}.{axis}" joint="{name}.{axis}" dyntype="integrator" '
                                 f'gainprm="0" biasprm="0 0 0" biastype="affine" ctrllimited="false"/>')
        out.append(f"{pad}  {geom(name)}")
        for c in children.get(name, []):
            visit(c, depth + 1)
        out.append(f"{pad}</body>")

    visit(names[0], 2)
    return f"""<mujoco model="agentsim">
  <compiler angle="degree" inertiafromgeom="false"/>
  <option timestep="{timestep:.9g}" gravity="0 -9.81 0" integrator="implicitfast" cone="elliptic" impratio="10" tolerance="1e-6"/>
  <default>
    <joint armature="0.02" damping="0.5"/>
    <geom contype="1" conaffinity="0" condim="3" friction="1 0.005 0.0001" rgba="0.7 0.7 0.8 1"/>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" zaxis="0 1 0" contype="1" conaffinity="1"/>
{chr(10).join(out)}
  </worldbody>
  <actuator>
    {(chr(10) + '    ').join(actuators)}
  </actuator>
</mujoco>
"""


def _id(find, name: str) -> int:
    """The id of a MuJoCo element by name, -1 if the model has none (an axis a joint never turns)."""
    try:
        return int(find(name).id)
    except KeyError:
        return -1


def build_model(body: Body, timestep: float):
    """The MuJoCo model of ``body`` and its :class:`Layout`."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(build_xml(body, timestep))
    names = simulated_joints(body)
    qpos, dof, actuator, body_id = {}, {}, {}, {}
    for name in names:
        body_id[name] = model.body(name).id
        if name == names[0]:
            continue
        ids = [_id(model.joint, f"{name}.{a}") for a in ("roll", "pitch", "yaw")]
        qpos[name] = tuple(int(model.jnt_qposadr[i]) if i >= 0 else -1 for i in ids)
        dof[name] = tuple(int(model.jnt_dofadr[i]) if i >= 0 else -1 for i in ids)
        actuator[name] = tuple(_id(model.actuator, f"{name}.{a}") for a in ("roll", "pitch", "yaw"))
    feet = frozenset(model.geom(f"{s}_ankle").id for s in SIDES)
    return model, Layout(names, qpos, dof, body_id, feet, model.geom("floor").id, actuator)
