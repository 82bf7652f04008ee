"""The one re-timing path: every peg move, whatever moved it, re-times what hangs from it, checks the planners'
validity, drops what became invalid, sends predictions of what moved and wakes the players.

:class:`Retiming` is the part of the :class:`~agentsim.core.scheduler.Scheduler` that does it;
:class:`Dependants` keeps, for pegs that move often (a speech's animator time), the behaviours that hang
from them by planned start, so that each move re-times only what is near.
"""

from __future__ import annotations

import math
from typing import Iterable

from agentsim.core import feedback as fb
from agentsim.core.pegboard import TimePeg
from agentsim.core.timed import BlockRun, TimedBehaviour

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

    def __init__(self, scheduler, pegs: Iterable[TimePeg], planned_now=None):
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


class Retiming:
    """Re-timing, predictions and validity for the scheduler (it provides ``env``, ``board``, ``log``,
    ``runs``, ``engine_list``, ``structure_version``, ``prediction_tolerance``, ``drop``, ``end_if_done``,
    ``dormant`` and ``predicted_start``)."""

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
        self.board.invalidate_times()
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
            first = last is None
            if last is None or len(indices) == len(last):
                last = run.predicted[timed.id] = list(times)
            else:
                for i, t in zip(indices, times):
                    last[i] = t
            run.note_end(timed, last[-1])
            if known is None and len(times) == len(timed.sync_ids):  # all of them, just computed
                start, syncs = times[0], dict(zip(timed.sync_ids, times))
            else:
                start, syncs = timed.start, {timed.sync_ids[i]: t for i, t in zip(indices, times)}
            entry = {"id": timed.id, "type": timed.behaviour.type, "globalStart": start, "globalEnd": last[-1],
                     "syncs": syncs}
            lexeme = timed.behaviour.attributes.get("lexeme") if first else None
            if lexeme:  # what it plays, as read (a draft's rotation="SHAKE" is lexeme SHAKE), said once
                entry["lexeme"] = lexeme
            entries.append(entry)
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
