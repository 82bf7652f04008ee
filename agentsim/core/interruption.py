"""Cutting a playing behaviour short: which sync points an interruption skips, giving the rest new times,
and which pegs the skipped ones leave for others to hang from.

An engine says what an interruption leaves of a behaviour (:meth:`~agentsim.core.engine.Engine.interruption`:
speech ends at once, a gesture goes into its retraction); the scheduler applies it with the helpers here.
"""

from __future__ import annotations

from agentsim.core.pegboard import ComputedPeg, OffsetPeg, PegBoard, TimePeg
from agentsim.core.timed import EPSILON, KeyRef, TimedBehaviour


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
        key.peg.rebase(TimePeg(t - key.offset, name=f"{timed.block_id}:{timed.id}:cut"), 0.0)
    else:
        timed.keys[i] = KeyRef(TimePeg(t, name=f"{timed.block_id}:{timed.id}:{timed.sync_ids[i]}:cut"))


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
