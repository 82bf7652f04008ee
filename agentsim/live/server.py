"""``agentsim serve``: a live realizer behind a WebSocket endpoint, which programs drive and people watch.

The realizer is the one simulated runs use, on SimPy's real-time clock, in a thread of its own
(:class:`LiveRealizer`); the network is an asyncio loop in the main thread (:class:`Server`, on the
``websockets`` library). Neither blocks the other: documents go through a bounded queue (counted and
weighed) to a reader thread that parses them and has their speech synthesised, then to a SimPy process that
submits the blocks every :data:`POLL` seconds; feedback reaches the loop through ``call_soon_threadsafe``.

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
  several); any other JSON is answered with a warning.

Each client has one bounded :class:`Outbox`: a client that falls behind loses poses first (counted), never
feedback, and one that takes nothing for :data:`STALL_SECONDS` while messages wait, or does not answer a ping
for that long while it is sent messages (what came before the ping lies unread in its buffers), is closed
with :data:`CLOSE_CODE` and a reason.

``http://HOST:PORT/`` serves the viewer page (the report's viewer, connected live).

Who may connect (:meth:`Server.admit`, in the ``process_request`` hook, before any handshake): a request with
an ``Origin`` header (a browser's) only from the server's own origin (the viewer's page) or one named in
``allow_origins``; requests without one (programs) are taken. With a ``token``, the WebSocket and the viewer's
page need ``?token=TOKEN`` (the page passes it on to its WebSocket); a server bound to an address other than
loopback without one makes one up. A refused request is answered ``403 Forbidden`` and nothing else.
"""

from __future__ import annotations

import asyncio
import collections
import gc
import ipaddress
import itertools
import json
import math
import queue
import secrets
import sys
import threading
import time
from pathlib import Path
from typing import Callable

from agentsim.core import feedback as fb
from agentsim.core.clock import make_environment
from agentsim.core.gcpause import CollectionPause
from agentsim.errors import AgentsimError, ScheduleError, UsageError
from agentsim.live.limits import Limits
from speech_timing.backend import audio_bytes

#: How often the realizer's thread takes what clients sent (s): a block waits at most this long.
POLL = 0.005
#: How many documents may wait for the realizer; more are refused with a warning.
QUEUE = 256
#: How many bytes the documents waiting for the realizer may weigh together, and one client's of them (a
#: message may weigh 4 MB: 256 of them had waited as a gigabyte); past either a document is refused with a
#: warning.
QUEUE_BYTES = 32 * 2 ** 20
SENDER_BYTES = 8 * 2 ** 20
#: What :meth:`LiveRealizer.warm_up` realizes: a speech with a beat on a word, a nod and a gaze shift.
WARM_UP = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="warmup"><speech id="s"><text>Hello '
           '<sync id="w"/>there.</text></speech><gesture id="g" lexeme="BEAT" stroke="s:w"/>'
           '<head id="h" lexeme="NOD" start="s:end"/><gazeShift id="z" target="user" influence="HEAD"/></bml>')

#: How many feedback items the realizer keeps (older ones are forgotten: a server runs for hours).
KEEP_FEEDBACK = 10_000
#: How many ended blocks the realizer keeps (older ones are released with their pegs: memory stays flat).
KEEP_BLOCKS = 256
#: How many blocks' senders are remembered (to address their feedback; the oldest are forgotten first).
KEEP_SENDERS = 4096

#: How many poses messages (a tenth of a second each) may wait for one client; past it the oldest waiting one
#: is dropped (counted in ``dropped_poses``): a client that falls behind loses poses first.
BACKLOG_POSES = 8
#: How many other messages (feedback, warnings, replies) may wait for one client; past it the client is closed
#: (it is not dropped: feedback is never lost while a client stays connected).
BACKLOG_MESSAGES = 2048
#: How long (s) a client may take nothing while messages wait for it before it is closed (:data:`CLOSE_CODE`).
STALL_SECONDS = 5.0
#: How often (s) a client that is being sent messages is pinged: one that has not answered a ping for
#: :data:`STALL_SECONDS` has not read what came before it, however large its buffers, and is closed.
PING_EVERY = 1.0
#: How long (s) after the last message sent to a client it is still pinged.
PING_WHILE = 2.0
#: How long (s) a client being closed is given to take its close frame before its connection is cut.
CLOSE_GRACE = 2.0
#: The close code for a client that did not read (1008, policy violation).
CLOSE_CODE = 1008
#: Bytes the transport holds for one client (websockets' ``write_limit``): past it, sending to it waits.
WRITE_LIMIT = 2 ** 15
#: The kernel's send buffer per connection (bytes; ``SO_SNDBUF``), which otherwise grows to megabytes.
SEND_BUFFER = 2 ** 15


class RealizerStopped(AgentsimError):
    """The realizer's thread died: the service stops with it (exit status 1)."""


def note(message: str) -> None:
    """One line on stderr about a fault the service goes on after."""
    print(f"agentsim serve: {message}", file=sys.stderr, flush=True)


