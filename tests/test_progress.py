"""Progress of the long commands on a terminal, and nothing of it anywhere else.

Each command runs as a user types it, once with stderr a pseudo-terminal (what a user's terminal is to the
program) and once with stderr a pipe: on the terminal, stderr names each stage (and draws a bar of simulated
seconds, or of strategies with --compare); in the pipe, stderr holds none of it, and stdout is the same.
The progress must not change a run either: a simulation advanced with a bar gives the same feedback as one
without. And after --compare the output folder holds the per-strategy folders and compare.json, nothing else.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import struct
import subprocess
import sys
import termios
import threading
from pathlib import Path

import pytest

from speech_timing.animator_time import STRATEGIES as SPEECH_STRATEGIES

SHORT_STORY = "the_north_wind_and_the_sun"
CONDUCTOR_STRATEGIES = ("follow", "target", "lead", "best")


def command(*args) -> list[str]:
    return [sys.executable, "-m", "agentsim", *map(str, args)]


def on_terminal(argv: list[str], cwd: Path, timeout: float = 300) -> tuple[int, str, str]:
    """Run ``argv`` with stderr a pseudo-terminal 100 columns wide (stdout a pipe); returns the exit status,
    stdout and everything written to the terminal."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave, cwd=cwd)
    os.close(slave)
    screen: list[bytes] = []

    def read():
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: every end of the terminal's other side is closed
                return
            if not data:
                return
            screen.append(data)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        out, _ = proc.communicate(timeout=timeout)
    finally:
        proc.kill()
    reader.join(timeout=10)
    os.close(master)
    return proc.returncode, out.decode(), b"".join(screen).decode(errors="replace")


def in_pipes(argv: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, cwd=cwd, timeout=timeout)


def stage_line(name: str) -> str:
    """A finished stage as the terminal shows it: its name, then its wall seconds."""
    return rf"(^|\n|\r){re.escape(name)} \.\.\. \d+\.\d s\r?\n"


def without_figures(text: str) -> str:
    """``text`` without its numbers (wall times differ from one run to the next)."""
    return re.sub(r"\d+(\.\d+)?", "N", text)


