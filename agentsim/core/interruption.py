"""Graceful interruption: which sync points an interruption skips, giving the rest new times, which pegs the
skipped ones leave for others to hang from, and the scheduler's part that interrupts blocks and behaviours.

An engine says what an interruption leaves of a behaviour (:meth:`~agentsim.core.engine.Engine.interruption`:
speech ends at once, a gesture goes into its retraction); :class:`Interrupter` applies it and removes what
hung from what will never come.

:class:`Interrupter` owns nothing but its collaborators. It writes the behaviours it cuts (their keys, skipped
sync points, when they stopped; a behaviour removed drops itself) and their runs' ``interrupted`` and
``gone``; it starts a pending run it takes whole (the run changes its own state); its drops go to the
:class:`~agentsim.core.book.BlockBook`, its warnings and the start it says to the
:class:`~agentsim.core.reporter.Reporter`. Re-timing what its cuts moved is the caller's
(:meth:`Interrupter.interrupt` says whether it did anything).
"""

from __future__ import annotations

from typing import Callable, Iterable

import simpy

from agentsim.core.book import BlockBook
from agentsim.core.pegboard import ComputedPeg, OffsetPeg, PegBoard, TimePeg
from agentsim.core.recording import DropRecord
from agentsim.core.reporter import Reporter
from agentsim.core.timed import ACTIVE, EPSILON, OPEN, PENDING, BlockRun, KeyRef, TimedBehaviour


def due_by(timed: TimedBehaviour, i: int, now: float) -> bool:
    """Whether sync point ``i`` is due by ``now`` (an interruption at ``now`` still lets it pass)."""
    t = timed.time(i)
    return t is not None and t <= now + EPSILON


def skip_until(timed: TimedBehaviour, stop: int, now: float) -> set[int]:
    """The sync points not yet passed before index ``stop`` that are not due by ``now``."""
    return {i for i in range(timed.next_index, stop) if not due_by(timed, i, now)}


def set_key_time(timed: TimedBehaviour, i: int, t: float) -> None:
    """Give sync point ``i`` the time ``t`` (global seconds).

    What shares its peg moves with it where the peg's time comes from this behaviour: a computed peg (a
    speech's animator time) is pinned, a peg it owns is re-based. A peg whose time comes from elsewhere (a
    number, an anticipator, another behaviour or block) keeps that time: the key gets a peg of its own.
    """
    key = timed.keys[i]
    if key is not None and isinstance(key.peg, ComputedPeg) and key.offset == 0.0:
        key.peg.pin(t)
    elif key is not None and timed.owns[i] and isinstance(key.peg, OffsetPeg):
        key.peg.rebase(TimePeg(t - key.offset, name=f"{timed.block_id}:{timed.id}:cut", cache=key.peg.cache), 0.0)
    else:
        timed.keys[i] = KeyRef(TimePeg(t, name=f"{timed.block_id}:{timed.id}:{timed.sync_ids[i]}:cut",
                                       cache=timed.run.block_peg.cache))


def pegs_left_behind(timed: TimedBehaviour, indices, board: PegBoard) -> set[int]:
    """``id()`` of the pegs through which other behaviours hang from sync points ``indices`` of ``timed``.

    Those are the pegs whose time comes from it and that its keys share with other behaviours, its computed
    animator-time pegs, and the pegs other blocks were handed for them. (A peg it shares but whose time
    comes from another behaviour, a number or an anticipator still comes: what hangs from it stays.)
    """
    found: set[int] = set()
    handed = board.handed_out(timed.block_id, timed.id)
    for i in indices:
        key = timed.keys[i]
        if key is not None and (isinstance(key.peg, ComputedPeg) or timed.owns[i]):
            found.add(id(key.peg))
        peg = handed.get(timed.sync_ids[i])
        if peg is not None:
            found.add(id(peg))
    return found


def hands(timed: TimedBehaviour) -> set[str]:
    """The hands a gesture or pointing uses: its ``mode``, else the right hand."""
    mode = timed.behaviour.attributes.get("mode", "").upper()
    if mode in ("BOTH_HANDS", "BOTH"):
        return {"l", "r"}
    if mode in ("LEFT_HAND", "LEFT"):
        return {"l"}
    return {"r"}


