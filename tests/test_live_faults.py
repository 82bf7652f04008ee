"""Faults of ``agentsim serve`` are reported, with real WebSocket clients: ``{"status": true}`` is answered
(to the asker alone) with counters that follow what happened (refused documents, closed clients, refused
origins and tokens); a dead realizer thread stops the server, and ``agentsim serve`` with exit status 1 and
one line saying why."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from agentsim.live.faults import RealizerStopped
from agentsim.live.service import Background, Service
from helpers import counted
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def status(ws) -> dict:
    ws.send(json.dumps({"status": True}))
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        item = json.loads(ws.recv(timeout=deadline - time.monotonic()))
        if item["type"] == "status":
            return item
    raise AssertionError("no status reply")


def test_status_counts_what_was_refused_and_who_left():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend(), queue_size=1)) as running:
        with connect(running.url) as ws, connect(running.url) as other:
            first = status(ws)
            assert first["clients"] == 2 and first["refused_documents"] == 0 and first["closed_clients"] == 0
            assert {"dropped_poses", "refused_origins", "refused_tokens", "realizer_faults"} <= set(first)
            # a burst into a queue of one: some are refused, each with a warning, each counted
            for i in range(200):
                ws.send(f'<bml {NS} id="q{i}"><wait id="w" start="0" end="0.001"/></bml>')
            refused = 0
            after = None
            ws.send(json.dumps({"status": True}))  # answered after the burst was taken
            deadline = time.monotonic() + 30
            while after is None and time.monotonic() < deadline:
                item = json.loads(ws.recv(timeout=deadline - time.monotonic()))
                if item["type"] == "warningFeedback" and "already waiting" in item["description"]:
                    refused += 1
                elif item["type"] == "status":
                    after = item
            assert refused >= 1 and after["refused_documents"] == refused
            # the other client was sent no status and no warning of ws's
            other.send(f'<bml {NS} id="mine"><head id="h" lexeme="NOD"/></bml>')
            seen = []
            while not seen or seen[-1]["id"] != "mine:end":
                seen.append(json.loads(other.recv(timeout=10)))
            assert all(f["id"].split(":")[0] == "mine" for f in seen), [f["id"] for f in seen]
            # a foreign origin and a client that leaves are counted
            with pytest.raises(InvalidStatus):
                connect(running.url, origin="https://evil.example", open_timeout=5)
            left = counted(running.service.server, "closed_clients")
            other.close()
            assert left.wait(10)
            now = status(ws)
            assert now["closed_clients"] == 1 and now["clients"] == 1
            assert now["refused_origins"] == first["refused_origins"] + 1


def test_a_dead_realizer_thread_stops_the_server(monkeypatch):
    running = Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend()))
    try:
        live = running.service.live

        def broken(prepared):
            raise RuntimeError("injected fault")

        monkeypatch.setattr(live, "submit", broken)
        with connect(running.url) as ws:
            ws.send(f'<bml {NS} id="b"><head id="h" lexeme="NOD"/></bml>')
            with pytest.raises(ConnectionClosed):  # the server closes its connections as it stops
                while True:
                    ws.recv(timeout=10)
        running.thread.join(10)
        assert not running.thread.is_alive()
        assert isinstance(running.error, RealizerStopped)
        assert str(running.error) == ("the realizer stopped (RuntimeError: injected fault); the service stopped "
                                      "with it")
        assert isinstance(live.error, RuntimeError)
    finally:
        running.close()


BROKEN_SERVE = """
import sys
from agentsim.cli import main
from agentsim.live.runtime import LiveRealizer

def broken(self, prepared):
    raise RuntimeError("injected fault")

