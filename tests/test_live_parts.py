"""The parts of ``agentsim serve`` driven directly, without a network: who hears what and what a client that
falls behind loses (:mod:`agentsim.live.routing`), who may connect (:mod:`agentsim.live.access`), the reader
that prepares blocks without a realizer (:mod:`agentsim.live.intake`), and the realizer's thread fed by hand
(:mod:`agentsim.live.runtime`)."""

from __future__ import annotations

import ast
import json
import queue
import threading
from pathlib import Path
from types import SimpleNamespace

import pytest

from agentsim.bml.parser import parse_document
from agentsim.core import feedback as fb
from agentsim.errors import UsageError
from agentsim.live import access, intake, routing
from agentsim.live.access import Access
from agentsim.live.intake import Intake, Prepared, TakeTurns
from agentsim.live.limits import Limits
from agentsim.live.routing import BACKLOG_MESSAGES, BACKLOG_POSES, PING_EVERY, PING_WHILE, STALL_SECONDS, Routing
from agentsim.live.runtime import BlockNames, HeldAudio, LiveRealizer
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def uses(module) -> tuple[set[str], set[str]]:
    """The modules ``module`` imports and the attributes its code reads or writes."""
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    return imported, {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)}


def test_the_reader_knows_nothing_of_the_realizer_and_routing_and_access_do_no_io():
    imported, attributes = uses(intake)
    assert not imported & {"agentsim.realizer", "agentsim.live.runtime", "agentsim.core.scheduler"}
    assert not attributes & {"realizer", "planner", "scheduler", "engines", "env"}
    for module in (routing, access):
        imported, attributes = uses(module)
        assert not {name.split(".")[0] for name in imported} & {"asyncio", "socket", "websockets", "threading"}
        assert not attributes & {"recv", "ping", "transport", "call_soon_threadsafe", "ensure_future", "create_task"}


def routed() -> tuple[Routing, list]:
    """A routing whose requests to close a client are listed."""
    closed = []
    return Routing(close=lambda client, why: closed.append((client, why))), closed


def waiting(routing: Routing, client) -> list:
    """The messages waiting for ``client``, read back."""
    return [json.loads(message) for message, _ in routing.outboxes[client].messages]


# ------------------------------------------------------------------------------------------------ routing
def test_feedback_goes_to_its_sender_and_the_subscribers_a_warning_to_its_sender_alone():
    routing, _ = routed()
    for client in ("sender", "subscriber", "bystander"):
        routing.join(client)
    assert routing.subscribe("subscriber", {"feedback"}) == []  # nobody says hello for the feedback
    sender = routing.key("sender")
    progress = {"type": "blockProgress", "id": "b:start", "globalTime": 0.25, "characterId": "agent"}
    about_block = fb.warning("b:h", "PARSING_FAILURE", "dropped", 0.25, "agent")
    about_none = fb.warning("", "PARSING_FAILURE", "a document of nobody's", 0.5, "agent")
    routing.address(progress, sender)
    routing.address(about_block, sender)
    routing.address(about_none)
    assert waiting(routing, "sender") == [progress, about_block]
    assert waiting(routing, "subscriber") == [progress, about_none]
    assert waiting(routing, "bystander") == []
    routing.reply(sender, '{"type": "status"}')
    assert waiting(routing, "sender")[-1] == {"type": "status"}


def test_a_subscriber_is_greeted_and_wanted_kinds_follow_who_is_there():
    routing, _ = routed()
    routing.hello["poses"] = {"type": "skeleton"}
    routing.join("a")
    routing.join("b")
    assert routing.kinds() == ["feedback", "poses"] and not routing.wanted("poses")
    assert routing.subscribe("a", {"poses", "feedback"}) == [{"type": "skeleton"}]
    assert routing.subscribe("a", {"poses"}) == [{"type": "skeleton"}]  # greeted again, counted once
    routing.subscribe("b", {"poses"})
    routing.broadcast({"type": "poses", "index": 0}, {"poses"}, True)
    assert waiting(routing, "a")[-1] == waiting(routing, "b")[-1] == {"type": "poses", "index": 0}
    routing.leave("a")
    assert routing.wanted("poses") and routing.wanted("feedback") is False
    routing.leave("b")
    assert not routing.wanted("poses")


