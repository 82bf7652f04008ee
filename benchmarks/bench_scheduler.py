"""Scheduler speed: time to schedule one parsed BML block of N behaviours with 3N constraints.

Prints JSON: the scheduling time for 1,000 behaviours and 3,000 constraints (target: under 100 ms on a
2-core machine; the time to parse the XML is reported beside it), and how the time grows from 100 to
10,000 behaviours (with the fitted exponent of time ~ N^k).
"""

from __future__ import annotations

import json
import platform
import statistics
import time

import numpy as np

from agentsim.bml.parser import _parse_ref, parse_bml
from agentsim.realizer import Realizer

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
    parse_s, schedule_s = [], []
    for _ in range(repeats):
        realizer = Realizer()
        _parse_ref.cache_clear()
        t0 = time.perf_counter()
        block = parse_bml(text)
        t1 = time.perf_counter()
        run = realizer.submit(block)
        t2 = time.perf_counter()
        assert run is not None and len(run.timed) == n, "every behaviour must be scheduled"
        parse_s.append(t1 - t0)
        schedule_s.append(t2 - t1)
    return {"behaviours": n, "constraints": n_constraints, "parse_ms": 1e3 * statistics.median(parse_s),
            "schedule_ms": 1e3 * statistics.median(schedule_s),
            "total_ms": 1e3 * (statistics.median(parse_s) + statistics.median(schedule_s))}


def main() -> None:
    sizes = [100, 300, 1000, 3000, 10000]
    rows = [measure(n, 7 if n <= 1000 else 3) for n in sizes]
    x = np.log([r["behaviours"] for r in rows])
    y = np.log([r["schedule_ms"] for r in rows])
    exponent = float(np.polyfit(x, y, 1)[0])
    at_1000 = next(r for r in rows if r["behaviours"] == 1000)
    print(json.dumps({
        "benchmark": "scheduler",
        "machine": f"{platform.processor() or platform.machine()}, python {platform.python_version()}",
        "schedule_ms_1000_behaviours_3000_constraints": round(at_1000["schedule_ms"], 2),
        "target_ms": 100,
        "meets_target": at_1000["schedule_ms"] < 100,
        "parse_ms": round(at_1000["parse_ms"], 2),
        "parse_and_schedule_ms": round(at_1000["total_ms"], 2),
        "growth": [{k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()} for r in rows],
        "growth_exponent": round(exponent, 2),
    }, indent=2))


if __name__ == "__main__":
    main()