LiveRealizer.submit = broken
sys.exit(main(["serve", "--port", "0", "--audio", "none", "--fps", "0", "--tts", "builtin"]))
"""


def test_serve_with_a_dead_realizer_exits_1_with_one_line():
    proc = subprocess.Popen([sys.executable, "-c", BROKEN_SERVE], stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        for line in proc.stderr:
            lines.append(line)
            if line.startswith("agentsim serve:"):
                break
        url = next(w for w in lines[-1].split() if w.startswith("ws://"))
        with connect(url) as ws:
            ws.send(f'<bml {NS} id="b"><head id="h" lexeme="NOD"/></bml>')
            assert proc.wait(timeout=30) == 1
        rest = [line for line in proc.stderr.read().splitlines() if line.strip()]
        assert rest == ["agentsim: the realizer stopped (RuntimeError: injected fault); the service stopped "
                        "with it"], rest
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_waiting_documents_are_weighed_in_all_and_per_client(monkeypatch):
    """Documents wait for the reader weighed, not only counted: past a client's share one of its documents is
    refused, past the whole queue's any client's but a small one that still fits; each refusal one warning to
    its sender, counted; what was taken runs once the reader goes on."""
    import threading

    def padded(block_id: str) -> str:  # a nod, with a comment that makes it weigh 256 kB
        head = f'<bml {NS} id="{block_id}"><head id="h" lexeme="NOD"/><!--'
        return head + "x" * (2 ** 18 - len(head) - len("--></bml>")) + "--></bml>"

    def refusal(ws) -> str:
        item = json.loads(ws.recv(timeout=10))
        assert item["type"] == "warningFeedback", item
        return item["description"]

    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        intake = running.service.intake
        intake.incoming.max_bytes, intake.incoming.sender_bytes = 2 ** 20, 3 * 2 ** 18
        at_gate, gate = threading.Event(), threading.Event()
        read_one = intake.read_one
        monkeypatch.setattr(intake, "read_one", lambda *entry: (at_gate.set(), gate.wait(30), read_one(*entry)))
        with connect(running.url) as a, connect(running.url) as b, connect(running.url) as c:
            a.send(f'<bml {NS} id="first"><head id="h" lexeme="NOD"/></bml>')  # the reader holds it at the gate
            assert at_gate.wait(10)
            assert len(padded("a1")) == 2 ** 18
            for name in ("a1", "a2", "a3"):
                a.send(padded(name))
            assert refusal(a) == ("document refused: this client's documents of 0.5 MB are already waiting for the "
                                  "realizer (at most 0.75 MB of one client's may); send fewer at once")
            for name in ("b1", "b2"):
                b.send(padded(name))
            assert refusal(b) == ("document refused: documents of 0.8 MB are already waiting for the realizer (at "
                                  "most 1 MB may); send fewer at once")
            c.send(f'<bml {NS} id="c1"><head id="h" lexeme="NOD"/></bml>')  # a small one still fits
            gate.set()
            ended = {}
            for ws, last in ((a, "a2"), (b, "b1"), (c, "c1")):
                deadline = time.monotonic() + 20
                while last not in ended and time.monotonic() < deadline:
                    item = json.loads(ws.recv(timeout=10))
                    assert item["type"] != "warningFeedback", item
                    if item["type"] == "blockProgress" and item["id"].endswith(":end"):
                        ended[item["id"].split(":")[0]] = item["globalTime"]
            assert set(ended) == {"first", "a1", "a2", "b1", "c1"}  # what was refused never ran
            now = status(c)
    assert now["refused_documents"] == 2


def test_a_fault_of_the_reader_in_one_document_refuses_it_and_the_next_runs(monkeypatch, capsys):
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        intake = running.service.intake
        prepare = intake.prepare

        def broken(block, reply=None):
            if block.id == "bad":
                raise RuntimeError("injected fault")
            return prepare(block, reply)

        monkeypatch.setattr(intake, "prepare", broken)
        with connect(running.url) as ws:
            ws.send(f'<bml {NS} id="bad"><head id="h" lexeme="NOD"/></bml>')
            ws.send(f'<bml {NS} id="good"><head id="h" lexeme="NOD"/></bml>')
            got = []
            while not got or got[-1].get("id") != "good:end":
                got.append(json.loads(ws.recv(timeout=10)))
            (warning,) = [m for m in got if m["type"] == "warningFeedback"]
            assert warning["description"] == "document refused: the server failed to read it (RuntimeError)"
            assert not [m for m in got if m["id"].startswith("bad")]
            assert status(ws)["realizer_faults"] == {"reader": 1}
        assert running.thread.is_alive()
    assert ("agentsim serve: reading a document failed (RuntimeError: injected fault); serving goes on"
            in capsys.readouterr().err.splitlines())


def test_a_dead_reader_thread_stops_the_server(monkeypatch):
    class Killed(BaseException):
        pass

    running = Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend()))
    try:
        def dies(*entry):
            raise Killed("the reader's thread died")

        monkeypatch.setattr(running.service.intake, "read_one", dies)
        with connect(running.url) as ws:
            ws.send(f'<bml {NS} id="b"><head id="h" lexeme="NOD"/></bml>')
            with pytest.raises(ConnectionClosed):
                while True:
                    ws.recv(timeout=10)
        running.thread.join(10)
        assert not running.thread.is_alive()
        assert str(running.error) == ("the realizer stopped (Killed: the reader's thread died); the service stopped "
                                      "with it")
    finally:
        running.close()
