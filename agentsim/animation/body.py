"""The body model: an H-Anim style skeleton with named degrees of freedom, forward and inverse kinematics.

Coordinates follow H-Anim (and BVH): +Y is up, the character faces +Z, +X is the character's left.
Every joint has three rotation channels written in BVH order ``Zrotation Xrotation Yrotation``; the
local rotation is ``Rz(roll) @ Rx(pitch) @ Ry(yaw)`` (degrees). The root also has three translation
channels. A degree of freedom (DOF) is one channel, addressed as ``"<joint>.<roll|pitch|yaw>"`` or, for
the root translation, ``"HumanoidRoot.tx|ty|tz"``.

With all rotations zero the figure stands with its arms hanging down, palms facing the thighs. Signs
that matter: a positive ``pitch`` turns a forward-pointing segment downwards (head nods down, eyes look
down); a positive ``yaw`` turns the face towards the character's left; for a hanging arm a positive
shoulder ``roll`` swings the hand towards +X (abduction of the left arm) and a negative elbow ``pitch``
bends the forearm forwards. The mouth: a positive jaw (``temporomandibular``) pitch opens it, a positive
``upper_lip`` and a negative ``lower_lip`` pitch close the lips, a positive ``l_lip_corner`` and a negative
``r_lip_corner`` yaw spread the mouth corners (the other signs round them).

Everything is vectorised over frames: angles are numpy arrays of shape ``(n,)``, rotations ``(n, 3, 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

#: DOF suffix -> BVH channel name, in BVH order for a joint.
ROTATION_AXES = (("roll", "Zrotation"), ("pitch", "Xrotation"), ("yaw", "Yrotation"))
#: Root translation DOF suffix -> BVH channel name.
TRANSLATION_AXES = (("tx", "Xposition"), ("ty", "Yposition"), ("tz", "Zposition"))

FREE = (-180.0, 180.0)
FIXED = (0.0, 0.0)
#: Rows of a pose array whose joint positions :meth:`Body.positions` computes at a time.
FK_ROWS = 16384


@dataclass
class Joint:
    """One joint of the skeleton.

    ``offset`` is the joint's position in its parent's frame at rest (metres). ``limits`` gives the
    (lowest, highest) angle in degrees of each rotation DOF. ``stage`` orders evaluation within a frame:
    drivers of lower stages are ticked first, so that a driver can read the pose of the joints above it
    (arms read the torso, eyes read the head, eyelids read the eyes). ``end_site`` is the tip of a leaf
    joint (BVH ``End Site``).
    """

    name: str
    parent: str | None
    offset: tuple[float, float, float]
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    stage: int = 1
    end_site: tuple[float, float, float] | None = None
    translation: bool = False

    def limit(self, axis: str) -> tuple[float, float]:
        return self.limits.get(axis, FREE)


def _arm(side: str) -> list[Joint]:
    s = 1.0 if side == "l" else -1.0
    return [
        Joint(f"{side}_sternoclavicular", "vt10", (0.02 * s, 0.20, 0.03),
              {"roll": (-20, 20), "pitch": (-10, 10), "yaw": (-20, 20)}, stage=0),
        Joint(f"{side}_shoulder", f"{side}_sternoclavicular", (0.16 * s, 0.0, -0.04),
              {"roll": FREE, "pitch": FREE, "yaw": FREE}),
        Joint(f"{side}_elbow", f"{side}_shoulder", (0.0, -0.29, 0.0),
              {"roll": FIXED, "pitch": (-160, 0), "yaw": (-90, 90)}),
        Joint(f"{side}_wrist", f"{side}_elbow", (0.0, -0.26, 0.0),
              {"roll": (-40, 40), "pitch": (-80, 80), "yaw": FIXED}),
        Joint(f"{side}_fingers", f"{side}_wrist", (0.0, -0.09, 0.0),
              {"roll": (-100, 10) if side == "l" else (-10, 100), "pitch": FIXED, "yaw": FIXED}),
        *_hand(side),
    ]


#: The four fingers: the knuckle (metacarpophalangeal joint) relative to the middle of the knuckles (the
#: ``fingers`` joint), then the lengths of the three phalanges (metres).
FINGERS = {"index": ((0.0, 0.004, 0.026), (0.045, 0.026, 0.020)),
           "middle": ((0.0, 0.0, 0.008), (0.049, 0.030, 0.021)),
           "ring": ((0.0, -0.003, -0.010), (0.045, 0.028, 0.020)),
           "pinky": ((0.0, -0.010, -0.026), (0.035, 0.020, 0.018))}
#: The names of the hand's joints on one side (without the ``l_``/``r_`` prefix), in H-Anim's naming.
HAND_JOINTS = ("thumb1", "thumb2", "thumb3", *(f"{f}{k}" for f in FINGERS for k in (1, 2, 3)))


def _hand(side: str) -> list[Joint]:
    """H-Anim's level-of-articulation-2 hand: the thumb (``thumb1`` at the carpometacarpal joint, ``thumb2``,
    ``thumb3``) on the wrist, and four fingers of three joints each (``index1`` at the knuckle, ``index2``,
    ``index3``; middle, ring, pinky) on the ``fingers`` joint, which stands for the knuckles as a whole and
    whose roll still curls all four (as before there were fingers); each end site is a finger tip.

    With the arm hanging the palm faces the thigh (the left palm -X), the fingers point down and the thumb
    is in front (+Z). A finger flexes towards the palm by its ``roll`` (negative on the left, positive on
    the right, as ``fingers.roll``); the knuckle's ``pitch`` spreads the finger (positive: towards the
    little finger, negative: towards the thumb, on either side). The thumb's ``roll`` brings it across the
    palm (the same signs as the fingers), its ``pitch`` swings it towards the index (negative: away), and
    ``thumb1.yaw`` turns it to oppose the fingers.
    """
    s = 1.0 if side == "l" else -1.0
    flex = (-100, 15) if side == "l" else (-15, 100)
    joints = []
    for finger, (knuckle, (a, b, c)) in FINGERS.items():
        joints += [
            Joint(f"{side}_{finger}1", f"{side}_fingers", knuckle, {"roll": flex, "pitch": (-20, 20), "yaw": FIXED}),
            Joint(f"{side}_{finger}2", f"{side}_{finger}1", (0.0, -a, 0.0), {"roll": flex, "pitch": FIXED,
                                                                            "yaw": FIXED}),
            Joint(f"{side}_{finger}3", f"{side}_{finger}2", (0.0, -b, 0.0), {"roll": flex, "pitch": FIXED,
                                                                            "yaw": FIXED},
                  end_site=(0.0, -c, 0.0)),
        ]
    joints += [
        Joint(f"{side}_thumb1", f"{side}_wrist", (-0.012 * s, -0.022, 0.022),
              {"roll": flex, "pitch": (-30, 60), "yaw": (-60, 60)}),
        Joint(f"{side}_thumb2", f"{side}_thumb1", (0.0, -0.032, 0.018), {"roll": flex, "pitch": (-10, 30),
                                                                         "yaw": FIXED}),
        Joint(f"{side}_thumb3", f"{side}_thumb2", (0.0, -0.030, 0.006), {"roll": flex, "pitch": FIXED,
                                                                         "yaw": FIXED},
              end_site=(0.0, -0.024, 0.0)),
    ]
    return joints


def _leg(side: str) -> list[Joint]:
    s = 1.0 if side == "l" else -1.0
    return [
        Joint(f"{side}_hip", "sacroiliac", (0.09 * s, -0.05, 0.0),
              {"roll": (-45, 45), "pitch": (-120, 30), "yaw": (-45, 45)}, stage=0),
        Joint(f"{side}_knee", f"{side}_hip", (0.0, -0.42, 0.0),
              {"roll": FIXED, "pitch": (0, 150), "yaw": (-10, 10)}, stage=0),
        Joint(f"{side}_ankle", f"{side}_knee", (0.0, -0.39, 0.0),
              {"roll": (-20, 20), "pitch": (-45, 30), "yaw": (-20, 20)}, stage=0,
              end_site=(0.0, -0.04, 0.14)),
    ]


def _eye(side: str) -> list[Joint]:
    s = 1.0 if side == "l" else -1.0
    return [
        Joint(f"{side}_eyeball", "skullbase", (0.032 * s, 0.075, 0.085),
              {"roll": FIXED, "pitch": (-30, 30), "yaw": (-35, 35)}, stage=2, end_site=(0.0, 0.0, 0.025)),
        Joint(f"{side}_eyelid", "skullbase", (0.032 * s, 0.075, 0.085),
              {"roll": FIXED, "pitch": (-25, 75), "yaw": FIXED}, stage=3, end_site=(0.0, 0.012, 0.015)),
        # the brow turns about a point behind the forehead, so that its pitch raises (negative) or lowers
        # its end site on the brow and its roll tilts that end (positive: the left brow's outer end up)
        Joint(f"{side}_eyebrow", "skullbase", (0.035 * s, 0.105, 0.045),
              {"roll": (-15, 15), "pitch": (-20, 15), "yaw": FIXED}, end_site=(0.02 * s, 0.0, 0.05)),
    ]


def _mouth() -> list[Joint]:
    """The lips: each of the four is a short segment whose end site is a lip edge or a mouth corner.

    ``upper_lip`` (on the skull) and ``lower_lip`` (on the jaw, so it drops with it) pitch their edges
    towards each other to close the mouth: a positive upper lip pitch lowers the upper lip, a negative
    lower lip pitch raises the lower one. At rest the two edges are 3 mm apart in front of the teeth.
    ``l_lip_corner`` and ``r_lip_corner`` turn about a vertical axis through a point behind the middle of
    the lips, so a corner swings outwards and back (spread, as in "ee") or inwards and forwards (rounded
    and protruded, as in "oo"). The pair follows the body's mirror convention for left and right (as
    shoulder and eyebrow rolls do): ``l_lip_corner.yaw`` spreads when positive, ``r_lip_corner.yaw`` when
    negative; about 1 mm of corner travel per 2 degrees. Their roll raises a corner (``l_lip_corner.roll``
    positive, ``r_lip_corner.roll`` negative, as the brows) and lowers it with the other sign.
    """
    return [
        Joint("lower_lip", "temporomandibular", (0.0, -0.028, 0.028),
              {"roll": FIXED, "pitch": (-20, 20), "yaw": FIXED}, end_site=(0.0, 0.003, 0.014)),
        Joint("upper_lip", "skullbase", (0.0, -0.018, 0.086),
              {"roll": FIXED, "pitch": (-10, 15), "yaw": FIXED}, end_site=(0.0, -0.004, 0.016)),
        Joint("l_lip_corner", "skullbase", (0.0, -0.025, 0.075),
              {"roll": (-20, 20), "pitch": FIXED, "yaw": (-30, 20)}, end_site=(0.026, 0.0, 0.02)),
        Joint("r_lip_corner", "skullbase", (0.0, -0.025, 0.075),
              {"roll": (-20, 20), "pitch": FIXED, "yaw": (-20, 30)}, end_site=(-0.026, 0.0, 0.02)),
    ]


def default_joints() -> list[Joint]:
    """The joints of the default figure (about 1.7 m tall), parents before children, in BVH order."""
    spine = (-180, 180)
    joints = [
        Joint("HumanoidRoot", None, (0.0, 0.0, 0.0), {"roll": spine, "pitch": spine, "yaw": spine},
              stage=0, translation=True),
        Joint("sacroiliac", "HumanoidRoot", (0.0, -0.05, 0.0),
              {"roll": (-30, 30), "pitch": (-30, 30), "yaw": (-30, 30)}, stage=0),
        *_leg("l"), *_leg("r"),
        Joint("vl5", "HumanoidRoot", (0.0, 0.10, -0.02),
              {"roll": (-30, 30), "pitch": (-30, 45), "yaw": (-40, 40)}, stage=0),
        Joint("vt10", "vl5", (0.0, 0.22, 0.0), {"roll": (-20, 20), "pitch": (-20, 30), "yaw": (-30, 30)},
              stage=0),
        Joint("vc4", "vt10", (0.0, 0.24, 0.01), {"roll": (-30, 30), "pitch": (-40, 40), "yaw": (-70, 70)}),
        Joint("skullbase", "vc4", (0.0, 0.08, 0.01),
              {"roll": (-30, 30), "pitch": (-40, 40), "yaw": (-70, 70)}, end_site=(0.0, 0.18, 0.0)),
        Joint("temporomandibular", "skullbase", (0.0, 0.0, 0.06),
              {"roll": FIXED, "pitch": (-5, 25), "yaw": FIXED}, end_site=(0.0, -0.05, 0.05)),
        *_mouth(),
        *_eye("l"), *_eye("r"),
        *_arm("l"), *_arm("r"),
    ]
    # BVH needs each joint's children right after it (depth-first); sort into that order.
    by_parent: dict[str | None, list[Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    ordered: list[Joint] = []

    def visit(j: Joint) -> None:
        ordered.append(j)
        for c in by_parent.get(j.name, []):
            visit(c)

    visit(by_parent[None][0])
    return ordered


# ---------------------------------------------------------------------------------------------- rotations
def euler_matrix(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrices ``Rz(roll) @ Rx(pitch) @ Ry(yaw)`` for angle arrays in degrees: shape (n, 3, 3)."""
    g, a, b = (np.radians(np.asarray(x, dtype=float)) for x in (roll, pitch, yaw))
    g, a, b = np.broadcast_arrays(g, a, b)
    cg, sg, ca, sa, cb, sb = np.cos(g), np.sin(g), np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    m = np.empty(g.shape + (3, 3))
    m[..., 0, 0] = cg * cb - sg * sa * sb
    m[..., 0, 1] = -sg * ca
    m[..., 0, 2] = cg * sb + sg * sa * cb
    m[..., 1, 0] = sg * cb + cg * sa * sb
    m[..., 1, 1] = cg * ca
    m[..., 1, 2] = sg * sb - cg * sa * cb
    m[..., 2, 0] = -ca * sb
    m[..., 2, 1] = sa
    m[..., 2, 2] = ca * cb
    return m


