"""The scheduler: BML blocks from submission to end, composition, re-timing and feedback.

It parses each block, has the :class:`~agentsim.core.solver.BlockSolver` tie its behaviours to time pegs,
hands the timed behaviours to the engines' planners and starts the block when its composition allows
(MERGE: now; APPEND: when every earlier block has ended; REPLACE: after ending every earlier block).
When a peg moves while a plan plays, every behaviour tied to it is re-timed through its pegs, the
planners are asked which behaviours became invalid, those are dropped with a warning, and a new
prediction is sent.
"""

from __future__ import annotations

import functools

import simpy

from agentsim.core import feedback as fb
from agentsim.core.block import Block
from agentsim.bml.parser import guess_block_id, parse_bml
from agentsim.core.errors import BMLError
from agentsim.core.pegboard import OffsetPeg, PegBoard, TimePeg
from agentsim.core.plan import EPSILON, Engine, ScheduleError, SyncPeg, TimedBehaviour
from agentsim.core.solver import BlockSolver


def _start_time(timed: TimedBehaviour) -> float:
    start = timed.start
    return start if start is not None and start < float("inf") else float("-inf")


class BlockRun:
    """One submitted block on its way: pending, running, ended (or refused)."""

    def __init__(self, env: simpy.Environment, block: Block, block_peg: TimePeg):
        self.block = block
        self.block_peg = block_peg
        self.state = "pending"
        self.timed: list[TimedBehaviour] = []
        self.ended = env.event()
        self.last_prediction: list | None = None

    @property
    def id(self) -> str:
        return self.block.id

    def live(self) -> list[TimedBehaviour]:
        return [t for t in self.timed if t.state in ("planned", "active")]


