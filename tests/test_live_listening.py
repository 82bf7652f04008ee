"""``agentsim serve`` listens as ``agentsim realize`` does: ``--metronome`` and ``--anticipator`` give a live
client's BML the same anticipators (welcome.xml's metronome beats realize live, on the metronome's times).
The audio beat anticipator on a live input (``--input``) is tests/system/test_serve_listening.py."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from websockets.sync.client import connect

from agentsim.examples import resolve
from tests.helpers import receive

#: The metronome the tests serve with: 100 BPM, beat 1 two seconds after the service's clock starts (welcome.xml
#: is sent well before its beat 5 then, whose gesture starts 0.45 s ahead).
BPM, START = 100.0, 2.0


def serve(*options: str) -> tuple[subprocess.Popen, str]:
    """``agentsim serve`` with ``options``, and its WebSocket URL once it listens."""
    proc = subprocess.Popen([sys.executable, "-m", "agentsim.cli", "serve", "--port", "0", "--audio", "none",
                             "--fps", "0", "--tts", "builtin", *options], stderr=subprocess.PIPE, text=True)
    for line in proc.stderr:
        if line.startswith("agentsim serve:"):
            return proc, next(w for w in line.split() if w.startswith("ws://"))
    proc.wait(30)
    raise AssertionError(f"the service did not start (exit status {proc.returncode})")


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def welcome(url: str) -> list[dict]:
    with connect(url) as ws:
        ws.send(Path(resolve("examples/welcome.xml")).read_bytes())
        return [m for _, m in receive(ws, lambda m: m["id"] == "welcome:end", timeout=30)]


@pytest.mark.parametrize("options", [("--metronome", f"{BPM:g},{START:g}"),
                                     ("--anticipator", f"metronome,bpm={BPM:g},start={START:g}")])
@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_welcome_realizes_its_metronome_beats_live(options):
    proc, url = serve(*options)
    try:
        got = welcome(url)
    finally:
        stop(proc)
    assert not [m for m in got if m["type"] == "warningFeedback"], got
    strokes = {m["id"]: m["globalTime"] for m in got if m["type"] == "syncPointProgress" and m["id"].endswith(":stroke")}
    for behaviour, beat in (("beat2", 5), ("beat3", 6), ("nod2", 7)):  # on the metronome's beats
        assert strokes[f"welcome:{behaviour}:stroke"] == pytest.approx(START + (beat - 1) * 60 / BPM, abs=1e-6)


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_without_a_metronome_welcome_loses_its_three_beats_with_warnings():
    proc, url = serve()
    try:
        got = welcome(url)
    finally:
        stop(proc)
    dropped = {b for m in got if m["type"] == "warningFeedback" for b in m["modifiedBehaviours"]}
    assert dropped == {"beat2", "beat3", "nod2"}
    assert "welcome:beat1:stroke" in {m["id"] for m in got}  # the rest is realized


@pytest.mark.parametrize("options, message", [
    (("--metronome", "0"), "the metronome tempo must be positive"),
    (("--anticipator", "metronome,bpm=fast"), "parameter 'bpm' expects a number"),
    (("--anticipator", "nosuch"), "no anticipator named 'nosuch'"),
    (("--input", "no such input device"), "no audio input device 'no such input device'"),
    (("--metronome", "100", "--anticipator", "metronome,bpm=90"), "two anticipators have the id 'metronome'"),
])
def test_bad_listening_options_are_said_before_anything_starts(options, message):
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "serve", "--port", "0", "--audio", "none",
                           "--fps", "0", "--tts", "builtin", *options], capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    lines = [line for line in proc.stderr.splitlines() if line.strip() and not line.startswith(" ")]
    assert message in lines[-1] and not [line for line in lines if "Traceback" in line], proc.stderr
