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
