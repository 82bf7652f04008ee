"""``agentsim anticipators`` and ``--anticipator`` as a user types them: the parameters each anticipator
declares, read with their types; one line naming the key for a wrong one; a template for a new plugin."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from agentsim import __version__
from anticipators import registry
from agentsim.errors import AgentsimError

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def agentsim(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=120, cwd=cwd)


def test_version():
    proc = agentsim("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"agentsim {__version__}"


def test_the_list_shows_each_anticipator_with_its_typed_parameters():
    proc = agentsim("anticipators", "list")
    assert proc.returncode == 0, proc.stderr
    lines = dict(line.split("\t", 1) for line in proc.stdout.splitlines())
    assert lines["metronome"] == "anticipators.metronome:Metronome\tbpm: float = 120.0, start: float = 0.0"
    assert "window: int = 8" in lines["tap"] and "keyboard: bool = False" in lines["tap"]


def test_the_list_has_its_own_help():
    proc = agentsim("anticipators", "list", "--help")
    assert proc.returncode == 0
    assert proc.stdout.startswith("usage: agentsim anticipators list")
    assert "parameters" in proc.stdout


@pytest.mark.parametrize("spec, message", [
    ("metronome:m,bpm=abc", "anticipator 'metronome': parameter 'bpm' expects a number (float), got 'abc'"),
    ("metronome:m,bmp=90", "anticipator 'metronome' has no parameter 'bmp' (its parameters: bpm, start)"),
    ("tap:t,window=2.5", "anticipator 'tap': parameter 'window' expects a whole number (int), got '2.5'"),
    ("tap:t,keyboard=maybe", "anticipator 'tap': parameter 'keyboard' expects true or false, got 'maybe'"),
])
def test_a_wrong_parameter_is_one_line_naming_it(tmp_path, spec, message):
    doc = tmp_path / "nod.xml"
    doc.write_text(f'<bml {NS} id="b"><head id="n" lexeme="NOD"/></bml>')
    proc = agentsim("realize", doc, "--tts", "builtin", "--anticipator", spec)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1] == f"agentsim: {message}"
    assert "Traceback" not in proc.stderr and proc.stdout == ""


def test_parameters_are_read_with_their_declared_types(tmp_path):
    doc = tmp_path / "nod.xml"
    doc.write_text(f'<bml {NS} id="b"><head id="n" lexeme="NOD" stroke="anticipators:m:beat3"/></bml>')
    proc = agentsim("realize", doc, "--tts", "builtin", "--anticipator", "metronome:m,bpm=90,start=1")
    assert proc.returncode == 0, proc.stderr
    times = {f["id"]: f["globalTime"] for f in map(json.loads, proc.stdout.splitlines())
             if f["type"] == "syncPointProgress"}
    assert times["b:n:stroke"] == pytest.approx(1 + 2 * 60 / 90)
    tap = registry.create("tap", "t", window="4", keyboard="no", initial_bpm="100")
    assert (tap.window, tap.period) == (4, 0.6)  # an int, and a float: 60 / 100


def test_the_template_writes_a_whole_plugin(tmp_path):
    proc = agentsim("anticipators", "new", "my_pulse", "--dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    folder = tmp_path / "agentsim-my-pulse"
    files = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert files == ["README.md", "agentsim_my_pulse.py", "pyproject.toml", "tests/test_my_pulse.py"]
    assert 'my_pulse = "agentsim_my_pulse:MyPulse"' in (folder / "pyproject.toml").read_text()
    # the module is the anticipator: loaded as the entry point would load it, it predicts its pulses
    sys.path.insert(0, str(folder))
    try:
        from agentsim_my_pulse import MyPulse

        assert [p.describe() for p in registry.parameters(MyPulse)] == \
            ["period: float = 0.5", "start: float = 0.0", "drift: float = 0.0"]
        assert MyPulse(period=0.25, start=1.0).make_peg("pulse5") == 2.0
        assert MyPulse().make_peg("pulse0") is False and MyPulse().make_peg("beat1") is False
    finally:
        sys.path.remove(str(folder))
        sys.modules.pop("agentsim_my_pulse", None)
    again = agentsim("anticipators", "new", "my_pulse", "--dir", tmp_path)
    assert again.returncode == 2 and "exists already" in again.stderr
    bad = agentsim("anticipators", "new", "My-Pulse", "--dir", tmp_path)
    assert bad.returncode == 2 and "lower case letters" in bad.stderr


def test_create_refuses_an_unknown_anticipator_naming_the_installed_ones():
    with pytest.raises(AgentsimError, match=r"no anticipator named 'nope' is installed \(installed: .*metronome"):
        registry.create("nope")


def test_an_unknown_lexeme_plays_as_its_default_and_is_named(tmp_path):
    doc = tmp_path / "lex.xml"
    doc.write_text(f'<bml {NS} id="b"><gesture id="g" lexeme="WAVE"/><head id="h" lexeme="WIGGLE"/>'
                   '<gesture id="k" lexeme="BEAT"/><head id="n" lexeme="NOD"/></bml>')
    for strict in ([], ["--strict"]):
        proc = agentsim("realize", doc, "--tts", "builtin", *strict)
        assert proc.returncode == 0, proc.stderr
        feedback = [json.loads(line) for line in proc.stdout.splitlines()]
        warnings = {f["id"]: f["description"] for f in feedback if f["type"] == "warningFeedback"}
        assert warnings == {
            "b:g": "lexemes with no motion of their own here, played as a generic gesture: WAVE (g)",
            "b:h": "lexemes with no motion of their own here, played as a nod: WIGGLE (h)"}
        ends = {f["id"] for f in feedback if f["type"] == "syncPointProgress" and f["id"].endswith(":end")}
        assert ends == {"b:g:end", "b:h:end", "b:k:end", "b:n:end"}  # all four still play


def test_an_attribute_nothing_reads_is_named(tmp_path):
    doc = tmp_path / "typo.xml"
    text = f'<bml {NS} id="b"><head id="h" lexme="NOD"/><gaze id="z" target="user" influence="HEAD"/></bml>'
    doc.write_text(text)
    proc = agentsim("realize", doc, "--tts", "builtin")
    assert proc.returncode == 0, proc.stderr
    warnings = [f for f in map(json.loads, proc.stdout.splitlines()) if f["type"] == "warningFeedback"]
    assert [(w["id"], w["warningType"], w["description"]) for w in warnings] == [
        ("b:h", "CUSTOM_ATTRIBUTE_NOT_SUPPORTED",
         f"attribute 'lexme' of h is not one this realizer reads; ignored (line 1, column {text.index('<head') + 1})")]


def test_anticipators_list_shows_the_built_in_audio_anticipator():
    proc = subprocess.run([sys.executable, "-m", "agentsim", "anticipators", "list"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    names = {line.split("\t")[0]: line.split("\t")[1] for line in proc.stdout.splitlines()}
    assert names["audio"] == "anticipators.audio:AudioBeatAnticipator"
    assert {"metronome", "tap"} <= set(names)
    audio_line = next(line for line in proc.stdout.splitlines() if line.startswith("audio\t"))
    assert "tracker: str = 'causal'" in audio_line


def test_anticipate_beats_json_prints_what_the_documentation_says(tmp_path):
    import re
    from pathlib import Path

    import soundfile

    from agentsim.music.ensemble import render_ensemble

    audio, sr, beats = render_ensemble(bpm=112, meter="4/4", bars=4, seed=2, sample_rate=22050)
    soundfile.write(tmp_path / "e.wav", audio, sr)
    proc = subprocess.run([sys.executable, "-m", "agentsim", "anticipate", "beats", "e.wav", "--json"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    run = json.loads(proc.stdout)
    page = Path(__file__).resolve().parents[1] / "docs" / "explanation" / "beat-tracking.md"
    said = re.search(r"`agentsim anticipate beats AUDIO --json` prints one JSON object: (.*?); `--reference",
                     " ".join(page.read_text(encoding="utf-8").split())).group(1)
    assert set(re.findall(r"`(\w+)`", said)) == set(run)  # every key it prints, and no other
    assert run["tracker"] == "causal" and run["audio_seconds"] == pytest.approx(len(audio) / sr)
    updates = run["updates"]
    assert [set(u) for u in updates] == [{"t", "beats"}] * len(updates)
    assert [u["t"] for u in updates] == sorted(u["t"] for u in updates)  # in the order they were made
    locked = [u for u in updates if u["beats"]]
    assert len(locked) > 5 and all(b > u["t"] for u in locked for b in u["beats"])  # upcoming beats only
    middle = min(locked, key=lambda u: abs(u["t"] - 6.0))  # and they are the music's
    assert max(min(abs(p - b) for b in beats) for p in middle["beats"] if p < beats[-1]) < 0.07
