"""What clients send ``agentsim serve``, on its way to the realizer: the bounded queue it waits in
(:class:`TakeTurns`), the one folder sound files may be named in (:class:`MediaDirectory`), and the reader's
thread (:class:`Intake`), which parses each document, has its speech synthesised and hands each block on
ready (:class:`Prepared`), so that the realizer's thread only plans and plays. The reader never touches the
realizer: it is handed the speech backend, a clock to read and a way to name blocks, and hands blocks on to
the runtime's inbox (:mod:`agentsim.live.runtime`)."""

from __future__ import annotations

import collections
import dataclasses
import queue
import sys
import threading
from pathlib import Path
from typing import Callable

from agentsim.core import feedback as fb
from agentsim.core.gcpause import paused
from agentsim.errors import ScheduleError
from agentsim.live.faults import note
from agentsim.live.limits import Limits
from speech_timing.backend import audio_bytes

#: How many documents may wait for the reader; more are refused with a warning.
QUEUE = 256
#: How many bytes the documents waiting for the reader may weigh together, and one client's of them (a
#: message may weigh 4 MB: 256 of them had waited as a gigabyte); past either a document is refused with a
#: warning.
QUEUE_BYTES = 32 * 2 ** 20
SENDER_BYTES = 8 * 2 ** 20
#: How many senders are remembered: whose turn it is in the queue, and who sent each block (the runtime
#: addresses its feedback so; the oldest are forgotten first).
KEEP_SENDERS = 4096


class MediaDirectory:
    """Where files that clients name (``<bmlt:audiofile fileName>``) are read: only in ``root`` and below it
    (None: nowhere), by a relative path without ``..`` that stays inside once links are followed, and only
    sound files. Every refusal is the same :class:`ScheduleError`, which says nothing of the file system (not
    whether a file exists, nor where the server runs). The realizer's audio engine calls it, in the
    realizer's thread."""

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


@dataclasses.dataclass(eq=False)
class Prepared:
    """A block read and ready for the realizer: who hears of it (``reply``, for what concerns its sender
    alone; ``sender``, the number feedback is addressed by) and its speeches synthesised ahead, each
    ``(behaviour, utterance, bytes of its audio)``."""

    block: object
    reply: Callable[[dict], None]
    sender: object = None
    speech: list = dataclasses.field(default_factory=list)

    @property
    def weight(self) -> int:
        """Bytes of audio synthesised for the block."""
        return sum(n for _, _, n in self.speech)


class Intake:
    """The reader of what clients send, in a thread of its own.

    ``offer(text, reply, sender)`` hands it a BML document from any thread (why not, if the queue is full: it
    is a :class:`TakeTurns`); the reader parses each, has its speeches synthesised by ``backend`` (which then
    forgets them: the block's speeches alone hold their audio) and hands each block within :attr:`limits` on
    to ``deliver`` as a :class:`Prepared`; what cannot be read or is refused is answered through ``reply``
    (in the reader's thread). ``name_block`` names the blocks without an id, ``now`` is the realizer's clock
    (the time of the warnings), ``strict``: read BML 1.0 only; ``lexicon``: the lexicon the realizer plays
    (the foreign names of other realizers' BML are read as its lexemes); ``gc_pause``: the pause of the garbage
    collector it shares with the realizer's thread (None: the collector is left alone). Should the thread die,
    :attr:`error` says why and each function in :attr:`on_failure` is called with it.
    """

    def __init__(self, deliver: Callable[[Prepared], None], backend, *, name_block: Callable[[], str] | None = None,
                 now: Callable[[], float] = lambda: 0.0, strict: bool = False, limits: Limits | None = None,
                 queue_size: int = QUEUE, lexicon=None, gc_pause=None):
        self.deliver, self.backend, self.name_block, self.now = deliver, backend, name_block, now
        self.strict, self.lexicon, self.gc_pause = strict, lexicon, gc_pause
        self.limits = limits if limits is not None else Limits()
        #: documents as clients sent them, for the reader
        self.incoming = TakeTurns(queue_size)
        #: faults gone on after, by kind; blocks refused for asking for too much speech
        self.faults: collections.Counter[str] = collections.Counter()
        self.refused_long = 0
        self.closing = False
        self.error: BaseException | None = None
        self.on_failure: list[Callable[[BaseException], None]] = []
        self.thread = threading.Thread(target=self.read, name="agentsim-reader", daemon=True)

    def start(self) -> None:
        self.thread.start()

    def close(self, timeout: float = 5.0) -> None:
        self.closing = True
        self.incoming.close()
        if self.thread.is_alive():
            self.thread.join(timeout)

    def offer(self, text: str | bytes, reply: Callable[[dict], None], sender: object = None) -> str | None:
        """Hand a document to the reader; why it was refused (the queue is full, by count or by weight), or
        None."""
        try:
            self.incoming.put_nowait((text, reply, sender), sender, sys.getsizeof(text))
            return None
        except Full as full:
            return str(full)

    # ------------------------------------------------------------------------------------------- the thread
    def read(self) -> None:
        """The reader's thread: parse each document in the order :class:`TakeTurns` gives them and have its
        speech synthesised. A fault of its own in one document refuses that document (its sender is told, the
        fault counted and said on stderr); should the thread itself die, the service stops as when the
        realizer's thread does."""
        try:
            while True:
                entry = self.incoming.get()
                if entry is None or self.closing:
                    return
                try:
                    self.read_one(*entry)
                except Exception as exc:
                    self.reader_failed(entry[1], exc)
                del entry  # (its reply reaches the client: not kept while the reader waits)
        except BaseException as exc:  # the server stops, saying why
            self.error = exc
            for fn in self.on_failure:
                fn(exc)

    def reader_failed(self, reply: Callable[[dict], None], exc: Exception) -> None:
        """The reader failed on a document: its sender hears that it was refused, the operator why."""
        self.faults["reader"] += 1
        note(f"reading a document failed ({type(exc).__name__}: {exc}); serving goes on")
        reply(fb.warning("", "PARSING_FAILURE", f"document refused: the server failed to read it "
                         f"({type(exc).__name__})", self.now(), "agent"))

    def read_one(self, text, reply: Callable[[dict], None], sender) -> None:
        """Parse one document and hand its blocks on."""
        from agentsim.bml.parser import Refused, parse_document

        try:
            with paused(self.gc_pause):
                blocks = parse_document(text, strict=self.strict, name_block=self.name_block, lexicon=self.lexicon)
        except Exception as exc:  # the reader's own fault: the client hears of it, the operator too
            self.reader_failed(reply, exc)
            return
        for block in blocks:
            if isinstance(block, Refused):
                error = block.error
                reply(fb.warning(block.block_id, "PARSING_FAILURE", f"block refused: {error}", self.now(),
                                 "agent", line=error.line, column=error.column))
                continue
            speech = self.prepare(block, reply)
            if speech is not None:
                self.deliver(Prepared(block, reply, sender, speech))

    def prepare(self, block, reply: Callable[[dict], None] | None = None) -> list | None:
        """A block's speeches synthesised ahead, each ``(behaviour, utterance, bytes)`` (the backend forgets
        them: the block's speeches alone hold their audio, until the block ends); None if the block asks for
        more speech than :attr:`limits` allow: it is refused with one warning."""
        from agentsim.engines.speech import speech_text

        backend = self.backend
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
                reply(fb.warning(block.id, "PARSING_FAILURE", f"block refused: {why}", self.now(),
                                 block.character_id))
            return None
        return [(behaviour, utterance, audio_bytes(utterance)) for behaviour, utterance in made]
