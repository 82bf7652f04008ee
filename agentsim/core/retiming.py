"""The one re-timing path: every peg move, whatever moved it, re-times what hangs from it, checks the planners'
validity, drops what became invalid, sends predictions of what moved and wakes the players.

:class:`Retimer` owns what is to be re-timed at this instant (``_pending``, up to ``_pending_until``), whether
a pass is due (``_retime_due``) and the prediction tolerance. It judges the behaviours a pass looks at
(:meth:`Retimer.retime` returns those that became invalid: the scheduler drops them and ends what is done)
and predicts (it writes a run's ``predicted``, ``predicted_start``, ``gone`` and noted ends, and sends
predictionFeedback through the :class:`~agentsim.core.reporter.Reporter`). :class:`Dependants` keeps, for pegs
that move often (a speech's animator time), the behaviours that hang from them by planned start, so that each
move re-times only what is near.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable

import simpy

from agentsim.core.book import BlockBook
from agentsim.core.pegboard import TimePeg
from agentsim.core.reporter import Reporter
from agentsim.core.timed import ACTIVE, BlockRun, TimedBehaviour

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

    def __init__(self, book: BlockBook, pegs: Iterable[TimePeg], planned_now: Callable[[], float]):
        self.book = book
        self.peg_ids = {id(p) for p in pegs}
        self.planned_now = planned_now
        self.version = -1
        self.behaviours: list[TimedBehaviour] = []
        self._starts: list[float] = []
        self._admitted = 0
        self._near: dict[TimedBehaviour, None] = {}

    def _refresh(self) -> None:
        if self.version == self.book.structure_version:
            return
        self.version = self.book.structure_version
        found = [t for t in self.book.live_behaviours() if t.hangs_from(self.peg_ids)]
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


@dataclass
class Judged:
    """What a re-timing pass found: the behaviours whose timing is no longer valid, with why, in the order
    they were looked at, and the times computed on the way (for the predictions that follow)."""

    invalid: list[tuple[TimedBehaviour, str]]
    times: dict[TimedBehaviour, list[float | None] | None]


class Retimer:
    """Re-timing, predictions and validity for the scheduler.

    Parameters
    ----------
    env : simpy.Environment
        The clock.
    book : BlockBook
        The runs and their live behaviours (for :meth:`dependants_of`).
    reporter : Reporter
        Where predictionFeedback goes.
    prediction_tolerance : float
        A behaviour is predicted again when one of its sync points moved by more than this (seconds).
    """

    def __init__(self, env: simpy.Environment, book: BlockBook, reporter: Reporter,
                 prediction_tolerance: float = FRAME):
        self.env = env
        self.book = book
        self.reporter = reporter
        self.prediction_tolerance = prediction_tolerance
        self._pending: dict[TimedBehaviour, None] | None = {}  # to re-time this instant; None: all
        self._pending_until = 0.0  # ... and up to when
        self._retime_due = False

    def dependants_of(self, pegs: Iterable[TimePeg], planned_now=None) -> Dependants:
        """The live behaviours whose timing hangs from ``pegs``, kept up to date as blocks come.

        ``planned_now()``: the planned time the owner of the pegs has reached (default: the clock).
        """
        env = self.env
        return Dependants(self.book, pegs, planned_now if planned_now is not None else (lambda: env.now))

    def moved(self, pegs: Iterable[TimePeg] | TimePeg | Dependants | None = None,
              horizon: float | None = None) -> bool:
        """Pegs moved (see :meth:`~agentsim.core.scheduler.Scheduler.pegs_moved`): note what is to be
        re-timed. True if a pass has to be run at this instant (none is due yet): the caller runs it after
        everything that moves pegs now, with what :meth:`due` then says.

        Without ``horizon`` every live behaviour is to be looked at; with ``pegs`` given as
        :class:`Dependants` and a ``horizon`` (seconds), only those that start within it.
        """
        if self._pending is not None:
            if horizon is not None and isinstance(pegs, Dependants):
                self._pending_until = self.env.now + horizon
                self._pending.update(dict.fromkeys(pegs.near(horizon)))
            else:
                self._pending = None
        if self._retime_due:
            return False
        self._retime_due = True
        return True

    def due(self) -> tuple[list[TimedBehaviour] | None, float | None]:
        """The pass is run now: the behaviours to re-time (None: every live one) and up to when (None: all
        of their sync points); what moves from now on is noted for another pass."""
        self._retime_due = False
        pending, self._pending = self._pending, {}
        if pending is None:
            return None, None
        return list(pending), self._pending_until

    def retime(self, candidates: Iterable[TimedBehaviour]) -> Judged:
        """Judge the live ``candidates`` as their pegs now place them: which became invalid (the caller
        drops them before the predictions), with the times computed for both."""
        invalid: list[tuple[TimedBehaviour, str]] = []
        timed_now: dict[TimedBehaviour, list[float | None] | None] = {}  # times computed once, for both uses
        for timed in candidates:
            if timed.live:
                planner = timed.engine.planner
                times = timed_now[timed] = timed.times() if planner.judges(timed) else None
                reason = planner.invalid(timed, times)
                if reason is not None:
                    invalid.append((timed, reason))
        return Judged(invalid, timed_now)

    def predict_moved(self, behaviours: list[TimedBehaviour], until: float | None,
                      timed_now: dict[TimedBehaviour, list[float | None] | None]) -> None:
        """Predict again, block by block, the sync points of ``behaviours`` due by ``until`` that moved."""
        by_run: dict[BlockRun, list[TimedBehaviour]] = {}
        for timed in behaviours:
            by_run.setdefault(timed.run, []).append(timed)
        for run, affected in by_run.items():
            self.predict(run, affected, until, timed_now)

    @staticmethod
    def kick(behaviours: Iterable[TimedBehaviour]) -> None:
        """Wake the players of the ``behaviours`` that play: their times may have moved."""
        for timed in behaviours:
            if timed.state is ACTIVE:
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
        predicted = run.predicted
        ends: list[tuple[TimedBehaviour, float | None]] = []  # (the predicted ends, noted at once after)
        for timed in run.live() if behaviours is None else [t for t in behaviours if t.live]:
            behaviour = timed.behaviour
            last = predicted.get(behaviour.id)
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
                last = predicted[behaviour.id] = list(times)
            else:
                for i, t in zip(indices, times):
                    last[i] = t
            ends.append((timed, last[-1]))
            if len(times) == len(timed.sync_ids):  # all of them
                start, syncs = times[0], dict(zip(timed.sync_ids, times))
            else:
                start, syncs = timed.start, {timed.sync_ids[i]: t for i, t in zip(indices, times)}
            entry = {"id": behaviour.id, "type": behaviour.type, "globalStart": start, "globalEnd": last[-1],
                     "syncs": syncs}
            lexeme = behaviour.attributes.get("lexeme") if first else None
            if lexeme:  # what it plays, as read (a draft's rotation="SHAKE" is lexeme SHAKE), said once
                entry["lexeme"] = lexeme
            entries.append(entry)
        run.note_ends(ends)
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
        self.reporter.prediction(run, start, end, entries)
