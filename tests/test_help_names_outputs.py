"""Every command's ``--help`` names every file and folder the command writes: each command runs as a user
types it (small inputs) into a new folder, and each thing it wrote there is looked for in its help."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

#: Numbered pictures are named by a pattern: timeline_0000-0015s.png stands for timeline_0015-0030s.png too.
NUMBERED = re.compile(r"_\d{4}-\d{4}s\.png")


def agentsim(*args, cwd) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "agentsim", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc


def written(folder: Path) -> set[str]:
    """What a command wrote in ``folder``: its files by name, its folders as ``name/``."""
    return {NUMBERED.sub("_NNNN-NNNNs.png", p.name) + ("/" if p.is_dir() else "") for p in folder.iterdir()}


def help_text(*command, cwd) -> str:
    text = " ".join(agentsim(*command, "--help", cwd=cwd).stdout.split())
    return NUMBERED.sub("_NNNN-NNNNs.png", text.replace("- ", "-"))  # argparse may wrap a name at a hyphen


RUNS = {
    "conductor": (["run", "conductor"], ["--bars", "6"]),
    "conductor --compare": (["run", "conductor"], ["--bars", "6", "--compare"]),
    "storytelling": (["run", "storytelling"], ["--story", "the_north_wind_and_the_sun", "--tts", "builtin"]),
    "storytelling --compare": (["run", "storytelling"], ["--story", "the_north_wind_and_the_sun", "--tts",
                                                         "builtin", "--compare"]),
}


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
@pytest.mark.parametrize("name", RUNS)
def test_a_scenario_help_names_everything_it_writes(name, tmp_path):
    command, extra = RUNS[name]
    agentsim(*command, *extra, "--out", tmp_path / "out", cwd=tmp_path)
    text = help_text(*command, cwd=tmp_path)
    missing = sorted(n for n in written(tmp_path / "out") if n not in text and n.rstrip("/") + "/" not in text)
    assert not missing, f"{' '.join(command)} --help does not name {missing}"


def test_the_demo_help_names_its_folders(tmp_path):
    text = help_text("demo", cwd=tmp_path)
    assert "conductor/" in text and "storytelling/" in text and "out/demo" in text


def test_every_command_and_argument_has_a_help_text():
    import argparse

    from agentsim.cli import build_parser

    def silent(parser, path):
        if len(path) > 1 and not parser.description:
            yield " ".join(path) + " (no description)"
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from silent(sub, [*path, name])
            elif not action.help and not isinstance(action, argparse._HelpAction):
                yield f"{' '.join(path)} {action.dest}"

    assert list(silent(build_parser(), ["agentsim"])) == []
