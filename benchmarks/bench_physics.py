"""The physical body (``agentsim realize --physics``): what a physics step costs, what physics adds to a
run, how well the balance stands and how it recovers from pushes.

Prints JSON. Targets, each with ``holds``: the simulation runs faster than real time (simulated seconds per
wall second >= 1); ``realize --physics`` of a 10 s run takes less than 10 s of wall time (the ratio to the
same run without physics, which evaluates poses alone and is far quicker, is reported beside it);
standing 10 s the centre of mass stays within 1 cm of where it stood at 1 s and over the support polygon at
every frame; after a push of 150 N for 0.2 s at 2 s, forward and sideways, the centre of mass moves more
than 1 cm along the push, the body never falls, and from 5 s on it stays within 2 cm of where it stood
between 1 and 2 s. Beside them: the strongest 0.2 s forward push of those tried that the body stands.

The scenarios (``--scenarios``, or ``--short`` for the conductor's 8 bars and the shortest story): the
conductor (seed 0) and the storyteller, each run as a command without and with ``--physics``, interleaved,
the minimum of 2 runs each: the wall-time ratio (target: at most 2 for the conductor as it stands, with its
pictures; the same runs with ``--no-pictures`` are reported beside it, and the storyteller's ratios with no
target: its 60 frames a second of a long story are 17 steps a frame), and the balance figures of the
physical runs: ``fallen`` never 1, ``com_inside`` on at least 99 % of the frames, and for the conductor the
standard deviation of the ``vl5`` rotation (its channels in the BVH, and their difference from the run
without physics: what the strokes' reaction adds) above 0.2 degrees.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import platform
import subprocess
import sys
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


def command(folder: Path, args: list[str]) -> float:
    """Wall seconds of ``agentsim ARGS`` run as a command in ``folder``."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "agentsim", *args], cwd=folder, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def bvh_frames(path: Path) -> tuple[list[str], np.ndarray]:
    """The channel names (joint.channel) and frames of a BVH file."""
    lines = path.read_text().splitlines()
    names, joint, k = [], None, 0
    while lines[k].strip() != "MOTION":
        words = lines[k].split()
        if words and words[0] in ("ROOT", "JOINT"):
            joint = words[1]
        elif words and words[0] == "CHANNELS":
            names += [f"{joint}.{c}" for c in words[2:]]
        k += 1
    return names, np.array([[float(x) for x in line.split()] for line in lines[k + 3:] if line.strip()])


def scenario(folder: Path, name: str, args: list[str], bvh: str) -> dict:
    """A scenario without and with ``--physics`` (interleaved, 2 runs each, with and without its pictures):
    the wall-time ratios and the physical run's balance figures."""
    walls: dict[str, list[float]] = {"plain": [], "physics": [], "plain_no_pictures": [], "physics_no_pictures": []}
    for _ in range(2):
        for key, extra in (("plain", []), ("physics", ["--physics"]), ("plain_no_pictures", ["--no-pictures"]),
                           ("physics_no_pictures", ["--physics", "--no-pictures"])):
            walls[key].append(command(folder, ["run", name, *args, "--out", key, *extra]))
    best = {k: min(v) for k, v in walls.items()}
    ratio, bare = best["physics"] / best["plain"], best["physics_no_pictures"] / best["plain_no_pictures"]
    data = table(list(csv.reader(open(folder / "physics" / "physics.csv", newline=""))))
    inside = float(data[:, 8].mean())
    out = {"wall_s": {k: round(v, 2) for k, v in best.items()},
           "ratio": round(ratio, 2), "ratio_holds": ratio <= 2.0,
           "ratio_no_pictures": round(bare, 2), "ratio_no_pictures_holds": bare <= 2.0,
           "frames": len(data), "fallen": bool(data[:, 10].max()), "com_inside_share": round(inside, 4),
           "balance_holds": not data[:, 10].max() and inside >= 0.99}
    names, physical = bvh_frames(folder / "physics" / bvh)
    _, plain = bvh_frames(folder / "plain" / bvh)
    vl5 = [names.index(f"vl5.{a}rotation") for a in "ZXY"]
    if name == "conductor":
        sd = float(physical[:, vl5].std(axis=0).max())
        added = float((physical[:, vl5] - plain[:, vl5]).std(axis=0).max())
        out.update(vl5_sd_deg=round(sd, 3), vl5_sd_added_by_physics_deg=round(added, 3),
                   vl5_holds=sd > 0.2 and added > 0.2)
    if name != "conductor":  # the cost target is the conductor's: the storyteller's ratios are reported
        for key in ("ratio_holds", "ratio_no_pictures_holds"):
            del out[key]
    out["holds"] = out.get("ratio_holds", True) and out["balance_holds"] and out.get("vl5_holds", True)
    return out


def scenarios(short: bool) -> dict:
    conductor_args = ["--bars", "8"] if short else []
    story_args = ["--story", "the_north_wind_and_the_sun"] if short else []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        return {"conductor": scenario(folder, "conductor", conductor_args, "conductor.bvh"),
                "storytelling": scenario(folder, "storytelling", story_args, "story.bvh")}


def main() -> None:
    if "--scenarios" in sys.argv or "--short" in sys.argv:
        found = scenarios("--short" in sys.argv)
        print(json.dumps({"benchmark": "the scenarios on the physical body (run ... --physics)",
                          "machine": {"python": platform.python_version(), "cpus": os.cpu_count()},
                          **found, "holds": all(v["holds"] for v in found.values())}, indent=2))
        return
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
