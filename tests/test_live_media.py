"""Sound files named by clients of ``agentsim serve``: read only from ``--media DIR``, by relative paths
without ``..``; every refusal is one warning to the sender alone that names the behaviour and says nothing
of the server's file system (the same words whether the file exists, is outside, or is not sound)."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest
import soundfile
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmlt="http://hmi.ewi.utwente.nl/bmlt"'


def audio_block(block_id: str, name: str) -> str:
    return f'<bml {NS} id="{block_id}"><bmlt:audiofile id="a" fileName="{name}"/></bml>'


def until_end(ws, block_id: str, timeout: float = 10.0) -> list[dict]:
    got = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got.append(json.loads(ws.recv(timeout=deadline - time.monotonic())))
        if got[-1]["id"] == f"{block_id}:end":
            return got
    raise AssertionError(f"no {block_id}:end in {[f['id'] for f in got]}")


@pytest.fixture(scope="module")
def media(tmp_path_factory):
    root = tmp_path_factory.mktemp("served")
    media = root / "media"
    (media / "sub").mkdir(parents=True)
    click = np.zeros(2205, dtype=np.float32)
    click[:20] = 0.5
    soundfile.write(media / "click.wav", click, 22050)
    soundfile.write(media / "sub" / "click.wav", click, 22050)
    soundfile.write(root / "outside.wav", click, 22050)
    (media / "notes.txt").write_text("not a sound\n")
    (media / "escape.wav").symlink_to(root / "outside.wav")
    return media


@pytest.fixture(scope="module")
def served(media):
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend(), media=media)) as running:
        yield running


PROBES = ["/etc/passwd", "/etc/shadow", "/no/such/file.wav", "../outside.wav", "sub/../click.wav",
          "..\\outside.wav", "missing.wav", "notes.txt", "escape.wav", "sub", "~/x.wav", "C:/x.wav",
          str("{media}/click.wav")]


def test_files_in_the_media_directory_play(served):
    with connect(served.url) as ws:
        for i, name in enumerate(["click.wav", "sub/click.wav", "./click.wav"]):
            ws.send(audio_block(f"ok{i}", name))
            got = until_end(ws, f"ok{i}")
            assert not [f for f in got if f["type"] == "warningFeedback"], got
            ends = [f for f in got if f["id"] == f"ok{i}:a:end"]
            assert len(ends) == 1 and ends[0]["time"] == pytest.approx(0.1, abs=1e-6)


def test_every_probe_is_one_warning_that_reveals_nothing_and_goes_to_the_sender_alone(served, media):
    with connect(served.url) as sender, connect(served.url) as other:
        other.send(json.dumps({"subscribe": "feedback"}))
        descriptions = set()
        for i, probe in enumerate(PROBES):
            name = probe.replace("{media}", str(media))
            sender.send(audio_block(f"p{i}", name))
            got = until_end(sender, f"p{i}")
            warnings = [f for f in got if f["type"] == "warningFeedback"]
            assert len(warnings) == 1, (name, warnings)
            (warning,) = warnings
            assert warning["id"] == f"p{i}:a" and warning["description"].startswith("a: audiofile refused: ")
            for secret in (str(media), str(media.parent), os.getcwd(), "/etc", "not found", "not a sound file",
                           "outside.wav", "Error opening"):
                assert secret not in warning["description"], (name, warning["description"])
            descriptions.add(warning["description"])
        assert len(descriptions) == 1, descriptions  # nothing tells one probe from another
        # the subscriber heard the probes' blocks run, and none of the warnings about them
        heard = until_end(other, f"p{len(PROBES) - 1}")
        assert "p0:end" in [f["id"] for f in heard]
        assert not [f for f in heard if f["type"] == "warningFeedback"]


def test_without_media_no_file_is_read():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        with connect(running.url) as ws:
            ws.send(audio_block("n", "click.wav"))
            (warning,) = [f for f in until_end(ws, "n") if f["type"] == "warningFeedback"]
    assert warning["description"] == ("a: audiofile refused: this server reads no sound files named by clients "
                                      "(it was started without --media DIR); behaviour dropped")


def test_realize_reads_local_files_as_before(tmp_path):
    import subprocess
    import sys

    soundfile.write(tmp_path / "click.wav", np.zeros(2205, dtype=np.float32), 22050)
    (tmp_path / "b.xml").write_text(audio_block("b", "click.wav"))
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "realize", "--tts", "builtin", str(tmp_path / "b.xml")],
                          capture_output=True, text=True, timeout=120, cwd="/")
    assert proc.returncode == 0, proc.stderr
    items = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [f["time"] for f in items if f["id"] == "b:a:end"] == [pytest.approx(0.1)]
    assert not [f for f in items if f["type"] == "warningFeedback"]
