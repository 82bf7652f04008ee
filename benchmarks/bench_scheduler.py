"""Scheduler speed: time to schedule one parsed BML block of N behaviours with 3N constraints.

Prints JSON: the time to parse (the strict BML 1.0 reader, and the lenient one ``Realizer.submit`` uses)
and to schedule a block of 1,000 behaviours and 3,000 constraints (target: parse plus schedule at most
50 ms), and how the time grows from 100 to 10,000 behaviours (target: the fitted exponent of parse plus
schedule, time ~ N^k, at most 1.05). Wall time and process CPU time are both reported, with the load
average: on a shared machine the CPU time is the steadier figure.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agentsim.bml.parser import _parse_ref, parse_bml, parse_document  # noqa: E402
from agentsim.realizer import Realizer  # noqa: E402
from speech_timing.builtin import BuiltinBackend  # noqa: E402

TARGET_MS = 50.0
EXPONENT_TARGET = 1.05

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


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
        parse_document(text)
        lenient_s.append(time.perf_counter() - t0)
        realizer = Realizer(tts=BuiltinBackend())
        _parse_ref.cache_clear()
        c0 = time.process_time()
        t0 = time.perf_counter()
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


def main() -> None:
    load = [os.getloadavg()[0]]
    sizes = [100, 300, 1000, 3000, 10000]
    rows = [measure(n, 9 if n <= 1000 else 3) for n in sizes]
    load.append(os.getloadavg()[0])
    x = np.log([r["behaviours"] for r in rows])

    def exponent(key: str) -> float:
        return round(float(np.polyfit(x, np.log([r[key] for r in rows]), 1)[0]), 3)

    at_1000 = next(r for r in rows if r["behaviours"] == 1000)
    growth = {"parse_and_schedule": exponent("total_ms"), "parse_and_schedule_cpu": exponent("total_cpu_ms"),
              "schedule": exponent("schedule_ms"), "parse": exponent("parse_ms")}
    print(json.dumps({
        "benchmark": "scheduler",
        "machine": f"{platform.processor() or platform.machine()}, python {platform.python_version()}",
        "load_average_1min": [round(v, 2) for v in load],
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
                         "growth": growth["parse_and_schedule"] <= EXPONENT_TARGET},
    }, indent=2))


if __name__ == "__main__":
    main()
