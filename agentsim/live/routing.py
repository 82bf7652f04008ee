"""Who hears what from ``agentsim serve``: each client's :class:`Outbox`, its subscriptions, the number its
blocks are sent with, and the counters of what was refused, dropped or went wrong (:class:`Routing`).

Nothing here sends or receives: the server's loop puts messages in the outboxes through :class:`Routing`, and
its sending tasks take them out (:meth:`Outbox.take`) and say how it went (:meth:`Outbox.sent`,
:meth:`Outbox.lost`); closing a client is asked of the server (``Routing.close``). Everything here runs in
the server's loop, but :meth:`Routing.wanted`, which other threads may ask. A client is whatever object the
server stands for a connection (it is only a key here).
"""

from __future__ import annotations

import collections
import itertools
import json
import math
from typing import Callable

from agentsim.core import feedback as fb

#: How many poses messages (a tenth of a second each) may wait for one client; past it the oldest waiting one
#: is dropped (counted in ``dropped_poses``): a client that falls behind loses poses first.
BACKLOG_POSES = 8
#: How many other messages (feedback, warnings, replies) may wait for one client; past it the client is closed
#: (it is not dropped: feedback is never lost while a client stays connected).
BACKLOG_MESSAGES = 2048
#: How long (s) a client may take nothing while messages wait for it before it is closed.
STALL_SECONDS = 5.0
#: How often (s) a client that is being sent messages is pinged: one that has not answered a ping for
#: :data:`STALL_SECONDS` has not read what came before it, however large its buffers, and is closed.
PING_EVERY = 1.0
#: How long (s) after the last message sent to a client it is still pinged.
PING_WHILE = 2.0


class Counters(dict):
    """What went wrong or was refused, by name (the ``{"status": true}`` reply shows them in this order);
    each function in :attr:`listeners` is called as ``listener(name, value)`` on every change (in the
    thread that made it)."""

    NAMES = ("refused_origins", "refused_tokens", "refused_documents", "closed_clients", "closed_not_reading",
             "broken_connections", "dropped_poses", "unsent", "faults")

    def __init__(self):
        super().__init__((name, 0) for name in self.NAMES)
        self.listeners: list[Callable[[str, int], None]] = []

    def __setitem__(self, name: str, value: int) -> None:
        super().__setitem__(name, value)
        for listener in self.listeners:
            listener(name, value)


