"""The scheduler: BML blocks from submission to end, and the feedback of what they do.

It has the :class:`~agentsim.core.solver.BlockSolver` tie each block's behaviours to time pegs, hands the
timed behaviours to the engines' planners and starts the block when its composition allows (MERGE: now;
APPEND: when every earlier block has ended; REPLACE: after ending every earlier block).

How blocks wait for one another is :mod:`~agentsim.core.composition`'s; every peg movement goes through
the one re-timing path of :mod:`~agentsim.core.retiming`; graceful interruption is
:mod:`~agentsim.core.interruption`'s. The :class:`Scheduler` joins the three.
"""

from __future__ import annotations

import functools

import simpy

from agentsim.core import feedback as fb
from agentsim.core.block import Block
from agentsim.core.composition import Composition
from agentsim.core.engine import Engine, EngineContext
from agentsim.errors import ScheduleError
from agentsim.core.interruption import Interruption
from agentsim.core.pegboard import PegBoard, TimePeg
from agentsim.core.recording import BlockRecord, DropRecord, Recording, record_behaviours
from agentsim.core.retiming import FRAME, Retiming
from agentsim.core.solver import BlockSolver
from agentsim.core.timed import BlockRun, SyncPeg, TimedBehaviour

__all__ = ["FRAME", "BlockControl", "Scheduler"]


class BlockControl:
    """What behaviours that act on blocks (BMLA interrupt, activate, parameter changes) may ask the scheduler."""

    def __init__(self, scheduler: "Scheduler"):
        self.scheduler = scheduler

    def state(self, block_id: str) -> str | None:
        """``pending``, ``running``, ``ended`` or None (no such block)."""
        run = self.scheduler.find_run(block_id)
        return None if run is None else run.state

    def behaviour(self, block_id: str, behaviour_id: str) -> TimedBehaviour | None:
        run = self.scheduler.find_run(block_id)
        return None if run is None else next((t for t in run.timed if t.id == behaviour_id), None)

    def interrupt(self, block_id: str, include=(), exclude=(), by: str = "") -> bool:
        """Interrupt a block now; False, with a warning, if there is none that runs or waits."""
        run = self.scheduler.find_run(block_id)
        if run is None:
            self.scheduler.warn(by or block_id, "NO_SUCH_TARGET", f"cannot interrupt block {block_id!r}: there "
                                "is no such block", "agent")
            return False
        self.scheduler.interrupt(run, include, exclude, by)
        return True

    def activate(self, block_id: str, by: str = "", what: str = "") -> bool:
        return self.scheduler.activate(block_id, by)

    def warn(self, target: str, kind: str, description: str, modified=()) -> None:
        self.scheduler.warn(target, kind, description, "agent", modified)


