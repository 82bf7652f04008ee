"""The scheduler: BML blocks from submission to end, and the feedback of what they do.

It has the :class:`~agentsim.core.solver.BlockSolver` tie each block's behaviours to time pegs, hands the
timed behaviours to the engines' planners and starts the block when its composition allows (MERGE: now;
APPEND: when every earlier block has ended; REPLACE: after ending every earlier block).

The :class:`Scheduler` keeps the life cycle of blocks (submit, start, activate, interrupt, end, cut, drop,
release) and runs the re-timing pass at each instant pegs moved; it owns the engines and anticipators it was
given and the context the engines are made with, and nothing else. Its parts are each handed what they talk
to when they are made (of the composer, the interrupter is handed its ``wake`` alone); none calls back into
the scheduler, nor round the parts to one that calls it:

* the :class:`~agentsim.core.book.BlockBook`: the runs, the drops, the structure version;
* the :class:`~agentsim.core.reporter.Reporter`: every feedback sent;
* the :class:`~agentsim.core.composition.Composer`: how blocks wait for one another;
* the :class:`~agentsim.core.retiming.Retimer`: what is to be re-timed, validity, predictions;
* the :class:`~agentsim.core.interruption.Interrupter`: graceful interruption.

:meth:`Scheduler.build` makes a scheduler with the standard parts.
"""

from __future__ import annotations

import functools
from typing import Iterable

import simpy

from agentsim.core import feedback as fb
from agentsim.core.block import Block
from agentsim.core.book import BlockBook
from agentsim.core.composition import Composer
from agentsim.core.engine import Engine, EngineContext
from agentsim.errors import ScheduleError
from agentsim.core.interruption import Interrupter
from agentsim.core.pegboard import PegBoard, TimePeg
from agentsim.core.recording import BlockRecord, DropRecord, Recording, record_behaviours
from agentsim.core.reporter import Reporter
from agentsim.core.retiming import FRAME, Dependants, Retimer
from agentsim.core.solver import BlockSolver
from agentsim.core.timed import ACTIVE, OPEN, PENDING, REFUSED, RUNNING, BlockRun, BlockState, SyncPeg, TimedBehaviour

__all__ = ["FRAME", "BlockControl", "Scheduler"]


class BlockControl:
    """What behaviours that act on blocks (BMLA interrupt, activate, parameter changes) may ask the scheduler
    (the engines' view of it: it owns nothing but the scheduler it asks)."""

    def __init__(self, scheduler: "Scheduler"):
        self.scheduler = scheduler

    def state(self, block_id: str) -> BlockState | None:
        """``pending``, ``running``, ``ended`` or None (no such block)."""
        run = self.scheduler.book.find(block_id)
        return None if run is None else run.state

    def behaviour(self, block_id: str, behaviour_id: str) -> TimedBehaviour | None:
        run = self.scheduler.book.find(block_id)
        return None if run is None else next((t for t in run.timed if t.id == behaviour_id), None)

    def interrupt(self, block_id: str, include=(), exclude=(), by: str = "") -> bool:
        """Interrupt a block now; False, with a warning, if there is none that runs or waits."""
        run = self.scheduler.book.find(block_id)
        if run is None:
            self.scheduler.reporter.warn(by or block_id, "NO_SUCH_TARGET", f"cannot interrupt block {block_id!r}: "
                                         "there is no such block", "agent")
            return False
        self.scheduler.interrupt(run, include, exclude, by)
        return True

    def activate(self, block_id: str, by: str = "", what: str = "") -> bool:
        return self.scheduler.activate(block_id, by)

    def warn(self, target: str, kind: str, description: str, modified=()) -> None:
        self.scheduler.reporter.warn(target, kind, description, "agent", modified)


