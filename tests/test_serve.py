"""``agentsim serve`` with a real WebSocket client: feedback on time, interruptions at once, bad input answered
to its sender alone, two clients, a client that leaves, a storm of blocks, a port in use. Who hears what is
tests/test_live_routing.py; who may connect, tests/test_live_access.py."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time

import pytest
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'
LATENESS_SPREAD = 0.020
INTERRUPT_LATENCY = 0.100


@pytest.fixture
def service():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        yield running


def receive_until(ws, done, timeout: float = 10.0) -> list[tuple[float, dict]]:
    """(arrival on time.monotonic(), feedback) until ``done(feedback)`` or ``timeout``."""
    got = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            message = ws.recv(timeout=0.2)
        except TimeoutError:
            continue
        item = json.loads(message)
        got.append((time.monotonic(), item))
        if done(item):
            return got
    raise AssertionError(f"timed out; got {[f['id'] for _, f in got]}")


def test_feedback_arrives_on_time_over_a_three_second_block(service):
    block = (f'<bml {NS} id="b1"><speech id="s"><text>One two three, four five six seven, eight nine ten.</text>'
             '</speech><wait id="w" start="0" end="3"/>'
             + "".join(f'<head id="h{i}" lexeme="NOD" start="{0.4 * i}"/>' for i in range(7)) + "</bml>")
    with connect(service.url) as ws:
        ws.send(block)
        got = receive_until(ws, lambda f: f["id"] == "b1:end")
    timed = [(arrival, f) for arrival, f in got if f["type"] in ("syncPointProgress", "blockProgress")]
    assert len(timed) > 40 and timed[-1][1]["globalTime"] >= 3.0
    lateness = [arrival - f["globalTime"] for arrival, f in timed]
    assert max(lateness) - min(lateness) <= LATENESS_SPREAD, (min(lateness), max(lateness))
    # in the order the realizer sent them, each once
    ids = [f["id"] for _, f in timed]
    assert len(ids) == len(set(ids))


def test_an_interrupt_sent_while_a_speech_plays_ends_it_at_once(service):
    talk = (f'<bml {NS} id="talk"><speech id="s"><text>This goes on <sync id="m"/>and on. '
            + "This goes on and on. " * 19 + "</text></speech></bml>")
    with connect(service.url) as ws:
        ws.send(talk)
        receive_until(ws, lambda f: f["id"] == "talk:s:m")  # well into the speech
        sent = time.monotonic()
        ws.send(f'<bml {NS} id="stop"><bmla:interrupt id="i" target="talk"/></bml>')
        got = receive_until(ws, lambda f: f["id"] == "talk:s:end")
    arrival, end = got[-1]
    assert arrival - sent <= INTERRUPT_LATENCY, arrival - sent
    assert end["globalTime"] < 5.0  # long before the 20 sentences would have ended
    # asked for: the speech's end says it was interrupted, and nothing is warned about
    assert end["status"] == "INTERRUPTED" and not [f for _, f in got if f["type"] == "warningFeedback"]


def test_a_malformed_message_is_answered_to_its_sender_and_the_next_block_runs(service):
    with connect(service.url) as sender, connect(service.url) as other:
        other.send('{"subscribe": "feedback"}')
        sender.send("<bml id='x'><head id='h' lexeme='NOD'></bml>")  # mismatched tag
        ((_, warning),) = receive_until(sender, lambda f: f["type"] == "warningFeedback")
        assert warning["warningType"] == "PARSING_FAILURE" and "mismatched tag" in warning["description"]
        sender.send("not BML at all")
        ((_, second),) = receive_until(sender, lambda f: f["type"] == "warningFeedback")
        assert "expected a <bml> element" in second["description"] or "malformed" in second["description"]
        sender.send('{"subscribe": 3}')
        receive_until(sender, lambda f: f["type"] == "warningFeedback")
        sender.send(f'<bml {NS} id="ok"><head id="h" lexeme="NOD"/></bml>')
        receive_until(sender, lambda f: f["id"] == "ok:end")
        # the other client (subscribed to the feedback) heard the block that ran, not the sender's mistakes
        heard = receive_until(other, lambda f: f["id"] == "ok:end")
        assert not [f for _, f in heard if f["type"] == "warningFeedback"]


def test_two_clients_both_hear_and_one_that_leaves_disturbs_nothing(service):
    block = f'<bml {NS} id="b"><head id="h1" lexeme="NOD"/><head id="h2" lexeme="NOD" start="1"/></bml>'
    with connect(service.url) as a, connect(service.url) as b:
        b.send('{"subscribe": "feedback"}')
        a.send(f'<bml {NS} id="first"><head id="h" lexeme="NOD"/></bml>')  # b's subscription is in
        receive_until(b, lambda f: f["id"] == "first:end")
        a.send(block)
        receive_until(b, lambda f: f["id"] == "b:h1:start")
        b.close()  # mid-block
        got = receive_until(a, lambda f: f["id"] == "b:end")
    ids = [f["id"] for _, f in got]
    assert "b:h2:end" in ids and "b:end" in ids


def test_a_storm_of_blocks_is_bounded_and_the_realizer_goes_on(service):
    import resource

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # 400 blocks of five messages each (prediction, start, two sync points, end) or one refusal: fewer than the
    # 2048 that may wait for a client, so that the client, which reads only once it has sent them all (its
    # library's queue unbounded meanwhile), is never closed for that however fast the blocks run; the queue's
    # bound itself is the intake's test's (test_live_parts).
    storm = 400
    with connect(service.url, max_queue=None) as ws:
        for i in range(storm):
            ws.send(f'<bml {NS} id="s{i}"><wait id="w" start="0" end="0.01"/></bml>')
        refused = 0
        ended = set()
        deadline = time.monotonic() + 60  # every block is answered: run or refused (a loaded machine is slow)
        while time.monotonic() < deadline and len(ended) + refused < storm:
            try:
                item = json.loads(ws.recv(timeout=1.0))
            except TimeoutError:
                continue
            if item["type"] == "warningFeedback" and "already waiting" in item["description"]:
                refused += 1
            elif item["type"] == "blockProgress" and item["id"].endswith(":end"):
                ended.add(item["id"])
        assert len(ended) + refused == storm, (len(ended), refused)
        assert len(ended) >= 256  # at least a queue's worth ran
        ws.send(f'<bml {NS} id="after"><head id="h" lexeme="NOD"/></bml>')
        receive_until(ws, lambda f: f["id"] == "after:end")
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) / 1024
    assert grown_mb < 200, grown_mb


def test_a_port_in_use_is_one_clear_line():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "serve", "--port", str(port), "--audio", "none", "--fps", "0",
                               "--tts", "builtin"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = [line for line in proc.stderr.splitlines() if not line.startswith("speech:")]
    assert len(lines) == 1 and f"cannot listen on 127.0.0.1:{port}" in lines[0], proc.stderr


def test_sigterm_stops_the_service_and_what_it_started():
    import os
    import select
    import signal
    from pathlib import Path

    proc = subprocess.Popen([sys.executable, "-m", "agentsim.cli", "serve", "--port", "0", "--audio", "none",
                             "--tts", "builtin"], stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stderr:  # "agentsim serve: ws://..." once it listens
            if line.startswith("agentsim serve:"):
                break
        children = [int(c) for t in Path(f"/proc/{proc.pid}/task").iterdir()
                    for c in (t / "children").read_text().split()]
        assert children  # the poses' evaluator (and multiprocessing's resource tracker)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 130
        deadline = time.monotonic() + 10
        for child in children:  # until each has ended (its pidfd is readable then)
            try:
                pidfd = os.pidfd_open(child)
            except ProcessLookupError:
                continue
            try:
                select.select([pidfd], [], [], max(0.0, deadline - time.monotonic()))
            finally:
                os.close(pidfd)
        assert not [c for c in children if Path(f"/proc/{c}").exists()
                    and "zombie" not in Path(f"/proc/{c}/status").read_text()]
    finally:
        if proc.poll() is None:
            proc.kill()


#: ALSA configurations PortAudio finds no output device in, whatever the machine has: only a default device
#: on a card that is not there (and no ``ctl.hw``, so no real card is listed), or one that only records.
NO_CARD = "pcm.!default {\n  type hw\n  card 99\n}\n"
INPUT_ONLY = "pcm.!default {\n  type asym\n  capture.pcm { type null }\n}\n"


def serve_without_sound_card(tmp_path, alsa: str, *options: str) -> subprocess.CompletedProcess:
    """``agentsim serve --port 0 OPTIONS`` where PortAudio's ALSA reads ``alsa`` and no PulseAudio answers."""
    import os

    (tmp_path / "asound.conf").write_text(alsa)
    env = dict(os.environ, ALSA_CONFIG_PATH=str(tmp_path / "asound.conf"),
               PULSE_SERVER=f"unix:{tmp_path / 'no-pulse'}", PULSE_RUNTIME_PATH=str(tmp_path / "no-pulse"))
    return subprocess.run([sys.executable, "-m", "agentsim.cli", "serve", "--port", "0", "--fps", "0", "--tts",
                           "builtin", *options], capture_output=True, text=True, timeout=120, env=env)


