"""Who hears what from ``agentsim serve``, with real WebSocket clients: feedback about a block goes to its
sender and to the clients subscribed to ``"feedback"``, warnings about it to its sender alone, nothing to
anyone else; JSON that is not a known control is answered with a warning (and subscribes to nothing); a
binary message must be UTF-8; the example client still hears its own blocks, the barge-in's too."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
EXAMPLE = Path(__file__).resolve().parents[1] / "agentsim" / "examples" / "live" / "client.py"


def nod(block_id: str) -> str:
    return f'<bml {NS} id="{block_id}"><head id="h" lexeme="NOD"/></bml>'


@pytest.fixture(scope="module")
def service():
    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        yield running


def until(ws, done, timeout: float = 10.0) -> list[dict]:
    got = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got.append(json.loads(ws.recv(timeout=max(0.01, deadline - time.monotonic()))))
        if done(got[-1]):
            return got
    raise AssertionError(f"timed out; got {[f['id'] for f in got]}")


def run(ws, block_id: str, text: str | None = None) -> list[dict]:
    """Send a block (a nod by default) and take everything up to its end."""
    ws.send(text if text is not None else nod(block_id))
    return until(ws, lambda f: f["id"] == f"{block_id}:end")


def subscribe(ws) -> None:
    """Subscribe to the feedback; the client's own block after it proves the subscription was taken."""
    ws.send(json.dumps({"subscribe": "feedback"}))
    run(ws, f"barrier{id(ws)}")


def ids(items: list[dict]) -> list[str]:
    return [f["id"] for f in items]


def test_feedback_to_the_sender_and_subscribers_warnings_to_the_sender_alone(service):
    block = (f'<bml {NS} id="a1"><head id="h" lexeme="NOD"/><head id="bad" lexeme="NOD" start="nosuch:end"/>'
             '<head id="h2" lexeme="NOD" start="h:end"/></bml>')
    with connect(service.url) as sender, connect(service.url) as subscriber, connect(service.url) as bystander:
        subscribe(subscriber)
        heard_by_sender = run(sender, "a1", block)
        warnings = [f for f in heard_by_sender if f["type"] == "warningFeedback"]
        assert [w["id"] for w in warnings] == ["a1:bad"]
        heard_by_subscriber = until(subscriber, lambda f: f["id"] == "a1:end")
        # the subscriber hears exactly what the sender hears, in the same order, but the warning
        assert ids(heard_by_subscriber) == [i for i in ids(heard_by_sender) if i != "a1:bad"]
        assert "a1:h2:stroke" in ids(heard_by_subscriber) and "a1" in ids(heard_by_subscriber)  # prediction too
        # the bystander hears its own block and nothing of the sender's (which all went out before)
        for name in ("n1", "n2", "n3"):
            own = run(bystander, name)
            assert all(i.split(":")[0] == name for i in ids(own)), ids(own)
        # the subscriber heard the bystander's blocks; the sender heard none of them
        heard = until(subscriber, lambda f: f["id"] == "n3:end")
        assert {"n1:end", "n2:end", "n3:end"} <= set(ids(heard))
        after = run(sender, "a2")
        assert all(i.split(":")[0] == "a2" for i in ids(after)), ids(after)


def test_a_bystander_hears_nothing_of_a_block_and_its_warnings(service):
    with connect(service.url) as sender, connect(service.url) as bystander:
        run(sender, "w1", f'<bml {NS} id="w1"><head id="x" lexeme="NOD" start="nosuch:end"/></bml>')
        sender.send("<bml id='broken'>")  # a parsing warning, to the sender
        until(sender, lambda f: f["type"] == "warningFeedback" and "PARSING_FAILURE" == f["warningType"])
        own = run(bystander, "mine")
        assert all(i.split(":")[0] == "mine" for i in ids(own)), ids(own)


@pytest.mark.parametrize("message, says", [
    ('{"a": 1}', "not a control message this server knows"),
    ('{"subscribe": "feedback", "a": 1}', "not a control message this server knows"),
    ('{"subscribe": "everything"}', 'nothing here to subscribe to by "everything"'),
    ('{"subscribe": ["feedback", 3]}', 'nothing here to subscribe to by ["feedback", 3]'),
    ('{"subscribe": []}', "nothing here to subscribe to by []"),
    ('{"subscribe": "poses"}', 'nothing here to subscribe to by "poses"'),  # this server streams no poses
    ('{"subscribe": ', "not JSON"),
    ('{"status": 1}', "not a control message this server knows"),  # ({"status": true} is)
])
def test_a_bad_control_message_is_answered_with_a_warning_and_subscribes_to_nothing(service, message, says):
    with connect(service.url) as client, connect(service.url) as other:
        client.send(message)
        (warning,) = until(client, lambda f: f["type"] == "warningFeedback")
        assert warning["warningType"] == "PARSING_FAILURE" and says in warning["description"], warning
        assert 'KIND one of "feedback", or {"status": true}; BML is sent as XML' in warning["description"]
        run(other, "others")
        own = run(client, "own")  # the other's block ended before: a subscription would have brought it
        assert all(i.split(":")[0] == "own" for i in ids(own)), ids(own)


