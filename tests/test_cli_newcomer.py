"""What a newcomer types, from any folder: the examples the README and the documentation use are found,
commands that write files say
what they wrote where and make the folders they need, and what is printed is what is saved."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from agentsim.examples import HOME, names

ROOT = Path(__file__).resolve().parent.parent


def agentsim(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def test_every_example_the_readme_and_the_documentation_name_is_installed():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    text = "".join(page.read_text(encoding="utf-8") for page in pages)
    named = set(re.findall(r"(?<![\w/])examples/[\w/.-]+\.(?:xml|py|wav)", text))
    assert named and named <= set(names()), named - set(names())


def test_examples_are_listed_with_what_they_are_and_found_from_any_folder(tmp_path):
    listed = agentsim("examples", cwd=tmp_path)
    assert listed.returncode == 0
    rows = dict(line.split("\t", 1) for line in listed.stdout.splitlines() if "\t" in line)
    assert rows["examples/welcome.xml"].startswith("A greeting")
    # tmp_path has no examples folder: the installed one is read, and its sound file found beside it
    proc = agentsim("realize", "examples/bmla/applause.xml", "--tts", "builtin", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    feedback = [json.loads(line) for line in proc.stdout.splitlines()]
    times = {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
    assert times["applause:n1:start"] > 0.5 and not [f for f in feedback if f["type"] == "warningFeedback"]


def test_examples_copy_into_a_folder_once(tmp_path):
    proc = agentsim("examples", "copy", tmp_path, cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr.strip() == f"wrote {tmp_path}/examples/ ({len(names())} files)"
    copied = sorted(f"examples/{p.relative_to(tmp_path / 'examples').as_posix()}"
                    for p in (tmp_path / "examples").rglob("*") if p.is_file())
    assert copied == names()
    again = agentsim("examples", "copy", tmp_path, cwd=tmp_path)  # the same files again: nothing to do
    assert again.returncode == 0 and "wrote the 0 that were missing" in again.stderr, again.stderr
    (tmp_path / "examples" / "welcome.xml").unlink()
    again = agentsim("examples", "copy", tmp_path, cwd=tmp_path)  # one gone: it alone is copied
    assert again.returncode == 0 and "wrote the 1 that were missing" in again.stderr
    assert (tmp_path / "examples" / "welcome.xml").read_bytes() == (HOME / "welcome.xml").read_bytes()
    (tmp_path / "examples" / "cue.xml").write_text("<bml/>")  # edited there: never overwritten
    again = agentsim("examples", "copy", tmp_path, cwd=tmp_path)
    assert again.returncode == 2 and "exists already and cue.xml there differs" in again.stderr
    assert (tmp_path / "examples" / "cue.xml").read_text() == "<bml/>"


def test_plot_timeline_makes_its_folder_and_says_what_it_wrote(tmp_path):
    out = tmp_path / "missing" / "deeper" / "x.png"
    proc = agentsim("plot", "timeline", "examples/welcome.xml", "--metronome", "100", "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_size > 10_000
    assert proc.stderr.strip().splitlines()[-1] == f"wrote {out}"


def test_speech_export_says_what_it_wrote(tmp_path):
    text = tmp_path / "t.txt"
    text.write_text("Hello there, my friend.")
    proc = agentsim("speech", "export", text, "--tts", "builtin", "--textgrid", tmp_path / "out" / "t.TextGrid",
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert re.fullmatch(rf"wrote {tmp_path}/out/t\.TextGrid \(\d+\.\d\d s of speech\)", proc.stderr.strip())
    assert "xmax" in (tmp_path / "out" / "t.TextGrid").read_text()


def test_speech_calibrate_prints_the_keys_it_saves(tmp_path):
    texts = tmp_path / "texts.txt"
    texts.write_text("The first line of text to fit.\nA second one, a little longer than the first.\n")
    model = tmp_path / "m" / "model.json"
    proc = agentsim("speech", "calibrate", "--tts", "builtin", "--texts", texts, "--out", model, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    printed = json.loads(proc.stdout)
    saved = json.loads(model.read_text())
    assert printed == {**saved, "saved": str(model)}
    assert proc.stderr.strip() == f"wrote {model}"


def test_every_command_writes_into_out_slash_its_name_by_default():
    from agentsim.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["run", "conductor"]).out == "out/conductor"
    assert parser.parse_args(["run", "storytelling"]).out == "out/storytelling"
    assert parser.parse_args(["demo"]).out == "out/demo"


def test_the_conductors_music_on_the_command_line(tmp_path):
    out = tmp_path / "c"
    proc = agentsim("run", "conductor", "--target-bpm", 100, "--start-bpm", 90, "--meter", "3/4", "--bars", 12,
                    "--fps", 60, "--json", "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads(proc.stdout)
    assert (metrics["target_bpm"], metrics["start_bpm"], metrics["meter"], metrics["bars"]) == (100.0, 90.0, "3/4", 12)
    assert metrics["glossary"] == "README.md#glossary"
    assert "Frame Time: 0.01666667" in (out / "conductor.bvh").read_text()
    # the progress bar is for terminals: nothing of it in a pipe
    assert "\r" not in proc.stderr and "it/s" not in proc.stderr
    bad = agentsim("run", "conductor", "--meter", "5/4", "--out", tmp_path / "never", cwd=tmp_path)
    assert bad.returncode == 1 and not (tmp_path / "never").exists()
    assert bad.stderr.strip().endswith("with --meter 5/4: [piece]: meter '5/4' has no conducting pattern: use 2/4, "
                                       "3/4 or 4/4")


def test_realize_says_what_it_wrote(tmp_path):
    proc = agentsim("realize", "examples/welcome.xml", "--tts", "builtin", "--bvh", "o/w.bvh", "--csv", "o/tables",
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "wrote o/w.bvh, o/tables/"
    assert (tmp_path / "o" / "w.bvh").is_file() and (tmp_path / "o" / "tables").is_dir()


def test_feedback_times_are_printed_to_the_nanosecond(tmp_path):
    proc = agentsim("realize", "examples/welcome.xml", "--tts", "builtin", cwd=tmp_path)
    times = [f["globalTime"] for f in map(json.loads, proc.stdout.splitlines())]
    # sums of floats print as 3.2410000000000005 unrounded; no time has more than 9 decimals
    assert times and all(len(repr(t).split(".")[1]) <= 9 for t in times), times
    assert any(repr(t) == "3.241" for t in times)