STORY_STAGES = ("synthesising speech", "simulating", "poses/BVH", "audio", "report", "pictures")
CONDUCTOR_STAGES = ("simulating", "measuring", "poses/BVH", "audio", "report", "pictures")


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_run_storytelling_names_its_stages_on_a_terminal_and_nothing_in_a_pipe(tmp_path):
    # each run with a speech cache of its own: both synthesise (and say so on stdout)
    args = ("run", "storytelling", "--story", SHORT_STORY, "--tts", "builtin", "--fps", 30, "--window", 60)
    status, out, screen = on_terminal(command(*args, "--out", tmp_path / "tty", "--cache", tmp_path / "tty-cache"),
                                      tmp_path)
    assert status == 0, screen
    for name in STORY_STAGES:
        assert re.search(stage_line(name), screen), (name, screen)
    # the simulation is a bar of simulated seconds (47 s of speech after 1 s of preparation)
    assert re.search(r"simulating +\d+%\|.*\| \d+/48 s \[", screen), screen
    assert [s for s in STORY_STAGES if s in screen] == list(STORY_STAGES)
    assert screen.index("synthesising speech") < screen.index("simulating") < screen.index("poses/BVH") \
        < screen.index("pictures")
    piped = in_pipes(command(*args, "--out", tmp_path / "pipe", "--cache", tmp_path / "pipe-cache"), tmp_path)
    assert piped.returncode == 0, piped.stderr
    assert piped.stderr == ""
    assert out.startswith("The North Wind and the Sun: 152 words")
    assert without_figures(out).replace("tty", "pipe") == without_figures(piped.stdout)
    for name in ("feedback.jsonl", "story.bvh", "gestures.csv", "story.TextGrid"):  # (the built-in voice: no audio)
        assert (tmp_path / "tty" / name).read_bytes() == (tmp_path / "pipe" / name).read_bytes(), name


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_run_conductor_names_its_stages_on_a_terminal_and_nothing_in_a_pipe(tmp_path):
    args = ("run", "conductor", "--bars", 4)
    status, out, screen = on_terminal(command(*args, "--out", tmp_path / "tty"), tmp_path)
    assert status == 0, screen
    for name in CONDUCTOR_STAGES:
        assert re.search(stage_line(name), screen), (name, screen)
    # 0.5 s before the first beat, 16 beats at 120 BPM and 1 s of tail: a bar of 10 simulated seconds
    assert re.search(r"simulating +\d+%\|.*\| \d+/10 s \[", screen), screen
    piped = in_pipes(command(*args, "--json", "--out", tmp_path / "pipe"), tmp_path)
    assert piped.returncode == 0, piped.stderr
    assert not any(name in piped.stderr for name in CONDUCTOR_STAGES) and "\r" not in piped.stderr
    assert json.loads(piped.stdout)["bars"] == 4  # stdout is the JSON alone
    assert "written to" in out and not any(f"{name} ..." in out for name in CONDUCTOR_STAGES)
    for name in ("feedback.jsonl", "conductor.bvh", "gestures.csv", "ensemble.wav"):
        assert (tmp_path / "tty" / name).read_bytes() == (tmp_path / "pipe" / name).read_bytes(), name


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_storytelling_compare_is_one_bar_of_strategies_and_writes_only_their_folders(tmp_path):
    args = ("run", "storytelling", "--compare", "--story", SHORT_STORY, "--tts", "builtin", "--fps", 30)
    out = tmp_path / "tty"
    status, printed, screen = on_terminal(command(*args, "--out", out, "--cache", tmp_path / "tty-cache"), tmp_path)
    assert status == 0, screen
    assert f"strategies {len(SPEECH_STRATEGIES)}/{len(SPEECH_STRATEGIES)} |" in screen
    for name in SPEECH_STRATEGIES:
        for stage in ("simulating", "poses/BVH", "report"):
            assert f"{name}: {stage}" in screen, (name, stage)
    assert "\n" not in screen.strip()  # one bar, redrawn in place: no stage lines
    # only the strategies' folders and the comparison beside them; each folder is one run's files but the
    # timeline pictures
    assert sorted(p.name for p in out.iterdir()) == sorted([*SPEECH_STRATEGIES, "compare.json"])
    for name in SPEECH_STRATEGIES:
        files = {p.name for p in (out / name).iterdir()}
        assert {"metrics.json", "feedback.jsonl", "story.bvh", "story.TextGrid", "gestures.csv", "story.bml",
                "report.html", "sync_errors.png"} <= files, (name, files)
        assert not any(f.startswith("timeline") for f in files), files
        assert json.loads((out / name / "metrics.json").read_text())["strategy"] == name
    assert set(json.loads((out / "compare.json").read_text())["strategies"]) == set(SPEECH_STRATEGIES)
    assert f"written to {out}/<strategy>/ and {out / 'compare.json'}" in printed
    piped = in_pipes(command(*args, "--out", tmp_path / "pipe", "--cache", tmp_path / "pipe-cache"), tmp_path)
    assert piped.returncode == 0, piped.stderr
    assert piped.stderr == ""
    assert without_figures(printed).replace("tty", "pipe") == without_figures(piped.stdout)


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_conductor_compare_is_one_bar_of_strategies_and_writes_only_their_folders(tmp_path):
    args = ("run", "conductor", "--compare", "--bars", 4)
    out = tmp_path / "tty"
    status, printed, screen = on_terminal(command(*args, "--out", out), tmp_path)
    assert status == 0, screen
    assert "strategies 4/4 |" in screen
    for name in CONDUCTOR_STRATEGIES:
        assert f"{name}: simulating" in screen and f"{name}: pictures" in screen, name
    assert sorted(p.name for p in out.iterdir()) == sorted([*CONDUCTOR_STRATEGIES, "compare.json"])
    for name in CONDUCTOR_STRATEGIES:
        files = {p.name for p in (out / name).iterdir()}
        assert {"metrics.json", "feedback.jsonl", "conductor.bvh", "ensemble.wav", "tempo.png"} <= files, files
        assert not any(f.startswith("timeline") for f in files), files
    piped = in_pipes(command(*args, "--out", tmp_path / "pipe"), tmp_path)
    assert piped.returncode == 0, piped.stderr
    # in a pipe stderr keeps only each strategy's time, as it always has
    assert re.fullmatch(r"(\w+: \d+\.\d s\n){4}", piped.stderr), piped.stderr
    assert without_figures(printed).replace("tty", "pipe") == without_figures(piped.stdout)


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_eval_speech_sync_shows_the_strategy_under_way_on_a_terminal_only(tmp_path):
    args = ("eval", "speech-sync", "--tts", "builtin")
    status, out, screen = on_terminal(command(*args, "--strategy", "all"), tmp_path)
    assert status == 0, screen
    assert f"strategies {len(SPEECH_STRATEGIES)}/{len(SPEECH_STRATEGIES)} |" in screen
    assert all(f"{name}: simulating" in screen for name in SPEECH_STRATEGIES)
    piped = in_pipes(command(*args, "--strategy", "all"), tmp_path)
    assert piped.returncode == 0
    assert piped.stderr.startswith("251 strokes") and piped.stderr.count("\n") == 1 and "\r" not in piped.stderr
    assert out == piped.stdout  # the same table: the built-in voice and the seed make it deterministic
    status, out, screen = on_terminal(command(*args, "--strategy", "skip-70ms", "--json"), tmp_path)
    assert status == 0 and re.search(stage_line("simulating skip-70ms"), screen), screen
    assert json.loads(out)["strategy"] == "skip-70ms"
    assert in_pipes(command(*args, "--strategy", "skip-70ms", "--json"), tmp_path).stderr == ""


