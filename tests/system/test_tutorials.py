"""Every tutorial and how-to guide of the documentation works as printed: each page's ```sh blocks run by
bash (``set -e``) and its ```python blocks by ``python``, each block a process of its own, all blocks of a page
in order, in one new empty folder per page, with only a virtual environment in which agentsim is installed as
a package first on PATH: as a reader types them. Blocks marked otherwise (```text, ```console, ```toml) are
only shown. What each page says it makes is then looked for.

A block may start a process in the background (``agentsim serve ... &``); a page stops what it started itself,
and whatever is left when the page ends is stopped here."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from helpers import fenced_blocks

pytestmark = pytest.mark.system

DOCS = Path(__file__).resolve().parents[2] / "docs"
PAGES = sorted(p for folder in ("tutorials", "howto") for p in (DOCS / folder).glob("*.md") if fenced_blocks(p))

#: What each page makes: files (non-empty) in its folder, and lines its blocks print (regular expressions).
MADE = {
    "tutorials/first-realization.md": (
        ["feedback.jsonl", "hello.jsonl", "welcome.wav", "welcome.bvh", "welcome.npz", "welcome.TextGrid",
         "tables/gestures.csv", "tables/visemes.csv", "run.html", "run_files/poses.js", "window.png",
         "python.html", "python_files/poses.js"],
        [r"^welcome:beat1:stroke +0\.450 s$", r"^welcome:beat2:stroke +2\.400 s$",
         r"^syncPointProgress welcome:beat2:stroke 2\.333333333333333$", r'"id": "hello:z2"']),
    "tutorials/conductor.md": (
        ["out/conductor/metrics.json", "out/conductor/report.html", "out/conductor/beats.csv",
         "out/compare/compare.json", "out/compare/best/metrics.json", "out/waltz/conductor.bvh"],
        [r"^beats to recover: \d+$", r"^follow +never"]),
    "tutorials/storyteller.md": (
        ["keeper.story", "out/keeper/metrics.json", "out/keeper/narration.wav", "out/keeper/story.TextGrid",
         "out/wind/compare.json", "out/wind/best/metrics.json", "out/again/metrics.json", "linear.json"],
        [r"^8 gestures on 23 words", r"^best +p95 +\d+\.\d\d ms  snaps +0 "]),
    "tutorials/trainer.md": (
        ["out/trainer/metrics.json", "out/trainer/report.html", "out/trainer/trainer.bvh", "out/trainer/narration.wav",
         "out/trainer/repetitions.csv", "out/all/compare.json", "out/all/lead/metrics.json", "reps.json"],
        [r"^repetition 3: person \d+\.\d\d s, trainer \d+\.\d\d s, count \d+\.\d\d s$", r"^fixed .* never ",
         r"^count 20 tempo "]),
    "tutorials/live-service.md": (
        ["serve.log", "examples/live/client.py"],
        [r"^skeleton of \d+ points at 30\.0 frames a second$", r"hello:g1:stroke$", r"hello:end$",
         r"'refused_documents': 0", r"talk:end", r"reply:end"]),
    "tutorials/anticipator.md": (
        ["agentsim-pulse/pyproject.toml", "agentsim-pulse/agentsim_pulse.py", "nod.xml"],
        [r"^pulse\tagentsim_pulse:Pulse\tperiod: float = 0\.5", r"3 passed",
         r'"id": "b:n:stroke", "time": 2\.0,', r'"id": "b:n:stroke", "time": 2\.4,', r"^b:g:stroke 3\.25$",
         r'"id": "b:g:stroke", "time": 3\.25,']),
    "tutorials/sweep.md": (
        ["out/sweep/results.parquet", "out/sweep/results.csv", "out/sweep/summary.png", "out/sweep/sweep.json"],
        [r"^\| best \| ", r"0 computed, 4 from the cache, 0 failed"]),
    "howto/dialects.md": ([], [r'"id": "bml1:end"', r"expected a <bml> element, found <fml-apml>",
                               r'"id": "helloWorld:key2:stroke"']),
    "howto/bmla.md": (
        ["on_start.jsonl", "chunk.jsonl", "softer.wav"],
        [r'"id": "talk:end".*"status": "INTERRUPTED"', r'"id": "applause:end"', r"^\['talk:end'\]$"]),
    "howto/voices.md": (
        ["welcome-festival.wav", "welcome-us.wav", "festival.json", "espeak.json", "linear_model.json",
         "linear.json", "story.wav", "story.TextGrid"],
        [r"^ ?\d+\.\d{3} s  Welcome$", r'"id": "p:h1:stroke"']),
    "howto/gestures.md": (["mine.toml", "present.bvh"], [r"^PRESENT +gesture form \(MURML\) +mine\.toml$"]),
    "howto/physics.md": (["talk.xml", "talk.bvh", "talk-physics.csv", "conductor-physics/physics.csv"],
                         [r'"id": "talk:hang:end"']),
    "howto/emotions.md": (["emotions.xml", "environment.csv", "feedback.jsonl"],
                          [r"^[\d.]+,joy,3\.2,close-up,eye,255,255,0,0\.5,positive,\S+$",
                           r"^[\d.]+,fear,6\.5,extreme-close-up,high,255,255,255,0\.65,negative,\S+$"]),
    "howto/piper.md": (["hello.xml", "hello.wav", "hello.TextGrid"],
                       [r'"id": "hello:g1:stroke"', r"^\['hello:g1:stroke'\]$"]),
    "howto/praat-blender.md": (
        ["talk.wav", "talk.bvh", "talk.npz", "talk.TextGrid", "tables/gestures.csv", "story.wav",
         "story.TextGrid"],
        [r"the right wrist is lowest at \d+\.\d{3} s", r"^ +g1 stroke +how "]),
}


def test_every_page_with_commands_says_what_it_makes():
    assert sorted(str(p.relative_to(DOCS)) for p in PAGES) == sorted(MADE)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(DOCS)))
def test_a_page_runs_as_printed(page, user_env, tmp_path):
    name = str(page.relative_to(DOCS))
    folder = tmp_path / page.stem
    folder.mkdir()
    printed, started = [], []
    begun = time.monotonic()
    try:
        for language, line, text in fenced_blocks(page):
            command = ["bash", "-c", "set -e -o pipefail\n" + text] if language == "sh" else ["python", "-c", text]
            proc = subprocess.Popen(command, cwd=folder, env=user_env, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True, start_new_session=True)
            started.append(proc.pid)
            out, err = proc.communicate(timeout=600)
            where = f"{name} line {line} ({language}):\n{text}"
            assert proc.returncode == 0, f"{where}\nexit status {proc.returncode}\n{err[-3000:]}"
            assert "Traceback" not in err, f"{where}\n{err[-3000:]}"
            printed.append(out)
    finally:
        for group in started:  # what a block left running in the background (its own session)
            try:
                os.killpg(group, signal.SIGTERM)
            except ProcessLookupError:
                pass
    seconds = time.monotonic() - begun
    files, lines = MADE[name]
    for made in files:
        assert (folder / made).is_file() and (folder / made).stat().st_size > 0, f"{name}: no {made}"
    output = "".join(printed)
    for pattern in lines:
        assert re.search(pattern, output, re.M), f"{name}: nothing printed matches {pattern!r}:\n{output[-3000:]}"
    print(f"{name}: {seconds:.1f} s")
