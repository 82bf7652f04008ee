"""A realized run played through the physical body: its controllers, its pushes, the poses and the CSV.

:func:`run_controllers` reads the controllers a recording played (their actual start and end);
:class:`PhysicalManager`, given to :func:`~agentsim.animation.evaluate_poses` as its manager, makes the poses
the physical body's (the root and the physical joints from the simulation, every other channel the
animation's); :func:`write_physics_csv` writes one row a frame. :func:`parse_push` reads ``--push TIME:FX,FY,FZ:DURATION``.
:func:`physical_poses` is what the scenarios call in place of :func:`~agentsim.animation.evaluate_poses` under
``--physics``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from agentsim.animation.manager import DriverManager
from agentsim.animation.output import records_of
from agentsim.physics.controllers import ControllerSpec, controller_spec, default_balance
from agentsim.physics.simulation import CSV_COLUMNS, PhysicsResult, Push, Stepper
from agentsim.written import written


def parse_push(text: str) -> Push:
    """A push from ``TIME:FX,FY,FZ:DURATION`` (seconds, newtons in the BVH's frame, seconds); ValueError
    saying what is wrong."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"expected TIME:FX,FY,FZ:DURATION, got {text!r}")
    try:
        time, duration = float(parts[0]), float(parts[2])
        force = tuple(float(x) for x in parts[1].split(","))
    except ValueError:
        raise ValueError(f"expected numbers in TIME:FX,FY,FZ:DURATION, got {text!r}") from None
    if len(force) != 3:
        raise ValueError(f"the force needs three components FX,FY,FZ (newtons), got {parts[1]!r}")
    if not all(math.isfinite(v) for v in (time, duration, *force)) or time < 0 or duration <= 0:
        raise ValueError(f"the time must be >= 0 and the duration > 0 seconds (finite), got {text!r}")
    return Push(time, force, duration)


def run_controllers(source) -> list[ControllerSpec]:
    """The controllers a run played, with the times they were active, and under them the default
    :func:`~agentsim.physics.controllers.default_balance` for the whole run (a BalanceController of the BML
    drives the balance's joints while it is active, having started later)."""
    specs = [default_balance()]
    specs[0].start = -math.inf
    for record in records_of(source):
        b = record.behaviour
        if b.type != "controller" or not record.times or record.times[0] is None:
            continue
        if not (record.passed and record.passed[0]):
            continue  # never started
        try:
            spec = controller_spec(b.attributes.get("class", ""), b.params)
        except ValueError:
            continue  # refused when it was planned (a warning said so)
        end = record.times[-1]
        if record.stopped is not None:
            end = record.stopped
        spec.start, spec.end = float(record.times[0]), float(end if end is not None else math.inf)
        spec.name = f"{record.block}:{record.id}"
        specs.append(spec)
    return specs


class PhysicalManager(DriverManager):
    """A :class:`~agentsim.animation.manager.DriverManager` whose frames are the physical body's: the physics
    runs inside the frame loop of :func:`~agentsim.animation.evaluate_poses` (give it as ``manager``). Each
    window of frames the drivers evaluate goes to the simulation as it comes, and the physical body's frames
    go on to the pose files (or the arrays) in order, two frames behind the drivers (a frame's velocities
    need the next one). :attr:`result` is the :class:`PhysicsResult` once the frames are evaluated.
    ``progress(body, times, values)``, if given, is called with the physical frames made so far (arrays) each
    time :data:`PROGRESS_FRAMES` frames or more have been made, and with every frame at the end, so that what
    needs them can begin.
    """

    def __init__(self, controllers: list[ControllerSpec], pushes: list[Push] = (), fps: float = 60.0,
                 progress=None, process=None, **kwargs):
        super().__init__(**kwargs)
        self.controllers, self.pushes, self.fps = list(controllers), list(pushes), float(fps)
        self.progress = progress
        #: the :class:`~agentsim.physics.process.PhysicsProcess` that simulates the frames kept in memory,
        #: beside the animation (None: this thread does, after the animation)
        self.process = process
        self.result: PhysicsResult | None = None

    def evaluate(self, times, sink=None, window: int = 16384):
        times = np.asarray(times, dtype=float)
        if sink is None:
            return self._in_memory(times)
        made: list[np.ndarray] = []  # physical frames not yet handed on
        state = {"sent": 0, "writers": np.empty((0, self.body.n_dofs), dtype=np.int32)}

        def send() -> None:
            if made:
                n = len(made)
                sink(state["sent"], np.array(made), state["writers"][:n])
                state["writers"] = state["writers"][n:]
                state["sent"] += n
                made.clear()

        def take(first: int, block: np.ndarray, writers: np.ndarray) -> None:
            state["writers"] = np.concatenate([state["writers"], writers])
            stepper.feed(block)
            send()

        stepper = Stepper(self.body, self.fps, times, self.controllers, self.pushes, lambda k, pose: made.append(pose))
        super().evaluate(times, sink=take, window=window)
        self.result = stepper.finish()
        send()
        return None

    def _in_memory(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The physical body's frames and the animation's writers, in arrays: simulated by :attr:`process`
        while the animation's next frames are evaluated here, when the manager was given one, else on this
        thread after the animation's frames. The frames are the same either way."""
        n = len(times)
        out = np.empty((n, self.body.n_dofs))
        made = [0]
        told = [0]

        def put(first: int, poses: np.ndarray) -> None:
            out[first:first + len(poses)] = poses
            made[0] = first + len(poses)
            if self.progress is not None and made[0] - told[0] >= PROGRESS_FRAMES:
                told[0] = made[0]
                self.progress(self.body, times[:told[0]], out[:told[0]])

        process, self.process = self.process, None  # (it serves one run of frames)
        if process is None:
            values, writers = super().evaluate(times)
            stepper = Stepper(self.body, self.fps, times, self.controllers, self.pushes,
                              lambda k, pose: put(k, pose[None]))
            for a in range(0, n, PROGRESS_FRAMES):
                stepper.feed(values[a:a + PROGRESS_FRAMES])
            self.result = stepper.finish()
        else:
            writers = np.empty((n, self.body.n_dofs), dtype=np.int32)

            def take(first: int, block: np.ndarray, block_writers: np.ndarray) -> None:
                writers[first:first + len(block)] = block_writers
                process.feed(block)  # (sent at once: the block's buffer may be reused afterwards)
                for at, poses in process.made():
                    put(at, poses)

            try:
                process.start(self.body, self.fps, times, self.controllers, self.pushes)
                super().evaluate(times, sink=take, window=ANIMATION_FRAMES)
                self.result = process.finish(put)
            finally:
                process.close()
        if self.progress is not None and made[0] > told[0]:
            self.progress(self.body, times, out)
        return out, writers


#: How many of the animation's frames :class:`PhysicalManager` simulates between two calls of its ``progress``.
PROGRESS_FRAMES = 64

#: How many of the animation's frames :class:`PhysicalManager` evaluates before it sends them to its process.
ANIMATION_FRAMES = 256


#: The modes of a gesture or pointing that leave the left hand alone.
RIGHT_ONLY = ("RIGHT_HAND", "RIGHT")


def hanging_left_arm(source, end: float) -> list[ControllerSpec]:
    """HangControllers on the left arm whenever no gesture or pointing of ``source`` (a recording, or
    records) uses it, up to ``end`` (s): it hangs while the right hand gestures alone, and is given back
    to the animation :data:`~agentsim.physics.simulation.RELEASE` seconds before a gesture with the left or
    both hands starts (so that the transition back has ended when the gesture begins), and taken again
    when that gesture ends."""
    from agentsim.physics.simulation import RELEASE

    busy = []
    for record in records_of(source):
        b = record.behaviour
        if b.type not in ("gesture", "pointing") or not record.times or record.times[0] is None:
            continue
        if b.attributes.get("mode", "").upper() in RIGHT_ONLY:
            continue
        last = record.stopped if record.stopped is not None else record.times[-1]
        busy.append((float(record.times[0]) - RELEASE, float(last if last is not None else end)))
    specs, free_from = [], 0.0
    for start, stop in sorted(busy) + [(end, end)]:
        if start > free_from + 1e-9:
            spec = controller_spec("HangController", {"part": "left_arm"})
            spec.start, spec.end, spec.name = free_from, start, "hanging left arm"
            specs.append(spec)
        free_from = max(free_from, stop)
    return specs


def physical_poses(recording, fps: float, seed: int, pushes=(), controllers=(), scene=None, folder=None,
                   progress=None, process=None):
    """The poses of a finished run on the physical body (as :func:`~agentsim.animation.evaluate_poses` gives
    the animation's), with the run's controllers under the default balance, ``controllers`` added (e.g. a
    scenario's HangControllers) and the ``pushes``; returns the stream and the :class:`PhysicsResult`.
    ``progress`` and ``process``: as :class:`PhysicalManager` takes them (poses held in memory, no
    ``folder``)."""
    from agentsim.animation import evaluate_poses
    from agentsim.animation.output import lexicon_of

    manager = PhysicalManager([*run_controllers(recording), *controllers], list(pushes), fps=fps, seed=seed,
                              scene=scene, lexicon=lexicon_of(recording), progress=progress, process=process)
    stream = evaluate_poses(recording, fps=fps, seed=seed, folder=folder, manager=manager)
    return stream, manager.result


def scenario_poses(recording, fps: float, seed: int, pushes, out: Path, controllers=(), scene=None, folder=None,
                   progress=None, process=None):
    """:func:`physical_poses` for a scenario's folder ``out``: its ``physics.csv`` written there, a fall or an
    unstable simulation said on one line of stderr (the scenario's feedback is its realizer's); the stream and
    the :class:`PhysicsResult`."""
    import sys

    stream, result = physical_poses(recording, fps, seed, pushes, controllers, scene, folder, progress, process)
    write_physics_csv(Path(out) / "physics.csv", result)
    line = fell_line(result)
    if line:
        print(f"agentsim: {line}", file=sys.stderr)
    return stream, result


def fell_line(result: PhysicsResult) -> str | None:
    """The line that says a run's body fell or its simulation became unstable (None: neither)."""
    said = []
    if result.fell_at is not None:
        said.append(f"the physical body fell at {result.fell_at:.3f} s")
    if result.unstable_at is not None:
        said.append(f"the physical body's simulation became unstable at {result.unstable_at:.3f} s and started "
                    f"again from its rest pose (MuJoCo: {result.unstable})")
    return "; ".join(said) or None


def write_physics_csv(path: str | Path, result: PhysicsResult) -> Path:
    """One row a frame: ``time`` (s), the centre of mass, the support polygon's bounding box (m, the BVH's
    frame), ``com_inside`` (1: the centre of mass's ground projection is in that box), ``pelvis_height``
    (m) and ``fallen`` (1 from the frame the body fell on)."""
    path = Path(path)
    with written(path) as tmp, open(tmp, "w") as f:
        f.write(",".join(CSV_COLUMNS) + "\n")
        for row in result.rows:
            f.write(",".join([f"{row[0]:.6f}", *(f"{v:.6f}" for v in row[1:8]), str(int(row[8])),
                              f"{row[9]:.6f}", str(int(row[10]))]) + "\n")
    return path


class LiveBody:
    """The physical body of a live run (``agentsim serve --physics``): the animation's frames come a window
    at a time (:meth:`frames`), in order, and the physical body's frames of the same window go out at once.
    A window's last frame has no next one yet: its velocity is taken as the window's last step's (the
    Hermite curve of that frame is then a straight line), which the next window's first step corrects. A
    window that does not follow the one before (frames skipped) starts the body again from its pose."""

    def __init__(self, body, fps: float, pushes=()):
        self.body, self.fps, self.pushes = body, float(fps), list(pushes)
        self.sim = None
        self.next = -1
        self.history: list[np.ndarray] = []

    def frames(self, k0: int, values: np.ndarray, controllers: list[ControllerSpec]) -> np.ndarray:
        """The physical body's poses of frames ``k0 .. k0 + len(values) - 1`` (``values``: the animation's),
        under ``controllers`` (those of the run so far, with their times)."""
        from agentsim.physics.simulation import Simulation

        values = np.asarray(values, dtype=float)
        n = len(values)
        out = np.empty_like(values)
        said: list[str] = []
        if self.sim is None or k0 != self.next:
            self.sim = Simulation(self.body, self.fps, controllers, self.pushes)
            self.history = []
        self.sim.controllers = sorted(controllers, key=lambda c: c.start)
        mj = self.sim.mj
        previous = mj.get_mju_user_warning()
        mj.set_mju_user_warning(said.append)
        try:
            for i in range(n):
                row, after = values[i], values[min(i + 1, n - 1)]
                if i == n - 1 and n > 1:
                    after = row + (row - values[i - 1])  # the window's last step goes on
                if not self.history:
                    out[i] = self.sim.start((k0 + i) / self.fps, np.stack([row, after]))
                else:
                    before = self.history[-2] if len(self.history) > 1 else self.history[-1]
                    out[i] = self.sim.advance((k0 + i - 1) / self.fps, np.stack([before, self.history[-1], row, after]))
                self.history = [*self.history[-1:], row]
        finally:
            mj.set_mju_user_warning(previous)
        self.next = k0 + n
        if said:  # unstable: start again from the animation's pose at the next window
            self.sim = None
        return out
