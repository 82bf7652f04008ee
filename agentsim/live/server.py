"""``agentsim serve``: a live realizer behind a WebSocket endpoint, which programs drive and people watch.

The realizer is the one simulated runs use, on SimPy's real-time clock, in a thread of its own that alone
touches it (:class:`~agentsim.live.runtime.LiveRealizer`); the network is an asyncio loop in the main thread
(:class:`Server`, on the ``websockets`` library). Neither blocks the other: documents go through a bounded
queue (counted and weighed) to a reader thread that parses them and has their speech synthesised
(:class:`~agentsim.live.intake.Intake`), then to the realizer's thread, which submits the blocks every
:data:`~agentsim.live.runtime.POLL` seconds; feedback reaches the loop through ``call_soon_threadsafe``. Who
hears what is :mod:`agentsim.live.routing`'s, who may connect :mod:`agentsim.live.access`'s: this module is
the WebSocket's glue.

Protocol, at ``ws://HOST:PORT/``:

* each text message a client sends (a binary one: UTF-8 text) is one BML document (any form ``agentsim
  realize`` reads); a message that is not BML, or that the full queue cannot take, is answered to that
  client alone with a ``warningFeedback``;
* each feedback about a block is sent as one JSON text message, the objects ``agentsim realize`` prints,
  to the client that sent the block and to the clients that subscribed to ``"feedback"``,
  :attr:`Server.delay` seconds after its ``globalTime`` on the realizer's clock (so that it arrives when
  its sound is heard, when the server plays sound); a warning about a block goes to its sender alone;
* a JSON message ``{"subscribe": "poses"}`` asks for the poses as well (see :mod:`agentsim.live.poses`),
  ``{"subscribe": "feedback"}`` for the feedback of every client's blocks (``{"subscribe": [...]}`` for
  several), ``{"status": true}`` for the counters of what was refused, dropped or failed; any other JSON is
  answered with a warning.

Each client has one bounded :class:`~agentsim.live.routing.Outbox` and one task that sends it: a client that
falls behind loses poses first (counted), never feedback, and one that takes nothing for
:data:`~agentsim.live.routing.STALL_SECONDS` while messages wait, or does not answer a ping for that long
while it is sent messages (what came before the ping lies unread in its buffers), is closed with
:data:`CLOSE_CODE` and a reason.

``http://HOST:PORT/`` serves the viewer page (the report's viewer, connected live). A request that
:class:`~agentsim.live.access.Access` refuses, checked in the ``process_request`` hook before any handshake,
is answered ``403 Forbidden`` and nothing else.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Callable

from agentsim.core import feedback as fb
from agentsim.errors import UsageError
from agentsim.live.access import Access
from agentsim.live.faults import RealizerStopped, note
from agentsim.live.intake import Intake
from agentsim.live.routing import Outbox, Routing
from agentsim.live.runtime import LiveRealizer

#: How long (s) a client being closed is given to take its close frame before its connection is cut.
CLOSE_GRACE = 2.0
#: The close code for a client that did not read (1008, policy violation).
CLOSE_CODE = 1008
#: Bytes the transport holds for one client (websockets' ``write_limit``): past it, sending to it waits.
WRITE_LIMIT = 2 ** 15
#: The kernel's send buffer per connection (bytes; ``SO_SNDBUF``), which otherwise grows to megabytes.
SEND_BUFFER = 2 ** 15
#: How often (s) the server looks for clients that do not read, and pings those being sent messages.
WATCH_EVERY = 0.25

#: The type each of the viewer's files is served as, by its suffix.
TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".css": "text/css",
         ".txt": "text/plain; charset=utf-8"}


class Link:
    """One client's connection as the server's loop drives it: its outbox, the task that sends it (woken by
    ``ready``), the task that pings it and the pong that ping waits for."""

    __slots__ = ("client", "outbox", "ready", "task", "pinging", "pong")

    def __init__(self, client, outbox: Outbox):
        self.client, self.outbox = client, outbox
        self.ready = asyncio.Event()
        outbox.wake = self.ready.set
        self.task: asyncio.Future | None = None
        self.pinging: asyncio.Future | None = None
        self.pong: asyncio.Future | None = None

    def tasks(self) -> list[asyncio.Future]:
        return [task for task in (self.task, self.pinging) if task is not None]


class Server:
    """The WebSocket endpoint (and the viewer page) in front of a :class:`~agentsim.live.runtime.LiveRealizer`
    and its :class:`~agentsim.live.intake.Intake`.

    ``delay`` (s): feedback is sent this long after its ``globalTime`` on the realizer's clock (the
    loudspeaker's latency, when the server plays sound, so that feedback arrives when it is heard).
    ``token`` and ``allow_origins``: who may connect (:class:`~agentsim.live.access.Access`). ``files``: the
    viewer's files, by name.
    """

    def __init__(self, live: LiveRealizer, intake: Intake, host: str = "127.0.0.1", port: int = 8765,
                 delay: float = 0.0, files: dict[str, Path] | None = None, token: str | None = None,
                 allow_origins: tuple[str, ...] | list[str] = ()):
        self.live, self.intake = live, intake
        self.access = Access(host, port, token, allow_origins)
        self.routing = Routing(close=self.close_client)
        #: functions whose dicts are added to the status (the service's sound, for one)
        self.status_sources: list[Callable[[], dict]] = []
        self.failure: BaseException | None = None
        self.delay = delay
        self.links: dict[object, Link] = {}
        self.loop: asyncio.AbstractEventLoop | None = None
        #: the library's server, once it listens
        self.endpoint = None
        self.files = files if files is not None else {}
        live.listeners.append(self.from_realizer)

    @property
    def port(self) -> int:
        return self.access.port

    @property
    def counters(self) -> dict:
        """What went wrong or was refused (:class:`~agentsim.live.routing.Counters`)."""
        return self.routing.counters

    def url(self, scheme: str = "ws") -> str:
        """The WebSocket's (``ws``) or the viewer's (``http``) address, with the token if there is one."""
        return self.access.url(scheme)

    # ------------------------------------------------------------------------------------------- output
    def from_realizer(self, item: dict, sender: object = None) -> None:
        """A feedback from the realizer's thread: sent when its time (plus the delay) comes."""
        if self.loop is not None:
            self.loop.call_soon_threadsafe(self.schedule, item, sender)

    def schedule(self, item: dict, sender: object = None) -> None:
        when = self.live.wall_time(item.get("globalTime", 0.0)) + self.delay
        if when > self.loop.time() + 0.0005:
            self.loop.call_at(when, self.routing.address, item, sender)
        else:
            self.routing.address(item, sender)

    def reply_to(self, key: int | None) -> Callable[[dict], None]:
        """A ``reply`` for the reader's and the realizer's threads that reaches the client of ``key`` alone."""

        def reply(item: dict) -> None:
            if self.loop is not None:
                self.loop.call_soon_threadsafe(self.routing.reply, key, fb.to_json(item))

        return reply

    async def deliver(self, link: Link) -> None:
        """The task that sends a client's outbox, in order."""
        from websockets.exceptions import ConnectionClosed

        loop = asyncio.get_running_loop()
        outbox, ready = link.outbox, link.ready
        while True:
            while not outbox.messages:
                ready.clear()
                await ready.wait()
            message = outbox.take(loop.time())
            try:
                await link.client.send(message)
                outbox.sent(loop.time())
            except ConnectionClosed:  # a client that went away: it is forgotten when its handler ends
                outbox.lost()
            except Exception as exc:
                outbox.failed()
                self.fault("sending to a client", exc)

    def close_client(self, client, why: str) -> None:
        """Close a client that does not read what it is sent (:data:`CLOSE_CODE`; routing let go of what
        waited for it), giving it :data:`CLOSE_GRACE` s to take the close frame before its connection is
        cut."""
        reason = f"the client did not read what it was sent ({why})"
        note(f"closed the client at {peer(client)}: it did not read what it was sent ({why})")

        async def close() -> None:
            try:
                await asyncio.wait_for(client.close(CLOSE_CODE, reason), CLOSE_GRACE)
            except TimeoutError:  # it does not even take the close frame: the connection is cut
                client.transport.abort()
            except Exception as exc:
                self.fault("closing a client that did not read", exc)
                client.transport.abort()

        asyncio.ensure_future(close())

    async def watch(self) -> None:
        """Every :data:`WATCH_EVERY` s: close the clients that took nothing for the stall time while messages
        waited for them, or did not answer a ping for that long; ping those being sent messages."""
        while True:
            await asyncio.sleep(WATCH_EVERY)
            now = self.loop.time()
            for client, why in self.routing.stalled(now):
                self.routing.close_slow(client, why)
            client = None  # (no loop variable keeps a client that has gone while the watch sleeps)
            for link in list(self.links.values()):
                self.keep_alive(link, now)
            link = None

    def keep_alive(self, link: Link, now: float) -> None:
        """Ping a client that is being sent messages (when its outbox says so), one ping at a time."""
        pong = link.pong
        if pong is not None and pong.done():
            if not pong.cancelled():
                pong.exception()  # retrieved (a closed connection's), so that asyncio does not log it
            link.pong = None
            link.outbox.answered()
        if link.outbox.ping_due(now):
            link.pinging = asyncio.ensure_future(self.ping(link))

    async def ping(self, link: Link) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            link.pong = await link.client.ping()
        except ConnectionClosed:  # it went away: forgotten when its handler ends
            link.outbox.answered()
        except Exception as exc:
            link.outbox.answered()
            self.fault("pinging a client", exc)

    # ------------------------------------------------------------------------------------------- input
    def fault(self, where: str, exc: BaseException) -> None:
        """A fault of the server's own that it goes on after: one line on stderr, counted."""
        self.routing.counters["faults"] += 1
        note(f"{where} failed ({type(exc).__name__}: {exc}); serving goes on")

    async def handler(self, client) -> None:
        from websockets.exceptions import ConnectionClosedError

        outbox = self.routing.join(client)
        link = self.links[client] = Link(client, outbox)
        link.task = asyncio.ensure_future(self.deliver(link))
        key = self.routing.key(client)
        try:
            sock = client.transport.get_extra_info("socket")
            if sock is not None:
                import socket

                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        except OSError as exc:
            self.fault("bounding a client's send buffer", exc)
        try:
            async for message in client:
                try:
                    self.receive(client, key, message)
                except Exception as exc:  # whatever a message does, the connection goes on
                    self.fault("taking a message", exc)
                    self.warn(client, f"message refused: the server failed to take it ({type(exc).__name__})")
        except ConnectionClosedError:  # the connection broke (or was cut): nothing else is disturbed
            if not outbox.closing:
                self.routing.counters["broken_connections"] += 1
        finally:
            self.routing.leave(client)
            self.links.pop(client, None)
            # (its sender and its ping have stopped once its handler has: nothing of it outlives it here)
            for task in link.tasks():
                task.cancel()
            await asyncio.gather(*link.tasks(), return_exceptions=True)

    def warn(self, client, description: str) -> None:
        """A ``warningFeedback`` about what ``client`` sent, to it alone."""
        self.routing.send(client, fb.to_json(fb.warning("", "PARSING_FAILURE", description, self.live.now(),
                                                        "agent")))

    def receive(self, client, key: int | None, message: str | bytes) -> None:
        if isinstance(message, bytes):
            try:
                text = message.decode("utf-8")
            except UnicodeDecodeError as exc:
                self.warn(client, f"message refused: a binary message must be UTF-8 text (byte {exc.start} is "
                                  "not); send BML as a text message")
                return
        else:
            text = message
        if text.lstrip().startswith("{"):
            self.control(client, text)
            return
        why = self.intake.offer(text, self.reply_to(key), key)
        if why is not None:
            self.routing.counters["refused_documents"] += 1
            self.warn(client, f"document refused: {why}; send fewer at once")

    def control(self, client, text: str) -> None:
        """A JSON message: ``{"subscribe": KIND or [KIND, ...]}`` or ``{"status": true}``; anything else is
        answered with a warning."""
        kinds = self.routing.kinds()
        usage = ('a JSON message must be {"subscribe": KIND} or {"subscribe": [KIND, ...]} with KIND one of '
                 + ", ".join(f'"{k}"' for k in kinds) + ', or {"status": true}; BML is sent as XML')
        try:
            message = json.loads(text)
        except ValueError as exc:
            self.warn(client, f"message refused: not JSON ({exc}); {usage}")
            return
        if isinstance(message, dict) and list(message) == ["status"] and message["status"] is True:  # (not 1)
            self.routing.send_json(client, self.status())
            return
        if isinstance(message, dict) and list(message) == ["motion"]:
            self.motion(client, message["motion"])
            return
        if not isinstance(message, dict) or set(message) != {"subscribe"}:
            self.warn(client, f"message refused: not a control message this server knows; {usage}")
            return
        wanted = message["subscribe"]
        wanted = [wanted] if isinstance(wanted, str) else wanted
        if not isinstance(wanted, list) or not wanted or not all(isinstance(w, str) and w in kinds for w in wanted):
            self.warn(client, f"message refused: nothing here to subscribe to by {json.dumps(message['subscribe'])}; "
                              f"{usage}")
            return
        for hello in self.routing.subscribe(client, set(wanted)):
            self.routing.send_json(client, hello)

    def motion(self, client, samples) -> None:
        """``{"motion": [[t, ax, ay, az], ...]}``: a phone's motion for the anticipators that take it
        (``--anticipator reps,input=ws``); what cannot be taken is one warning to the sender."""
        takers = [a for a in self.live.realizer.scheduler.anticipators.values() if hasattr(a, "offer")
                  and getattr(a, "input", "") == "ws"]
        if not takers:
            self.warn(client, "motion refused: no anticipator here takes motion (serve --anticipator reps,input=ws)")
            return
        for anticipator in takers:
            why = anticipator.offer(samples, self.live.now())
            if why is not None:
                self.warn(client, f"motion refused: {why}")
                return

    def status(self) -> dict:
        """The reply to ``{"status": true}``: clients, messages sent, and what was refused, dropped or failed."""
        live, intake, routing = self.live, self.intake, self.routing
        status = {"type": "status", "clients": len(routing.clients), "sent": routing.sent, **routing.counters,
                  "refused_long_blocks": intake.refused_long, "refused_taken_ids": live.refused_taken,
                  "speech_audio_bytes": live.audio_bytes, "speech_audio_released": live.audio_released,
                  "realizer_faults": {**live.faults, **intake.faults}, "time": live.now()}
        for source in self.status_sources:
            status.update(source())
        return status

    def request(self, connection, request):
        """Refused requests get 403; plain HTTP requests get the viewer's files; WebSocket upgrades go on to
        :meth:`handler`."""
        from websockets.datastructures import MultipleValuesError

        try:
            origin = request.headers.get("Origin")
        except MultipleValuesError:
            origin = "several"
        why = self.access.refuses(origin, request.headers, request.path)
        if why is not None:
            self.routing.counters[f"refused_{why}s"] += 1
            return connection.respond(403, "Forbidden\n")
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return None
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = request.path.split("?", 1)[0]
        name = "index.html" if path in ("", "/") else path.lstrip("/")
        file = self.files.get(name)
        if file is None or not file.is_file():
            return connection.respond(404, f"no such file: {path}\n")
        body = file.read_bytes()
        headers = Headers([("Content-Type", TYPES.get(file.suffix, "application/octet-stream")),
                           ("Content-Length", str(len(body))), ("Cache-Control", "no-store")])
        return Response(200, "OK", headers, body)

    # ------------------------------------------------------------------------------------------- serving
    async def serve(self, ready: Callable[[], None] | None = None, stop: asyncio.Event | None = None) -> None:
        """Serve until ``stop`` is set (or forever). Raises :class:`UsageError` if the port is taken,
        :class:`~agentsim.live.faults.RealizerStopped` once the realizer's thread or the reader's died."""
        from websockets.asyncio.server import serve

        self.loop = asyncio.get_running_loop()
        stop = stop if stop is not None else asyncio.Event()
        loop = self.loop

        def failed(exc: BaseException) -> None:  # in the realizer's thread, or the reader's
            self.failure = exc
            loop.call_soon_threadsafe(stop.set)

        for part in (self.live, self.intake):
            part.on_failure.append(failed)
            if part.error is not None:
                failed(part.error)
        access = self.access
        try:
            server = await serve(self.handler, access.host, access.port, process_request=self.request,
                                 max_size=2 ** 22, ping_interval=20, write_limit=WRITE_LIMIT,
                                 server_header=None)  # no Server: header naming the library and its version
        except OSError as exc:
            raise UsageError(f"cannot listen on {access.host}:{access.port}: {exc.strerror or exc} (is another "
                             f"server running there? choose another with --port)") from None
        self.endpoint = server
        access.port = server.sockets[0].getsockname()[1]
        if ready is not None:
            ready()
        watcher = asyncio.ensure_future(self.watch())
        try:
            async with server:
                await stop.wait()
        finally:
            watcher.cancel()
        if self.failure is not None:
            exc = self.failure
            raise RealizerStopped(f"the realizer stopped ({type(exc).__name__}: {exc}); the service stopped "
                                  "with it") from None


def peer(client) -> str:
    """A client's address, as ``host:port``."""
    address = getattr(client, "remote_address", None)
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return "an unknown address"

