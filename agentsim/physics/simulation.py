"""Mixed dynamics: the physical body stepped frame by frame under the procedural animation.

The kinematic joints (those no active controller holds: the neck, head, arms and hands by default) follow
the animation's angles inside the simulation, held there by stiff servos (:data:`KINEMATIC_KP`,
:data:`KINEMATIC_KV`, on a large armature :data:`KINEMATIC_ARMATURE` that makes every kinematic hinge as
heavy to the servo and has no reaction on the parent body): the torques the servos exert are those the
motion needs, the inverse dynamics of the prescribed motion, computed by MuJoCo's implicit step rather than
by ``mj_inverse``, and the physical part (the root, and the joints of the active controllers) feels their
reaction through the common joints, as well as gravity, the floor's contacts, the pushes and its
controllers' servos. Physics never changes a kinematic joint's angle in the poses nor any behaviour's
timing: the poses show the animation's angles for those joints, and the simulation's only for the root and
the physical joints.

The clock: the physics runs on the animation's frame times, inside the loop that evaluates the poses
(:class:`Stepper` takes the frames as the drivers make them, :class:`~agentsim.physics.run.PhysicalManager`
puts it in :func:`~agentsim.animation.evaluate_poses`), ``substeps`` steps of ``1 / (fps * substeps)`` s
between two frames, with ``substeps`` the smallest number that makes a step 1 ms or shorter (17 steps of
0.98 ms at 60 frames per second, 34 at 30).

Python is kept out of the per-step loop: a frame is :data:`CALLS` calls of ``mj_step`` with ``nstep``
(a push's start and end add a call each). The kinematic motion is set once a frame: the cubic Hermite curve
through the frame and the next with their central-difference velocities; each servo's target is its
actuator's activation, which MuJoCo integrates at the rate the control gives (``dyntype="integrator"``), so
the target glides straight from the curve's value at one call's start to the next call's, with that slope
as the target velocity. What this costs in accuracy: the target is the Hermite curve at the calls' ends and
straight between them (within a few thousandths of a degree of the curve for a conductor's strokes); the
servo lags the target by a few hundredths of a degree under a stroke's torque (the reaction the trunk
feels is that of the motion the servo makes); the controllers' targets and the balance's corrections are
set once a frame (a 17 to 33 ms control period, shorter than a human's fastest postural reflexes), while
the servos themselves run inside MuJoCo at every step, with implicit damping; the balance reads the frame's
state with ``mj_kinematics``, ``mj_comPos``, ``mj_comVel`` and ``mj_rne`` rather than a whole
``mj_forward``, and the contacts of the frame's last step. A hinge is made only for the axes the skeleton
turns (not the knees' and elbows' roll nor the wrists' yaw). A profile of a standing body gives about 80 %
of the time to ``mj_step`` (40 to 50 us a step on a busy two-core machine) and the rest to the per-frame
work; ``benchmarks/bench_physics.py`` measures it and what physics adds to the scenarios.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agentsim.animation.body import Body, matrix_euler
from agentsim.physics.controllers import LEGS, SPINE, ControllerSpec
from agentsim.physics.model import FOOT_HALF_WIDTH, FOOT_HEEL, FOOT_SOLE, FOOT_TOE, build_model

#: The longest physics step (s).
MAX_STEP = 0.001
#: The armature (kg m^2) of a kinematic joint's hinges: every kinematic hinge is as heavy to its servo, so that
#: one stiffness holds them all on the animation's curve, stable at the step; the armature has no reaction on
#: the parent body, so the physical part feels only the torque the joint's true motion needs.
KINEMATIC_ARMATURE = 20.0
#: The stiffness (N m/rad) and damping (N m s/rad) of the servo that keeps a kinematic joint on the
#: animation's curve: with the armature, a critically damped servo of 300 rad/s (48 Hz), whose error under
#: a stroke's torque is a few hundredths of a degree (inside the simulation; the pose shows the animation's).
KINEMATIC_KP = KINEMATIC_ARMATURE * 300.0 ** 2
KINEMATIC_KV = 2.0 * KINEMATIC_ARMATURE * 300.0
#: How many calls of mj_step make a frame: the kinematic targets glide straight between the Hermite curve's
#: values at the calls' ends.
CALLS = 4
#: The armature of a physical joint's hinges (that of the model).
PHYSICAL_ARMATURE = 0.02
#: How long a part given back to the animation takes to reach it, and a joint's servo target takes to go
#: from where the joint is to where a controller that takes it over wants it (s).
RELEASE = 0.3
#: The body has fallen when the pelvis is below this fraction of its standing height.
FALL_FRACTION = 0.6
#: The columns of the physics CSV.
CSV_COLUMNS = ("time", "com_x", "com_y", "com_z", "support_min_x", "support_max_x", "support_min_z",
               "support_max_z", "com_inside", "pelvis_height", "fallen")


@dataclass(frozen=True)
class Push:
    """A force (newtons, in the BVH's frame) on the pelvis from ``time`` for ``duration`` seconds."""

    time: float
    force: tuple[float, float, float]
    duration: float


@dataclass
class PhysicsResult:
    """What a simulation gave: the CSV rows (one a frame), when the body fell (None: it did not), and when
    MuJoCo found the simulation unstable (it then starts the body again from the model's rest pose) with
    what it said."""

    rows: list[tuple] = field(default_factory=list)
    fell_at: float | None = None
    unstable_at: float | None = None
    unstable: str = ""


def _hermite_at(u: np.ndarray) -> np.ndarray:
    """The cubic Hermite basis at the fractions ``u`` of a frame, (len(u), 4): times the frame's coefficients
    (its angle, its velocity times the frame time, the next frame's angle and velocity) gives the curve."""
    u2, u3 = u * u, u * u * u
    return np.stack([2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2], axis=1)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _matrix_quat(m: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(m, dtype=float).ravel())
    return q


class Simulation:
    """The physical body of one run, advanced a frame at a time by :meth:`advance`.

    ``controllers`` are the run's controllers with their times (the physical configuration at a moment is
    the root and every joint of the controllers active then; of two controllers holding a joint, the one
    that started later drives it); ``pushes`` the forces on the pelvis.
    """

    def __init__(self, body: Body, fps: float, controllers: list[ControllerSpec], pushes: list[Push] = ()):
        import mujoco

        self.mj = mujoco
        self.body = body
        self.frame_time = 1.0 / fps
        self.substeps = max(1, math.ceil(self.frame_time / MAX_STEP - 1e-9))
        self.step = self.frame_time / self.substeps
        self.model, self.layout = build_model(body, self.step)
        self.data = mujoco.MjData(self.model)
        self.controllers = sorted(controllers, key=lambda c: c.start)
        self.pushes = list(pushes)
        self.joints = self.layout.joints[1:]
        self.index = {j: i for i, j in enumerate(self.joints)}
        self.columns = np.array([body.rotation_columns[j] for j in self.joints], dtype=np.intp)  # (J, 3)
        self.qadr = np.array([self.layout.qpos[j] for j in self.joints], dtype=np.intp)
        self.dadr = np.array([self.layout.dof[j] for j in self.joints], dtype=np.intp)
        self.aadr = np.array([self.layout.actuator[j] for j in self.joints], dtype=np.intp)
        #: the axes that have a hinge (the others, never turned, are read as 0 through address 0, masked)
        self.valid = self.qadr >= 0
        for adr in (self.qadr, self.dadr, self.aadr):
            adr[~self.valid] = 0
        self.qv, self.dv, self.av = self.qadr[self.valid], self.dadr[self.valid], self.aadr[self.valid]
        #: joints without hinges (the clavicles): their bodies are turned as the animation turns them
        self.welded = [i for i in range(len(self.joints)) if not self.valid[i].any()]
        self.welded_body = [self.layout.body_id[self.joints[i]] for i in self.welded]
        self.root_translation = np.array(body.translation_columns, dtype=np.intp)
        self.root_rotation = np.array(body.rotation_columns[body.joints[0].name], dtype=np.intp)
        self.pelvis = self.layout.body_id["sacroiliac"]
        #: the steps of a frame at which a call of mj_step ends (the kinematic targets' knots)
        self.bounds = sorted({round(k * self.substeps / CALLS) for k in range(CALLS + 1)})
        #: the Hermite basis at those ends (a frame with a push has its own)
        self._basis = _hermite_at(np.asarray(self.bounds, dtype=float) / self.substeps)
        self._physical(np.zeros(len(self.joints), dtype=bool))
        self.release: dict[int, tuple[float, np.ndarray]] = {}  # joint -> (time given back, angle offsets)
        self.taken: dict[int, np.ndarray] = {}  # joint -> its angles (rad) when a JointController took it
        self.handover: dict[int, tuple[float, np.ndarray]] = {}  # joint -> (time taken, its angles then)
        self.owner: list[ControllerSpec | None] = [None] * len(self.joints)
        self.model.dof_armature[self.dv] = KINEMATIC_ARMATURE
        self.model.actuator_gainprm[self.av, 0] = KINEMATIC_KP
        self.model.actuator_biasprm[self.av, 1] = -KINEMATIC_KP
        self.model.actuator_biasprm[self.av, 2] = -KINEMATIC_KV
        self.result = PhysicsResult()
        self.standing: float | None = None
        self.balance_target: np.ndarray | None = None
        self._sole = np.array([[sx * FOOT_HALF_WIDTH, FOOT_SOLE, z] for sx in (-1, 1)
                               for z in (FOOT_HEEL, FOOT_TOE)])
        self._feet = [self.layout.body_id[f"{s}_ankle"] for s in ("l", "r")]
        self._ids = {name: self.index[name] for name in LEGS}
        self._spine = [self.index[name] for name in SPINE]
        self._bias = np.zeros(self.model.nv)

    # ------------------------------------------------------------------ state and configuration
    def start(self, time: float, rows: np.ndarray) -> np.ndarray:
        """Put the body in the animation's pose of the first frame (``rows``: that frame and the next) and
        return the first frame's pose."""
        d = self.data
        pose = rows[0]
        d.qpos[0:3] = pose[self.root_translation]
        r = self.root_rotation
        from agentsim.animation.body import euler_matrix

        d.qpos[3:7] = _matrix_quat(euler_matrix(*(pose[[c]] for c in r))[0])
        d.qpos[self.qv] = np.radians(pose[self.columns])[self.valid]
        self._turn_welded(pose[self.columns])
        d.act[self.av] = d.qpos[self.qv]
        if len(rows) > 1:
            d.qvel[self.dv] = np.radians(_wrapped(rows[1][self.columns] - pose[self.columns]))[self.valid] / self.frame_time
        self.mj.mj_forward(self.model, d)
        self.standing = float(d.xpos[self.pelvis][1])
        self._configure(time)
        return self._frame(time, pose)

    def _turn_welded(self, angles: np.ndarray) -> None:
        """Turn the joints without hinges to ``angles`` (degrees, (J, 3): the animation's)."""
        if self.welded:
            from agentsim.animation.body import euler_matrix

            turned = euler_matrix(*angles[self.welded].T)
            for body, matrix in zip(self.welded_body, turned):
                self.model.body_quat[body] = _matrix_quat(matrix)

    def _angles(self, i: int) -> np.ndarray:
        """Joint ``i``'s angles now (rad; 0 about an axis it never turns)."""
        return np.where(self.valid[i], self.data.qpos[self.qadr[i]], 0.0)

    def _active(self, time: float) -> list[ControllerSpec]:
        return [c for c in self.controllers if c.start <= time + 1e-9 < c.end]

    def _configure(self, time: float) -> None:
        """The physical configuration at ``time``: who drives which joint, the servos' gains; a joint given
        back to the animation starts its transition from where it is."""
        owner: list[ControllerSpec | None] = [None] * len(self.joints)
        for c in self._active(time):
            for j in c.joints:
                owner[self.index[j]] = c
        d, m = self.data, self.model
        for i, (old, new) in enumerate(zip(self.owner, owner)):
            if old is new:
                continue
            if new is None:  # given back: reach the animation from where it is
                self.release[i] = (time, self._angles(i))
            else:  # taken over: its servo's target goes from where it is to the controller's in a transition
                self.release.pop(i, None)
                self.handover[i] = (time, self._angles(i))
                if new.kind == "JointController":
                    self.taken[i] = self._angles(i)
            if new is None:
                kp, kd = KINEMATIC_KP, KINEMATIC_KV
            elif new.kind == "HangController":
                kp, kd = 0.0, new.params["damping"]
            elif new.kind == "BalanceController" and self.joints[i] in SPINE:
                kp, kd = new.params["spine_kp"], new.params["spine_kd"]
            else:
                kp, kd = new.params["kp"], new.params["kd"]
            m.dof_armature[self.dadr[i][self.valid[i]]] = KINEMATIC_ARMATURE if new is None else PHYSICAL_ARMATURE
            a = self.aadr[i][self.valid[i]]
            m.actuator_gainprm[a, 0] = kp
            m.actuator_biasprm[a, 1] = -kp
            m.actuator_biasprm[a, 2] = -kd
            if new is not None:
                m.actuator_biasprm[a, 0] = 0.0
                d.ctrl[a] = 0.0
        self.owner = owner
        physical = np.array([o is not None for o in owner])
        if not np.array_equal(physical, self.physical):
            self._physical(physical)

    def _physical(self, physical: np.ndarray) -> None:
        """The joints that are ``physical`` now, and the hinges and actuators of either kind, which every frame
        reads until the configuration changes."""
        self.physical = physical
        #: the physical joints' hinges, (J, 3); the kinematic joints' hinges, their actuators and positions
        self.physical_hinges = physical[:, None] & self.valid
        self.moving = ~physical[:, None] & self.valid
        self.moving_actuators, self.moving_qpos = self.aadr[self.moving], self.qadr[self.moving]
        self.physical_actuators = self.aadr[self.physical_hinges]

    # ------------------------------------------------------------------ the frame loop
    def advance(self, time: float, rows: np.ndarray) -> np.ndarray:
        """Step from the frame at ``time`` to the next one and return the next frame's pose.

        ``rows`` are the animation's poses of the frames before, at, after and two after ``time`` (clamped
        at the ends of the run: the same row repeated).
        """
        m, d, mj = self.model, self.data, self.mj
        self._configure(time)
        targets = np.radians(np.stack([self._kinematic(time + (k - 1) * self.frame_time, rows[k])
                                       for k in range(4)]))  # (4, J, 3)
        targets = targets[1] + _wrapped_rad(targets - targets[1])  # no turn through +-180 degrees
        h = self.frame_time
        v1 = (targets[2] - targets[0]) / (2 * h)
        v2 = (targets[3] - targets[1]) / (2 * h)
        moving = self.moving  # the kinematic joints' hinges
        coeffs = np.stack([targets[1], h * v1, targets[2], h * v2])[:, moving]  # (4, hinges)
        ka = self.moving_actuators
        self._servo_targets(time, rows[2])
        self._turn_welded(np.degrees(targets[2]))
        pushes = [p for p in self.pushes if p.time < time + h and p.time + p.duration > time]
        bounds, basis = self.bounds, self._basis
        if pushes:  # a push starts and ends at a step: a call of mj_step ends there
            edges = [round((t - time) / self.step) for p in pushes for t in (p.time, p.time + p.duration)]
            bounds = sorted({*bounds, *(e for e in edges if 0 < e < self.substeps)})
            basis = _hermite_at(np.asarray(bounds, dtype=float) / self.substeps)
        knots = basis @ coeffs  # (chunks + 1, kinematic DOFs): the curve at the calls' ends
        hinges = self.moving_qpos
        turns = np.round((d.qpos[hinges] - knots[0]) / (2 * math.pi))
        if turns.any():  # an angle of the animation wrapped through +-180 degrees: so does the joint's (same pose)
            d.qpos[hinges] -= 2 * math.pi * turns
        for j in range(len(bounds) - 1):
            n = bounds[j + 1] - bounds[j]
            slope = (knots[j + 1] - knots[j]) / (n * self.step)
            d.act[ka] = knots[j]
            d.ctrl[ka] = slope
            m.actuator_biasprm[ka, 0] = KINEMATIC_KV * slope
            if pushes:
                t = time + bounds[j] * self.step
                force = np.zeros(3)
                for p in pushes:
                    if p.time - 1e-12 <= t + 0.5 * self.step < p.time + p.duration - 1e-12:
                        force += p.force
                d.xfrc_applied[self.pelvis, :3] = force
            mj.mj_step(m, d, nstep=n)
        if pushes:
            d.xfrc_applied[self.pelvis, :3] = 0.0
        return self._frame(time + h, rows[2])

    def _kinematic(self, time: float, row: np.ndarray) -> np.ndarray:
        """The angles (degrees, (J, 3)) the kinematic joints take at ``time``: the animation's, plus what is
        left of a returning part's offset."""
        angles = row[self.columns].copy()
        for i, (t0, start) in self.release.items():
            u = min(max((time - t0) / RELEASE, 0.0), 1.0)
            w = 1.0 - u * u * (3 - 2 * u)
            angles[i] += w * _wrapped(np.degrees(start) - angles[i]) if w > 0 else 0.0
        return angles

    def _servo_targets(self, time: float, row: np.ndarray) -> None:
        """Each physical joint's servo target for the next frame: the animation's angles (and the balance's
        corrections) for the balance's joints, the targets for a JointController's."""
        d = self.data
        ctrl = np.radians(row[self.columns])  # (J, 3)
        for i, owner in enumerate(self.owner):
            if owner is not None and owner.kind == "JointController":
                ctrl[i] = self.taken.get(i, ctrl[i])
                for name, value in owner.targets.items():
                    j, axis = name.split(".")
                    if self.index[j] == i:
                        ctrl[i, ("roll", "pitch", "yaw").index(axis)] = math.radians(value)
        balance = next((o for o in self.owner if o is not None and o.kind == "BalanceController"), None)
        if balance is not None:
            self._balance(balance, ctrl)
        for i, (t0, start) in list(self.handover.items()):
            u = min(max((time + self.frame_time - t0) / RELEASE, 0.0), 1.0)
            if u >= 1.0:
                del self.handover[i]
                continue
            w = u * u * (3 - 2 * u)
            ctrl[i] = start + w * _wrapped_rad(ctrl[i] - start)
        d.act[self.physical_actuators] = ctrl[self.physical_hinges]

    def _balance(self, spec: ControllerSpec, ctrl: np.ndarray) -> None:
        """Ankle and hip corrections that bring the centre of mass over the middle of the feet."""
        m, d, mj = self.model, self.data, self.mj
        # the frame's positions are there (_frame); its velocities and the forces a zero acceleration needs
        mj.mj_comVel(m, d)
        mj.mj_subtreeVel(m, d)
        mj.mj_rne(m, d, 0, self._bias)
        com, vel = d.subtree_com[0], d.subtree_linvel[0]
        corners = self._corners(self._feet)
        centre = (corners.min(axis=0) + corners.max(axis=0)) / 2
        err = (com - centre) * 100.0  # cm
        speed = vel * 100.0
        kp, kd = spec.params["com_kp"], spec.params["com_kd"]
        lean_forward = -math.radians(kp * err[2] + kd * speed[2])
        lean_left = -math.radians(kp * err[0] + kd * speed[0])
        squat = 0.0
        height = spec.params.get("pelvis_height")
        if height is not None and self.standing is not None and height < self.standing:
            leg = 0.81
            squat = math.acos(max(0.2, min(1.0, (leg - (self.standing - height)) / leg)))
        spine_kp = spec.params["spine_kp"]
        if spine_kp > 0:  # the soft spine holds the body above it against gravity (the torque that keeps it still)
            for i in self._spine:
                ctrl[i] += self._bias[self.dadr[i]] / spine_kp  # (every axis of the spine turns)
        for side in ("l", "r"):
            hip, knee, ankle = (self._ids[f"{side}_{j}"] for j in ("hip", "knee", "ankle"))
            ctrl[ankle, 1] += -lean_forward - squat
            ctrl[hip, 1] += -squat
            ctrl[knee, 1] += 2 * squat
            ctrl[ankle, 0] += lean_left
            ctrl[hip, 0] -= lean_left

    # ------------------------------------------------------------------ what a frame shows
    def _corners(self, feet: list[int]) -> np.ndarray:
        d = self.data
        return np.concatenate([d.xpos[b] + self._sole @ d.xmat[b].reshape(3, 3).T for b in feet])

    def _frame(self, time: float, row: np.ndarray) -> np.ndarray:
        """The pose the frame at ``time`` shows (the animation's, with the root and the physical joints from
        the simulation) and its CSV row."""
        m, d, mj = self.model, self.data, self.mj
        mj.mj_kinematics(m, d)  # the positions at the frame (the contacts are the last step's)
        mj.mj_comPos(m, d)
        pose = np.array(row, dtype=float)
        pose[self.root_translation] = d.qpos[0:3]
        roll, pitch, yaw = matrix_euler(_quat_matrix(d.qpos[3:7]))
        pose[self.root_rotation] = (roll, pitch, yaw)
        angles = self._kinematic(time, row)
        physical = self.physical_hinges
        angles[physical] = np.degrees(d.qpos[self.qadr[physical]])
        pose[self.columns] = angles
        pairs = d.contact.geom[:d.ncon]
        floor = self.layout.floor_geom
        on = pairs[(pairs == floor).any(axis=1)]
        bodies = set(m.geom_bodyid[np.where(on[:, 0] == floor, on[:, 1], on[:, 0])].tolist())
        touching, other = bodies & set(self._feet), bool(bodies - set(self._feet))
        com = d.subtree_com[0].copy()
        feet = [b for b in self._feet if b in touching] or self._feet
        corners = self._corners(feet)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        inside = int(lo[0] <= com[0] <= hi[0] and lo[2] <= com[2] <= hi[2])
        pelvis = float(d.xpos[self.pelvis][1])
        if self.result.fell_at is None and (other or pelvis < FALL_FRACTION * (self.standing or pelvis)):
            self.result.fell_at = time
        fallen = int(self.result.fell_at is not None)
        self.result.rows.append((time, *com, lo[0], hi[0], lo[2], hi[2], inside, pelvis, fallen))
        return pose


def _wrapped(angle):
    return (np.asarray(angle, dtype=float) + 180.0) % 360.0 - 180.0


def _wrapped_rad(angle):
    return (np.asarray(angle, dtype=float) + math.pi) % (2 * math.pi) - math.pi


class Stepper:
    """A :class:`Simulation` fed the animation's frames in order, a block at a time (:meth:`feed`), making
    the physical body's frames as soon as the animation's frames they need have come (each needs the next
    two, for the velocities): ``out(k, pose)`` takes frame ``k``. :meth:`finish` makes the last frames.
    MuJoCo's warnings are kept in the result (when the simulation became unstable), not printed."""

    def __init__(self, body: Body, fps: float, times: np.ndarray, controllers: list[ControllerSpec],
                 pushes: list[Push], out) -> None:
        self.sim = Simulation(body, fps, controllers, pushes)
        self.times = np.asarray(times, dtype=float)
        self.out = out
        self.rows: dict[int, np.ndarray] = {}  # the animation's frames still needed, by index
        self.received = 0  # frames fed so far
        self.made = 0  # physical frames made so far
        self.said: list[str] = []

    def _row(self, k: int) -> np.ndarray:
        return self.rows[min(max(k, 0), len(self.times) - 1)]

    def _make(self, last: int) -> None:
        """Make the physical frames up to ``last`` (exclusive) whose animation frames have all come."""
        mj, sim = self.sim.mj, self.sim
        previous = mj.get_mju_user_warning()
        mj.set_mju_user_warning(self.said.append)
        try:
            while self.made < last:
                k = self.made
                if k == 0:
                    pose = sim.start(float(self.times[0]), np.stack([self._row(0), self._row(1)]))
                else:
                    rows = np.stack([self._row(k - 2), self._row(k - 1), self._row(k), self._row(k + 1)])
                    pose = sim.advance(float(self.times[k - 1]), rows)
                    if self.said and sim.result.unstable_at is None:
                        sim.result.unstable_at, sim.result.unstable = float(self.times[k]), self.said[0]
                self.out(k, pose)
                self.made += 1
                self.rows.pop(self.made - 3, None)  # no longer needed (frame k needs k - 2 .. k + 1)
        finally:
            mj.set_mju_user_warning(previous)

    def feed(self, block: np.ndarray) -> None:
        """The animation's next frames."""
        for row in np.asarray(block, dtype=float):
            self.rows[self.received] = row.copy()
            self.received += 1
        self._make(max(0, self.received - 1))  # frame k needs frame k + 1

    def finish(self) -> PhysicsResult:
        """Make the last frames (the run's last frame repeated where one after it is wanted)."""
        self._make(len(self.times))
        return self.sim.result


def simulate(body: Body, fps: float, times: np.ndarray, frames, controllers: list[ControllerSpec],
             pushes: list[Push] = (), sink=None) -> PhysicsResult:
    """Run the physical body over the animation's frames.

    ``frames(first, last)`` gives the animation's poses of frames ``first .. last - 1``; ``sink(k, pose)``
    takes the physical body's pose of frame ``k`` as it is made.
    """
    stepper = Stepper(body, fps, times, controllers, list(pushes), sink)
    for first in range(0, len(times), 256):
        stepper.feed(frames(first, min(len(times), first + 256)))
    return stepper.finish()
