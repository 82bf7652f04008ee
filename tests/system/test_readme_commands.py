"""Every command the README prints works as printed from an empty folder, with only a virtual environment
on PATH in which agentsim is installed as a package (not from the checkout): the README's ```sh blocks run
in order, each as a bash script of its own, and its ```python blocks run one after another in one Python,
as a reader would type them. The commands are read from the README, so this test follows it as it changes.

The first two blocks install from the checkout and run these tests; they are what CI itself runs. The
tutorials and how-to guides the README leads to are run the same way by ``test_tutorials.py``."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from helpers import fenced_blocks

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: The blocks that set up the checkout (install, run the tests): CI runs them itself.
SETUP_BLOCKS = 2
#: Before every shell block: stop at the first command that fails, saying which README line it is, and stop
#: what the block started in the background when it ends.
PROLOGUE = """set -e -o pipefail
trap 'echo "README.md line $((LINENO - {offset})): exit status $?: $BASH_COMMAND" >&2' ERR
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT
"""


def blocks(language: str) -> list[tuple[int, str]]:
    """The README's fenced blocks in ``language``: (the line of its first command, its text)."""
    return [(line, text) for _, line, text in fenced_blocks(README, (language,))]


def test_the_readme_shows_the_commands_of_ci_and_a_tour():
    shell = blocks("sh")
    assert shell[0][1] == "bash scripts/install.sh && .venv/bin/agentsim demo\n"
    assert shell[1][1] == ".venv/bin/python -m pytest -q -n auto && .venv/bin/python -m pytest -q -m system\n"
    assert (ROOT / ".ci" / "run").read_text().count(shell[1][1].strip()) == 1  # what CI runs, word for word
    tour = [line for _, text in shell[SETUP_BLOCKS:] for line in text.splitlines() if line.strip()]
    assert tour and all(line.startswith("agentsim realize ") for line in tour)
    assert len(blocks("python")) == 1
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 150


def test_every_readme_command_works_from_an_empty_folder(user_environment, user_env, tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    located = subprocess.run(["python", "-c", "import agentsim, scenarios; print(agentsim.__file__)"], cwd=folder,
                             env=user_env, capture_output=True, text=True, check=True).stdout
    assert str(user_environment) in located and str(ROOT) not in located  # the package, not the checkout
    for line, text in blocks("sh")[SETUP_BLOCKS:]:
        prologue = PROLOGUE.format(offset=PROLOGUE.count("\n") - line + 1)
        proc = subprocess.run(["bash", "-c", prologue + text], cwd=folder, env=user_env, capture_output=True,
                              text=True, timeout=600)
        assert proc.returncode == 0, f"README.md line {line}:\n{text}\n{proc.stderr[-3000:]}"
        assert "Traceback" not in proc.stderr, f"README.md line {line}:\n{proc.stderr[-3000:]}"
    python = "".join(text for _, text in blocks("python"))
    proc = subprocess.run(["python", "-c", python], cwd=folder, env=user_env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # the same stroke, where the README says: in the command's feedback and in the program's
    assert re.search(r"^syncPointProgress welcome:beat1:stroke 0\.45$", proc.stdout, re.M), proc.stdout[:2000]
    feedback = [json.loads(line) for line in (folder / "feedback.jsonl").read_text().splitlines()]
    strokes = {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
    assert strokes["welcome:beat1:stroke"] == 0.45 and strokes["welcome:beat2:stroke"] == 2.4  # metronome beat 5
