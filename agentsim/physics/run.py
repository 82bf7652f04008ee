"""A realized run played through the physical body: its controllers, its pushes, the poses and the CSV.

:func:`run_controllers` reads the controllers a recording played (their actual start and end);
:class:`PhysicalManager`, given to :func:`~agentsim.animation.evaluate_poses` as its manager, makes the poses
the physical body's (the root and the physical joints from the simulation, every other channel the
animation's); :func:`write_physics_csv` writes one row a frame. :func:`parse_push` reads ``--push TIME:FX,FY,FZ:DURATION``.
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
    """

    def __init__(self, controllers: list[ControllerSpec], pushes: list[Push] = (), fps: float = 60.0, **kwargs):
        super().__init__(**kwargs)
        self.controllers, self.pushes, self.fps = list(controllers), list(pushes), float(fps)
        self.result: PhysicsResult | None = None

    def evaluate(self, times, sink=None, window: int = 16384):
        times = np.asarray(times, dtype=float)
        if sink is None:
            values, writers = super().evaluate(times)
            out = np.empty_like(values)
            stepper = Stepper(self.body, self.fps, times, self.controllers, self.pushes, out.__setitem__)
            stepper.feed(values)
            self.result = stepper.finish()
            return out, writers
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