class Scheduler(Composition, Interruption, Retiming):
    """Schedules BML blocks onto engines and reports what happens as feedback.

    Parameters
    ----------
    env : simpy.Environment
        The clock.
    board : PegBoard
        The shared time pegs.
    log : FeedbackLog
        Where feedback goes.
    prediction_tolerance : float
        A behaviour is predicted again when one of its sync points moved by more than this (seconds).
    """

    def __init__(self, env: simpy.Environment, board: PegBoard, log: fb.FeedbackLog,
                 prediction_tolerance: float = FRAME, keep: int | None = None):
        self.env = env
        self.board = board
        self.log = log
        self.prediction_tolerance = prediction_tolerance
        self.engines: dict[str, Engine] = {}  # behaviour type -> engine
        self.engine_list: list[Engine] = []
        self.anticipators: dict[str, object] = {}
        self.fault_counts: dict[str, int] = {}  # anticipator id -> faults refused
        self.runs: list[BlockRun] = []  # not yet ended, in submission order
        self.all_runs: list[BlockRun] = []
        self.drops: list[DropRecord] = []
        #: how many ended blocks are kept (None: all): older ones, once nothing refers to them by name any more,
        #: are released with their pegs, registrations and records (see :meth:`release`)
        self.keep = keep
        self._ended: list[BlockRun] = []  # ended or refused runs, oldest first (with ``keep``)
        #: bumped whenever behaviours are added, so that :class:`Dependants` know to look again
        self.structure_version = 0
        self._pending: dict[TimedBehaviour, None] | None = {}  # to re-time this instant; None: all
        self._pending_until = 0.0  # ... and up to when
        self._retime_scheduled = False
        board.on_move(self.pegs_moved)
        self.context = EngineContext(env=env, board=board, sync_passed=self.sync_passed,
                                     pegs_moved=self.pegs_moved, dependants_of=self.dependants_of,
                                     blocks=BlockControl(self))

    def add_engine(self, engine: Engine) -> None:
        """Let ``engine`` realize the behaviour types its planner names (it was made with :attr:`context`)."""
        self.engine_list.append(engine)
        for behaviour_type in engine.planner.behaviour_types:
            self.engines[behaviour_type] = engine

    # ------------------------------------------------------------------ anticipators
    def add_anticipator(self, anticipator) -> None:
        self.anticipators[anticipator.id] = anticipator
        anticipator.report = self.anticipator_fault

    #: Most warnings about one anticipator's faults; after them its faults are only counted.
    MAX_FAULT_WARNINGS = 100

    def anticipator_fault(self, anticipator, sync_id: str, description: str) -> None:
        """An anticipator did something that was refused (see :mod:`~agentsim.core.anticipator`): warn."""
        counts = self.fault_counts
        n = counts[anticipator.id] = counts.get(anticipator.id, 0) + 1
        if n > self.MAX_FAULT_WARNINGS:
            return
        if n == self.MAX_FAULT_WARNINGS:
            description += f" (further faults of anticipator {anticipator.id!r} are not reported)"
        target = f"anticipators:{anticipator.id}" + (f":{sync_id}" if sync_id else "")
        self.warn(target, "IMPOSSIBLE_TO_SCHEDULE", description, "agent")

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
    def warn(self, target: str, kind: str, description: str, character: str, modified=(),
             line: int | None = None, column: int | None = None, adaptations=()) -> None:
        self.log.send(fb.warning(target, kind, description, self.env.now, character, modified, line, column,
                                 adaptations))

    def submit(self, block: Block, source: str = "") -> BlockRun | None:
        """Submit one parsed block now. Returns its run, or None if it was refused."""
        return self._submit(block, source)

    def _submit(self, block: Block, source: str) -> BlockRun | None:
        where = f" in {source}" if source else ""
        character = block.character_id
        for w in block.warnings:
            # (an adaptation warning is about the block, and lists every behaviour it touched)
            one = w.behaviours and w.warning_type != "NONSTANDARD_BML"
            target = f"{block.id}:{w.behaviours[0]}" if one else block.id
            self.warn(target, w.warning_type, w.description, character, w.behaviours, w.line, w.column, w.details)
        if any(r.id == block.id for r in self.runs):
            self.warn(block.id, "PARSING_FAILURE", f"block refused{where}: a block with id {block.id!r} is "
                      "already pending or running", character)
            return None
        if block.composition == "REPLACE":
            for run in list(self.runs):
                self.cut(run, block.id)
        now = self.env.now
        run = BlockRun(block, self.board.new_block_peg(block.id, now), self.env.event())
        self.link(run)
        run.block_peg.set(self.predicted_start(run))
        solver = BlockSolver(block, run, self.board, self.engines, self.anticipator_peg, self.live_behaviours)
        run.timed = solver.solve()
        for issue in solver.issues:
            ids = issue.behaviours if not solver.failed else []
            target = f"{block.id}:{ids[0]}" if len(ids) == 1 else block.id
            where = block.behaviour(ids[0]) if len(ids) == 1 else None
            self.warn(target, issue.warning_type, issue.description, character, issue.behaviours,
                      where.line if where else None, where.column if where else None)
        self.all_runs.append(run)
        self.drops.extend(DropRecord(block.id, behaviour_id, now, kind, reason)
                          for behaviour_id, (kind, reason) in solver.dropped.items())
        if solver.failed:
            run.state = "refused"
            run.ended.succeed()
            self.retire(run)
            return run
        for timed in list(run.timed):
            reason = timed.engine.planner.admit(timed)
            if reason is not None:
                run.timed.remove(timed)
                timed.state = "dropped"
                self.drops.append(DropRecord(block.id, timed.id, now, "NO_SUCH_TARGET", reason))
                self.warn(f"{block.id}:{timed.id}", "NO_SUCH_TARGET", f"{timed.id}: {reason}; behaviour dropped",
                          character, [timed.id], timed.behaviour.line, timed.behaviour.column)
        self.board.forget_block(block.id)
        for timed in run.timed:
            timed.planned_start = timed.start
            timed.engine.planner.add(timed)
            self.board.register_behaviour(block.id, timed.id, timed.sync_ids, functools.partial(SyncPeg, timed))
        self.structure_version += 1
        self.runs.append(run)
        if run.chunk_after:
            self.coarticulate(run)
        self.predict(run, force=True)
        if self.waits(run) is None:
            self.start(run)
        else:
            self.env.process(self.await_start(run))
        return run

    def live_behaviours(self) -> list[TimedBehaviour]:
        return [t for r in self.runs for t in r.live()]

    def find_run(self, block_id: str) -> BlockRun | None:
        """The latest run of a block with this id (pending, running or ended), or None."""
        return next((r for r in reversed(self.all_runs) if r.id == block_id and r.state != "refused"), None)

    # ------------------------------------------------------------------ block life
    def await_start(self, run: BlockRun):
        """The process of a pending block: wait until it may start, then start it now."""
        while run.state == "pending":
            waiting = self.waits(run)
            if waiting is None:
                # the time it waited for exactly (the clock reaches it only up to rounding), else now
                start = self.awaited(run)
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
        run.state = "running"
        character = run.block.character_id
        self.log.send(fb.block_progress(run.id, "start", run.block_peg.time, character))
        for timed in run.live():
            timed.engine.activate(timed)
        for block_id in run.block.on_start:
            self.activate(block_id, by=run.id, what="onStart: ")
        self.end_if_done(run, run.block_peg.time)

    def activate(self, block_id: str, by: str = "", what: str = "") -> bool:
        """Start a preplanned block now (or as soon as what it waits for allows). False, with a warning, if
        there is no such pending block."""
        target = self.find_run(block_id)
        who = by or block_id
        if target is None or target.state != "pending":
            state = "there is no such block" if target is None else f"it is {target.state}"
            self.warn(who, "NO_SUCH_TARGET", f"{what}cannot activate block {block_id!r}: {state}", "agent")
            return False
        target.activated = True
        with self.board.quiet():
            target.block_peg.set(self.predicted_start(target))
        self.retime()
        if target.state == "pending" and target.wake is None:  # planned, never waited: start it now
            self.env.process(self.await_start(target))
        self.wake(target)
        return True

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        """Sync point ``index`` of ``timed`` was passed at ``time``: feedback, and the end of what is done."""
        run = timed.run
        sync_id = timed.sync_ids[index]
        last = index == len(timed.sync_ids) - 1
        self.log.send(fb.sync_point_progress(run.id, timed.id, sync_id, time - run.block_peg.time, time,
                                             run.block.character_id,
                                             fb.INTERRUPTED if last and timed.interrupted else None))
        if last:
            timed.state = "finished"
            timed.engine.planner.remove(timed)
            self.end_if_done(run, time)

    def end_if_done(self, run: BlockRun, time: float) -> None:
        if run.state == "running" and not run.live_count:  # (a count: ends come one by one, N of them)
            self.end(run, time)

    def end(self, run: BlockRun, time: float) -> None:
        run.state = "ended"
        run.ended_at = time
        self.log.send(fb.block_progress(run.id, "end", time, run.block.character_id,
                                        fb.INTERRUPTED if run.interrupted else None))
        if run in self.runs:
            self.runs.remove(run)
        run.ended.succeed()
        self.retire(run)

    def retire(self, run: BlockRun) -> None:
        """A run is over (ended or refused): with :attr:`keep`, release the oldest ones beyond it (in batches,
        so that each costs O(1) amortised)."""
        if self.keep is None:
            return
        self._ended.append(run)
        if len(self._ended) > 2 * self.keep + 16:
            cut = len(self._ended) - self.keep
            self.release(self._ended[:cut])
            del self._ended[:cut]

    #: A passed anticipator peg is forgotten this long (s) after its time, when blocks are released.
    PEG_MEMORY = 60.0

    def release(self, runs: list[BlockRun]) -> None:
        """Forget ended runs: they leave :attr:`all_runs` and the records, their sync points can no longer be
        referred to by name (a reference to them is a warning, as to a block that never was), their block pegs
        and registrations go, and so do the engines' records of them and the anticipators' passed pegs.
        Whatever still holds one of their pegs (a later block tied to them) keeps it."""
        gone = {id(r) for r in runs}
        self.all_runs = [r for r in self.all_runs if id(r) not in gone]
        kept = {r.id for r in self.all_runs}
        for run in runs:
            if run.id not in kept:  # no later block of that id has taken its place on the board
                self.board.forget_block(run.id)
                if self.board.block_pegs.get(run.id) is run.block_peg:
                    del self.board.block_pegs[run.id]
        released = {r.id for r in runs} - kept
        self.drops = [d for d in self.drops if d.block not in released]
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
        if run.state == "pending":
            self.log.send(fb.block_progress(run.id, "start", now, character))
            run.state = "running"
        for timed in run.live():
            started = timed.state == "active" and timed.passed[0] is not None
            timed.state = "dropped"
            timed.stopped = now
            if started:  # what it makes (its sound) stops here too
                timed.engine.stopped(timed, now)
            timed.engine.remove(timed)
            self.drops.append(DropRecord(run.id, timed.id, now, "INTERRUPTED", cause))
            self.warn(f"{run.id}:{timed.id}", "INTERRUPTED", f"{timed.id}: {cause}; "
                      + ("stopped at once" if started else "it will not start"), character, [timed.id])
            if started:
                last = len(timed.sync_ids) - 1
                timed.passed[last] = now
                self.log.send(fb.sync_point_progress(run.id, timed.id, timed.sync_ids[last], now - run.block_peg.time,
                                                     now, character, fb.INTERRUPTED))
            run.interrupted = True
        self.end(run, now)

    def drop(self, timed: TimedBehaviour, reason: str) -> None:
        timed.state = "dropped"
        timed.stopped = self.env.now
        timed.engine.remove(timed)
        run = timed.run
        self.drops.append(DropRecord(run.id, timed.id, self.env.now, "IMPOSSIBLE_TO_SCHEDULE", reason))
        self.warn(f"{run.id}:{timed.id}", "IMPOSSIBLE_TO_SCHEDULE", f"{timed.id}: {reason}; behaviour dropped",
                  run.block.character_id, [timed.id])

    def recording(self) -> Recording:
        """What the run has done so far, as values (see :class:`~agentsim.core.recording.Recording`)."""
        runs = [r for r in self.all_runs if r.state != "refused"]
        blocks = tuple(BlockRecord(r.id, r.block.character_id, r.block.composition, r.state, r.block_peg.time
                                   if r.state != "pending" else None, r.ended_at) for r in self.all_runs)
        pegs = {name: {sync: peg.time for sync, peg in a.pegs.items()} for name, a in self.anticipators.items()}
        return Recording(behaviours=tuple(record_behaviours(t for r in runs for t in r.timed)), blocks=blocks,
                         drops=tuple(self.drops), anticipators=pegs, feedback=tuple(self.log.items),
                         now=self.env.now)

