"""Benchmark of agentsim sweep: the speedup of 2 Dask workers over 1 on a 24-point sweep, and the overhead per
point; prints JSON.

The 24 points are ``eval speech-sync --tts builtin`` on the bundled 431-word text (4 strategies x 6 seeds, most
of a second each). Each sweep runs into a fresh folder (nothing cached) on a new LocalCluster, first with one
worker, then with two, in this one run. Reported for each: the whole sweep's wall time, the cluster's start,
the compute phase (from the first point sent to the last result), the points' own time (the command's time
in its worker, summed), and the overhead per point, the compute phase's worker time not spent in a point's
command: ``(compute_s * workers - sum of point seconds) / points``. The speedup is the ratio of the compute
phases (and, end to end, of the whole sweeps, which include starting the cluster). The two sweeps alternate
``--repeat`` times (1, 2, 1, 2, ...) and the fastest of each counts, so that other work on the machine slows
neither alone. For comparison, one point as its own ``agentsim`` process: the start-up a process per point
would add.

Usage::

    python benchmarks/bench_sweep.py [--points-per-strategy 6] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import OrderedDict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agentsim.cli.sweep import runner, spec  # noqa: E402 (after the path is set)
from agentsim.cli.sweep.results import read  # noqa: E402

STRATEGIES = ["best", "chang-naive", "chang-smooth", "skip-70ms"]


def write_spec(folder: Path, seeds: int) -> Path:
    path = folder / "bench.toml"
    path.write_text('command = ["eval", "speech-sync"]\n[grid]\n'
                    f"strategy = {json.dumps(STRATEGIES)}\nseed = {json.dumps(list(range(1, seeds + 1)))}\n"
                    '[fixed]\ntts = "builtin"\n')
    return path


def sweep(path: Path, folder: Path, workers: int) -> OrderedDict:
    checked = spec.load(path)
    outcome = runner.run(checked, folder, workers=workers, quiet=True)
    assert outcome.failed == 0 and outcome.computed == outcome.points, outcome
    table = read(folder)
    own = float(table["seconds"].sum())
    return OrderedDict(
        workers=workers, points=outcome.points, sweep_s=round(outcome.seconds, 2),
        cluster_start_s=round(outcome.startup_seconds, 2), compute_s=round(outcome.compute_seconds, 2),
        points_own_s=round(own, 2), mean_point_s=round(own / outcome.points, 3),
        overhead_per_point_s=round((outcome.compute_seconds * workers - own) / outcome.points, 4),
        workers_used=int(table["worker"].nunique()))


def process_per_point(path: Path) -> OrderedDict:
    """One point as its own process: its wall time against the command's own time in it."""
    point = spec.load(path).points[0]
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "agentsim", *point.argv], cwd=ROOT, capture_output=True, text=True,
                          check=True)
    wall = time.perf_counter() - started
    own = json.loads(done.stdout)["wall_seconds"]
    return OrderedDict(process_s=round(wall, 3), simulation_s=round(own, 3), startup_s=round(wall - own, 3))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points-per-strategy", type=int, default=6, help="seeds per strategy (6: 24 points)")
    ap.add_argument("--repeat", type=int, default=2, help="sweeps of each kind, alternating; the fastest counts (2)")
    args = ap.parse_args(argv)
    runs: dict[int, list] = {1: [], 2: []}
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
        tmp = Path(tmp)
        path = write_spec(tmp, args.points_per_strategy)
        for repeat in range(args.repeat):
            for workers in (1, 2):
                runs[workers].append(sweep(path, tmp / f"{workers}-{repeat}", workers))  # a fresh folder each
        alone = process_per_point(path)
    one, two = (min(runs[w], key=lambda r: r["compute_s"]) for w in (1, 2))
    result = OrderedDict(
        benchmark="sweep",
        command="eval speech-sync --tts builtin (431 words)",
        points=one["points"],
        speedup_2_over_1=round(one["compute_s"] / two["compute_s"], 2),
        speedup_2_over_1_end_to_end=round(one["sweep_s"] / two["sweep_s"], 2),
        target_speedup=1.8,
        one_worker=one,
        two_workers=two,
        compute_s_of_every_run={f"{w} worker{'s' if w > 1 else ''}": [r["compute_s"] for r in runs[w]] for w in runs},
        process_per_point=alone,
        cores=len(os.sched_getaffinity(0)),
        load_average_1min=OrderedDict(before=round(load_before, 2), after=round(os.getloadavg()[0], 2)),
        python=platform.python_version(),
    )
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
