"""The scheduler: BML blocks from submission to end, composition, re-timing and feedback.

It has the :class:`~agentsim.core.solver.BlockSolver` tie each block's behaviours to time pegs, hands the
timed behaviours to the engines' planners and starts the block when its composition allows (MERGE: now;
APPEND: when every earlier block has ended; REPLACE: after ending every earlier block).

Every peg movement, whatever moved it (an anticipator, a speech's animator time, a block starting
later than planned), goes through one entry point, :meth:`Scheduler.pegs_moved`. Once per instant, after
everything that moved pegs at that instant, :meth:`Scheduler.retime` asks the planners which of the
affected behaviours became invalid, drops those with a warning, sends predictionFeedback for the
behaviours whose predicted timing moved by more than the prediction tolerance, and wakes the players.
"""

from __future__ import annotations

import functools
import math
from typing import Iterable

import simpy

from agentsim.core import feedback as fb
from agentsim.core.block import Block
from agentsim.core.engine import Engine, EngineContext
from agentsim.core.interruption import hands, pegs_left_behind, set_key_time
from agentsim.core.errors import ScheduleError
from agentsim.core.pegboard import PegBoard, TimePeg, invalidate_times
from agentsim.core.recording import BlockRecord, DropRecord, Recording, record_behaviours
from agentsim.core.solver import BlockSolver
from agentsim.core.timed import EPSILON, BlockRun, KeyRef, SyncPeg, TimedBehaviour

#: Predictions are sent again for a behaviour when one of its sync points moved by more than this
#: (seconds): one frame at 60 frames per second.
FRAME = 1.0 / 60.0


def _moved(times: list[float | None], last: list[float | None], tolerance: float) -> bool:
    if len(times) != len(last):
        return True
    for a, b in zip(times, last):
        if (a is None) != (b is None):
            return True
        if a is not None and a != b and not abs(a - b) <= tolerance:
            return True
    return False


class Dependants:
    """The live behaviours whose timing hangs from some pegs, by planned start, with the near ones at hand.

    It follows the blocks as they come: when a block is submitted, the list is made again the next time it
    is asked for. :meth:`near` keeps the behaviours that have come within a horizon and are still live, so
    that pegs moving at every progress event of a speech re-time only what is about to happen. Nearness is
    judged on the planned timeline: ``planned_now()`` says which planned time the owner of the pegs has
    reached (a speech: its planned start plus how far its animator time has got), so that a strategy
    whose predictions run far ahead or behind does not make behaviours come too late.
    """

    def __init__(self, scheduler: "Scheduler", pegs: Iterable[TimePeg], planned_now=None):
        self.scheduler = scheduler
        self.peg_ids = {id(p) for p in pegs}
        self.planned_now = planned_now if planned_now is not None else (lambda: scheduler.env.now)
        self.version = -1
        self.behaviours: list[TimedBehaviour] = []
        self._starts: list[float] = []
        self._admitted = 0
        self._near: dict[TimedBehaviour, None] = {}

    def _refresh(self) -> None:
        if self.version == self.scheduler.structure_version:
            return
        self.version = self.scheduler.structure_version
        found = [t for t in self.scheduler.live_behaviours() if t.hangs_from(self.peg_ids)]
        starts = [t.planned_start if t.planned_start is not None and math.isfinite(t.planned_start) else -math.inf
                  for t in found]
        order = sorted(range(len(found)), key=starts.__getitem__)
        self.behaviours = [found[i] for i in order]
        self._starts = [starts[i] for i in order]
        self._admitted = 0
        self._near = {}

    def all(self) -> list[TimedBehaviour]:
        """Every live dependant, by planned start."""
        self._refresh()
        return [t for t in self.behaviours if t.live]

    def near(self, horizon: float) -> list[TimedBehaviour]:
        """The live dependants planned to start within ``horizon`` seconds of the planned time reached now,
        or with no planned start."""
        self._refresh()
        until = self.planned_now() + horizon
        while self._admitted < len(self.behaviours) and self._starts[self._admitted] <= until:
            self._near[self.behaviours[self._admitted]] = None
            self._admitted += 1
        self._near = {t: None for t in self._near if t.live}
        return list(self._near)


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

    def activate(self, block_id: str, by: str = "") -> bool:
        return self.scheduler.activate(block_id, by)

    def warn(self, target: str, kind: str, description: str, modified=()) -> None:
        self.scheduler.warn(target, kind, description, "agent", modified)


