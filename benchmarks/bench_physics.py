"""The physical body (``agentsim realize --physics``): what a physics step costs, what physics adds to a
run, how well the balance stands and how it recovers from pushes.

Prints JSON. Targets, each with ``holds``: the simulation runs faster than real time (simulated seconds per
wall second >= 1); ``realize --physics`` of a 10 s run takes less than 10 s of wall time (the ratio to the
same run without physics, which evaluates poses alone and is far quicker, is reported beside it);
standing 10 s the centre of mass stays within 1 cm of where it stood at 1 s and over the support polygon at
every frame; after a push of 150 N for 0.2 s at 2 s, forward and sideways, the centre of mass moves more
than 1 cm along the push, the body never falls, and from 5 s on it stays within 2 cm of where it stood
between 1 and 2 s. Beside them: the strongest 0.2 s forward push of those tried that the body stands.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from agentsim.animation.body import Body
from agentsim.cli import main as cli
from agentsim.physics.controllers import default_balance
from agentsim.physics.simulation import Simulation

BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><head id="h1" lexeme="NOD" start="3" '
       'end="4"/><head id="h2" lexeme="NOD" start="{end}" end="{end2}"/></bml>')


def step_cost(seconds: float = 5.0) -> dict:
    body = Body()
    sim = Simulation(body, 60.0, [default_balance()])
    rows = np.stack([body.rest_pose()] * 4)
    sim.start(0.0, rows[:2])
    frames = int(seconds * 60)
    t0 = time.perf_counter()
    for k in range(frames):
        sim.advance(k / 60.0, rows)
    wall = time.perf_counter() - t0
    steps = frames * sim.substeps
    return {"step_s": round(sim.step, 7), "steps_per_frame": sim.substeps, "steps": steps,
            "us_per_step": round(wall / steps * 1e6, 1), "simulated_s_per_wall_s": round(seconds / wall, 2),
            "holds": seconds / wall >= 1.0}


def realize(folder: Path, end: float, *extra: str) -> tuple[float, list[list[str]] | None]:
    xml = folder / "run.xml"
    xml.write_text(BML.format(end=end - 1.5, end2=end - 1.0))
    argv = ["realize", str(xml), "--tts", "builtin", "--bvh", str(folder / "run.bvh"), *extra]
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = cli(argv)
    wall = time.perf_counter() - t0
    assert status == 0
    if "--physics-csv" in extra:
        with open(folder / "p.csv", newline="") as f:
            return wall, list(csv.reader(f))
    return wall, None


def table(rows: list[list[str]]) -> np.ndarray:
    return np.array([[float(x) for x in r] for r in rows[1:]])


def push(folder: Path, force: str, axis: int) -> dict:
    _, rows = realize(folder, 8.0, "--physics", "--physics-csv", str(folder / "p.csv"), "--push", f"2:{force}:0.2")
    data = table(rows)
    t, com = data[:, 0], data[:, 1:4]
    stood = com[(t >= 1) & (t <= 2)].mean(axis=0)
    moved = float((com[:, axis] - stood[axis]).max())
    late = float(np.linalg.norm(com[t >= 5] - stood, axis=1).max())
    fell = bool(data[:, 10].max())
    return {"force_n": force, "moved_along_push_cm": round(100 * moved, 2), "fell": fell,
            "max_offset_from_5s_cm": round(100 * late, 2), "holds": moved > 0.01 and not fell and late < 0.02}


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        os.chdir(folder)
        cost = step_cost()
        plain = min(realize(folder, 10.0)[0] for _ in range(2))
        physical = min(realize(folder, 10.0, "--physics")[0] for _ in range(2))
        _, rows = realize(folder, 10.0, "--physics", "--physics-csv", str(folder / "p.csv"))
        data = table(rows)
        t, com = data[:, 0], data[:, 1:4]
        at1 = com[np.argmin(np.abs(t - 1.0))]
        drift = float(np.linalg.norm(com[t >= 1] - at1, axis=1).max())
        balance = {"seconds": round(float(t[-1]), 3), "com_drift_from_1s_cm": round(100 * drift, 3),
                   "com_inside_every_frame": bool(data[:, 8].min() == 1),
                   "pelvis_height_m": [round(float(data[:, 9].min()), 4), round(float(data[:, 9].max()), 4)],
                   "holds": drift < 0.01 and bool(data[:, 8].min() == 1)}
        forward, sideways = push(folder, "0,0,150", 2), push(folder, "150,0,0", 0)
        strongest = None
        for newtons in (200, 250, 300, 400):
            if push(folder, f"0,0,{newtons}", 2)["fell"]:
                break
            strongest = newtons
    print(json.dumps({
        "benchmark": "physical body (mixed dynamics on MuJoCo)",
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "cpus": os.cpu_count()},
        "physics_step": cost,
        "realize_10s_wall_s": {"without_physics": round(plain, 3), "with_physics": round(physical, 3),
                               "ratio": round(physical / plain, 2), "holds": physical < 10.0},
        "standing_balance": balance,
        "push_recovery": {"forward": forward, "sideways": sideways,
                          "strongest_forward_push_stood_of_200_250_300_400_n": strongest},
        "holds": all(x["holds"] for x in (cost, balance, forward, sideways)) and physical < 10.0,
    }, indent=2))


if __name__ == "__main__":
    main()
