"""A realized run played through the physical body: its controllers, its pushes, the poses and the CSV.

:func:`run_controllers` reads the controllers a recording played (their actual start and end);
:func:`physical_stream` simulates the body under a :class:`~agentsim.animation.output.PoseStream` evaluated
from that recording and returns the stream the physical body shows (the root and the physical joints from
the simulation, every other channel the animation's), with the :class:`PhysicsResult`;
:func:`write_physics_csv` writes one row a frame. :func:`parse_push` reads ``--push TIME:FX,FY,FZ:DURATION``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from agentsim.animation.output import FrameFile, PoseStream, records_of
from agentsim.physics.controllers import ControllerSpec, controller_spec, default_balance
from agentsim.physics.simulation import CSV_COLUMNS, PhysicsResult, Push, simulate
from agentsim.written import written

#: Frames handed on at a time.
BLOCK = 256


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


def physical_stream(stream: PoseStream, controllers: list[ControllerSpec], pushes: list[Push] = (),
                    folder: str | Path | None = None) -> tuple[PoseStream, PhysicsResult]:
    """The stream the physical body shows under ``stream`` (into files in ``folder`` when given, as
    :func:`~agentsim.animation.evaluate_poses` does), and what the simulation gave."""
    body, n = stream.body, stream.n_frames
    joints = list(stream.joints)
    pending: list[np.ndarray] = []
    if folder is not None:
        folder = Path(folder)
        files = {"values": FrameFile(folder / "physics_values.npy", (n, body.n_dofs), np.float64),
                 "positions": FrameFile(folder / "physics_positions.npy", (n, len(joints), 3), np.float64)}
    else:
        files = None
        values = np.empty((n, body.n_dofs))

    def flush() -> None:
        block = np.array(pending)
        pending.clear()
        files["values"].append(block)
        files["positions"].append(body.positions(block, joints))

    def sink(k: int, pose: np.ndarray) -> None:
        if files is None:
            values[k] = pose
            return
        pending.append(pose)
        if len(pending) == BLOCK:
            flush()

    try:
        result = simulate(body, stream.fps, np.asarray(stream.times), lambda a, b: stream.rows("values", a, b),
                          controllers, list(pushes), sink)
        if files is not None and pending:
            flush()
    except BaseException:
        for f in (files or {}).values():
            f.close(check=False)
        raise
    if files is None:
        out = dataclasses.replace(stream, values=values, positions=body.positions(values, joints))
    else:
        for f in files.values():
            f.close()
        merged = dict(stream.files or {})
        merged.update(files)
        out = dataclasses.replace(stream, values=files["values"].mapped(), positions=files["positions"].mapped(),
                                  files=merged)
    return out, result


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