class Outbox:
    """What waits to be sent to one client, in order, and how its sending goes.

    Poses messages (``droppable``) wait at most :data:`BACKLOG_POSES` at a time: past it the oldest waiting
    one is dropped. Other messages are kept, up to :data:`BACKLOG_MESSAGES`, past which the client is closed.
    A client that took nothing for :data:`STALL_SECONDS` while messages waited, or did not answer a ping for
    that long, is :meth:`stalled`. ``wake`` is called whenever a message is added (the sending task's
    signal)."""

    def __init__(self, routing: "Routing", client):
        self.routing, self.client = routing, client
        self.messages: collections.deque[tuple[str, bool]] = collections.deque()
        self.poses = 0
        self.wake: Callable[[], None] = lambda: None
        #: since when the message being sent waits for the client to take what it was sent (None: none waits)
        self.waiting_since: float | None = None
        #: when a message was last sent; when the ping not yet answered was sent (None: none waits) and when
        #: the last one was
        self.last_sent = -math.inf
        self.ping_sent: float | None = None
        self.last_ping = -math.inf
        self.closing = False

    def put(self, message: str, droppable: bool = False) -> None:
        counters = self.routing.counters
        if self.closing:
            counters["unsent"] += 1
            return
        if droppable:
            if self.poses >= BACKLOG_POSES:
                for i, (_, kind) in enumerate(self.messages):
                    if kind:
                        del self.messages[i]
                        break
                self.poses -= 1
                counters["dropped_poses"] += 1
            self.poses += 1
        elif len(self.messages) - self.poses >= BACKLOG_MESSAGES:
            counters["unsent"] += 1
            self.routing.close_slow(self.client, f"{BACKLOG_MESSAGES} messages were waiting for it")
            return
        self.messages.append((message, droppable))
        self.wake()

    def take(self, now: float) -> str | None:
        """The next message to send (None: none waits); it waits for the client from ``now`` on."""
        if not self.messages:
            return None
        message, droppable = self.messages.popleft()
        if droppable:
            self.poses -= 1
        self.waiting_since = now
        return message

    def sent(self, now: float) -> None:
        """The message taken was sent (the client took it, or the transport has room for it)."""
        self.routing.sent += 1
        self.last_sent = now
        self.waiting_since = None

    def failed(self) -> None:
        """Sending the message taken failed for a reason of the server's own: the next one is tried."""
        self.waiting_since = None

    def lost(self) -> None:
        """The connection went away while a message was sent: it and what waits are counted as unsent."""
        self.routing.counters["unsent"] += 1 + len(self.messages)
        self.clear()
        self.closing = True
        self.waiting_since = None

    def clear(self) -> int:
        """Let go of what waits; how many messages that was."""
        dropped = len(self.messages)
        self.messages.clear()
        self.poses = 0
        return dropped

    def stalled(self, now: float) -> str | None:
        """Why the client is taken not to read (None: it reads): it took nothing for :data:`STALL_SECONDS`
        while more messages waited for it, or it has not answered a ping for that long (what came before the
        ping lies unread in its buffers)."""
        if self.closing:
            return None
        if self.waiting_since is not None and self.messages and now - self.waiting_since >= STALL_SECONDS:
            return f"nothing taken for {STALL_SECONDS:g} s"
        if self.ping_sent is not None and now - self.ping_sent >= STALL_SECONDS:
            return f"no answer to a ping for {STALL_SECONDS:g} s"
        return None

    def ping_due(self, now: float) -> bool:
        """Whether to ping the client now (then it is taken as pinged): one being sent messages, every
        :data:`PING_EVERY` s, one ping at a time."""
        if (self.closing or self.ping_sent is not None or now - self.last_sent > PING_WHILE
                or now - self.last_ping < PING_EVERY):
            return False
        self.ping_sent = self.last_ping = now
        return True

    def answered(self) -> None:
        """The ping waiting was answered (or cannot be any more): another may be sent."""
        self.ping_sent = None