def matrix_euler(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(roll, pitch, yaw) in degrees with ``m = Rz(roll) @ Rx(pitch) @ Ry(yaw)``; pitch in [-90, 90].

    At gimbal lock (pitch = +-90 degrees) yaw is set to 0 and roll takes the whole turn.
    """
    m = np.asarray(m, dtype=float)
    sa = np.clip(m[..., 2, 1], -1.0, 1.0)
    pitch = np.arcsin(sa)
    ca = np.sqrt(np.maximum(0.0, 1.0 - sa * sa))
    locked = ca < 1e-7
    yaw = np.where(locked, 0.0, np.arctan2(-m[..., 2, 0], m[..., 2, 2]))
    roll = np.where(locked, np.arctan2(m[..., 1, 0], m[..., 0, 0]), np.arctan2(-m[..., 0, 1], m[..., 1, 1]))
    return np.degrees(roll), np.degrees(pitch), np.degrees(yaw)


def wrap180(angle):
    """Angles (degrees) wrapped into [-180, 180)."""
    return (np.asarray(angle, dtype=float) + 180.0) % 360.0 - 180.0


# ---------------------------------------------------------------------------------------------- the body
class Body:
    """A skeleton: joints in BVH (depth-first) order, their DOFs as columns of a pose array, kinematics.

    A *pose array* has one row per frame and one column per DOF (:attr:`dof_names`, in BVH channel
    order): degrees for rotations, metres for the root translation.
    """

    def __init__(self, joints: Sequence[Joint] | None = None, hip_height: float = 0.95):
        self.joints: list[Joint] = list(joints) if joints is not None else default_joints()
        self.joint = {j.name: j for j in self.joints}
        self.joint_index = {j.name: i for i, j in enumerate(self.joints)}
        self.hip_height = hip_height
        names: list[str] = []
        channels: list[tuple[str, str]] = []
        lo: list[float] = []
        hi: list[float] = []
        stages: list[int] = []
        self.rotation_columns: dict[str, tuple[int, int, int]] = {}
        for j in self.joints:
            if j.translation:
                for suffix, bvh in TRANSLATION_AXES:
                    names.append(f"{j.name}.{suffix}")
                    channels.append((j.name, bvh))
                    lo.append(-np.inf)
                    hi.append(np.inf)
                    stages.append(j.stage)
            start = len(names)
            for suffix, bvh in ROTATION_AXES:
                names.append(f"{j.name}.{suffix}")
                channels.append((j.name, bvh))
                a, b = j.limit(suffix)
                lo.append(a)
                hi.append(b)
                stages.append(j.stage)
            self.rotation_columns[j.name] = (start, start + 1, start + 2)
        self.dof_names = names
        self.channels = channels
        self.dof_index = {n: i for i, n in enumerate(names)}
        self.lower = np.array(lo)
        self.upper = np.array(hi)
        self.stage = np.array(stages, dtype=int)
        self.n_dofs = len(names)
        self.offsets = np.array([j.offset for j in self.joints], dtype=float)
        self.parent_index = [self.joint_index[j.parent] if j.parent else -1 for j in self.joints]
        root = self.joints[0]
        self._fk_columns: dict[tuple, np.ndarray] = {}  # rotation columns of the joints forward kinematics needs
        self.translation_columns = tuple(self.dof_index[f"{root.name}.{s}"] for s, _ in TRANSLATION_AXES)
        self._rest = self._make_rest()

    # ------------------------------------------------------------------ naming
    def dof(self, name: str) -> int:
        """Column of a DOF given by name (``"r_shoulder.yaw"``); KeyError with the known names if unknown."""
        try:
            return self.dof_index[name]
        except KeyError:
            raise KeyError(f"no DOF {name!r}; DOFs look like 'skullbase.pitch' or 'r_shoulder.yaw'") from None

    def dofs(self, names: Iterable[str]) -> list[int]:
        return [self.dof(n) for n in names]

    def joint_dofs(self, joint: str, axes: Iterable[str] = ("roll", "pitch", "yaw")) -> list[str]:
        return [f"{joint}.{a}" for a in axes]

    def chain(self, joint: str) -> list[int]:
        """Indices of the joints from the root down to ``joint``."""
        path = []
        i = self.joint_index[joint]
        while i >= 0:
            path.append(i)
            i = self.parent_index[i]
        return path[::-1]

    # ------------------------------------------------------------------ rest pose and limits
    def _make_rest(self) -> np.ndarray:
        rest = np.zeros(self.n_dofs)
        rest[self.translation_columns[1]] = self.hip_height
        for side, s in (("l", 1.0), ("r", -1.0)):
            values = {f"{side}_shoulder.roll": 6.0 * s, f"{side}_elbow.pitch": -12.0,
                      f"{side}_fingers.roll": -25.0 * s, f"{side}_wrist.pitch": -4.0}
            for name, v in values.items():
                if name in self.dof_index:
                    rest[self.dof_index[name]] = v
        return rest

    def rest_pose(self) -> np.ndarray:
        """The standing rest pose: arms hanging relaxed, fingers a little curled (one pose row)."""
        return self._rest.copy()

    def clip(self, columns, values: np.ndarray) -> np.ndarray:
        """Values limited to the joint limits of the DOF columns (last axis of ``values``)."""
        return np.clip(values, self.lower[columns], self.upper[columns])

    # ------------------------------------------------------------------ forward kinematics
    def local_rotations(self, pose: np.ndarray, joint: int) -> np.ndarray:
        r, p, y = self.rotation_columns[self.joints[joint].name]
        return euler_matrix(pose[:, r], pose[:, p], pose[:, y])

    def forward_kinematics(self, pose: np.ndarray, joints: Iterable[str] | None = None
                           ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """World rotation (n, 3, 3) and position (n, 3) of joints for every row of a pose array.

        With ``joints`` given, only those joints and their ancestors are computed (and returned).
        """
        pose = np.atleast_2d(np.asarray(pose, dtype=float))
        if joints is None:
            needed = range(len(self.joints))
        else:
            needed_set: set[int] = set()
            for name in joints:
                needed_set.update(self.chain(name))
            needed = sorted(needed_set)
        rot: dict[int, np.ndarray] = {}
        pos: dict[int, np.ndarray] = {}
        tx, ty, tz = self.translation_columns
        # every joint's local rotation at once (the same numbers as joint by joint)
        needed = tuple(needed)
        columns = self._fk_columns.get(needed)
        if columns is None:
            columns = self._fk_columns[needed] = np.array(
                [self.rotation_columns[self.joints[i].name] for i in needed], dtype=np.intp)
        angles = pose[:, columns]
        locals_ = euler_matrix(angles[..., 0], angles[..., 1], angles[..., 2])
        for k, i in enumerate(needed):  # parents come before children in BVH order
            local = locals_[:, k]
            parent = self.parent_index[i]
            if parent < 0:
                rot[i] = local
                pos[i] = np.stack([pose[:, tx], pose[:, ty], pose[:, tz]], axis=1) + self.offsets[i]
            else:
                rot[i] = rot[parent] @ local
                pos[i] = pos[parent] + rot[parent] @ self.offsets[i]
        wanted = needed if joints is None else [self.joint_index[j] for j in joints]
        return {self.joints[i].name: (rot[i], pos[i]) for i in wanted}

    def parent_frame(self, pose: np.ndarray, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """World rotation of ``joint``'s parent (n, 3, 3) and the joint's world position (n, 3).

        This is the frame the joint's own local rotation is expressed in.
        """
        i = self.joint_index[joint]
        parent = self.joints[self.parent_index[i]].name
        rot, pos = self.forward_kinematics(pose, [parent])[parent]
        return rot, pos + rot @ self.offsets[i]

    def positions(self, pose: np.ndarray, joints: Sequence[str]) -> np.ndarray:
        """World positions (n, len(joints), 3) of some joints (computed :data:`FK_ROWS` rows at a time, so
        that a long pose array needs no rotations of all its rows at once)."""
        pose = np.atleast_2d(np.asarray(pose, dtype=float))
        joints = list(joints)
        out = np.empty((len(pose), len(joints), 3))
        for a in range(0, len(pose), FK_ROWS):
            fk = self.forward_kinematics(pose[a:a + FK_ROWS], joints)
            for k, j in enumerate(joints):
                out[a:a + FK_ROWS, k] = fk[j][1]
        return out

    # ------------------------------------------------------------------ arms
    def arm_lengths(self, side: str) -> tuple[float, float]:
        """Upper arm and forearm length (shoulder to elbow, elbow to wrist) in metres."""
        upper = float(np.linalg.norm(self.joint[f"{side}_elbow"].offset))
        fore = float(np.linalg.norm(self.joint[f"{side}_wrist"].offset))
        return upper, fore

    def arm_reach(self, side: str) -> float:
        a, b = self.arm_lengths(side)
        return a + b

    def arm_ik(self, side: str, target, swivel: float | np.ndarray = 0.0, elbow_hint=None) -> dict[str, np.ndarray]:
        """Analytic two-link inverse kinematics: shoulder and elbow angles that put the wrist on ``target``.

        ``target`` (n, 3) or (3,) is the wrist position relative to the shoulder joint, in the frame of
        the shoulder's parent (the sternoclavicular joint). The elbow lies in the plane through the
        shoulder-wrist axis that points most towards ``elbow_hint`` (default: down, a little outwards
        and back), turned by ``swivel`` degrees about that axis. Targets out of reach are pulled onto the
        reachable shell. Returns degrees for ``<side>_shoulder.roll/pitch/yaw`` and ``<side>_elbow.pitch``.
        """
        s = 1.0 if side == "l" else -1.0
        l1, l2 = self.arm_lengths(side)
        p = np.atleast_2d(np.asarray(target, dtype=float))
        d = np.linalg.norm(p, axis=1)
        d_safe = np.maximum(d, 1e-9)
        n_hat = p / d_safe[:, None]
        d_clip = np.clip(d, abs(l1 - l2) + 1e-4, l1 + l2 - 1e-4)
        p = n_hat * d_clip[:, None]
        cos_inner = np.clip((l1 * l1 + l2 * l2 - d_clip ** 2) / (2 * l1 * l2), -1.0, 1.0)
        flex = np.pi - np.arccos(cos_inner)  # 0 = straight arm
        # Elbow on the circle around the shoulder-wrist axis.
        c = (l1 * l1 - l2 * l2 + d_clip ** 2) / (2 * d_clip)
        r = np.sqrt(np.maximum(l1 * l1 - c * c, 0.0))
        hint = np.asarray(elbow_hint if elbow_hint is not None else (0.35 * s, -1.0, -0.25), dtype=float)
        u = hint - (n_hat @ hint)[:, None] * n_hat
        u_norm = np.linalg.norm(u, axis=1)
        fallback = np.cross(n_hat, np.array([1.0, 0.0, 0.0]))
        u = np.where(u_norm[:, None] > 1e-9, u / np.maximum(u_norm, 1e-12)[:, None], fallback)
        u /= np.maximum(np.linalg.norm(u, axis=1), 1e-12)[:, None]
        swivel = np.radians(np.broadcast_to(np.asarray(swivel, dtype=float), d.shape))
        v = np.cross(n_hat, u)
        u = np.cos(swivel)[:, None] * u + np.sin(swivel)[:, None] * v
        elbow = c[:, None] * n_hat + r[:, None] * u
        a_w = elbow / np.maximum(np.linalg.norm(elbow, axis=1), 1e-12)[:, None]
        fore = p - elbow
        b_w = fore - np.sum(fore * a_w, axis=1)[:, None] * a_w
        b_norm = np.linalg.norm(b_w, axis=1)
        # A (nearly) straight arm has no bend plane: bend towards the front.
        front = np.array([0.0, 0.0, 1.0]) - a_w[:, 2:3] * a_w
        b_w = np.where(b_norm[:, None] > 1e-9, b_w / np.maximum(b_norm, 1e-12)[:, None],
                       front / np.maximum(np.linalg.norm(front, axis=1), 1e-12)[:, None])
        c_w = np.cross(a_w, b_w)
        world = np.stack([a_w, b_w, c_w], axis=2)  # columns
        a_l, b_l = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
        local = np.stack([a_l, b_l, np.cross(a_l, b_l)], axis=1)
        rot = world @ local.T
        roll, pitch, yaw = matrix_euler(rot)
        return {f"{side}_shoulder.roll": roll, f"{side}_shoulder.pitch": pitch, f"{side}_shoulder.yaw": yaw,
                f"{side}_elbow.pitch": -np.degrees(flex)}

    def arm_fk(self, side: str, angles: Mapping[str, np.ndarray | float]) -> np.ndarray:
        """Wrist position relative to the shoulder, in the shoulder's parent frame (inverse of arm_ik)."""
        get = lambda k: np.atleast_1d(np.asarray(angles.get(k, 0.0), dtype=float))  # noqa: E731
        sh = euler_matrix(get(f"{side}_shoulder.roll"), get(f"{side}_shoulder.pitch"), get(f"{side}_shoulder.yaw"))
        el = euler_matrix(np.zeros(1), get(f"{side}_elbow.pitch"), get(f"{side}_elbow.yaw"))
        upper = np.asarray(self.joint[f"{side}_elbow"].offset)
        fore = np.asarray(self.joint[f"{side}_wrist"].offset)
        return sh @ upper + (sh @ el) @ fore

    def shoulder_rest(self, side: str) -> np.ndarray:
        """Rest position of the shoulder joint relative to vt10 (metres)."""
        sc = np.asarray(self.joint[f"{side}_sternoclavicular"].offset)
        return sc + np.asarray(self.joint[f"{side}_shoulder"].offset)
