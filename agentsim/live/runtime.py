"""The realizer's thread of ``agentsim serve``: :class:`LiveRealizer`, a :class:`~agentsim.realizer.Realizer` on
SimPy's real-time clock, and the one thread that touches it.

Other threads reach it through what is made to be shared: blocks come ready from the reader
(:mod:`agentsim.live.intake`) through :meth:`LiveRealizer.take`; the reader names blocks without an id with
:class:`BlockNames` (the ids the realizer holds, as this thread last published them); the audio of the blocks
waiting and playing is weighed in :class:`HeldAudio`; feedback leaves through :attr:`LiveRealizer.listeners`,
called in this thread.
"""

from __future__ import annotations

import collections
import gc
import queue
import threading
from pathlib import Path
from typing import Callable, Iterable

from agentsim.core import feedback as fb
from agentsim.core.clock import make_environment
from agentsim.core.gcpause import CollectionPause
from agentsim.live.faults import note
from agentsim.live.intake import KEEP_SENDERS, MediaDirectory, Prepared

#: How often the realizer's thread takes the blocks that were read (s): a block waits at most this long.
POLL = 0.005
#: What :meth:`LiveRealizer.warm_up` realizes: a speech with a beat on a word, a nod and a gaze shift.
WARM_UP = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="warmup"><speech id="s"><text>Hello '
           '<sync id="w"/>there.</text></speech><gesture id="g" lexeme="BEAT" stroke="s:w"/>'
           '<head id="h" lexeme="NOD" start="s:end"/><gazeShift id="z" target="user" influence="HEAD"/></bml>')
#: How many feedback items the realizer keeps (older ones are forgotten: a server runs for hours).
KEEP_FEEDBACK = 10_000
#: How many ended blocks the realizer keeps (older ones are released with their pegs: memory stays flat).
KEEP_BLOCKS = 256


class BlockNames:
    """Names for blocks without an id, ``bml1``, ``bml2``, ... in the order they are asked for (in the
    reader's thread), skipping the ids of the blocks the realizer holds as the realizer's thread last
    :meth:`published <publish>` them (blocks come to the realizer from that thread alone, which publishes
    after submitting them)."""

    def __init__(self):
        self.count = 0
        self.taken: frozenset[str] = frozenset()

    def publish(self, ids: Iterable[str]) -> None:
        """The ids of the blocks the realizer holds now (in the realizer's thread)."""
        self.taken = frozenset(ids)

    def __call__(self) -> str:
        taken = self.taken
        while True:
            self.count += 1
            name = f"bml{self.count}"
            if name not in taken:
                return name


class HeldAudio:
    """The audio synthesised for blocks, weighed in bytes: waiting for the realizer (:meth:`arrived`, in the
    reader's thread), then held by each block's speeches (:meth:`hold`) until the block ends or is refused
    (:meth:`release`, in the realizer's thread). :attr:`bytes` and :attr:`released` may be read from any
    thread."""

    def __init__(self):
        self.lock = threading.Lock()
        self.waiting = 0
        self.held = 0
        #: bytes of audio released with their blocks, since the start
        self.released = 0
        #: each block's speeches' (utterance, bytes), by block id (the realizer's thread's alone)
        self.by_block: dict[str, list] = {}

    @property
    def bytes(self) -> int:
        """Bytes of audio held for blocks that have not ended (or not yet started)."""
        with self.lock:
            return self.waiting + self.held

    def arrived(self, n: int) -> None:
        with self.lock:
            self.waiting += n

    def hold(self, block_id: str, speech: list) -> list:
        """A block's speeches ``(behaviour, utterance, bytes)`` taken from the inbox: held by its id; what is
        held, ``(utterance, bytes)``."""
        weighed = [(utterance, n) for _, utterance, n in speech]
        if weighed:
            self.by_block.setdefault(block_id, []).extend(weighed)
        n = sum(n for _, n in weighed)
        with self.lock:
            self.waiting -= n
            self.held += n
        return weighed

    def release(self, block_id: str, only: list | None = None) -> None:
        """A block ended (or was refused): its speeches' audio (``only`` these of them) is let go, wherever
        the realizer keeps it."""
        if only is None:
            let_go = self.by_block.pop(block_id, [])
        else:  # (by identity: utterances compare by their fields, audio and all)
            mine = {id(utterance) for utterance, _ in only}
            kept = self.by_block.pop(block_id, [])
            let_go = [entry for entry in kept if id(entry[0]) in mine]
            kept = [entry for entry in kept if id(entry[0]) not in mine]
            if kept:
                self.by_block[block_id] = kept
        n = 0
        for utterance, size in let_go:
            utterance.audio = None
            n += size
        with self.lock:
            self.held -= n
            self.released += n