class Scheduler:
    """Schedules BML blocks onto engines and reports what happens as feedback.

    Parameters
    ----------
    env : simpy.Environment
        The clock.
    board : PegBoard
        The shared time pegs.
    reporter, book, composer, retimer, interrupter
        Its parts (see the module's docstring); :meth:`build` makes the standard ones.
    """

    def __init__(self, env: simpy.Environment, board: PegBoard, reporter: Reporter, book: BlockBook,
                 composer: Composer, retimer: Retimer, interrupter: Interrupter):
        self.env = env
        self.board = board
        self.reporter = reporter
        self.book = book
        self.composer = composer
        self.retimer = retimer
        self.interrupter = interrupter
        self.engines: dict[str, Engine] = {}  # behaviour type -> engine
        self.engine_list: list[Engine] = []
        self.anticipators: dict[str, object] = {}
        board.on_move(self.pegs_moved)
        self.context = EngineContext(env=env, board=board, sync_passed=self.sync_passed,
                                     pegs_moved=self.pegs_moved, dependants_of=retimer.dependants_of,
                                     blocks=BlockControl(self))

    @classmethod
    def build(cls, env: simpy.Environment, board: PegBoard, log: fb.FeedbackLog,
              prediction_tolerance: float = FRAME, keep: int | None = None) -> "Scheduler":
        """A scheduler with the standard parts.

        ``log``: where feedback goes; ``prediction_tolerance``: a behaviour is predicted again when one of its
        sync points moved by more than this (seconds); ``keep``: how many ended blocks are kept (None: all).
        """
        reporter = Reporter(env, log)
        book = BlockBook(keep)
        composer = Composer(env, book, reporter)
        return cls(env, board, reporter, book, composer, Retimer(env, book, reporter, prediction_tolerance),
                   Interrupter(env, board, book, reporter, composer.wake))

    def add_engine(self, engine: Engine) -> None:
        """Let ``engine`` realize the behaviour types its planner names (it was made with :attr:`context`)."""
        self.engine_list.append(engine)
        for behaviour_type in engine.planner.behaviour_types:
            self.engines[behaviour_type] = engine

    # ------------------------------------------------------------------ anticipators
    def add_anticipator(self, anticipator) -> None:
        self.anticipators[anticipator.id] = anticipator
        anticipator.report = self.reporter.anticipator_fault

    def anticipator_peg(self, anticipator_id: str, sync_id: str) -> TimePeg:
        """The anticipator peg BML calls ``anticipators:<id>:<sync>``; ScheduleError if there is none."""
        anticipator = self.anticipators.get(anticipator_id)
        if anticipator is None:
            known = ", ".join(sorted(self.anticipators)) or "none"
            raise ScheduleError(f"no anticipator {anticipator_id!r} (registered: {known})")
        peg = anticipator.peg(sync_id)
        if peg is None:
            raise ScheduleError(f"anticipator {anticipator_id!r} has no sync point {sync_id!r}")
        return peg

    # ------------------------------------------------------------------ submission
    def submit(self, block: Block, source: str = "") -> BlockRun | None:
        """Submit one parsed block now. Returns its run, or None if it was refused."""
        return self._submit(block, source)

    def _submit(self, block: Block, source: str) -> BlockRun | None:
        book, warn = self.book, self.reporter.warn
        where = f" in {source}" if source else ""
        character = block.character_id
        for w in block.warnings:
            # (an adaptation warning is about the block, and lists every behaviour it touched)
            one = w.behaviours and w.warning_type != "NONSTANDARD_BML"
            target = f"{block.id}:{w.behaviours[0]}" if one else block.id
            warn(target, w.warning_type, w.description, character, w.behaviours, w.line, w.column, w.details)
        if book.is_open(block.id):
            warn(block.id, "PARSING_FAILURE", f"block refused{where}: a block with id {block.id!r} is already "
                 "pending or running", character)
            return None
        if block.composition == "REPLACE":
            for run in list(book.runs):
                self.cut(run, block.id)
        now = self.env.now
        run = BlockRun(block, self.board.new_block_peg(block.id, now), self.env.event())
        self.composer.link(run)
        run.block_peg.set(self.composer.predicted_start(run))
        solver = BlockSolver(block, run, self.board, self.engines, self.anticipator_peg, book.live_behaviours)
        run.timed = solver.solve()
        for issue in solver.issues:
            ids = issue.behaviours if not solver.failed else []
            target = f"{block.id}:{ids[0]}" if len(ids) == 1 else block.id
            where = block.behaviour(ids[0]) if len(ids) == 1 else None
            warn(target, issue.warning_type, issue.description, character, issue.behaviours,
                 where.line if where else None, where.column if where else None)
        book.enter(run)
        book.add_drops(DropRecord(block.id, behaviour_id, now, kind, reason)
                       for behaviour_id, (kind, reason) in solver.dropped.items())
        if solver.failed:
            run.refuse()
            self.retire(run)
            return run
        for timed in list(run.timed):
            reason = timed.engine.planner.admit(timed)
            if reason is not None:
                run.timed.remove(timed)
                timed.drop()
                book.add_drop(DropRecord(block.id, timed.id, now, "NO_SUCH_TARGET", reason))
                warn(f"{block.id}:{timed.id}", "NO_SUCH_TARGET", f"{timed.id}: {reason}; behaviour dropped",
                     character, [timed.id], timed.behaviour.line, timed.behaviour.column)
        self.board.forget_block(block.id)
        times = solver.times_now()  # (what the solver computed last: still the times if no peg moved since)
        for timed in run.timed:
            known = times.get(timed)
            timed.planned_start = known[0] if known is not None else timed.start
            timed.engine.planner.add(timed)
            self.board.register_behaviour(block.id, timed.id, timed.sync_ids, functools.partial(SyncPeg, timed))
        book.changed()
        book.open(run)
        if run.chunk_after:
            self.composer.coarticulate(run)
        # (the solver's times, unless a peg moved since, or earlier gestures were keyed anew: then made again)
        self.retimer.predict(run, timed_now=solver.times_now() if not run.chunk_after else None, force=True)
        if self.waits(run) is None:
            self.start(run)
        else:
            self.env.process(self.await_start(run))
        return run

    # ------------------------------------------------------------------ block life
    def waits(self, run: BlockRun) -> list[simpy.Event] | None:
        """What a pending block still waits for (events to wait on), or None if it may start now.

        A block that names blocks to interrupt interrupts them the first time it may start, and then waits
        for them to end.
        """
        waiting = self.composer.waits(run)
        if waiting is not None or not run.block.interrupt or run.interrupting:
            return waiting
        run.interrupting = True
        for block_id in run.block.interrupt:
            target = self.book.find(block_id)
            if target is None:
                self.reporter.warn(run.id, "NO_SUCH_TARGET", f"interrupt: there is no block {block_id!r}; ignored",
                                   run.block.character_id)
            elif target.state in OPEN:
                self.interrupt(target, by=run.id)
                run.after.append(target)
        return self.waits(run)

    def await_start(self, run: BlockRun):
        """The process of a pending block: wait until it may start, then start it now."""
        while run.state is PENDING:
            waiting = self.waits(run)
            if waiting is None:
                # the time it waited for exactly (the clock reaches it only up to rounding), else now
                start = self.composer.awaited(run)
                if start is None or not abs(start - self.env.now) < 1e-6:
                    start = self.env.now
                moved = start != run.block_peg.time
                if moved:
                    with self.board.quiet():
                        run.block_peg.set(start)
                self.start(run)
                if moved:
                    self.retime()
                return
            yield simpy.AnyOf(self.env, waiting)

    def start(self, run: BlockRun) -> None:
        run.start()
        self.reporter.block_progress(run, "start", run.block_peg.time)
        by_engine: dict[Engine, list[TimedBehaviour]] = {}  # (in the order each engine is first met)
        for timed in run.live():
            by_engine.setdefault(timed.engine, []).append(timed)
        for engine, behaviours in by_engine.items():
            engine.activate_all(behaviours)
        for block_id in run.block.on_start:
            self.activate(block_id, by=run.id, what="onStart: ")
        self.end_if_done(run, run.block_peg.time)

    def activate(self, block_id: str, by: str = "", what: str = "") -> bool:
        """Start a preplanned block now (or as soon as what it waits for allows). False, with a warning, if
        there is no such pending block."""
        target = self.book.find(block_id)
        who = by or block_id
        if target is None or target.state is not PENDING:
            state = "there is no such block" if target is None else f"it is {target.state}"
            self.reporter.warn(who, "NO_SUCH_TARGET", f"{what}cannot activate block {block_id!r}: {state}", "agent")
            return False
        target.activated = True
        with self.board.quiet():
            target.block_peg.set(self.composer.predicted_start(target))
        self.retime()
        if target.state is PENDING and target.wake is None:  # planned, never waited: start it now
            self.env.process(self.await_start(target))
        self.composer.wake(target)
        return True

    def interrupt(self, run: BlockRun, include=(), exclude=(), by: str = "") -> None:
        """Interrupt a block now, gracefully (see :meth:`Interrupter.interrupt`), and re-time what moved."""
        if self.interrupter.interrupt(run, include, exclude, by):
            self.pegs_moved()

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        """Sync point ``index`` of ``timed`` was passed at ``time``: feedback, and the end of what is done."""
        last = index == len(timed.sync_ids) - 1
        self.reporter.sync_point(timed, index, time, last and timed.interrupted)
        if last:
            timed.finish()
            timed.engine.planner.remove(timed)
            self.end_if_done(timed.run, time)

    def end_if_done(self, run: BlockRun, time: float) -> None:
        if run.state is RUNNING and not run.live_count:  # (a count: ends come one by one, N of them)
            self.end(run, time)

    def end(self, run: BlockRun, time: float) -> None:
        run.end(time)
        self.reporter.block_progress(run, "end", time, run.interrupted)
        self.book.close(run)
        run.ended.succeed()  # (after the end was said: what is told of it sees the run not yet over)
        self.retire(run)

    def retire(self, run: BlockRun) -> None:
        """A run is over (ended or refused): with the book's ``keep``, release the oldest ones beyond it."""
        gone = self.book.retire(run)
        if gone:
            self.release(gone)

    #: A passed anticipator peg is forgotten this long (s) after its time, when blocks are released.
    PEG_MEMORY = 60.0

    def release(self, runs: list[BlockRun]) -> None:
        """Forget ended runs: they leave the book and the records, their sync points can no longer be
        referred to by name (a reference to them is a warning, as to a block that never was), their block pegs
        and registrations go, and so do the engines' records of them and the anticipators' passed pegs.
        Whatever still holds one of their pegs (a later block tied to them) keeps it."""
        released = self.book.release(runs)
        for run in runs:
            if run.id in released:  # no later block of that id has taken its place on the board
                self.board.forget_block(run.id)
                if self.board.block_pegs.get(run.id) is run.block_peg:
                    del self.board.block_pegs[run.id]
        for engine in self.engine_list:
            engine.forget(released)
        before = self.env.now - self.PEG_MEMORY
        for anticipator in self.anticipators.values():
            forget = getattr(anticipator, "forget_passed", None)
            if forget is not None:
                forget(before)

    def cut(self, run: BlockRun, by: str = "") -> None:
        """End a block now (composition REPLACE): its behaviours stop where they are.

        Every behaviour cut is said in an INTERRUPTED warning; one that had started also gets its end, now,
        with ``"status": "INTERRUPTED"``, as the block's end has if it cut anything.
        """
        now = self.env.now
        character = run.block.character_id
        cause = f"its block was replaced by {by}" if by else "its block was replaced"
        if run.state is PENDING:
            self.reporter.block_progress(run, "start", now)
            run.start()
        for timed in run.live():
            started = timed.state is ACTIVE and timed.passed[0] is not None
            timed.drop(now)
            if started:  # what it makes (its sound) stops here too
                timed.engine.stopped(timed, now)
            timed.engine.remove(timed)
            self.book.add_drop(DropRecord(run.id, timed.id, now, "INTERRUPTED", cause))
            self.reporter.warn(f"{run.id}:{timed.id}", "INTERRUPTED", f"{timed.id}: {cause}; "
                               + ("stopped at once" if started else "it will not start"), character, [timed.id])
            if started:
                last = len(timed.sync_ids) - 1
                timed.passed[last] = now
                self.reporter.sync_point(timed, last, now, interrupted=True)
            run.interrupted = True
        self.end(run, now)

    def drop(self, timed: TimedBehaviour, reason: str) -> None:
        now = self.env.now
        timed.drop(now)
        timed.engine.remove(timed)
        run = timed.run
        self.book.add_drop(DropRecord(run.id, timed.id, now, "IMPOSSIBLE_TO_SCHEDULE", reason))
        self.reporter.warn(f"{run.id}:{timed.id}", "IMPOSSIBLE_TO_SCHEDULE", f"{timed.id}: {reason}; behaviour "
                           "dropped", run.block.character_id, [timed.id])

    # ------------------------------------------------------------------ re-timing
    def pegs_moved(self, pegs: Iterable[TimePeg] | TimePeg | Dependants | None = None,
                   horizon: float | None = None) -> None:
        """Pegs moved (set, shifted, or their computed times changed): re-time what hangs from them.

        The one entry point for every peg movement. Without ``horizon`` every live behaviour is looked at;
        with ``pegs`` given as :class:`~agentsim.core.retiming.Dependants` and a ``horizon`` (seconds), only
        those that start within it. The re-timing itself happens once per instant, after everything that
        moved pegs then.
        """
        self.board.invalidate_times()  # (every time computed before the move is stale)
        if self.retimer.moved(pegs, horizon):
            self.env.process(self._retime_soon())

    def _retime_soon(self):
        yield self.env.timeout(0)
        behaviours, until = self.retimer.due()
        self.retime(behaviours, until)

    def retime(self, behaviours: list[TimedBehaviour] | None = None, until: float | None = None) -> None:
        """Pegs moved: drop behaviours that became invalid, update predictions, wake the players.

        ``behaviours``: the ones affected (default: every live behaviour, and the start of every block
        waiting to be appended). ``until``: only their sync points due by then (global seconds) are
        predicted again; later ones are when they come nearer.
        """
        composer, retimer = self.composer, self.retimer
        if behaviours is None:
            with self.board.quiet():
                for run in self.book.runs:
                    if composer.appended(run):
                        run.block_peg.set(composer.predicted_start(run))
            judged = retimer.retime([t for engine in self.engine_list for t in engine.planner.plan])
        else:
            judged = retimer.retime(behaviours)
        for timed, reason in judged.invalid:
            self.drop(timed, f"after re-timing: {reason}")
        now = self.env.now
        if behaviours is None:
            for run in list(self.book.runs):
                retimer.predict(run, timed_now=judged.times)
                self.end_if_done(run, now)
            for engine in self.engine_list:
                engine.plan.kick()
            return
        retimer.predict_moved(behaviours, until, judged.times)
        for run in dict.fromkeys(timed.run for timed, _ in judged.invalid):
            self.end_if_done(run, now)
        retimer.kick(behaviours)

    def recording(self) -> Recording:
        """What the run has done so far, as values (see :class:`~agentsim.core.recording.Recording`)."""
        all_runs = self.book.all_runs
        runs = [r for r in all_runs if r.state is not REFUSED]
        blocks = tuple(BlockRecord(r.id, r.block.character_id, r.block.composition, r.state, r.block_peg.time
                                   if r.state is not PENDING else None, r.ended_at) for r in all_runs)
        pegs = {name: {sync: peg.time for sync, peg in a.pegs.items()} for name, a in self.anticipators.items()}
        return Recording(behaviours=tuple(record_behaviours(t for r in runs for t in r.timed)), blocks=blocks,
                         drops=tuple(self.book.drops), anticipators=pegs, feedback=tuple(self.reporter.log.items),
                         now=self.env.now)