def test_a_client_behind_loses_the_oldest_poses_never_feedback_and_is_closed_past_the_backlog():
    routing, closed = routed()
    outbox = routing.join("slow")
    woken = []
    outbox.wake = lambda: woken.append(True)
    routing.subscribe("slow", {"poses"})
    for i in range(BACKLOG_POSES + 3):
        routing.broadcast({"type": "poses", "index": i}, {"poses"}, True)
        if i == 1:
            routing.send("slow", '{"id": "f1"}')
    assert [m.get("index", m.get("id")) for m in waiting(routing, "slow")] == ["f1", *range(3, BACKLOG_POSES + 3)]
    assert routing.counters["dropped_poses"] == 3 and outbox.poses == BACKLOG_POSES and len(woken) == 12
    for i in range(BACKLOG_MESSAGES - 1):  # feedback is kept, up to the backlog
        routing.send("slow", f'{{"id": "g{i}"}}')
    assert routing.counters["unsent"] == 0 and closed == []
    routing.send("slow", '{"id": "one too many"}')
    assert closed == [("slow", f"{BACKLOG_MESSAGES} messages were waiting for it")]
    assert routing.counters["closed_not_reading"] == 1
    assert routing.counters["unsent"] == 1 + BACKLOG_MESSAGES + BACKLOG_POSES and not outbox.messages
    routing.send("slow", '{"id": "after"}')  # the client is being closed: nothing more waits for it
    routing.close_slow("slow", "again")
    assert routing.counters["unsent"] == 2 + BACKLOG_MESSAGES + BACKLOG_POSES and len(closed) == 1


def test_a_client_that_takes_nothing_or_answers_no_ping_is_stalled():
    routing, _ = routed()
    outbox = routing.join("c")
    routing.send("c", "m1")
    routing.send("c", "m2")
    assert outbox.take(10.0) == "m1"
    assert outbox.stalled(10.0 + STALL_SECONDS - 0.25) is None
    assert routing.stalled(10.0 + STALL_SECONDS) == [("c", "nothing taken for 5 s")]
    outbox.sent(16.0)
    assert routing.sent == 1 and outbox.stalled(100.0) is None  # m2 waits, but nothing is being sent
    # pinged while it is sent messages, one ping at a time, every PING_EVERY s
    assert outbox.ping_due(16.25) and not outbox.ping_due(16.5)
    assert outbox.stalled(16.25 + STALL_SECONDS) == "no answer to a ping for 5 s"
    outbox.answered()
    assert not outbox.ping_due(16.25 + PING_EVERY - 0.25) and outbox.ping_due(16.25 + PING_EVERY)
    outbox.answered()
    assert not outbox.ping_due(16.0 + PING_WHILE + 0.25)  # nothing sent for a while: no more pings
    outbox.closing = True
    assert outbox.stalled(1000.0) is None


def test_a_client_that_leaves_or_is_lost_counts_what_waited_as_unsent():
    routing, _ = routed()
    changes = []
    routing.counters.listeners.append(lambda name, value: changes.append((name, value)))
    outbox = routing.join("gone")
    key = routing.key("gone")
    for i in range(3):
        routing.send("gone", f"m{i}")
    outbox.take(1.0)
    outbox.lost()  # the connection went away while m0 was sent
    assert routing.counters["unsent"] == 3 and outbox.closing and outbox.waiting_since is None
    routing.send("gone", "m3")
    routing.leave("gone")
    routing.reply(key, "m4")  # its blocks' feedback, after it left
    routing.send("gone", "m5")
    assert changes == [("unsent", 3), ("unsent", 4), ("closed_clients", 1), ("unsent", 4), ("unsent", 5),
                       ("unsent", 6)]
    assert not routing.clients and not routing.outboxes and not routing.key_of and not routing.by_key


# ------------------------------------------------------------------------------------------------ access
def test_origins_and_tokens():
    here = {"Host": "127.0.0.1:8765"}
    access = Access("127.0.0.1", 8765, allow_origins=["https://Friend.example:8443/"])
    assert access.refuses(None, {}, "/") is None  # a program
    assert access.refuses("http://127.0.0.1:8765", here, "/") is None
    assert access.refuses("http://localhost:8765", {"Host": "localhost:8765"}, "/") is None
    assert access.refuses("https://friend.example:8443", here, "/") is None
    assert access.refuses("http://evil.example:8765", {"Host": "evil.example:8765"}, "/") == "origin"
    assert access.refuses("https://evil.example", here, "/") == "origin"
    assert access.refuses("several", here, "/") == "origin"
    assert access.refuses("http://127.0.0.1:8766", {"Host": "127.0.0.1:8766"}, "/") == "origin"
    token = Access("127.0.0.1", 8765, token="s3cret")
    upgrade = {**here, "Upgrade": "websocket"}
    assert token.refuses(None, upgrade, "/") == "token"
    assert token.refuses(None, upgrade, "/?token=s3cre") == "token"
    assert token.refuses(None, upgrade, "/?token=s3cret") is None
    assert token.refuses(None, here, "/index.html?token=nope") == "token"
    assert token.refuses(None, here, "/report.js") is None  # the package's own files
    assert token.url("http") == "http://127.0.0.1:8765/?token=s3cret" and not token.token_made
    wide = Access("0.0.0.0", 8765)
    assert wide.token_made and len(wide.token) >= 32 and wide.url().endswith(f"/?token={wide.token}")
    assert Access("::1", 0).url() == "ws://[::1]:0/"
    with pytest.raises(UsageError, match="--token must not be empty"):
        Access("127.0.0.1", 8765, token=" ")