class Scheduler:
    """Schedules BML blocks onto engines and reports what happens as feedback."""

    def __init__(self, env: simpy.Environment, board: PegBoard, engines: list[Engine], log: fb.FeedbackLog):
        self.env = env
        self.board = board
        self.engines = {t: e for e in engines for t in e.planner.behaviour_types}
        self.engine_list = engines
        self.log = log
        self.anticipators: dict[str, object] = {}
        self.runs: list[BlockRun] = []  # not yet ended, in submission order
        self.all_runs: list[BlockRun] = []
        self._retime_scheduled = False
        board.on_move(self.peg_moved)
        for engine in engines:
            engine._report = self.sync_passed
            if hasattr(engine, "progress"):
                engine.progress = self.speech_progress
                engine.dependants_of = self.dependants_of

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

    def submit(self, bml: str | bytes | Block, source: str = "") -> BlockRun | None:
        """Submit one BML block now. Returns its run, or None if it was refused."""
        where = f" in {source}" if source else ""
        if isinstance(bml, Block):
            block = bml
        else:
            try:
                block = parse_bml(bml)
            except BMLError as exc:
                self.warn(guess_block_id(bml), "PARSING_FAILURE", f"block refused{where}: {exc}", "agent",
                          line=exc.line, column=exc.column)
                return None
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
                self.interrupt(run)
        now = self.env.now
        start = now
        if block.composition == "APPEND":
            start = max([now] + [self.predicted_end(r) for r in self.runs])
        block_peg = TimePeg(start, name=f"{block.id}:start", board=self.board)
        self.board.block_pegs[block.id] = block_peg
        run = BlockRun(self.env, block, block_peg)
        earlier = list(self.runs)
        solver = BlockSolver(block, run, self.board, self.engines, self.anticipator_peg, self.live_behaviours)
        run.timed = solver.solve()
        for issue in solver.issues:
            ids = issue.behaviours if not solver.failed else []
            target = f"{block.id}:{ids[0]}" if len(ids) == 1 else block.id
            where = block.behaviour(ids[0]) if len(ids) == 1 else None
            self.warn(target, issue.warning_type, issue.description, character, issue.behaviours,
                      where.line if where else None, where.column if where else None)
        self.all_runs.append(run)
        if solver.failed:
            run.state = "refused"
            run.ended.succeed()
            return run
        self.board.forget_block(block.id)
        for timed in run.timed:
            timed.engine.planner.add(timed)
            self.board.register_behaviour(block.id, timed.id, timed.sync_ids, functools.partial(SyncPeg, timed))
        self.runs.append(run)
        self.predict(run, force=True)
        if block.composition == "APPEND" and earlier:
            self.env.process(self.start_after(run, earlier))
        else:
            self.start(run)
        return run

    def live_behaviours(self) -> list[TimedBehaviour]:
        return [t for r in self.runs for t in r.live()]

    def predicted_end(self, run: BlockRun) -> float:
        ends = [t.end for t in run.live()]
        return max([run.block_peg.time] + [e for e in ends if e is not None])

    # ------------------------------------------------------------------ block life
    def start_after(self, run: BlockRun, earlier: list[BlockRun]):
        yield simpy.AllOf(self.env, [r.ended for r in earlier])
        if run.state != "pending":
            return
        if abs(run.block_peg.time - self.env.now) > EPSILON:
            with self.board.quiet():
                run.block_peg.set(self.env.now)
            self.retime()
        self.start(run)

    def start(self, run: BlockRun) -> None:
        run.state = "running"
        character = run.block.character_id
        self.log.send(fb.block_progress(run.id, "start", run.block_peg.time, character))
        for timed in run.live():
            timed.engine.activate(timed)
        self.end_if_done(run, run.block_peg.time)

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
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
        self.log.send(fb.block_progress(run.id, "end", time, run.block.character_id))
        if run in self.runs:
            self.runs.remove(run)
        run.ended.succeed()

    def interrupt(self, run: BlockRun) -> None:
        """End a block now (composition REPLACE): its behaviours stop where they are."""
        now = self.env.now
        for timed in run.live():
            timed.state = "dropped"
            timed.engine.remove(timed)
        if run.state == "pending":
            self.log.send(fb.block_progress(run.id, "start", now, run.block.character_id))
            run.state = "running"
        self.end(run, now)

    # ------------------------------------------------------------------ re-timing
    def peg_moved(self, peg: TimePeg) -> None:
        if not self._retime_scheduled:
            self._retime_scheduled = True
            self.env.process(self._retime_soon())

    def _retime_soon(self):
        yield self.env.timeout(0)
        self._retime_scheduled = False
        self.retime()

    def retime(self) -> None:
        """Pegs moved: drop behaviours that became invalid, update predictions, wake the players."""
        with self.board.quiet():
            for i, run in enumerate(self.runs):
                if run.state == "pending" and run.block.composition == "APPEND":
                    earlier = [self.predicted_end(r) for r in self.runs[:i]]
                    run.block_peg.set(max([self.env.now] + earlier))
        for engine in self.engine_list:
            for timed, reason in engine.planner.invalid_behaviours():
                self.drop(timed, f"after re-timing: {reason}")
        for run in list(self.runs):
            self.predict(run)
            self.end_if_done(run, self.env.now)
        for engine in self.engine_list:
            engine.plan.kick()

    #: Behaviours tied to a speech whose next sync point is further ahead than this (seconds) are not
    #: woken at every progress event; they are checked when they come closer.
    SPEECH_HORIZON = 2.0

    def dependants_of(self, pegs: set[int]) -> list[TimedBehaviour]:
        """Live behaviours with a key hanging from one of ``pegs`` (ids), by their next sync time."""
        found = []
        for timed in self.live_behaviours():
            for key in timed.keys:
                peg = key.peg if key is not None else None
                while isinstance(peg, OffsetPeg) and id(peg) not in pegs:
                    peg = peg.base
                if peg is not None and id(peg) in pegs:
                    found.append(timed)
                    break
        found.sort(key=_start_time)
        return found

    def speech_progress(self, playback) -> None:
        """A speech's animator time changed: wake the players of the behaviours tied to it that are near."""
        horizon = self.env.now + self.SPEECH_HORIZON
        speech = playback.timed
        if speech.state == "active":
            speech.engine.plan.kick([speech])
        dependants = playback.dependants  # in order of start, as planned when the speech began
        starts = playback.dependant_starts
        first = playback.first_live
        while first < len(dependants) and dependants[first].state in ("finished", "dropped"):
            first += 1
        playback.first_live = first
        for i in range(first, len(dependants)):
            if starts[i] > horizon:
                break
            timed = dependants[i]
            if timed.state == "active":
                timed.engine.plan.kick([timed])

    def drop(self, timed: TimedBehaviour, reason: str) -> None:
        timed.state = "dropped"
        timed.engine.remove(timed)
        run = timed.run
        self.warn(f"{run.id}:{timed.id}", "IMPOSSIBLE_TO_SCHEDULE", f"{timed.id}: {reason}; behaviour dropped",
                  run.block.character_id, [timed.id])

    def predict(self, run: BlockRun, force: bool = False) -> None:
        """Send predictionFeedback for a block if its predicted timing changed (or ``force``)."""
        behaviours = []
        flat: list[float] = []
        for timed in run.live():
            times = timed.times()
            flat.extend(t if t is not None else float("nan") for t in times)
            behaviours.append({"id": timed.id, "type": timed.behaviour.type, "globalStart": times[0],
                               "globalEnd": times[-1], "syncs": dict(zip(timed.sync_ids, times))})
        start = run.block_peg.time
        signature = [start] + flat
        if not force and run.last_prediction is not None and len(signature) == len(run.last_prediction) and all(
                abs(a - b) <= EPSILON or (a != a and b != b) for a, b in zip(signature, run.last_prediction)):
            return
        run.last_prediction = signature
        end = max([start] + [b["globalEnd"] for b in behaviours if b["globalEnd"] is not None])
        self.log.send(fb.prediction(run.id, self.env.now, run.block.character_id, start, end, behaviours))

