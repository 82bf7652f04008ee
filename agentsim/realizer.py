"""The realizer: clock, PegBoard, engines, scheduler, anticipators and feedback, put together."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterable

import simpy

from agentsim.animation.lexicon import Lexicon, as_lexicon
from agentsim.bml.parser import Refused, parse_document
from agentsim.core.block import Behaviour, Block
from agentsim.core.clock import make_environment, run_until
from agentsim.core.feedback import FeedbackLog
from agentsim.core.gcpause import CollectionPause, paused
from agentsim.core.pegboard import PegBoard
from agentsim.core.recording import Recording
from agentsim.core.scheduler import FRAME, Scheduler
from agentsim.core.timed import BlockRun
from agentsim.engines.animation import AnimationEngine
from agentsim.engines.audio import AudioEngine, resolve_audio
from agentsim.engines.control import ControlEngine
from agentsim.engines.expression import ExpressionEngine
from agentsim.engines.physics import ControllerEngine
from agentsim.engines.speech import SpeechConfig, SpeechEngine
from agentsim.engines.wait import WaitEngine
from speech_timing.backend import TTSBackend


class Realizer:
    """Turns BML blocks into timed behaviour on one SimPy clock and reports BML feedback.

    Parameters
    ----------
    env : simpy.Environment, optional
        The clock; by default a new one (simulated, or real time if ``realtime``).
    realtime : bool
        Run in real time (``simpy.rt.RealtimeEnvironment``) instead of as fast as possible.
    tts : TTSBackend, optional
        Text-to-speech backend for speech timing; by default espeak-ng when it is installed, else the
        deterministic built-in one (with a warning), as every command does
        (:func:`speech_timing.choice.default_backend`).
    anticipators : iterable of Anticipator
        Anticipators whose pegs BML may refer to as ``anticipators:<id>:<sync>``.
    speech : SpeechConfig, optional
        How speech audio and its progress events meet the animation (animator-time strategy, event
        delivery, what the planner knows); by default the audio plays exactly as planned.
    prediction_tolerance : float
        A behaviour is predicted again when one of its sync points moved by more than this (seconds).
    keep : int, optional
        How many ended blocks to keep, with what was recorded of them (None, the default: all, so that
        :meth:`recording` holds the whole run). A realizer that runs for days (the live service) keeps a few
        hundred: older blocks are released with their pegs, and the feedback log keeps the last ``100 * keep``
        items (its listeners still get everything).
    strict : bool
        Read only BML 1.0 (one block a document). By default BML as other realizers write it is read too,
        each block's adaptations said in one ``NONSTANDARD_BML`` warning; blocks without an id are named
        ``bml1``, ``bml2``, ... in the order they come, skipping ids already used.
    lexicon : Lexicon, str or Path, optional
        What the lexemes of gestures, faces, FACS units, postures and visemes play: a
        :class:`~agentsim.animation.lexicon.Lexicon`, or the path of a lexicon file (the built-in lexicon
        extended with it, its entries winning); by default the built-in one. It is this realizer's alone: the
        BML reader, the animation engine and the poses of its recording use it.
    gc_pause : CollectionPause, optional
        Hold the garbage collector off while documents are read and planned, as this
        :class:`~agentsim.core.gcpause.CollectionPause` does (the command line and the live service pass
        theirs); by default the collector is left alone.
    locate_audio : callable, optional
        Where the file of a ``<bmlt:audiofile>`` behaviour is (given the behaviour; a ScheduleError if it may
        not be read); by default beside its BML document, else in the working directory. The live service
        confines it to one directory.
    keep_feedback : int, optional
        How many feedback items the log keeps (by default ``100 * keep``, or all).
    """

    def __init__(self, env: simpy.Environment | None = None, realtime: bool = False,
                 tts: TTSBackend | None = None, anticipators: Iterable = (), speech: SpeechConfig | None = None,
                 prediction_tolerance: float = FRAME, strict: bool = False, keep: int | None = None,
                 lexicon: Lexicon | str | Path | None = None, gc_pause: CollectionPause | None = None, *,
                 locate_audio: Callable[[Behaviour], Path] | None = None, keep_feedback: int | None = None):
        self.strict = strict
        self.lexicon = as_lexicon(lexicon)
        self.gc_pause = gc_pause
        self._unnamed = 0
        self.env = env if env is not None else make_environment(realtime)
        self.board = PegBoard()
        if keep_feedback is None and keep is not None:
            keep_feedback = 100 * keep
        self.feedback = FeedbackLog(keep=keep_feedback)
        if tts is None:
            from speech_timing.choice import default_backend
            tts = default_backend()
        self.scheduler = Scheduler.build(self.env, self.board, self.feedback, prediction_tolerance, keep=keep)
        context = self.scheduler.context
        self.speech = SpeechEngine(context, tts, speech)
        self.animation = AnimationEngine(context, self.lexicon)
        self.wait = WaitEngine(context)
        self.control = ControlEngine(context)
        self.audio = AudioEngine(context, locate_audio or resolve_audio)
        self.physics = ControllerEngine(context)
        self.expression = ExpressionEngine(context)
        self.engines = [self.speech, self.animation, self.wait, self.control, self.audio, self.physics,
                        self.expression]
        for engine in self.engines:
            self.scheduler.add_engine(engine)
        self._submissions: list[simpy.Event] = []
        for anticipator in anticipators:
            self.add_anticipator(anticipator)

    def add_anticipator(self, anticipator) -> None:
        anticipator.attach(self.env, self.board)
        self.scheduler.add_anticipator(anticipator)

    def submit(self, bml: str | bytes | Block, source: str = "") -> BlockRun | None:
        """Submit a BML document now (XML text or a parsed block). Returns the run of its block (of its last
        block if it holds several), or None if that was refused.

        A block that cannot be read is refused with one PARSING_FAILURE warning (with line and column).
        """
        runs = self.submit_document(bml, source)
        return runs[-1] if runs else None

    def submit_document(self, bml: str | bytes | Block, source: str = "") -> list[BlockRun | None]:
        """Submit every block of a BML document now, in order. Returns their runs (None where refused)."""
        with self._paused():
            if isinstance(bml, Block):
                return [self._submit_block(bml, source)]
            runs: list[BlockRun | None] = []
            for block in self.read_document(bml):
                if isinstance(block, Refused):
                    where = f" in {source}" if source else ""
                    error = block.error
                    self.scheduler.reporter.warn(block.block_id, "PARSING_FAILURE", f"block refused{where}: {error}",
                                                 "agent", line=error.line, column=error.column)
                    runs.append(None)
                else:
                    runs.append(self._submit_block(block, source))
            return runs

    def read_document(self, bml: str | bytes) -> list[Block | Refused]:
        """The blocks of a BML document as this realizer reads them (strictly or not, with its lexicon, blocks
        without an id named by :meth:`name_block`), each parsed or refused; nothing is submitted."""
        with self._paused():
            return parse_document(bml, strict=self.strict, name_block=self.name_block, lexicon=self.lexicon)

    def _paused(self):
        """The garbage collector held off as :attr:`gc_pause` does, if the realizer was given one."""
        return paused(self.gc_pause)

    def name_block(self) -> str:
        """The next free ``bml<n>`` for a block without id."""
        used = {run.id for run in self.scheduler.book.all_runs}
        while True:
            self._unnamed += 1
            name = f"bml{self._unnamed}"
            if name not in used:
                return name

    def _submit_block(self, block: Block, source: str) -> BlockRun | None:
        if source:
            block.source = source
            for behaviour in block.behaviours:
                behaviour.source = source
        return self.scheduler.submit(block, source)

    def interrupt(self, block_id: str, include: Iterable[str] = (), exclude: Iterable[str] = ()) -> bool:
        """Interrupt a block now, gracefully (speech stops, gestures retract), or only the behaviours in
        ``include``, or all but those in ``exclude``. False, with a warning, if there is no such block."""
        return self.scheduler.context.blocks.interrupt(block_id, tuple(include), tuple(exclude))

    def activate(self, block_id: str) -> bool:
        """Start a preplanned block now. False, with a warning, if there is no such pending block."""
        return self.scheduler.activate(block_id)

    def submit_at(self, time: float, bml: str | bytes | Block, source: str = "") -> simpy.Process:
        """Submit a BML document at simulated time ``time`` (seconds)."""

        def later():
            delay = time - self.env.now
            if delay > 0:
                yield self.env.timeout(delay)
            return self.submit(bml, source)

        process = self.env.process(later())
        if len(self._submissions) > 64:  # those done already are not waited for
            self._submissions = [p for p in self._submissions if not p.triggered]
        self._submissions.append(process)
        return process

    def recording(self) -> Recording:
        """What the run has done so far, as values: behaviours with their actual key times, blocks, drops,
        anticipator pegs, feedback and the speech as heard."""
        return replace(self.scheduler.recording(), speech=tuple(self.speech.heard()),
                       audio=tuple(self.audio.played), lexicon=self.lexicon)

    def all_ended(self) -> simpy.Process:
        """An event that happens when every block submitted (or due to be submitted) so far has ended,
        and every block submitted meanwhile too."""
        return self.env.process(self._all_done())

    def _all_done(self):
        yield simpy.AllOf(self.env, self._submissions)
        while True:
            pending = [r.ended for r in self.scheduler.book.all_runs if not r.ended.triggered and not r.dormant]
            if not pending:
                return
            yield simpy.AllOf(self.env, pending)

    def run(self, until: float | None = None, on_time=None) -> None:
        """Run until every submitted block has ended (preplanned blocks nothing activated stay pending), or
        until simulated time ``until``. ``on_time``: called with the simulated time every simulated second
        (for a progress bar; the run is the same without it)."""
        done = self.all_ended()
        if until is not None:
            done = done | self.env.timeout(max(0.0, until - self.env.now))
        try:
            run_until(self.env, done, on_time)
        except RuntimeError as exc:
            if "No scheduled events left" not in str(exc):
                raise
            for run in self.scheduler.book.runs:  # nothing can happen any more: say what is stuck
                self.scheduler.reporter.warn(run.id, "IMPOSSIBLE_TO_SCHEDULE", f"block {run.id} is still "
                                             f"{run.state} and nothing left in the run can move it on",
                                             run.block.character_id)
