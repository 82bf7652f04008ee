"""Scheduler speed: time to parse and schedule one BML block of N behaviours with 3N constraints.

Prints JSON with every figure, its target and whether it ``holds``:

* the command line as the issue defines it (``cli``): ``agentsim realize DOC --until 0.001`` for a document of
  1,000 behaviours and 3,000 constraints minus the same for a document of one behaviour, the wall time of the
  command in a subprocess, minimum of 3 (target: at most 60 ms). It runs with the default speech backend
  (espeak-ng when installed, and the figure says which backend it had: the block's 100 speeches are read from
  the speech cache, which the first run of each command fills, as a document realized again reads them) and
  again with ``--tts builtin`` (``cli_builtin``), the figure of reading, scheduling and the feedback printed.
  The commands run with their compiled bytecode cached (in a scratch folder, after a first run of each), as an
  installed package runs; their CPU time is reported too.
* the time growth (``growth_exponent``): parse plus schedule in-process from 100 to 10,000 behaviours, the
  fitted exponent of time ~ N^k (target: at most 1.05);
* in-process, at 1,000 behaviours: the time to parse (the strict BML 1.0 reader, and the lenient one
  ``Realizer.submit`` uses) and to schedule (``Realizer.submit`` of the parsed block), with a target of its own
  for parse plus schedule: at most 50 ms.

In process, the garbage collector is held off while a block is read and while it is scheduled, as the
command line holds it off (one :class:`~agentsim.core.gcpause.CollectionPause`).

Wall time and process CPU time are both reported, with the load average: on a shared machine the CPU time is
the steadier figure. ``--no-cli`` leaves the command line out; ``--cli-only`` measures only that.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agentsim.bml.parser import _parse_ref, parse_bml, parse_document  # noqa: E402
from agentsim.core.gcpause import CollectionPause  # noqa: E402
from agentsim.realizer import Realizer  # noqa: E402
from speech_timing.builtin import BuiltinBackend  # noqa: E402

TARGET_MS = 50.0
EXPONENT_TARGET = 1.05
#: The issue's figure: ``agentsim realize`` of 1,000 behaviours minus one behaviour (ms, wall).
CLI_TARGET_MS = 60.0
CLI_BEHAVIOURS = 1000

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
#: The collector's pause, as the command line has one.
PAUSE = CollectionPause()


def make_block(n: int, seed: int = 0) -> tuple[str, int]:
    """A block of ``n`` behaviours (speech every tenth) and about ``3 n`` constraints."""
    rng = np.random.default_rng(seed)
    parts, constraints = [], []
    for i in range(n):
        if i % 10 == 0:
            words = " ".join(rng.choice(["we", "walk", "along", "the", "river", "slowly", "today"], 6))
            parts.append(f'<speech id="b{i}"><text>{words} <sync id="m"/>{words}.</text></speech>')
        else:
            kind = ("gesture", "head", "faceLexeme")[i % 3]
            lexeme = {"gesture": "BEAT", "head": "NOD", "faceLexeme": "RAISE_BROWS"}[kind]
            parts.append(f'<{kind} id="b{i}" lexeme="{lexeme}"/>')
        if i == 0:
            constraints.append('<synchronize><sync ref="b0:start"/><sync ref="0"/></synchronize>')
            constraints += ['<after ref="0"><sync ref="b0:end"/></after>'] * 2
            continue
        prev = f"b{i - 1}"
        # 1: tie this start to the previous behaviour's end; 2: the same tie stated again (one peg);
        # 3: an ordering constraint that holds.
        constraints.append(f'<synchronize><sync ref="b{i}:start"/><sync ref="{prev}:end+0.05"/></synchronize>')
        constraints.append(f'<synchronize><sync ref="{prev}:end"/><sync ref="b{i}:start-0.05"/></synchronize>')
        constraints.append(f'<after ref="{prev}:start"><sync ref="b{i}:end"/></after>')
    body = "".join(parts) + "<constraint>" + "".join(constraints) + "</constraint>"
    return f'<bml {NS} id="bench">{body}</bml>', len(constraints)


def measure(n: int, repeats: int) -> dict:
    text, n_constraints = make_block(n)
    parse_s, lenient_s, schedule_s, cpu_s = [], [], [], []
    for _ in range(repeats):
        _parse_ref.cache_clear()
        t0 = time.perf_counter()
        with PAUSE.paused():
            parse_document(text)
        lenient_s.append(time.perf_counter() - t0)
        realizer = Realizer(tts=BuiltinBackend(), gc_pause=PAUSE)
        _parse_ref.cache_clear()
        c0 = time.process_time()
        t0 = time.perf_counter()
        with PAUSE.paused():
            block = parse_bml(text)
        t1 = time.perf_counter()
        run = realizer.submit(block)
        t2 = time.perf_counter()
        cpu_s.append(time.process_time() - c0)
        assert run is not None and len(run.timed) == n, "every behaviour must be scheduled"
        parse_s.append(t1 - t0)
        schedule_s.append(t2 - t1)
    return {"behaviours": n, "constraints": n_constraints, "parse_ms": 1e3 * statistics.median(parse_s),
            "lenient_parse_ms": 1e3 * statistics.median(lenient_s),
            "schedule_ms": 1e3 * statistics.median(schedule_s),
            "total_ms": 1e3 * (statistics.median(parse_s) + statistics.median(schedule_s)),
            "total_best_ms": 1e3 * min(p + s for p, s in zip(parse_s, schedule_s)),
            "total_cpu_ms": 1e3 * statistics.median(cpu_s)}


def _realize(document: Path, backend: list[str], env: dict) -> tuple[float, float, str]:
    """Wall and CPU seconds of one ``agentsim realize DOCUMENT --until 0.001`` (and its first line on stderr)."""
    command = [sys.executable, "-m", "agentsim", "realize", str(document), "--until", "0.001", *backend]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return wall, cpu, done.stderr.splitlines()[0] if done.stderr else ""


def measure_cli(backend: list[str], repeats: int = 3) -> dict:
    """The issue's figure: ``agentsim realize`` of :data:`CLI_BEHAVIOURS` behaviours minus one behaviour, the
    minimum of ``repeats`` runs of each (interleaved), in ms; ``backend``: extra arguments (``--tts builtin``)."""
    with tempfile.TemporaryDirectory(prefix="bench-scheduler-") as scratch:
        folder = Path(scratch)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(
            os.pathsep), PYTHONPYCACHEPREFIX=str(folder / "pycache"))
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        documents = {}
        for n in (1, CLI_BEHAVIOURS):
            documents[n] = folder / f"block-{n}.xml"
            documents[n].write_text(make_block(n)[0], encoding="utf-8")
        runs: dict[int, list[tuple[float, float, str]]] = {1: [], CLI_BEHAVIOURS: []}
        for n in runs:  # first runs: the bytecode is compiled and cached, as an installed package has it
            _realize(documents[n], backend, env)
        for _ in range(repeats):
            for n in runs:
                runs[n].append(_realize(documents[n], backend, env))
    wall = {n: min(r[0] for r in rs) for n, rs in runs.items()}
    cpu = {n: min(r[1] for r in rs) for n, rs in runs.items()}
    ms = 1e3 * (wall[CLI_BEHAVIOURS] - wall[1])
    return {"command": "agentsim realize DOC --until 0.001" + "".join(f" {a}" for a in backend),
            "speech": runs[1][0][2].removeprefix("speech: "),
            "ms": round(ms, 1), "cpu_ms": round(1e3 * (cpu[CLI_BEHAVIOURS] - cpu[1]), 1),
            "one_behaviour_ms": round(1e3 * wall[1], 1), "target_ms": CLI_TARGET_MS, "holds": ms <= CLI_TARGET_MS}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-cli", action="store_true", help="leave out the command-line figure")
    parser.add_argument("--cli-only", action="store_true", help="measure only the command-line figure")
    parser.add_argument("--cli-repeats", type=int, default=3,
                        help="runs of each command (default 3; the minimum counts)")
    args = parser.parse_args(argv)
    load = [os.getloadavg()[0]]
    cli = {}
    if not args.no_cli:
        cli = {"cli": measure_cli([], args.cli_repeats),
               "cli_builtin": measure_cli(["--tts", "builtin"], args.cli_repeats)}
    if args.cli_only:
        load.append(os.getloadavg()[0])
        print(json.dumps({"benchmark": "scheduler", "machine": _machine(),
                          "load_average_1min": [round(v, 2) for v in load], **cli}, indent=2))
        return
    sizes = [100, 300, 1000, 3000, 10000]
    rows = [measure(n, 9 if n <= 1000 else 3) for n in sizes]
    load.append(os.getloadavg()[0])
    x = np.log([r["behaviours"] for r in rows])

    def exponent(key: str) -> float:
        return round(float(np.polyfit(x, np.log([r[key] for r in rows]), 1)[0]), 3)

    at_1000 = next(r for r in rows if r["behaviours"] == 1000)
    growth = {"parse_and_schedule": exponent("total_ms"), "parse_and_schedule_cpu": exponent("total_cpu_ms"),
              "schedule": exponent("schedule_ms"), "parse": exponent("parse_ms")}
    targets = [{"figure": "parse_and_schedule_ms (in-process, 1,000 behaviours)",
                "value": round(at_1000["total_ms"], 2), "target": TARGET_MS, "holds": at_1000["total_ms"] <= TARGET_MS},
               {"figure": "growth_exponent.parse_and_schedule", "value": growth["parse_and_schedule"],
                "target": EXPONENT_TARGET, "holds": growth["parse_and_schedule"] <= EXPONENT_TARGET}]
    targets += [{"figure": f"{key}.ms ({figure['command']}; speech: {figure['speech']})", "value": figure["ms"],
                 "target": CLI_TARGET_MS, "holds": figure["holds"]} for key, figure in cli.items()]
    print(json.dumps({
        "benchmark": "scheduler",
        "machine": _machine(),
        "load_average_1min": [round(v, 2) for v in load],
        **cli,
        "parse_ms": round(at_1000["parse_ms"], 2),
        "lenient_parse_ms": round(at_1000["lenient_parse_ms"], 2),
        "schedule_ms_1000_behaviours_3000_constraints": round(at_1000["schedule_ms"], 2),
        "parse_and_schedule_ms": round(at_1000["total_ms"], 2),
        "parse_and_schedule_best_ms": round(at_1000["total_best_ms"], 2),
        "parse_and_schedule_cpu_ms": round(at_1000["total_cpu_ms"], 2),
        "target_ms": TARGET_MS,
        "growth": [{k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()} for r in rows],
        "growth_exponent": growth,
        "exponent_target": EXPONENT_TARGET,
        "meets_target": {"parse_and_schedule": at_1000["total_ms"] <= TARGET_MS,
                         "growth": growth["parse_and_schedule"] <= EXPONENT_TARGET,
                         **{key: figure["holds"] for key, figure in cli.items()}},
        "targets": targets,
    }, indent=2))


def _machine() -> str:
    return f"{platform.processor() or platform.machine()}, python {platform.python_version()}"


if __name__ == "__main__":
    main()
