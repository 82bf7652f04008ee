"""What several benchmarks share: the environment of the processes they measure."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def child_env() -> dict:
    """The environment of the measured processes: this checkout first on the path, and bytecode cached (in
    a folder of the benchmark's own), as an installed package has it."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")
    env["PYTHONPYCACHEPREFIX"] = str(Path(tempfile.gettempdir()) / "agentsim-bench-pycache")
    return env


def whole_command(argv: list[str], runs: int = 2) -> list[dict]:
    """``agentsim ARGV --out DIR`` as a user runs it, ``runs`` times after one run that is not counted (it
    compiles the bytecode and fills the speech cache): for each, the wall seconds from the process's launch
    to its exit, every output written, its ``metrics.json`` (None if it writes none there) and the names in
    its folder."""
    import json
    import subprocess
    import sys
    import time

    out = []
    for k in range(runs + 1):
        with tempfile.TemporaryDirectory() as folder:
            started = time.perf_counter()
            subprocess.run([sys.executable, "-m", "agentsim", *argv, "--out", folder], env=child_env(), check=True,
                           capture_output=True, text=True)
            wall = time.perf_counter() - started
            if k:
                metrics = Path(folder) / "metrics.json"
                out.append({"wall_s": wall, "metrics": json.loads(metrics.read_text()) if metrics.exists() else None,
                            "files": sorted(p.name for p in Path(folder).iterdir())})
    return out