# ------------------------------------------------------------------------------------------------ intake
def test_the_reader_prepares_blocks_without_a_realizer():
    delivered, replies = [], []
    names = BlockNames()
    names.publish(["bml1", "x"])
    intake = Intake(delivered.append, BuiltinBackend(), name_block=names, now=lambda: 1.5)
    intake.read_one(f'<bml {NS} id="a"><speech id="s"><text>Hello there.</text></speech></bml>', replies.append, 7)
    intake.read_one('<bml><head id="h" lexeme="NOD"/></bml>', replies.append, 8)  # no id: named
    intake.read_one("<bml id='x'><head id='h' lexeme='NOD'></bml>", replies.append, 7)  # malformed
    first, second = delivered
    assert isinstance(first, Prepared) and first.block.id == "a" and first.sender == 7
    ((behaviour, utterance, size),) = first.speech
    assert behaviour.id == "s" and utterance.duration > 0.5 and size == first.weight == 0  # (no audio here)
    assert second.block.id == "bml2" and second.sender == 8 and second.speech == []
    assert "block without id: named bml2" in second.block.warnings[0].details
    (warning,) = replies
    assert warning["type"] == "warningFeedback" and warning["id"] == "x" and warning["globalTime"] == 1.5
    assert warning["description"].startswith("block refused: ") and "mismatched tag" in warning["description"]


def test_the_reader_refuses_a_block_past_the_limits_before_it_is_handed_on():
    delivered, replies = [], []
    intake = Intake(delivered.append, BuiltinBackend(), now=lambda: 2.0, limits=Limits(speech_characters=5))
    intake.read_one(f'<bml {NS} id="a"><speech id="s"><text>Hello there.</text></speech></bml>', replies.append, 1)
    assert delivered == [] and intake.refused_long == 1
    assert [(r["id"], r["description"], r["globalTime"]) for r in replies] == [
        ("a", "block refused: speech s has 12 characters, more than the 5 a speech may have here "
              "(--max-speech-chars)", 2.0)]


def test_documents_are_taken_in_turn_by_sender_and_refused_past_the_queue():
    turns = TakeTurns(4)
    for entry, sender in (("a1", "A"), ("a2", "A"), ("a3", "A"), ("b1", "B")):
        turns.put_nowait(entry, sender)
    with pytest.raises(Exception, match="4 documents are already waiting for the realizer"):
        turns.put_nowait("b2", "B")
    assert [turns.get() for _ in range(4)] == ["a1", "b1", "a2", "a3"]
    turns.close()
    assert turns.get() is None


def test_the_readers_thread_hands_documents_on_and_stops():
    ready: queue.Queue = queue.Queue()
    intake = Intake(ready.put, BuiltinBackend(), queue_size=1)
    assert intake.offer(f'<bml {NS} id="a"><head id="h" lexeme="NOD"/></bml>', print, 1) is None
    assert intake.offer("<bml/>", print, 2) == "1 documents are already waiting for the realizer"
    intake.start()
    assert ready.get(timeout=10).block.id == "a"
    intake.close()
    assert not intake.thread.is_alive() and intake.error is None


# ------------------------------------------------------------------------------------------------ runtime
def test_block_names_skip_the_ids_published():
    names = BlockNames()
    assert names() == "bml1"
    names.publish(["bml2", "bml3", "other"])
    assert [names(), names()] == ["bml4", "bml5"]


def test_held_audio_is_weighed_until_its_block_ends():
    audio = HeldAudio()
    one, two = SimpleNamespace(audio=b"x" * 10), SimpleNamespace(audio=b"y" * 5)
    audio.arrived(15)
    assert audio.bytes == 15
    held = audio.hold("b", [(None, one, 10), (None, two, 5)])
    assert audio.bytes == 15 and held == [(one, 10), (two, 5)]
    audio.release("b", [(two, 5)])  # one of them (refused), by identity
    assert audio.bytes == 10 and audio.released == 5 and two.audio is None and one.audio is not None
    audio.release("b")
    assert audio.bytes == 0 and audio.released == 15 and one.audio is None and audio.by_block == {}


def test_the_realizers_thread_submits_what_it_is_handed_and_refuses_a_taken_id():
    live = LiveRealizer(tts=BuiltinBackend())
    heard, ended = [], threading.Event()

    def listener(item: dict, sender) -> None:
        heard.append((item["id"], sender))
        if item["id"] == "n:end":
            ended.set()

    live.listeners.append(listener)
    nod = f'<bml {NS} id="n"><wait id="w" start="0" end="0.3"/><head id="h" lexeme="NOD"/></bml>'
    replies = {1: [], 2: []}
    live.start()
    try:
        for sender in (1, 2):
            (block,) = parse_document(nod)
            live.take(Prepared(block, replies[sender].append, sender))
        assert ended.wait(10)
    finally:
        live.close()
    assert not live.thread.is_alive()
    assert replies[1] == [] and [r["description"] for r in replies[2]] == [
        "block refused: another client's block 'n' has not ended; give yours an id of its own"]
    assert {sender for _, sender in heard} == {1} and ("n:h:end", 1) in heard
    assert live.refused_taken == 1 and "n" in live.names.taken and live.senders == {"n": 1}
