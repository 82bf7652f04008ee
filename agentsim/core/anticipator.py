"""The anticipator interface: an owner of time pegs that stand for predicted events in the world.

An anticipator is code from outside the realizer (a plugin, a beat tracker): what it does wrong loses only
itself or one of its pegs. Its pegs refuse times that are not finite, and moves of a peg that has not come
yet into the past; an exception in its process stops that process (but for
:class:`~agentsim.errors.Unavailable`, which says the run cannot go on), and one in :meth:`Anticipator.make_peg`
refuses that peg. Each is said to :attr:`Anticipator.report` (the scheduler turns it into a warning).
"""

from __future__ import annotations

import math
from typing import Callable

import simpy

from agentsim.errors import ScheduleError, Unavailable
from agentsim.core.pegboard import PegBoard, TimePeg

#: A peg move this far (seconds) before the clock still counts as "now".
PAST_TOLERANCE = 1e-9


class AnticipatorPeg(TimePeg):
    """A peg an anticipator moves: it refuses NaN and infinite times, and a move from a time still to come
    into the past; each refusal is reported to its anticipator, and the peg keeps its time."""

    __slots__ = ("owner", "sync_id")

    def __init__(self, time: float | None, owner: "Anticipator", sync_id: str):
        super().__init__(time, name=f"anticipators:{owner.id}:{sync_id}", board=owner.board)
        self.owner = owner
        self.sync_id = sync_id

    def set(self, time: float | None) -> None:
        if time is not None:
            try:
                time = float(time)
            except (TypeError, ValueError):
                self.owner.fault(self.sync_id, f"{self.name} moved to {time!r}, which is not a time; move refused")
                return
            if not math.isfinite(time):
                self.owner.fault(self.sync_id, f"{self.name} moved to {time!r}; move refused (times must be finite)")
                return
            env = self.owner.env
            old = self.time
            if env is not None and old is not None and old >= env.now - PAST_TOLERANCE \
                    and time < env.now - PAST_TOLERANCE:
                self.owner.fault(self.sync_id, f"{self.name} moved from {old:.6g} s into the past ({time:.6g} s, now "
                                 f"{env.now:.6g} s); move refused")
                return
        super().set(time)


class Anticipator:
    """Owns pegs named by sync ids (``beat1``, ``beat2``, ...) and moves them as its predictions change.

    BML refers to them as ``anticipators:<id>:<sync>``. Subclasses create pegs on demand in
    :meth:`make_peg`, move them with :meth:`move`, and may run a SimPy process (:meth:`run`) that consumes
    perceptions; :meth:`stop` ends it cleanly. ``confidence`` (0 to 1) says how much the predictions can be
    trusted. ``report(anticipator, sync_id, description)`` is told what went wrong (by default nothing is).
    """

    def __init__(self, anticipator_id: str):
        self.id = anticipator_id
        self.pegs: dict[str, TimePeg] = {}
        self.confidence = 1.0
        self.env: simpy.Environment | None = None
        self.board: PegBoard | None = None
        self.process: simpy.Process | None = None
        self.report: Callable[["Anticipator", str, str], None] | None = None
        #: why its process stopped, if it failed
        self.failed: str | None = None

    def attach(self, env: simpy.Environment, board: PegBoard) -> None:
        """Join a realizer: pegs report their moves to ``board``; :meth:`run` starts if defined."""
        self.env = env
        self.board = board
        for peg in self.pegs.values():
            peg.board, peg.cache = board, board.cache
        run = self.run()
        if run is not None:
            self.process = env.process(self._guarded(run))

    def _guarded(self, process):
        """Its process, stopped (and reported) rather than let an exception out into the clock."""
        try:
            return (yield from process)
        except simpy.Interrupt as interrupt:
            if interrupt.cause != "stop":
                self.failed = f"interrupted ({interrupt.cause})"
        except Unavailable:  # the anticipator itself says the run cannot go on (its live input is dead)
            raise
        except Exception as exc:  # code from outside the realizer: lose it, not the run
            self.failed = f"{type(exc).__name__}: {exc}"
            self.fault("", f"anticipator {self.id!r} stopped: its process raised {self.failed}; its pegs keep their "
                           "last predictions")
        return None

    def fault(self, sync_id: str, description: str) -> None:
        """Say that something it did was refused (see :attr:`report`)."""
        if self.report is not None:
            self.report(self, sync_id, description)

    def peg(self, sync_id: str) -> TimePeg | None:
        """The peg for ``sync_id`` (created on first use), or None if this anticipator has no such sync.

        :class:`~agentsim.errors.ScheduleError` if making it failed, or gave a time that is not finite.
        """
        peg = self.pegs.get(sync_id)
        if peg is None:
            try:
                time = self.make_peg(sync_id)
            except Exception as exc:  # code from outside the realizer: lose the peg, not the run
                raise ScheduleError(f"anticipator {self.id!r} failed to predict {sync_id!r}: "
                                    f"{type(exc).__name__}: {exc}") from None
            if time is False:
                return None
            if time is not None:
                try:
                    time = float(time)
                except (TypeError, ValueError):
                    raise ScheduleError(f"anticipator {self.id!r} predicted {time!r} for {sync_id!r}, which is not "
                                        "a time") from None
                if not math.isfinite(time):
                    raise ScheduleError(f"anticipator {self.id!r} predicted {time!r} for {sync_id!r}: times must be "
                                        "finite")
            peg = AnticipatorPeg(time, self, sync_id)
            self.pegs[sync_id] = peg
        return peg

    def make_peg(self, sync_id: str) -> float | None | bool:
        """Predicted time for a new peg ``sync_id`` (None if not known yet), or False if there is none."""
        return False

    def move(self, sync_id: str, time: float | None) -> None:
        """Move one of this anticipator's pegs; everything tied to it is re-timed."""
        self.peg(sync_id).set(time)

    def forget_passed(self, before: float, keep: Callable[[TimePeg], bool] = lambda peg: False) -> int:
        """Drop the pegs whose time is before ``before`` (global s) and that ``keep`` does not ask to keep:
        a later reference to one makes it again. Returns how many were dropped."""
        gone = [s for s, peg in self.pegs.items() if peg.time is not None and peg.time < before and not keep(peg)]
        for sync_id in gone:
            del self.pegs[sync_id]
        return len(gone)

    def run(self):
        """A SimPy process consuming perceptions (None: this anticipator needs none)."""
        return None

    def stop(self) -> None:
        """End the process, if one runs."""
        if self.process is not None and self.process.is_alive:
            self.process.interrupt("stop")