def test_binary_messages_must_be_utf8(service):
    with connect(service.url) as ws:
        good = f'<bml {NS} id="bin1"><speech id="s"><text>Caf\u00e9 au lait.</text></speech></bml>'.encode()
        got = run(ws, "bin1", good)
        assert not [f for f in got if f["type"] == "warningFeedback"], got
        head = f'<bml {NS} id="bin2"><speech id="s"><text>Caf'.encode()
        ws.send(head + b"\xe9 au lait.</text></speech></bml>")  # Latin-1
        (warning,) = until(ws, lambda f: f["type"] == "warningFeedback")
        assert warning["description"] == (f"message refused: a binary message must be UTF-8 text (byte {len(head)} "
                                          "is not); send BML as a text message"), warning
        after = run(ws, "bin3")
        assert not [i for i in ids(after) if i.startswith("bin2")]  # the refused one never ran


def test_the_example_client_hears_its_block_and_its_barge_in(service):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(EXAMPLE.parents[3]), os.environ.get("PYTHONPATH", "")]))
    with connect(service.url) as bystander:
        proc = subprocess.run([sys.executable, str(EXAMPLE), service.url], capture_output=True, text=True,
                              timeout=60, env=env)
        assert proc.returncode == 0, proc.stderr
        heard = {line.split()[2] for line in proc.stdout.splitlines() if len(line.split()) >= 3}
        assert {"talk:start", "talk:s1:start", "talk:s1:end", "talk:end", "reply:s2:start", "reply:s2:end",
                "reply:end"} <= heard, proc.stdout
        own = run(bystander, "quiet")
        assert all(i.split(":")[0] == "quiet" for i in ids(own)), ids(own)


def test_a_client_that_has_gone_is_not_kept_by_its_blocks():
    """The realizer remembers who sent a block by a number, not by its connection: a client's connection (its
    buffers) is let go when it leaves, though the blocks it sent are remembered (a server with thousands of
    clients coming and going had kept 4,096 closed connections, 250 MB)."""
    import asyncio
    import gc
    import weakref

    with Background(Service(port=0, audio="none", fps=0, tts=BuiltinBackend())) as running:
        server = running.service.server
        routing = server.routing
        with connect(running.url) as ws:
            ws.send(nod("gone"))
            until(ws, lambda m: m["id"] == "gone:end")
            (connection,) = routing.clients
            held = weakref.ref(connection)
            del connection

        async def handled() -> None:
            """Until the library's task for the connection has ended (the library holds a connection until
            its socket has closed, after the server's handler returned; the server's handler returns once
            its tasks for the client have)."""
            if server.endpoint.handler_tasks:
                await asyncio.wait(set(server.endpoint.handler_tasks))

        asyncio.run_coroutine_threadsafe(handled(), server.loop).result(timeout=10)
        gc.collect()
        assert not routing.clients and not routing.outboxes and not routing.key_of and not server.links
        assert "gone" in running.service.live.senders  # its block is remembered
        assert held() is None  # its connection is not


def test_two_clients_sending_the_same_block_id_do_not_take_each_others_feedback(service):
    """A block whose id is that of another client's block that has not ended is refused to its sender alone;
    the first block's feedback still goes to the first client, to its end. Once it has ended, the id is
    free again."""
    wait = f'<bml {NS} id="bml1"><wait id="w" start="0" end="1.5"/><head id="h" lexeme="NOD" start="1"/></bml>'
    with connect(service.url) as a, connect(service.url) as b:
        a.send(wait)
        until(a, lambda m: m["id"] == "bml1:start")
        b.send(f'<bml {NS} id="bml1"><head id="h" lexeme="NOD"/></bml>')
        (warning,) = [m for m in until(b, lambda m: m["type"] == "warningFeedback")]
        assert warning["description"] == ("block refused: another client's block 'bml1' has not ended; give yours "
                                          "an id of its own")
        got = until(a, lambda m: m["id"] == "bml1:end")
        assert {"bml1:h:start", "bml1:h:end", "bml1:end"} <= {m["id"] for m in got}  # all of it, to a
        assert not [m for m in got if m["type"] == "warningFeedback"]
        b.send(f'<bml {NS} id="bml1"><head id="h" lexeme="NOD"/></bml>')  # ended: b may use the id now
        assert until(b, lambda m: m["id"] == "bml1:end")[-1]["id"] == "bml1:end"
        a.send('{"status": true}')
        status = until(a, lambda m: m.get("type") == "status")[-1]
        assert status["refused_taken_ids"] == 1
