"""Start-up: how long ``agentsim --help`` and ``agentsim realize`` of a one-behaviour file take, from the
process start to its exit (target: at most 0.3 s each; the commands import what they use when they use it).

Prints JSON: the median and the best of several runs of each command (each in a new interpreter), beside
a bare ``python -c pass``, and the machine's load average while they ran (the machine may be shared: the
best run is the one least disturbed).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import child_env

ROOT = Path(__file__).resolve().parent.parent
TARGET_S = 0.3
ONE = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="bml1">'
       '<gesture id="g1" lexeme="BEAT"/></bml>\n')




def wall(argv: list[str], runs: int) -> list[float]:
    env = child_env()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 9
    with tempfile.TemporaryDirectory() as folder:
        one = Path(folder) / "one.xml"
        one.write_text(ONE, encoding="utf-8")
        commands = {
            "python -c pass": [sys.executable, "-c", "pass"],
            "agentsim --help": [sys.executable, "-m", "agentsim", "--help"],
            "agentsim realize one.xml": [sys.executable, "-m", "agentsim", "realize", str(one)],
            "agentsim realize one.xml --tts builtin": [sys.executable, "-m", "agentsim", "realize", str(one),
                                                       "--tts", "builtin"],
        }
        for argv in commands.values():  # compile the bytecode once
            wall(argv, 1)
        load_before = os.getloadavg()[0]
        rows = {}
        for _ in range(2):  # interleaved, so that a burst of load falls on every command alike
            for name, argv in commands.items():
                rows.setdefault(name, []).extend(wall(argv, (runs + 1) // 2))
        load_after = os.getloadavg()[0]
    figures = {name: {"median_s": round(statistics.median(t), 3), "best_s": round(min(t), 3)}
               for name, t in rows.items()}
    print(json.dumps({
        "benchmark": "startup",
        "python": sys.version.split()[0],
        "load_average_1min": [round(load_before, 2), round(load_after, 2)],
        "commands": figures,
        "target_s": TARGET_S,
        "meets_target": all(figures[name]["median_s"] <= TARGET_S for name in figures if name.startswith("agentsim")),
    }, indent=2))


if __name__ == "__main__":
    main()