@pytest.mark.system  # the whole demo, twice (about a minute): with the long system tests
def test_demo_names_the_stages_of_both_scenarios_on_a_terminal_and_nothing_in_a_pipe(tmp_path):
    # the demo takes no options to make it shorter: the two runs go side by side
    piped = subprocess.Popen(command("demo", "--out", tmp_path / "pipe"), stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        status, out, screen = on_terminal(command("demo", "--out", tmp_path / "tty"), tmp_path, timeout=600)
        piped_out, piped_err = piped.communicate(timeout=600)
    finally:
        piped.kill()
    assert status == 0, screen
    conductor, _, storyteller = screen.partition("synthesising speech")
    for name in CONDUCTOR_STAGES:
        assert re.search(stage_line(name), conductor), name
    for name in STORY_STAGES[1:]:
        assert re.search(stage_line(name), storyteller), name
    assert out.startswith(f"== agentsim run conductor --out {tmp_path / 'tty' / 'conductor'}\n")
    assert piped.returncode == 0, piped_err
    assert piped_err == ""
    assert without_figures(out).replace("tty", "pipe") == without_figures(piped_out)


def test_a_telling_advanced_with_a_bar_is_the_same_run(capsys):
    """The bar of simulated seconds steps the clock itself: every event in the same order, none added."""
    from agentsim.core.progress import Stages
    from scenarios.storytelling.markup import read_story
    from scenarios.storytelling.run import STORIES_DIR
    from scenarios.storytelling.telling import make_voice, tell

    story = read_story(STORIES_DIR / f"{SHORT_STORY}.story")
    voice = make_voice("builtin", cache=False)
    plain = tell(story, "skip-70ms", voice=voice)
    assert capsys.readouterr().err == ""
    shown = tell(story, "skip-70ms", voice=voice, stages=Stages(enabled=True))
    assert shown.realizer.feedback.items == plain.realizer.feedback.items
    assert shown.realizer.env.now == plain.realizer.env.now
    assert re.search(r"simulating +100%\|.*\| (\d+)/\1 s", capsys.readouterr().err)  # full at the end


def test_a_conductor_run_advanced_with_a_bar_is_the_same_run(capsys):
    from agentsim.core.progress import Stages
    from scenarios.conductor.config import load_config
    from scenarios.conductor.scenario import simulate

    config = load_config(None, {"piece": {"bars": 4}}, "--bars 4")
    plain = simulate(config, "best", 1)
    assert capsys.readouterr().err == ""
    shown = simulate(config, "best", 1, stages=Stages(enabled=True))
    assert shown.realizer.feedback.items == plain.realizer.feedback.items
    assert shown.realizer.env.now == plain.realizer.env.now
    assert re.search(r"simulating +100%\|.*\| (\d+)/\1 s", capsys.readouterr().err)