class MediaDirectory:
    """Where files that clients name (``<bmlt:audiofile fileName>``) are read: only in ``root`` and below it
    (None: nowhere), by a relative path without ``..`` that stays inside once links are followed, and only
    sound files. Every refusal is the same :class:`ScheduleError`, which says nothing of the file system (not
    whether a file exists, nor where the server runs)."""

    def __init__(self, root: str | Path | None):
        self.root = Path(root).resolve() if root is not None else None

    def refuse(self) -> ScheduleError:
        if self.root is None:
            return ScheduleError("audiofile refused: this server reads no sound files named by clients (it was "
                                 "started without --media DIR)")
        return ScheduleError("audiofile refused: fileName must name a sound file in the server's media "
                             "directory, by a relative path without '..'")

    def __call__(self, behaviour) -> Path:
        name = behaviour.attributes.get("fileName", "").strip()
        if self.root is None or not name:
            raise self.refuse()
        parts = name.replace("\\", "/").split("/")
        if name.startswith(("/", "\\", "~")) or ".." in parts or ":" in parts[0] or "\0" in name:
            raise self.refuse()
        try:
            path = (self.root / name).resolve()
            path.relative_to(self.root)
            if not path.is_file():
                raise ValueError
            import soundfile

            info = soundfile.info(str(path))
            if not info.frames or not info.samplerate:
                raise ValueError
        except Exception:  # whatever the reason (missing, outside, unreadable, not sound): the same refusal
            raise self.refuse() from None
        return path


class Full(queue.Full):
    """A document the queue cannot take; ``str()`` says why."""


class TakeTurns:
    """The documents waiting for the reader, taken in turn from each sender (round robin), at most ``maxsize``
    in all, weighing at most ``max_bytes`` together and ``sender_bytes`` from one sender (a sender's first
    waiting document is taken whatever it weighs, if the others leave room for it): a client that sends many
    long speeches delays another client's next document by one of its own at most, not by all of them.
    ``put_nowait(entry, sender, weight)`` raises :class:`Full`; ``get()`` waits, and gives None once
    :meth:`close` was called."""

    def __init__(self, maxsize: int, max_bytes: int = QUEUE_BYTES, sender_bytes: int = SENDER_BYTES):
        self.maxsize, self.max_bytes, self.sender_bytes = maxsize, max_bytes, sender_bytes
        #: each sender's waiting (entry, weight), and what they weigh
        self.lanes: dict[object, collections.deque] = {}
        self.weights: dict[object, int] = {}
        self.bytes = 0
        #: when each sender was last served (a count of documents taken); the least recently served goes next
        self.served: collections.OrderedDict[object, int] = collections.OrderedDict()
        self.taken = 0
        self.count = 0
        self.closed = False
        self.changed = threading.Condition()

    def put_nowait(self, entry, sender: object = None, weight: int = 0) -> None:
        with self.changed:
            if self.count >= self.maxsize:
                raise Full(f"{self.maxsize} documents are already waiting for the realizer")
            if self.count and self.bytes + weight > self.max_bytes:
                raise Full(f"documents of {self.bytes / 2 ** 20:.1f} MB are already waiting for the realizer (at "
                           f"most {self.max_bytes / 2 ** 20:g} MB may)")
            mine = self.weights.get(sender, 0)
            if sender in self.lanes and mine + weight > self.sender_bytes:
                raise Full(f"this client's documents of {mine / 2 ** 20:.1f} MB are already waiting for the "
                           f"realizer (at most {self.sender_bytes / 2 ** 20:g} MB of one client's may)")
            self.lanes.setdefault(sender, collections.deque()).append((entry, weight))
            self.weights[sender] = mine + weight
            self.bytes += weight
            self.count += 1
            self.changed.notify()

    def get(self):
        with self.changed:
            while not self.count and not self.closed:
                self.changed.wait()
            if self.closed:
                return None
            sender = min(self.lanes, key=lambda s: self.served.get(s, -1))
            lane = self.lanes[sender]
            entry, weight = lane.popleft()
            self.count -= 1
            self.bytes -= weight
            self.weights[sender] -= weight
            if not lane:
                del self.lanes[sender], self.weights[sender]
            self.taken += 1
            self.served[sender] = self.taken  # its next document after every other sender's
            self.served.move_to_end(sender)
            while len(self.served) > KEEP_SENDERS:
                self.served.popitem(last=False)
            return entry

    def close(self) -> None:
        with self.changed:
            self.closed = True
            self.changed.notify_all()