class Routing:
    """The clients of a server, what waits for each, who subscribed to what and who sent which block.

    A client joins (:meth:`join`: its outbox and the number the runtime remembers its blocks by, never the
    connection, so that a client that has gone is not kept alive by its blocks) and leaves (:meth:`leave`).
    Feedback about a block goes to its sender and to the subscribers of ``"feedback"``, a warning about it to
    its sender alone (:meth:`address`); poses to their subscribers (:meth:`broadcast`). ``close(client,
    why)`` closes a client that does not read (the server's; by default nothing).
    """

    def __init__(self, close: Callable[[object, str], None] | None = None):
        self.counters = Counters()
        self.close = close if close is not None else (lambda client, why: None)
        self.clients: set = set()
        self.outboxes: dict[object, Outbox] = {}
        #: each connected client by the key its blocks are sent with, and back
        self.by_key: dict[int, object] = {}
        self.key_of: dict[object, int] = {}
        self.keys = itertools.count(1)
        self.subscribers: dict[object, set[str]] = {}
        #: how many clients subscribed to each kind (:meth:`wanted`)
        self.wanting: collections.Counter[str] = collections.Counter()
        #: what a new subscriber of each kind is sent first (set by whoever publishes it)
        self.hello: dict[str, dict] = {}
        #: messages sent, to every client
        self.sent = 0

    # ------------------------------------------------------------------------------------------- clients
    def join(self, client) -> Outbox:
        """A client connected: its outbox."""
        self.clients.add(client)
        outbox = self.outboxes[client] = Outbox(self, client)
        key = next(self.keys)
        self.by_key[key] = client
        self.key_of[client] = key
        return outbox

    def leave(self, client) -> None:
        """A client has gone: what waits for it is counted as unsent, and it is forgotten."""
        self.counters["closed_clients"] += 1
        self.clients.discard(client)
        key = self.key_of.pop(client, None)
        self.by_key.pop(key, None)
        outbox = self.outboxes.pop(client, None)
        if outbox is not None:
            self.counters["unsent"] += outbox.clear()
            outbox.closing = True
        self.wanting.subtract(self.subscribers.pop(client, ()))

    def key(self, client) -> int | None:
        """The number ``client``'s blocks are sent with (None: it has gone)."""
        return self.key_of.get(client)

    # ------------------------------------------------------------------------------------------- subscribing
    def kinds(self) -> list[str]:
        """What a client may subscribe to."""
        return sorted({"feedback", *self.hello})

    def subscribe(self, client, kinds: set[str]) -> list[dict]:
        """``client`` subscribes to ``kinds`` (each one of :meth:`kinds`): what it is told first."""
        had = self.subscribers.setdefault(client, set())
        self.wanting.update(kinds - had)
        had.update(kinds)
        return [self.hello[kind] for kind in sorted(kinds) if kind in self.hello]

    def wanted(self, kind: str) -> bool:
        """Whether a client subscribed to ``kind`` (asked from any thread)."""
        return self.wanting.get(kind, 0) > 0

    # ------------------------------------------------------------------------------------------- sending
    def address(self, item: dict, sender: int | None = None) -> None:
        """Send a feedback to whom it concerns: a warning about a block to its sender alone; anything else to
        its sender and the clients subscribed to ``"feedback"`` (a warning about no client's block, to them)."""
        to = set()
        client = self.by_key.get(sender) if sender is not None else None
        if client is not None:
            to.add(client)
        if not (item.get("type") == "warningFeedback" and sender is not None):
            to.update(c for c in self.clients if "feedback" in self.subscribers.get(c, ()))
        if to:
            message = fb.to_json(item)
            for client in to:
                self.send(client, message)

    def reply(self, sender: int | None, message: str) -> None:
        """A message for the client whose key is ``sender`` alone (counted as unsent if it has gone)."""
        client = self.by_key.get(sender)
        if client is None:
            self.counters["unsent"] += 1
            return
        self.send(client, message)

    def broadcast(self, item: dict, only: set[str] | None = None, droppable: bool = False) -> None:
        """Send ``item`` to every client (subscribed to one of ``only``); ``droppable``: poses, which a client
        that falls behind loses first."""
        message = fb.to_json(item)
        for client in list(self.clients):
            if only is not None and not only & self.subscribers.get(client, set()):
                continue
            self.send(client, message, droppable)

    def send(self, client, message: str, droppable: bool = False) -> None:
        """Queue ``message`` for ``client`` (a client that has gone: counted as unsent)."""
        outbox = self.outboxes.get(client)
        if outbox is None:
            self.counters["unsent"] += 1
            return
        outbox.put(message, droppable)

    def send_json(self, client, message: dict) -> None:
        """Queue a reply that is not feedback (a greeting, the status) for ``client``."""
        self.send(client, json.dumps(message))

    # ------------------------------------------------------------------------------------------- closing
    def stalled(self, now: float) -> list[tuple[object, str]]:
        """The clients taken not to read, and why (see :meth:`Outbox.stalled`)."""
        return [(client, why) for client, outbox in self.outboxes.items() if (why := outbox.stalled(now))]

    def close_slow(self, client, why: str) -> None:
        """Close a client that does not read what it is sent: what waits for it is let go, counted, and the
        server asked to close it (once)."""
        outbox = self.outboxes.get(client)
        if outbox is None or outbox.closing:
            return
        outbox.closing = True
        self.counters["closed_not_reading"] += 1
        self.counters["unsent"] += outbox.clear()
        self.close(client, why)
