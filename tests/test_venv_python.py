"""The interpreter ``scripts/install.sh`` makes ``.venv`` from (``scripts/venv_python.sh``): Debian's own Python
when it is 3.11 or newer, the one ``AGENTSIM_PYTHON`` names, and a clear refusal of one too old or missing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "venv_python.sh"


def choose(**env: str) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if k != "AGENTSIM_PYTHON"} | env
    return subprocess.run(["bash", str(SCRIPT)], capture_output=True, text=True, env=environment, timeout=60)


def new_enough(python: str) -> bool:
    return subprocess.run([python, "-c", "import sys; sys.exit(sys.version_info < (3, 11))"]).returncode == 0


def test_debians_own_python_when_it_is_new_enough():
    done = choose()
    assert done.returncode == 0, done.stderr
    debian = Path("/usr/bin/python3")
    expected = str(debian) if debian.exists() and new_enough(str(debian)) else "python3"
    assert done.stdout == expected + "\n"


def test_the_one_agentsim_python_names():
    done = choose(AGENTSIM_PYTHON=sys.executable)
    assert done.returncode == 0, done.stderr
    assert done.stdout == sys.executable + "\n"


def test_one_too_old_or_missing_is_refused_with_how_to_name_another(tmp_path):
    old = tmp_path / "python2"
    old.write_text("#!/bin/sh\nexit 1\n")  # (what an interpreter older than 3.11 answers the check)
    old.chmod(0o755)
    for python in (str(old), str(tmp_path / "missing")):
        done = choose(AGENTSIM_PYTHON=python)
        assert done.returncode == 1 and done.stdout == ""
        assert done.stderr == (f"install.sh: {python} is not Python 3.11 or newer: install it, or name one with "
                               "AGENTSIM_PYTHON=/path/to/python3\n")