class LiveRealizer:
    """A :class:`~agentsim.realizer.Realizer` on the real-time clock, in a thread of its own: the only thread
    that touches it.

    :meth:`take` hands it a block ready (from the reader's thread); every :attr:`poll` seconds it submits
    those that came. Every feedback goes to each function in :attr:`listeners` as ``listener(feedback,
    sender)``, ``sender`` that of the block it is about (None if unknown; in this thread: they must not
    block). ``every(period, fn)`` calls ``fn(now)`` every ``period`` simulated seconds while it runs.
    ``media``: the directory sound files that clients name are read from (:class:`~agentsim.live.intake.
    MediaDirectory`; None: none are). ``hearers``: who hears what the speech and audio engines play
    (``sound_started``, ``file_started``, ``sound_stopped``). Realizer options (``tts``, ``strict``,
    ``speech``, ``anticipators``, ``keep``, ``lexicon``) are passed on. The service holds the garbage collector
    off while its two threads read and plan blocks, with one :class:`~agentsim.core.gcpause.CollectionPause`
    they share (the realizer's ``gc_pause``, made here unless one is given; the reader is handed it).

    The audio synthesised for a block is weighed (:attr:`audio`) and released when the block ends: nothing
    but the block's own speeches holds it (the backend is not asked to remember it).
    """

    def __init__(self, poll: float = POLL, media: str | Path | None = None, hearers: Iterable = (),
                 tts=None, strict: bool = False, **realizer_options):
        from agentsim.realizer import Realizer

        if tts is None:
            from speech_timing.choice import default_backend

            tts = default_backend()
        #: the speech backend (the reader synthesises with it too) and whether BML 1.0 alone is read
        self.backend, self.strict = tts, strict
        self.env = make_environment(realtime=True)
        realizer_options.setdefault("keep", KEEP_BLOCKS)
        realizer_options.setdefault("gc_pause", CollectionPause())
        self.realizer = Realizer(env=self.env, tts=tts, strict=strict, locate_audio=MediaDirectory(media),
                                 keep_feedback=KEEP_FEEDBACK, **realizer_options)
        for hearer in hearers:
            self.realizer.speech.listeners.append(hearer)
            self.realizer.audio.listeners.append(hearer)
        self.realizer.feedback.listen(self.emit)
        self.poll = poll
        #: blocks read and ready, from the reader; names for those without an id; their audio, weighed
        self.inbox: queue.SimpleQueue[Prepared] = queue.SimpleQueue()
        self.names = BlockNames()
        self.audio = HeldAudio()
        #: who sent each block (by block id, the latest KEEP_SENDERS)
        self.senders: collections.OrderedDict[str, object] = collections.OrderedDict()
        self.listeners: list[Callable[[dict, object], None]] = []
        self.periodic: list[tuple[float, Callable[[float], None]]] = []
        #: faults gone on after, by kind; blocks refused because another client's block of the same id had
        #: not ended
        self.faults: collections.Counter[str] = collections.Counter()
        self.refused_taken = 0
        #: what stopped the thread (None while it runs); each function in :attr:`on_failure` is called with
        #: it, in this thread
        self.error: BaseException | None = None
        self.on_failure: list[Callable[[BaseException], None]] = []
        self.closing = False
        self.started = threading.Event()
        self.thread = threading.Thread(target=self.run, name="agentsim-realizer", daemon=True)

    # ------------------------------------------------------------------------------------------- shared
    def take(self, prepared: Prepared) -> None:
        """A block read and ready (from the reader's thread): submitted at the next poll."""
        self.audio.arrived(prepared.weight)
        self.inbox.put(prepared)

    def now(self) -> float:
        """The realizer's clock (simulated seconds, as its feedback says; read from any thread)."""
        return self.env.now

    def wall_time(self, t: float) -> float:
        """The ``time.monotonic()`` time at which simulated time ``t`` happens."""
        return self.env.real_start + t * self.env.factor

    @property
    def audio_bytes(self) -> int:
        """Bytes of synthesised audio held for blocks that have not ended (or not yet started)."""
        return self.audio.bytes

    @property
    def audio_released(self) -> int:
        """Bytes of audio released with their blocks, since the start."""
        return self.audio.released

    # ------------------------------------------------------------------------------------------- the thread
    def start(self) -> None:
        """Start the clock (simulated time 0 is now) and the realizer's thread."""
        self.warm_up()
        self.thread.start()
        self.started.wait(5.0)

    def warm_up(self) -> None:
        """Realize a small block once on a simulated clock with the same speech backend, before the real clock
        starts: the first block a client sends then finds every module imported and the synthesiser running
        (without this the first blocks' feedback came up to 170 ms late)."""
        from agentsim.realizer import Realizer

        try:
            rehearsal = Realizer(tts=self.backend, strict=self.strict)
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
        if self.thread.is_alive():
            self.thread.join(timeout)

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
        """Submit the blocks that were read, every :attr:`poll` seconds; then publish the ids taken."""
        while not self.closing:
            submitted = False
            while True:
                try:
                    prepared = self.inbox.get_nowait()
                except queue.Empty:
                    break
                self.submit(prepared)
                submitted = True
                del prepared  # (its reply reaches the client: not kept while the realizer waits)
            if submitted:
                self.names.publish(self.block_ids())
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

    # ------------------------------------------------------------------------------------------- blocks
    def running(self, block_id: str) -> bool:
        """Whether a block of this id has not ended."""
        return self.realizer.scheduler.book.is_open(block_id)

    def block_ids(self) -> list[str]:
        """The ids of the blocks the realizer holds, those that ended and are kept too."""
        return [run.id for run in self.realizer.scheduler.book.all_runs]

    def submit(self, prepared: Prepared) -> None:
        """Submit a block that was read. A block whose id is that of another client's block that has not
        ended is refused, to its sender alone: the other block's feedback still goes to whom it went to."""
        block, reply, sender = prepared.block, prepared.reply, prepared.sender
        weighed = self.audio.hold(block.id, prepared.speech)
        if self.running(block.id) and block.id in self.senders and self.senders[block.id] != sender:
            self.audio.release(block.id, weighed)
            self.refused_taken += 1
            reply(fb.warning(block.id, "PARSING_FAILURE", f"block refused: another client's block {block.id!r} "
                             "has not ended; give yours an id of its own", self.env.now, block.character_id))
            return
        self.senders[block.id] = sender
        self.senders.move_to_end(block.id)
        while len(self.senders) > KEEP_SENDERS:
            self.senders.popitem(last=False)
        planner = self.realizer.speech.planner
        for behaviour, utterance, _ in prepared.speech:
            planner.set_utterance(behaviour, utterance)
        try:
            run = self.realizer.submit(block)
        except Exception as exc:
            self.audio.release(block.id, weighed)
            reply(fb.warning(block.id, "IMPOSSIBLE_TO_SCHEDULE", f"block refused: the realizer failed to plan it "
                             f"({type(exc).__name__}: {exc})", self.env.now, block.character_id))
            return
        if run is None:  # refused (with a warning): what was synthesised for it goes
            self.audio.release(block.id, weighed)

    def emit(self, item: dict) -> None:
        block_id = str(item.get("id", "")).split(":", 1)[0]
        if item.get("type") == "blockProgress" and item.get("id") == f"{block_id}:end":
            self.audio.release(block_id)
        sender = self.senders.get(block_id)
        for listener in self.listeners:
            listener(item, sender)