class LiveRealizer:
    """A :class:`~agentsim.realizer.Realizer` on the real-time clock, in a thread of its own.

    ``offer(text, reply, sender)`` hands it a BML document from any thread (why not, if the queue is full; the
    reader takes each sender's documents in turn, :class:`TakeTurns`);
    what cannot be read is answered through ``reply(feedback)`` (in the reader's or the realizer's thread);
    every feedback goes to each function in :attr:`listeners` as ``listener(feedback, sender)``, ``sender``
    that of the block it is about (None if unknown; in the realizer's thread: they must not block). ``every(period,
    fn)`` calls ``fn(now)`` every ``period`` simulated seconds while it runs. ``media``: the directory sound
    files that clients name are read from (:class:`MediaDirectory`; None: none are). ``limits``: how much
    speech a block may ask for (:class:`Limits`). Realizer options (``tts``, ``strict``, ``speech``,
    ``anticipators``, ``lexicon``) are passed on. The service holds the garbage collector off while its two
    threads read and plan blocks, with one :class:`~agentsim.core.gcpause.CollectionPause` they share
    (``gc_pause``, unless another is given).

    The audio synthesised for a block is weighed (:attr:`audio_bytes`, by block) and released when the block
    ends: nothing but the block's own speeches holds it (the backend is not asked to remember it).
    """

    def __init__(self, queue_size: int = QUEUE, poll: float = POLL, media: str | Path | None = None,
                 limits: Limits | None = None, **realizer_options):
        from agentsim.realizer import Realizer

        self.env = make_environment(realtime=True)
        realizer_options.setdefault("keep", KEEP_BLOCKS)
        realizer_options.setdefault("gc_pause", CollectionPause())
        self.realizer = Realizer(env=self.env, **realizer_options)
        self.realizer.audio.planner.locate = MediaDirectory(media)
        self.realizer.feedback.keep = KEEP_FEEDBACK
        #: documents as clients sent them, for the reader; blocks read and ready, for the realizer
        self.incoming = TakeTurns(queue_size)
        self.inbox: queue.Queue = queue.Queue()
        self.poll = poll
        self.reader = threading.Thread(target=self.read, name="agentsim-reader", daemon=True)
        self.listeners: list[Callable[[dict, object], None]] = []
        #: who sent each block (by block id, the latest KEEP_SENDERS), written and read in the realizer's thread
        self.senders: collections.OrderedDict[str, object] = collections.OrderedDict()
        self.realizer.feedback.listen(self.emit)
        self.periodic: list[tuple[float, Callable[[float], None]]] = []
        self.closing = False
        self.started = threading.Event()
        #: what stopped the realizer's thread (None while it runs); each function in :attr:`on_failure` is
        #: called with it, in that thread
        self.error: BaseException | None = None
        self.on_failure: list[Callable[[BaseException], None]] = []
        #: functions called with a block's id when its audio is released (the loudspeaker lets its go)
        self.on_release: list[Callable[[str], None]] = []
        #: faults gone on after, by kind (reported in the server's status)
        self.faults: collections.Counter[str] = collections.Counter()
        self.limits = limits if limits is not None else Limits()
        #: blocks refused for asking for too much speech (:class:`Limits`)
        self.refused_long = 0
        #: the synthesised speeches of each block not yet ended, with their audio's bytes (block id -> list
        #: of (utterance, bytes)); written by the reader, released by the realizer's thread
        self.audio: dict[str, list] = {}
        self.audio_lock = threading.Lock()
        #: bytes of audio released with their blocks, since the start
        self.audio_released = 0
        #: what was synthesised for each block read and not yet submitted (by ``id(block)``)
        self.prepared: dict[int, list] = {}
        #: blocks refused because another client's block of the same id had not ended
        self.refused_taken = 0
        self.thread = threading.Thread(target=self.run, name="agentsim-realizer", daemon=True)

    # ------------------------------------------------------------------------------------------- threads
    def start(self) -> None:
        """Start the clock (simulated time 0 is now) and the realizer's thread."""
        self.warm_up()
        self.thread.start()
        self.reader.start()
        self.started.wait(5.0)

    def warm_up(self) -> None:
        """Realize a small block once on a simulated clock with the same speech backend, before the real clock
        starts: the first block a client sends then finds every module imported and the synthesiser running
        (without this the first blocks' feedback came up to 170 ms late)."""
        from agentsim.realizer import Realizer

        backend = self.realizer.speech.planner.backend
        try:
            rehearsal = Realizer(tts=backend, strict=self.realizer.strict)
            rehearsal.submit(WARM_UP)
            rehearsal.run()
        except Exception as exc:  # a backend that cannot speak will say so again on the first real block
            self.faults["warm_up"] += 1
            note(f"warming up failed ({type(exc).__name__}: {exc}); the first blocks' feedback may come late")
        # What exists now (modules, the synthesiser, the rehearsal's leftovers collected first) lives as long
        # as the service: moved out of the collector's generations, a full collection no longer scans it.
        gc.collect()
        gc.freeze()

    def close(self, timeout: float = 5.0) -> None:
        self.closing = True
        self.incoming.close()
        self.thread.join(timeout)
        self.reader.join(timeout)

    def run(self) -> None:
        """The realizer's thread: the SimPy real-time loop, until :meth:`close`."""
        self.env.sync()
        pump = self.env.process(self.pump())
        for period, fn in self.periodic:
            self.env.process(self.tick(period, fn))
        self.started.set()
        try:
            # until the pump stops, at :meth:`close`: what still plays then (a long speech, an anticipator's
            # beats) is not waited for in real time
            self.env.run(until=pump)
        except BaseException as exc:  # the server stops, saying why
            self.error = exc
            for fn in self.on_failure:
                fn(exc)

    def pump(self):
        """Take what clients sent, every :attr:`poll` seconds."""
        while not self.closing:
            while True:
                try:
                    entry = self.inbox.get_nowait()
                except queue.Empty:
                    break
                self.submit(*entry)
                del entry  # (its reply holds the client's connection: not kept while the realizer waits)
            yield self.env.timeout(self.poll)

    def tick(self, period: float, fn: Callable[[float], None]):
        while not self.closing:
            yield self.env.timeout(period)
            try:
                fn(self.env.now)
            except Exception as exc:  # a viewer's fault must not stop the realizer: said once, counted
                if not self.faults["periodic"]:
                    note(f"a periodic task failed ({type(exc).__name__}: {exc}); it goes on, and further "
                         "faults are only counted")
                self.faults["periodic"] += 1

    def every(self, period: float, fn: Callable[[float], None]) -> None:
        """Call ``fn(now)`` every ``period`` seconds in the realizer's thread (set before :meth:`start`)."""
        self.periodic.append((period, fn))

    # ------------------------------------------------------------------------------------------- input
    def offer(self, text: str | bytes, reply: Callable[[dict], None], sender: object = None) -> str | None:
        """Hand a document to the realizer; why it was refused (the queue is full, by count or by weight), or
        None."""
        try:
            self.incoming.put_nowait((text, reply, sender), sender, sys.getsizeof(text))
            return None
        except Full as full:
            return str(full)

    def read(self) -> None:
        """The reader's thread: parse each document in the order it came and have its speech synthesised,
        so that the realizer's thread (whose clock the feedback keeps) only plans and plays. A fault of its own
        in one document refuses that document (its sender is told, the fault counted and said on stderr);
        should the thread itself die, the service stops as when the realizer's thread does."""
        realizer = self.realizer
        try:
            while True:
                entry = self.incoming.get()
                if entry is None or self.closing:
                    return
                try:
                    self.read_one(*entry, realizer)
                except Exception as exc:
                    self.reader_failed(entry[1], exc)
                del entry  # (its reply holds the client's connection: not kept while the reader waits)
        except BaseException as exc:  # the server stops, saying why
            self.error = exc
            for fn in self.on_failure:
                fn(exc)

    def reader_failed(self, reply: Callable[[dict], None], exc: Exception) -> None:
        """The reader failed on a document: its sender hears that it was refused, the operator why."""
        self.faults["reader"] += 1
        note(f"reading a document failed ({type(exc).__name__}: {exc}); serving goes on")
        reply(fb.warning("", "PARSING_FAILURE", f"document refused: the server failed to read it "
                         f"({type(exc).__name__})", self.env.now, "agent"))

    def read_one(self, text, reply: Callable[[dict], None], sender, realizer) -> None:
        """Parse one document and hand its blocks on (in the reader's thread)."""
        from agentsim.bml.parser import Refused

        try:
            blocks = realizer.read_document(text)
        except Exception as exc:  # the reader's own fault: the client hears of it, the operator too
            self.reader_failed(reply, exc)
            return
        for block in blocks:
            if isinstance(block, Refused):
                error = block.error
                reply(fb.warning(block.block_id, "PARSING_FAILURE", f"block refused: {error}", self.env.now,
                                 "agent", line=error.line, column=error.column))
                continue
            if self.prepare(block, reply):
                self.inbox.put((block, reply, sender))

    def prepare(self, block, reply: Callable[[dict], None] | None = None) -> bool:
        """Synthesise a block's speeches ahead, so that the realizer's thread (whose clock the feedback keeps)
        only plans and plays: the planner is handed each utterance, the backend forgets it (the block's
        speeches alone hold its audio, weighed in :attr:`audio`, until the block ends). A block that asks for
        more speech than :attr:`limits` allow is refused with one warning (False)."""
        from agentsim.engines.speech import speech_text

        planner = self.realizer.speech.planner
        backend = planner.backend
        # espeak-ng's rate is words a minute; another backend's, a factor on its own pace (taken as 175 a minute)
        rate = getattr(backend, "rate", None) or 1.0
        rate = float(rate) if getattr(backend, "name", "") == "espeak" else 175.0 * float(rate)
        speeches = [b for b in block.behaviours if b.type == "speech"]
        texts = [(b.id, speech_text(b)) for b in speeches]
        why = self.limits.check([(i, t.text) for i, t in texts], rate)
        made = []
        if why is None:
            for behaviour, (_, text) in zip(speeches, texts):
                try:
                    utterance = backend.synthesize(text)
                except Exception:  # the planner meets the same problem, and warns the sender; counted here
                    self.faults["synthesis_ahead"] += 1
                    continue
                forget = getattr(backend, "forget", None)
                if forget is not None:
                    forget(text)
                made.append((behaviour, utterance))
            durations = {i: 0.0 for i, _ in texts}  # (one that could not be synthesised: the planner warns)
            durations.update((b.id, u.duration) for b, u in made)
            why = self.limits.check([(i, t.text) for i, t in texts], rate, durations)
        if why is not None:
            made.clear()  # what was synthesised goes with them
            self.refused_long += 1
            if reply is not None:
                reply(fb.warning(block.id, "PARSING_FAILURE", f"block refused: {why}", self.env.now,
                                 block.character_id))
            return False
        weighed = []
        for behaviour, utterance in made:
            planner.set_utterance(behaviour, utterance)
            weighed.append((utterance, audio_bytes(utterance)))
        if weighed:
            with self.audio_lock:
                self.prepared[id(block)] = weighed
        return True

    @property
    def audio_bytes(self) -> int:
        """Bytes of synthesised audio held for blocks that have not ended (or not yet started)."""
        with self.audio_lock:
            return sum(n for store in (self.audio, self.prepared) for held in store.values() for _, n in held)

    def release(self, block_id: str, only: list | None = None) -> None:
        """A block ended (or was refused): its speeches' audio (``only`` these of them) is let go, wherever
        the realizer keeps them."""
        with self.audio_lock:
            if only is None:
                held = self.audio.pop(block_id, [])
            else:  # (by identity: utterances compare by their fields, audio and all)
                mine = {id(utterance) for utterance, _ in only}
                kept = self.audio.pop(block_id, [])
                held = [entry for entry in kept if id(entry[0]) in mine]
                kept = [entry for entry in kept if id(entry[0]) not in mine]
                if kept:
                    self.audio[block_id] = kept
        for utterance, n in held:
            utterance.audio = None
            self.audio_released += n
        if only is None:
            for fn in self.on_release:
                fn(block_id)

    def submit(self, block, reply: Callable[[dict], None], sender: object = None) -> None:
        """Submit a block that was read (in the realizer's thread). A block whose id is that of another
        client's block that has not ended is refused, to its sender alone: the other block's feedback still
        goes to whom it went to."""
        with self.audio_lock:
            weighed = self.prepared.pop(id(block), [])
            if weighed:
                self.audio.setdefault(block.id, []).extend(weighed)
        running = self.realizer.scheduler.book.is_open(block.id)
        if running and block.id in self.senders and self.senders[block.id] != sender:
            self.release(block.id, weighed)
            self.refused_taken += 1
            reply(fb.warning(block.id, "PARSING_FAILURE", f"block refused: another client's block {block.id!r} "
                             "has not ended; give yours an id of its own", self.env.now, block.character_id))
            return
        self.senders[block.id] = sender
        self.senders.move_to_end(block.id)
        while len(self.senders) > KEEP_SENDERS:
            self.senders.popitem(last=False)
        try:
            run = self.realizer.submit(block)
        except Exception as exc:
            self.release(block.id, weighed)
            reply(fb.warning(block.id, "IMPOSSIBLE_TO_SCHEDULE", f"block refused: the realizer failed to plan it "
                             f"({type(exc).__name__}: {exc})", self.env.now, block.character_id))
            return
        if run is None:  # refused (with a warning): what was synthesised for it goes
            self.release(block.id, weighed)

    def emit(self, item: dict) -> None:
        block_id = str(item.get("id", "")).split(":", 1)[0]
        if item.get("type") == "blockProgress" and item.get("id") == f"{block_id}:end":
            self.release(block_id)
        sender = self.senders.get(block_id)
        for listener in self.listeners:
            listener(item, sender)

    def wall_time(self, t: float) -> float:
        """The ``time.monotonic()`` time at which simulated time ``t`` happens."""
        return self.env.real_start + t * self.env.factor