class Scheduler:
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
                 prediction_tolerance: float = FRAME):
        self.env = env
        self.board = board
        self.log = log
        self.prediction_tolerance = prediction_tolerance
        self.engines: dict[str, Engine] = {}  # behaviour type -> engine
        self.engine_list: list[Engine] = []
        self.anticipators: dict[str, object] = {}
        self.runs: list[BlockRun] = []  # not yet ended, in submission order
        self.all_runs: list[BlockRun] = []
        self.drops: list[DropRecord] = []
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
        """Let ``engine`` realise the behaviour types its planner names (it was made with :attr:`context`)."""
        self.engine_list.append(engine)
        for behaviour_type in engine.planner.behaviour_types:
            self.engines[behaviour_type] = engine

    # ------------------------------------------------------------------ anticipators
    def add_anticipator(self, anticipator) -> None:
        self.anticipators[anticipator.id] = anticipator

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
             line: int | None = None, column: int | None = None) -> None:
        self.log.send(fb.warning(target, kind, description, self.env.now, character, modified, line, column))

    def submit(self, block: Block, source: str = "") -> BlockRun | None:
        """Submit one parsed block now. Returns its run, or None if it was refused."""
        where = f" in {source}" if source else ""
        character = block.character_id
        for w in block.warnings:
            target = f"{block.id}:{w.behaviours[0]}" if w.behaviours else block.id
            self.warn(target, w.warning_type, w.description, character, w.behaviours, w.line, w.column)
        if any(r.id == block.id for r in self.runs):
            self.warn(block.id, "PARSING_FAILURE", f"block refused{where}: a block with id {block.id!r} is "
                      "already pending or running", character)
            return None
        if block.composition == "REPLACE":
            for run in list(self.runs):
                self.cut(run)
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

    # ------------------------------------------------------------------ composition
    def link(self, run: BlockRun) -> None:
        """Find what a new block waits for (APPEND, APPEND-AFTER, CHUNK-AFTER and their BMLA forms), and make
        the blocks its prependBefore and chunkBefore name wait for it. Unknown blocks and circles are
        reported and left out."""
        block = run.block
        if block.composition == "APPEND":
            run.after.extend(r for r in self.runs if not self.dormant(r))
        for ids, found, what in ((block.append_after, run.after, "appendAfter"),
                                 (block.chunk_after, run.chunk_after, "chunkAfter")):
            for block_id in ids:
                other = self.find_run(block_id)
                if other is None:
                    self.warn(block.id, "NO_SUCH_TARGET", f"{what}: there is no block {block_id!r}; ignored",
                              block.character_id)
                elif other not in found and other.state in ("pending", "running"):
                    found.append(other)
        for ids, what in ((block.prepend_before, "prependBefore"), (block.chunk_before, "chunkBefore")):
            for block_id in ids:
                other = self.find_run(block_id)
                if other is None or other.state != "pending":
                    state = "there is no such block" if other is None else f"it is {other.state}"
                    self.warn(block.id, "NO_SUCH_TARGET", f"{what}: block {block_id!r} cannot wait for this one "
                              f"({state}); ignored", block.character_id)
                    continue
                if self.waits_for(run, other):
                    self.warn(block.id, "IMPOSSIBLE_TO_SCHEDULE", f"{what}: block {block_id!r} waits for this "
                              "one already, directly or not; ignored", block.character_id)
                    continue
                (other.after if what == "prependBefore" else other.chunk_after).append(run)
                self.wake(other)
        for block_id in block.interrupt + block.on_start:
            if self.find_run(block_id) is None:
                what = "interrupt" if block_id in block.interrupt else "onStart"
                self.warn(block.id, "NO_SUCH_TARGET", f"{what}: there is no block {block_id!r} (yet); ignored",
                          block.character_id)

    def waits_for(self, run: BlockRun, other: BlockRun) -> bool:
        """Whether ``run`` waits, directly or through others, for ``other`` to end or subside."""
        seen: set[int] = set()
        todo = [run]
        while todo:
            current = todo.pop()
            if current is other:
                return True
            if id(current) not in seen:
                seen.add(id(current))
                todo.extend(current.after + current.chunk_after)
        return False

    @staticmethod
    def dormant(run: BlockRun) -> bool:
        """A preplanned block that nothing has activated yet: nobody waits for it."""
        return run.block.preplan and not run.activated and run.state == "pending"

    def predicted_end(self, run: BlockRun) -> float:
        if run.state == "ended":
            return run.ended_at
        ends = [t.end for t in run.live()]
        return max([run.block_peg.time] + [e for e in ends if e is not None and e < float("inf")])

    def subsiding_time(self, run: BlockRun) -> float:
        """When a block subsides: every behaviour past its relax (the start of its retraction), or ended."""
        if run.state == "ended":
            return run.ended_at
        times = [run.block_peg.time]
        for timed in run.live():
            t = timed.sync_time("relax") if "relax" in timed.sync_ids else timed.end
            if t is not None and t < float("inf"):
                times.append(t)
        return max(times)

    def awaited(self, run: BlockRun) -> float | None:
        """When what a pending block waits for ends or subsides, as things stand (None: it waits for none)."""
        times = [self.predicted_end(r) for r in run.after if not self.dormant(r)]
        times += [self.subsiding_time(r) for r in run.chunk_after if not self.dormant(r)]
        return max(times) if times else None

    def predicted_start(self, run: BlockRun) -> float:
        """When a pending block would start as things stand: now, or when what it waits for ends or subsides."""
        awaited = self.awaited(run)
        return self.env.now if awaited is None else max(self.env.now, awaited)

    def coarticulate(self, run: BlockRun) -> None:
        """A chunk follows the gestures of the chunks before it without a gap: a gesture of an earlier chunk
        whose hand a gesture of this one takes while it retracts skips its retraction and ends when the new
        gesture starts (so that its relax, its end and the new start meet)."""
        arm = ("gesture", "pointing")
        new = sorted((t for t in run.timed if t.behaviour.type in arm), key=lambda t: t.start or 0.0)
        for earlier in run.chunk_after:
            for old in earlier.live():
                if old.behaviour.type not in arm or "relax" not in old.sync_ids:
                    continue
                relax, end = old.sync_time("relax"), old.end
                follower = next((t for t in new if hands(t) & hands(old) and t.start is not None
                                 and relax - EPSILON <= t.start <= end + EPSILON), None)
                if follower is not None:
                    self.hold_relax(old)
                    old.keys[-1] = KeyRef(SyncPeg(follower, 0))
                    old.tied[-1] = old.fixed[-1] = True
                    old.owns[-1] = False
                    self.structure_version += 1

    @staticmethod
    def hold_relax(timed: TimedBehaviour) -> None:
        """Key a behaviour's relax where it is now, relative to the nearest keyed sync point before it, so
        that moving its end does not move it."""
        relax = timed.sync_ids.index("relax")
        if timed.keys[relax] is not None:
            return
        before = max(i for i in range(relax) if timed.keys[i] is not None)
        key = timed.keys[before]
        timed.keys[relax] = KeyRef(key.peg, key.offset + timed.time(relax) - timed.time(before))

    # ------------------------------------------------------------------ block life
    def waits(self, run: BlockRun) -> list[simpy.Event] | None:
        """What a pending block still waits for (events to wait on), or None if it may start now.

        A block that names blocks to interrupt interrupts them the first time it may start, and then waits
        for them to end.
        """
        now = self.env.now
        if run.block.preplan and not run.activated:
            return [self.wake_event(run)]
        ending = [r.ended for r in run.after if not r.ended.triggered and not self.dormant(r)]
        if ending:
            return ending + [self.wake_event(run)]
        subsides = max([now] + [self.subsiding_time(r) for r in run.chunk_after if not self.dormant(r)])
        if subsides > now + EPSILON:
            return [self.env.timeout(subsides - now), self.wake_event(run)]
        if run.block.interrupt and not run.interrupting:
            run.interrupting = True
            for block_id in run.block.interrupt:
                target = self.find_run(block_id)
                if target is not None and target.state in ("pending", "running"):
                    self.interrupt(target, by=run.id)
                    run.after.append(target)
            return self.waits(run)
        return None

    def wake_event(self, run: BlockRun) -> simpy.Event:
        if run.wake is None or run.wake.triggered:
            run.wake = self.env.event()
        return run.wake

    def wake(self, run: BlockRun) -> None:
        """What a pending block waits for changed: look again."""
        if run.wake is not None and not run.wake.triggered:
            run.wake.succeed()

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
            self.activate(block_id, by=run.id)
        self.end_if_done(run, run.block_peg.time)

    def activate(self, block_id: str, by: str = "") -> bool:
        """Start a preplanned block now (or as soon as what it waits for allows). False, with a warning, if
        there is no such pending block."""
        target = self.find_run(block_id)
        who = by or block_id
        if target is None or target.state != "pending":
            state = "there is no such block" if target is None else f"it is {target.state}"
            self.warn(who, "NO_SUCH_TARGET", f"cannot activate block {block_id!r}: {state}", "agent")
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
        self.log.send(fb.sync_point_progress(run.id, timed.id, sync_id, time - run.block_peg.time, time,
                                             run.block.character_id))
        if index == len(timed.sync_ids) - 1:
            timed.state = "finished"
            timed.engine.planner.remove(timed)
            self.end_if_done(run, time)

    def end_if_done(self, run: BlockRun, time: float) -> None:
        if run.state == "running" and not run.live():
            self.end(run, time)

    def end(self, run: BlockRun, time: float) -> None:
        run.state = "ended"
        run.ended_at = time
        self.log.send(fb.block_progress(run.id, "end", time, run.block.character_id))
        if run in self.runs:
            self.runs.remove(run)
        run.ended.succeed()

    def cut(self, run: BlockRun) -> None:
        """End a block now (composition REPLACE): its behaviours stop where they are."""
        now = self.env.now
        for timed in run.live():
            timed.state = "dropped"
            timed.stopped = now
            timed.engine.remove(timed)
            self.drops.append(DropRecord(run.id, timed.id, now, "INTERRUPTED", "its block was replaced"))
        if run.state == "pending":
            self.log.send(fb.block_progress(run.id, "start", now, run.block.character_id))
            run.state = "running"
        self.end(run, now)

    # ------------------------------------------------------------------ interruption
    def interrupt(self, run: BlockRun, include: Iterable[str] = (), exclude: Iterable[str] = (),
                  by: str = "") -> None:
        """Interrupt a block now, gracefully: speech stops, gestures retract, what hung from what will never
        come is removed (quietly, unless it was required). ``include``: only these behaviours; ``exclude``:
        all but these. A block that has not started is not started at all (it still gets its start and end,
        now); every behaviour of it goes."""
        include, exclude = set(include), set(exclude)
        if run.state not in ("pending", "running"):
            return
        cause = f"interrupted by {by}" if by else "interrupted"
        scope = [t for t in run.live() if (not include or t.id in include) and t.id not in exclude]
        whole = len(scope) == len(run.live())
        for timed in scope:
            self.interrupt_behaviour(timed, cause)
        if run.state == "pending" and whole:
            now = self.env.now
            self.log.send(fb.block_progress(run.id, "start", now, run.block.character_id))
            run.state = "running"
            self.wake(run)
        self.pegs_moved()

    def interrupt_behaviour(self, timed: TimedBehaviour, cause: str) -> None:
        """Interrupt one behaviour now: a started one does what its engine says an interruption leaves of it,
        one that has not started is removed; what hangs from the sync points that will not come goes too."""
        if not timed.live or timed.interrupted:
            return
        now = self.env.now
        if timed.state != "active" or timed.passed[0] is None:
            self.remove(timed, cause)
            return
        plan = timed.engine.interruption(timed, now)
        if plan is None:
            return
        skip, times = plan
        left = pegs_left_behind(timed, skip, self.board)
        timed.interrupted = True
        timed.stopped = now
        timed.skipped |= skip
        for i, t in times.items():
            set_key_time(timed, i, t)
        while timed.next_index in timed.skipped:
            timed.next_index += 1
        timed.engine.stopped(timed, now)
        self.drops.append(DropRecord(timed.block_id, timed.id, now, "INTERRUPTED", cause))
        self.remove_dependants(left, timed, cause)
        timed.engine.plan.kick([timed])

    def remove(self, timed: TimedBehaviour, cause: str) -> None:
        """Take out a behaviour that has not started: it will not happen; neither will what hangs from it."""
        if not timed.live:
            return
        run = timed.run
        left = pegs_left_behind(timed, range(len(timed.sync_ids)), self.board)
        timed.state = "dropped"
        timed.stopped = self.env.now
        timed.engine.remove(timed)
        self.board.forget_behaviour(run.id, timed.id)
        run.gone.append(timed)
        self.drops.append(DropRecord(run.id, timed.id, self.env.now, "INTERRUPTED", cause))
        if timed.behaviour.required:
            self.warn(f"{run.id}:{timed.id}", "INTERRUPTED", f"{timed.id}: required, but {cause}; behaviour "
                      "removed", run.block.character_id, [timed.id])
        self.remove_dependants(left, timed, cause)

    def remove_dependants(self, peg_ids: set[int], origin: TimedBehaviour, cause: str) -> None:
        """Every live behaviour that hangs from ``peg_ids`` (sync points that will not come) is interrupted if
        it started, removed if it did not."""
        if not peg_ids:
            return
        why = f"{cause}: it was tied to {origin.block_id}:{origin.id}"
        for timed in self.live_behaviours():
            if timed is not origin and timed.live and timed.hangs_from(peg_ids):
                self.interrupt_behaviour(timed, why)

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

    # ------------------------------------------------------------------ re-timing
    def dependants_of(self, pegs: Iterable[TimePeg], planned_now=None) -> Dependants:
        """The live behaviours whose timing hangs from ``pegs``, kept up to date as blocks come.

        ``planned_now()``: the planned time the owner of the pegs has reached (default: the clock).
        """
        return Dependants(self, pegs, planned_now)

    def pegs_moved(self, pegs: Iterable[TimePeg] | TimePeg | Dependants | None = None,
                   horizon: float | None = None) -> None:
        """Pegs moved (set, shifted, or their computed times changed): re-time what hangs from them.

        The one entry point for every peg movement. Without ``horizon`` every live behaviour is looked at;
        with ``pegs`` given as :class:`Dependants` and a ``horizon`` (seconds), only those that start
        within it. The re-timing itself happens once per instant, after everything that moved pegs then.
        """
        invalidate_times()
        if self._pending is not None:
            if horizon is not None and isinstance(pegs, Dependants):
                self._pending_until = self.env.now + horizon
                self._pending.update(dict.fromkeys(pegs.near(horizon)))
            else:
                self._pending = None
        if not self._retime_scheduled:
            self._retime_scheduled = True
            self.env.process(self._retime_soon())

    def _retime_soon(self):
        yield self.env.timeout(0)
        self._retime_scheduled = False
        pending, self._pending = self._pending, {}
        if pending is None:
            self.retime()
        else:
            self.retime(list(pending), until=self._pending_until)

    def retime(self, behaviours: list[TimedBehaviour] | None = None, until: float | None = None) -> None:
        """Pegs moved: drop behaviours that became invalid, update predictions, wake the players.

        ``behaviours``: the ones affected (default: every live behaviour, and the start of every block
        waiting to be appended). ``until``: only their sync points due by then (global seconds) are
        predicted again; later ones are when they come nearer.
        """
        if behaviours is None:
            with self.board.quiet():
                for run in self.runs:
                    if run.state == "pending" and not self.dormant(run) and (run.after or run.chunk_after):
                        run.block_peg.set(self.predicted_start(run))
            candidates = [t for engine in self.engine_list for t in engine.planner.plan]
        else:
            candidates = behaviours
        dropped: dict[BlockRun, None] = {}
        timed_now: dict[TimedBehaviour, list[float | None]] = {}  # times computed once, for both uses
        for timed in candidates:
            if timed.live:
                planner = timed.engine.planner
                times = timed_now[timed] = timed.times() if planner.judges(timed) else None
                reason = planner.invalid(timed, times)
                if reason is not None:
                    self.drop(timed, f"after re-timing: {reason}")
                    dropped[timed.run] = None
        if behaviours is None:
            for run in list(self.runs):
                self.predict(run, timed_now=timed_now)
                self.end_if_done(run, self.env.now)
            for engine in self.engine_list:
                engine.plan.kick()
            return
        by_run: dict[BlockRun, list[TimedBehaviour]] = {}
        for timed in behaviours:
            by_run.setdefault(timed.run, []).append(timed)
        for run, affected in by_run.items():
            self.predict(run, affected, until, timed_now)
        for run in dropped:
            self.end_if_done(run, self.env.now)
        for timed in behaviours:
            if timed.state == "active":
                timed.engine.plan.kick([timed])

    def predict(self, run: BlockRun, behaviours: list[TimedBehaviour] | None = None, until: float | None = None,
                timed_now: dict[TimedBehaviour, list[float | None] | None] | None = None,
                force: bool = False) -> None:
        """Send predictionFeedback for the behaviours of a block whose predicted timing moved by more than
        the tolerance since they were last predicted (all of the block's live behaviours if ``force``).

        ``behaviours``: the ones to look at (default: every live behaviour of the block). ``until``: look
        only at their sync points not yet passed and due by then (global seconds), and say only those.
        ``timed_now``: times of some of them computed already.
        """
        if run.state not in ("pending", "running"):
            return
        tolerance = self.prediction_tolerance
        entries = []
        for timed in run.live() if behaviours is None else behaviours:
            if not timed.live:
                continue
            last = run.predicted.get(timed.id)
            known = timed_now.get(timed) if timed_now else None
            if until is None or last is None:
                indices = range(len(timed.sync_ids))
                times = known if known is not None else timed.times()
            elif known is not None:
                indices = range(timed.next_index, len(timed.sync_ids))
                times = known[timed.next_index:]
            else:
                indices, times = timed.window(until)
            if not (force or last is None or _moved(times, [last[i] for i in indices], tolerance)):
                continue
            if last is None or len(indices) == len(last):
                last = run.predicted[timed.id] = list(times)
            else:
                for i, t in zip(indices, times):
                    last[i] = t
            run.note_end(timed, last[-1])
            entries.append({"id": timed.id, "type": timed.behaviour.type, "globalStart": timed.start,
                            "globalEnd": last[-1], "syncs": {timed.sync_ids[i]: t for i, t in zip(indices, times)}})
        for timed in run.gone:
            entries.append({"id": timed.id, "type": timed.behaviour.type, "status": "removed"})
        run.gone.clear()
        start = run.block_peg.time
        start_moved = run.predicted_start is None or (start != run.predicted_start
                                                       and not abs(start - run.predicted_start) <= tolerance)
        if not (force or entries or start_moved):
            return
        run.predicted_start = start
        end = run.predicted_end()
        end = start if end is None else max(start, end)
        self.log.send(fb.prediction(run.id, self.env.now, run.block.character_id, start, end, entries))
