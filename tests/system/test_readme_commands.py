"""Every command the README prints works as printed from an empty folder, with only a virtual environment
on PATH in which agentsim is installed as a package (not from the checkout): the README's ```sh blocks run
in order, each as a bash script of its own, and its ```python blocks run one after another in one Python,
as a reader would type them. The commands are read from the README, so this test follows it as it changes.

The first two blocks install from the checkout and run these tests; they are what CI itself runs."""

from __future__ import annotations

import os
import re
import subprocess
import threading
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: The blocks that set up the checkout (install, run the tests): CI runs them itself.
SETUP_BLOCKS = 2
#: Before every shell block: stop at the first command that fails, saying which README line it is, and stop
#: what the block started in the background (``agentsim serve ... &``) when it ends.
PROLOGUE = """set -e -o pipefail
trap 'echo "README.md line $((LINENO - {offset})): exit status $?: $BASH_COMMAND" >&2' ERR
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT
"""


def blocks(language: str) -> list[tuple[int, str]]:
    """The README's fenced blocks in ``language``: (the line of its first command, its text)."""
    found, lines = [], README.read_text(encoding="utf-8").splitlines()
    for number, line in enumerate(lines, 1):
        if line.strip() == f"```{language}":
            end = lines.index("```", number)
            found.append((number + 1, "\n".join(lines[number:end]) + "\n"))
    return found


def test_the_readme_shows_commands_to_run():
    shell = blocks("sh")
    assert shell[0][1].startswith("bash scripts/install.sh") and "pytest" in shell[1][1]
    commands = [line for _, text in shell[SETUP_BLOCKS:] for line in text.splitlines() if line.strip()]
    assert len(commands) > 30 and any(c.startswith("agentsim sweep speech_sync") for c in commands)
    assert len(blocks("python")) >= 3


def user_env(venv: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.update(PATH=f"{venv / 'bin'}:/usr/bin:/bin", VIRTUAL_ENV=str(venv))
    return env


class Playing:
    """A rendered ensemble played into the default output (the null sink) over and over, for the commands
    that listen to a real input device (its monitor)."""

    def __init__(self):
        from agentsim.music.ensemble import render_ensemble

        self.audio, self.sr, _ = render_ensemble(bpm=112, meter="4/4", bars=16, seed=2, sample_rate=22050)
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self.play, daemon=True)

    def play(self):
        import sounddevice

        while not self.stopping.is_set():
            sounddevice.play(self.audio, self.sr, device="pulse")
            while sounddevice.get_stream().active and not self.stopping.is_set():
                self.stopping.wait(0.1)
        sounddevice.stop()

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stopping.set()
        self.thread.join(timeout=10)


def test_every_readme_command_works_from_an_empty_folder(user_environment, pulse_null_sink, tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    env = user_env(user_environment)
    located = subprocess.run(["python", "-c", "import agentsim, scenarios; print(agentsim.__file__)"], cwd=folder,
                             env=env, capture_output=True, text=True, check=True).stdout
    assert str(user_environment) in located and str(ROOT) not in located  # the package, not the checkout
    for line, text in blocks("sh")[SETUP_BLOCKS:]:
        prologue = PROLOGUE.format(offset=PROLOGUE.count("\n") - line + 1)
        listening = Playing() if "--input" in text else None
        try:
            if listening:
                listening.__enter__()
            proc = subprocess.run(["bash", "-c", prologue + text], cwd=folder, env=env, capture_output=True,
                                  text=True, timeout=1800)
        finally:
            if listening:
                listening.__exit__()
        assert proc.returncode == 0, f"README.md line {line}:\n{text}\n{proc.stderr[-3000:]}"
        assert "Traceback" not in proc.stderr, f"README.md line {line}:\n{proc.stderr[-3000:]}"
    python = "".join(text for _, text in blocks("python"))
    proc = subprocess.run(["python", "-c", python], cwd=folder, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r"^syncPointProgress welcome:beat1:stroke [0-9.]+$", proc.stdout, re.M), proc.stdout[:2000]
    assert "run_files/" in (folder / "run.html").read_text() and (folder / "run_files" / "poses.js").stat().st_size > 0
    # what the commands wrote is where the README says, in the folder they ran in
    # (run storytelling --compare, after the single run, replaces out/storytelling whole with its own files)
    for written in ("out/conductor/metrics.json", "out/storytelling/compare.json",
                    "out/storytelling/best/metrics.json", "welcome.bvh",
                    "timeline.png", "talk.TextGrid", "tables/gestures.csv", "story.wav", "errors.png",
                    "out/sweeps/conductor/results.parquet", "agentsim-pulse/pyproject.toml"):
        assert (folder / written).stat().st_size > 0, written