VIEWER_DIR = Path(__file__).resolve().parent / "viewer"
TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".css": "text/css",
         ".txt": "text/plain; charset=utf-8"}


#: Host names that are loopback whatever the resolver says.
LOOPBACK_NAMES = ("localhost",)


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is reachable from this machine only."""
    host = host.strip().strip("[]").lower()
    if host in LOOPBACK_NAMES or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def origin_of(url: str) -> str:
    """``url`` as browsers write an ``Origin`` (``scheme://host[:port]``, lower case, no path);
    :class:`UsageError` if it is not one."""
    from urllib.parse import urlsplit

    text = url.strip()
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        parts, port = None, None
    if (parts is None or parts.scheme.lower() not in ("http", "https") or not parts.hostname
            or parts.path not in ("", "/") or parts.query or parts.fragment or parts.username):
        raise UsageError(f"--allow-origin takes an origin such as https://example.org or http://localhost:8000 "
                         f"(a scheme, a host and a port if any, no path), got {url!r}")
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"
    return f"{parts.scheme.lower()}://{host}" + (f":{port}" if port is not None else "")


class Outbox:
    """What waits to be sent to one client, and the one task that sends it, in order (in the server's loop).

    Poses messages (``droppable``) wait at most :data:`BACKLOG_POSES` at a time: past it the oldest waiting
    one is dropped. Other messages are kept, up to :data:`BACKLOG_MESSAGES`, past which the client is closed.
    The transport holds at most :data:`WRITE_LIMIT` bytes besides (``send`` waits while it is full), so what a
    client that does not read costs the server is bounded; :meth:`Server.watch` closes it once it has taken
    nothing for :data:`STALL_SECONDS` while messages waited.
    """

    def __init__(self, server: "Server", client):
        self.server, self.client = server, client
        self.messages: collections.deque[tuple[str, bool]] = collections.deque()
        self.poses = 0
        self.ready = asyncio.Event()
        #: since when (``loop.time()``) the message being sent waits for the client to take what it was sent
        self.waiting_since: float | None = None
        #: when a message was last sent; when the ping not yet answered was sent (None: none waits), and the
        #: pong it waits for
        self.last_sent = -math.inf
        self.ping_sent: float | None = None
        self.last_ping = -math.inf
        self.pong: asyncio.Future | None = None
        self.closing = False
        self.task = asyncio.ensure_future(self.run())

    def put(self, message: str, droppable: bool = False) -> None:
        counters = self.server.counters
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
            self.server.close_slow(self.client, f"{BACKLOG_MESSAGES} messages were waiting for it")
            return
        self.messages.append((message, droppable))
        self.ready.set()

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

    def keep_alive(self, now: float) -> None:
        """Ping a client that is being sent messages, every :data:`PING_EVERY` s, one ping at a time."""
        if self.pong is not None and self.pong.done():
            if not self.pong.cancelled():
                self.pong.exception()  # retrieved (a closed connection's), so that asyncio does not log it
            self.pong, self.ping_sent = None, None
        if (self.closing or self.ping_sent is not None or now - self.last_sent > PING_WHILE
                or now - self.last_ping < PING_EVERY):
            return
        self.ping_sent = self.last_ping = now
        asyncio.ensure_future(self.send_ping())

    async def send_ping(self) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            self.pong = await self.client.ping()
        except ConnectionClosed:  # it went away: forgotten when its handler ends
            self.ping_sent = None
        except Exception as exc:
            self.ping_sent = None
            self.server.fault("pinging a client", exc)

    async def run(self) -> None:
        from websockets.exceptions import ConnectionClosed

        loop = asyncio.get_running_loop()
        while True:
            while not self.messages:
                self.ready.clear()
                await self.ready.wait()
            message, droppable = self.messages.popleft()
            if droppable:
                self.poses -= 1
            self.waiting_since = loop.time()
            try:
                await self.client.send(message)
                self.server.sent += 1
                self.last_sent = loop.time()
            except ConnectionClosed:  # a client that went away: it is forgotten when its handler ends
                self.server.counters["unsent"] += 1 + len(self.messages)
                self.messages.clear()
                self.poses = 0
                self.closing = True
            except Exception as exc:
                self.server.fault("sending to a client", exc)
            finally:
                self.waiting_since = None

    def stop(self) -> None:
        """The client has gone: what still waits is counted as unsent, the sender stops."""
        self.server.counters["unsent"] += len(self.messages)
        self.messages.clear()
        self.closing = True
        self.task.cancel()


class Server:
    """The WebSocket endpoint (and the viewer page) in front of a :class:`LiveRealizer`.

    ``delay`` (s): feedback is sent this long after its ``globalTime`` on the realizer's clock (the
    loudspeaker's latency, when the server plays sound, so that feedback arrives when it is heard).
    ``token``: what the WebSocket and the viewer's page need as ``?token=`` (None: nothing; made up when
    ``host`` is not loopback, :attr:`token_made` then). ``allow_origins``: origins (``https://host[:port]``)
    whose pages may connect besides the viewer's own.
    """

    def __init__(self, live: LiveRealizer, host: str = "127.0.0.1", port: int = 8765, delay: float = 0.0,
                 files: dict[str, Path] | None = None, token: str | None = None,
                 allow_origins: tuple[str, ...] | list[str] = ()):
        self.live = live
        self.host, self.port = host, port
        self.loopback = is_loopback(host)
        if token is not None and not token.strip():
            raise UsageError("--token must not be empty")
        self.token_made = token is None and not self.loopback
        self.token = secrets.token_urlsafe(24) if self.token_made else token
        self.allow_origins = frozenset(origin_of(o) for o in allow_origins)
        #: what went wrong or was refused, for ``{"status": true}``
        self.counters = {"refused_origins": 0, "refused_tokens": 0, "refused_documents": 0, "closed_clients": 0,
                         "closed_not_reading": 0, "broken_connections": 0, "dropped_poses": 0, "unsent": 0, "faults": 0}
        #: functions whose dicts are added to the status (the service's sound, for one)
        self.status_sources: list[Callable[[], dict]] = []
        self.failure: BaseException | None = None
        self.delay = delay
        self.clients: set = set()
        #: each connected client by the key its blocks are sent with (the realizer remembers who sent a block by
        #: this number, never by the connection: a client that has gone is not kept alive by its blocks)
        self.by_key: dict[int, object] = {}
        self.key_of: dict[object, int] = {}
        self.keys = itertools.count(1)
        #: each client's :class:`Outbox`
        self.outboxes: dict[object, Outbox] = {}
        self.subscribers: dict[object, set[str]] = {}
        self.loop: asyncio.AbstractEventLoop | None = None
        self.files = files if files is not None else {}
        #: what a new subscriber of each kind is sent first (set by whoever publishes it)
        self.hello: dict[str, dict] = {}
        self.sent = 0
        live.listeners.append(self.from_realizer)

    # ------------------------------------------------------------------------------------------- output
    def from_realizer(self, item: dict, sender: object = None) -> None:
        """A feedback from the realizer's thread: send it when its time (plus the delay) comes."""
        if self.loop is not None:
            self.loop.call_soon_threadsafe(self.schedule, item, sender)

    def schedule(self, item: dict, sender: object = None) -> None:
        when = self.live.wall_time(item.get("globalTime", 0.0)) + self.delay
        if when > self.loop.time() + 0.0005:
            self.loop.call_at(when, self.address, item, sender)
        else:
            self.address(item, sender)

    def address(self, item: dict, sender: object = None) -> None:
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

    def broadcast(self, item: dict, only: set[str] | None = None, droppable: bool = False) -> None:
        """Send ``item`` to every client (subscribed to one of ``only``); ``droppable``: poses, which a client
        that falls behind loses first."""
        message = fb.to_json(item)
        for client in list(self.clients):
            if only is not None and not only & self.subscribers.get(client, set()):
                continue
            self.send(client, message, droppable)

    def send(self, client, message: str, droppable: bool = False) -> None:
        """Queue ``message`` for ``client`` (see :class:`Outbox`; a client that has gone: counted as unsent)."""
        outbox = self.outboxes.get(client)
        if outbox is None:
            self.counters["unsent"] += 1
            return
        outbox.put(message, droppable)

    def close_slow(self, client, why: str) -> None:
        """Close a client that does not read what it is sent (:data:`CLOSE_CODE`), giving it
        :data:`CLOSE_GRACE` s to take the close frame before its connection is cut."""
        outbox = self.outboxes.get(client)
        if outbox is None or outbox.closing:
            return
        outbox.closing = True
        self.counters["closed_not_reading"] += 1
        dropped = len(outbox.messages)
        self.counters["unsent"] += dropped
        outbox.messages.clear()
        outbox.poses = 0
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
        """Every quarter of a second: close the clients that took nothing for :data:`STALL_SECONDS` while
        messages waited for them, or did not answer a ping for that long; ping those being sent messages."""
        while True:
            await asyncio.sleep(0.25)
            now = self.loop.time()
            # (comprehensions: no loop variable keeps a client that has gone while the watch sleeps)
            for client, why in [(c, o.stalled(now)) for c, o in self.outboxes.items() if o.stalled(now)]:
                self.close_slow(client, why)
            client = None
            for outbox in list(self.outboxes.values()):
                outbox.keep_alive(now)
            outbox = None

    def reply_to(self, client) -> Callable[[dict], None]:
        """A ``reply`` for the realizer's thread that reaches ``client`` alone."""

        def reply(item: dict) -> None:
            if self.loop is not None:
                self.loop.call_soon_threadsafe(self.send, client, fb.to_json(item))

        return reply

    # ------------------------------------------------------------------------------------------- input
    def fault(self, where: str, exc: BaseException) -> None:
        """A fault of the server's own that it goes on after: one line on stderr, counted."""
        self.counters["faults"] += 1
        note(f"{where} failed ({type(exc).__name__}: {exc}); serving goes on")

    async def handler(self, client) -> None:
        from websockets.exceptions import ConnectionClosedError

        self.clients.add(client)
        self.outboxes[client] = Outbox(self, client)
        key = next(self.keys)
        self.by_key[key] = client
        self.key_of[client] = key
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
                    self.receive(client, message)
                except Exception as exc:  # whatever a message does, the connection goes on
                    self.fault("taking a message", exc)
                    self.warn(client, f"message refused: the server failed to take it ({type(exc).__name__})")
        except ConnectionClosedError:  # the connection broke (or was cut): nothing else is disturbed
            outbox = self.outboxes.get(client)
            if outbox is None or not outbox.closing:
                self.counters["broken_connections"] += 1
        finally:
            self.counters["closed_clients"] += 1
            self.clients.discard(client)
            self.by_key.pop(key, None)
            self.key_of.pop(client, None)
            outbox = self.outboxes.pop(client, None)
            if outbox is not None:
                outbox.stop()
            self.subscribers.pop(client, None)

    def warn(self, client, description: str) -> None:
        """A ``warningFeedback`` about what ``client`` sent, to it alone."""
        self.send(client, fb.to_json(fb.warning("", "PARSING_FAILURE", description, self.live.env.now, "agent")))

    def receive(self, client, message: str | bytes) -> None:
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
        why = self.live.offer(text, self.reply_to(client), self.key_of.get(client))
        if why is not None:
            self.counters["refused_documents"] += 1
            self.send(client, fb.to_json(fb.warning("", "PARSING_FAILURE", f"document refused: {why}; send fewer "
                                                    "at once", self.live.env.now, "agent")))

    def kinds(self) -> list[str]:
        """What a client may subscribe to here."""
        return sorted({"feedback", *self.hello})

    def control(self, client, text: str) -> None:
        """A JSON message: ``{"subscribe": KIND or [KIND, ...]}``; anything else is answered with a warning."""
        usage = ('a JSON message must be {"subscribe": KIND} or {"subscribe": [KIND, ...]} with KIND one of '
                 + ", ".join(f'"{k}"' for k in self.kinds()) + ', or {"status": true}; BML is sent as XML')
        try:
            message = json.loads(text)
        except ValueError as exc:
            self.warn(client, f"message refused: not JSON ({exc}); {usage}")
            return
        if isinstance(message, dict) and list(message) == ["status"] and message["status"] is True:  # (not 1)
            self.send(client, json.dumps(self.status()))
            return
        if not isinstance(message, dict) or set(message) != {"subscribe"}:
            self.warn(client, f"message refused: not a control message this server knows; {usage}")
            return
        wanted = message["subscribe"]
        wanted = [wanted] if isinstance(wanted, str) else wanted
        kinds = self.kinds()
        if not isinstance(wanted, list) or not wanted or not all(isinstance(w, str) and w in kinds for w in wanted):
            self.warn(client, f"message refused: nothing here to subscribe to by {json.dumps(message['subscribe'])}; "
                              f"{usage}")
            return
        wanted = set(wanted)
        self.subscribers.setdefault(client, set()).update(wanted)
        for hello in self.greetings(wanted):
            self.send(client, json.dumps(hello))

    def status(self) -> dict:
        """The reply to ``{"status": true}``: clients, messages sent, and what was refused, dropped or failed."""
        status = {"type": "status", "clients": len(self.clients), "sent": self.sent, **self.counters,
                  "refused_long_blocks": self.live.refused_long, "refused_taken_ids": self.live.refused_taken,
                  "speech_audio_bytes": self.live.audio_bytes,
                  "speech_audio_released": self.live.audio_released,
                  "realizer_faults": dict(self.live.faults), "time": self.live.env.now}
        for source in self.status_sources:
            status.update(source())
        return status

    def greetings(self, wanted: set[str]) -> list[dict]:
        """What a new subscriber is told first (set by whoever publishes what it subscribes to)."""
        return [self.hello[w] for w in sorted(wanted) if w in self.hello]

    def own_origin(self, origin: str, host_header: str | None) -> bool:
        """Whether ``origin`` is the viewer's page as the browser reached it: ``http://`` and the ``Host`` the
        request names, when that host is this server's address, or a loopback name on a loopback server (a
        page elsewhere that a name of its own resolves here, DNS rebinding, names its own host), or anything
        on a server that needs a token (the page then had the token)."""
        if not host_header or origin != f"http://{host_header.strip().lower()}":
            return False
        from urllib.parse import urlsplit

        try:
            parts = urlsplit(origin)
            name, port = parts.hostname or "", parts.port or 80
        except ValueError:
            return False
        if port != self.port:
            return False
        if self.token is not None:
            return True
        return is_loopback(name) if self.loopback else name == self.host.strip("[]").lower()

    def admit(self, request) -> str | None:
        """Why ``request`` is refused (None: it is not): a foreign ``Origin``, or no or a wrong token."""
        from urllib.parse import parse_qs

        from websockets.datastructures import MultipleValuesError

        try:
            origin = request.headers.get("Origin")
        except MultipleValuesError:
            origin = "several"
        if origin is not None and origin.lower() not in self.allow_origins \
                and not self.own_origin(origin.lower(), request.headers.get("Host")):
            self.counters["refused_origins"] += 1
            return "origin"
        if self.token is not None:
            path, _, query = request.path.partition("?")
            upgrade = request.headers.get("Upgrade", "").lower() == "websocket"
            if upgrade or path in ("", "/", "/index.html"):  # the page's scripts and style are the package's
                given = parse_qs(query).get("token", [""])[-1]
                if not secrets.compare_digest(given.encode(), self.token.encode()):
                    self.counters["refused_tokens"] += 1
                    return "token"
        return None

    def request(self, connection, request):
        """Refused requests get 403; plain HTTP requests get the viewer's files; WebSocket upgrades go on to
        :meth:`handler`."""
        if self.admit(request) is not None:
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

    def url(self, scheme: str = "ws") -> str:
        """The WebSocket's (``ws``) or the viewer's (``http``) address, with the token if there is one."""
        host = f"[{self.host}]" if ":" in self.host and not self.host.startswith("[") else self.host
        query = f"?token={self.token}" if self.token is not None else ""
        return f"{scheme}://{host}:{self.port}/{query}"

    # ------------------------------------------------------------------------------------------- serving
    async def serve(self, ready: Callable[[], None] | None = None, stop: asyncio.Event | None = None) -> None:
        """Serve until ``stop`` is set (or forever). Raises :class:`UsageError` if the port is taken,
        :class:`RealizerStopped` once the realizer's thread died."""
        from websockets.asyncio.server import serve

        self.loop = asyncio.get_running_loop()
        stop = stop if stop is not None else asyncio.Event()
        loop = self.loop

        def failed(exc: BaseException) -> None:  # in the realizer's thread
            self.failure = exc
            loop.call_soon_threadsafe(stop.set)

        self.live.on_failure.append(failed)
        if self.live.error is not None:
            failed(self.live.error)
        try:
            server = await serve(self.handler, self.host, self.port, process_request=self.request,
                                 max_size=2 ** 22, ping_interval=20, write_limit=WRITE_LIMIT,
                                 server_header=None)  # no Server: header naming the library and its version
        except OSError as exc:
            raise UsageError(f"cannot listen on {self.host}:{self.port}: {exc.strerror or exc} (is another "
                             f"server running there? choose another with --port)") from None
        self.port = server.sockets[0].getsockname()[1]
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


def wait_for_port(host: str, port: int, timeout: float = 10.0) -> bool:
    """Whether something listens on ``host:port`` within ``timeout`` s (for clients that start a server)."""
    import socket

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection((host, port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False