@pytest.mark.parametrize("alsa, options, problem", [
    (NO_CARD, (), "there is no audio output device here (PortAudio finds no sound card and no sound server)"),
    (NO_CARD, ("--audio", "default"), "there is no audio output device here (PortAudio finds no sound card"),
    (INPUT_ONLY, (), "there is no audio output device here (PortAudio finds no sound card and no sound server; "
                     "only input devices: default)"),
    (INPUT_ONLY, ("--audio", "0"), "audio device 0 (default) has no output channels; output devices here: none"),
], ids=["no-card", "no-card-default", "input-only", "input-only-by-index"])
def test_serve_without_an_output_device_says_so_and_names_audio_none(tmp_path, alsa, options, problem):
    proc = serve_without_sound_card(tmp_path, alsa, *options)
    assert proc.returncode == 1, proc.stderr
    (line,) = proc.stderr.splitlines()  # one line, before anything started (not even the speech line)
    assert line.startswith(f"agentsim: {problem}"), line
    assert "Serve without sound with --audio none" in line and "with --audio DEVICE" in line, line
    assert "Error querying device" not in line and "internal error" not in line


def test_serve_calibrating_from_no_input_device_names_calibrate(tmp_path):
    proc = serve_without_sound_card(tmp_path, NO_CARD, "--calibrate", "default")
    assert proc.returncode == 1, proc.stderr
    (line,) = proc.stderr.splitlines()
    assert line.startswith("agentsim: there is no audio output device here"), line  # the output is looked at first
    proc = serve_without_sound_card(tmp_path, "pcm.!default { type null }\n", "--calibrate", "no such input")
    assert proc.returncode == 1, proc.stderr
    (line,) = proc.stderr.splitlines()
    assert line.startswith("agentsim: no audio input device 'no such input'") and "--calibrate INPUT" in line, line