class Interrupter:
    """Graceful interruption for the scheduler.

    An interruption that was asked for (a block's ``bmla:interrupt``, a ``<bmla:interrupt>``,
    :meth:`~agentsim.realizer.Realizer.interrupt`) is feedback, not a fault: the last syncPointProgress of
    each behaviour it cut and the end blockProgress of its block carry ``"status": "INTERRUPTED"``, and a
    behaviour it removed before it started is ``{"status": "removed"}`` in the next prediction. A warning
    (``INTERRUPTED``) is left for what nobody asked for: a ``required`` behaviour lost, and a behaviour of
    another block that hung from a sync point that will now never come.

    Parameters
    ----------
    env : simpy.Environment
        The clock (an interruption happens now).
    board : PegBoard
        Which pegs of a behaviour other blocks were handed (what hangs from it).
    book : BlockBook
        The live behaviours (what may hang from a cut one) and where drops are recorded.
    reporter : Reporter
        Where warnings and the start of a pending block taken whole go.
    wake : callable
        ``wake(run)``: a pending run was started here; its waiting process looks again (the composer's).
    """

    def __init__(self, env: simpy.Environment, board: PegBoard, book: BlockBook, reporter: Reporter,
                 wake: Callable[[BlockRun], None]):
        self.env = env
        self.board = board
        self.book = book
        self.reporter = reporter
        self.wake = wake

    def interrupt(self, run: BlockRun, include: Iterable[str] = (), exclude: Iterable[str] = (),
                  by: str = "") -> bool:
        """Interrupt a block now, gracefully, as asked: speech stops, gestures retract, what hung from what
        will never come is removed. ``include``: only these behaviours; ``exclude``: all but these. A block
        that has not started is not started at all (it still gets its start and end, now); every behaviour
        of it goes. False if the block had ended (nothing was done); else pegs may have moved."""
        include, exclude = set(include), set(exclude)
        if run.state not in OPEN:
            return False
        cause = f"interrupted by {by}" if by else "interrupted"
        scope = [t for t in run.live() if (not include or t.id in include) and t.id not in exclude]
        whole = len(scope) == len(run.live())
        for timed in scope:
            self.interrupt_behaviour(timed, cause, asked=True)
        if run.state is PENDING and whole:
            now = self.env.now
            run.interrupted = True
            self.reporter.block_progress(run, "start", now)
            run.start()
            self.wake(run)
        return True

    def interrupt_behaviour(self, timed: TimedBehaviour, cause: str, asked: bool = False) -> None:
        """Interrupt one behaviour now: a started one does what its engine says an interruption leaves of it,
        one that has not started is removed; what hangs from the sync points that will not come goes too.
        ``asked``: the interruption was asked for (no warning unless the behaviour was required)."""
        if not timed.live or timed.interrupted:
            return
        now = self.env.now
        if timed.state is not ACTIVE or timed.passed[0] is None:
            self.remove(timed, cause, asked)
            return
        plan = timed.engine.interruption(timed, now)
        if plan is None:
            return
        skip, times = plan
        left = pegs_left_behind(timed, skip, self.board)
        timed.interrupted = True
        timed.run.interrupted = True
        timed.stopped = now
        timed.skipped |= skip
        for i, t in times.items():
            set_key_time(timed, i, t)
        while timed.next_index in timed.skipped:
            timed.next_index += 1
        timed.engine.stopped(timed, now)
        self.book.add_drop(DropRecord(timed.block_id, timed.id, now, "INTERRUPTED", cause))
        if not asked or timed.behaviour.required:
            required = "required, but " if timed.behaviour.required else ""
            self.reporter.warn(f"{timed.block_id}:{timed.id}", "INTERRUPTED", f"{timed.id}: {required}{cause}; "
                               "what is left of it ends now", timed.run.block.character_id, [timed.id])
        self.remove_dependants(left, timed, cause)
        timed.engine.plan.kick([timed])

    def remove(self, timed: TimedBehaviour, cause: str, asked: bool = False) -> None:
        """Take out a behaviour that has not started: it will not happen; neither will what hangs from it."""
        if not timed.live:
            return
        run = timed.run
        left = pegs_left_behind(timed, range(len(timed.sync_ids)), self.board)
        timed.drop(self.env.now)
        run.interrupted = True
        timed.engine.remove(timed)
        self.board.forget_behaviour(run.id, timed.id)
        run.gone.append(timed)
        self.book.add_drop(DropRecord(run.id, timed.id, self.env.now, "INTERRUPTED", cause))
        if not asked or timed.behaviour.required:
            required = "required, but " if timed.behaviour.required else ""
            self.reporter.warn(f"{run.id}:{timed.id}", "INTERRUPTED", f"{timed.id}: {required}{cause}; behaviour "
                               "removed before it started", run.block.character_id, [timed.id])
        self.remove_dependants(left, timed, cause)

    def remove_dependants(self, peg_ids: set[int], origin: TimedBehaviour, cause: str) -> None:
        """Every live behaviour that hangs from ``peg_ids`` (sync points that will not come) is interrupted if
        it started, removed if it did not: as asked when it is of the origin's block (the block was asked to
        stop there), with a warning when it is of another block (that block did not ask)."""
        if not peg_ids:
            return
        why = f"{cause}: it was tied to {origin.block_id}:{origin.id}"
        for timed in self.book.live_behaviours():
            if timed is not origin and timed.live and timed.hangs_from(peg_ids):
                self.interrupt_behaviour(timed, why, asked=timed.run is origin.run)
