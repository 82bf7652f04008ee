"""Behaviours placed in time, and the runs of the blocks they belong to.

A :class:`TimedBehaviour` has one key per sync point. Keys tied to time pegs (:class:`KeyRef`) move when
their pegs move; the other keys are placed by linear time warping between their tied neighbours, using
the behaviour's preferred timing. A :class:`BlockRun` is one submitted block on its way from pending to
ended, with the timed behaviours the solver made of it and what was last predicted of them.

Each owns its state (:class:`BehaviourState`, :class:`BlockState`) and changes it only in its own methods
(:meth:`TimedBehaviour.activate`, :meth:`~TimedBehaviour.finish`, :meth:`~TimedBehaviour.drop`;
:meth:`BlockRun.start`, :meth:`~BlockRun.end`, :meth:`~BlockRun.refuse`). The states are strings too
(``enum.StrEnum``): the recording, the reports and the warnings print and compare them as they always did.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Iterable, Iterator, Sequence

import simpy

from agentsim.core.block import Behaviour, Block
from agentsim.core.pegboard import ComputedPeg, OffsetPeg, TimePeg

#: Two times closer than this (seconds) are the same time.
EPSILON = 1e-9


class BehaviourState(StrEnum):
    """Where a timed behaviour is: ``planned`` -> ``active`` -> ``finished`` | ``dropped``."""

    PLANNED = "planned"
    ACTIVE = "active"
    FINISHED = "finished"
    DROPPED = "dropped"


class BlockState(StrEnum):
    """Where a block run is: ``pending`` -> ``running`` -> ``ended``, or ``refused``."""

    PENDING = "pending"
    RUNNING = "running"
    ENDED = "ended"
    REFUSED = "refused"


#: The states as names of this module too, which the code that checks them often reads (an enum's member looked
#: up on its class goes through the enum's metaclass: several times slower).
PLANNED, ACTIVE, FINISHED, DROPPED = BehaviourState
PENDING, RUNNING, ENDED, REFUSED = BlockState
#: The states of a block run that is still to end (it waits, or it runs).
OPEN = (PENDING, RUNNING)


@dataclass(frozen=True, slots=True)
class KeyRef:
    """Where a key is tied: ``peg.time + offset`` (global seconds)."""

    peg: TimePeg
    offset: float = 0.0

    @property
    def time(self) -> float | None:
        t = self.peg.time
        return None if t is None else t + self.offset


_LIVE = ("planned", "active")
_NONE_SKIPPED: frozenset[int] = frozenset()


class TimedBehaviour:
    """A behaviour placed in time: its sync points, preferred timing, keys and what has been played.

    ``engine`` is the :class:`~agentsim.core.engine.Engine` that plays it; ``order`` its place in the
    order its realizer planned behaviours (:meth:`~agentsim.core.pegboard.PegBoard.plan_order`).
    """

    # (its fields in slots: a block makes thousands, and the scheduler and the players read them all the time)
    __slots__ = ("run", "behaviour", "sync_ids", "preferred", "keys", "engine", "passed", "order", "tied", "fixed",
                 "owns", "heap_version", "next_index", "_state", "stopped", "planned_start", "interrupted", "skipped",
                 "parameters", "phonemes", "__weakref__")

    def __init__(self, run: "BlockRun", behaviour: Behaviour, preferred: Sequence[float],
                 keys: list[KeyRef | None], engine: Any, order: int, tied: list[bool] | None = None,
                 fixed: list[bool] | None = None, owns: list[bool] | None = None):
        self.run = run
        self.behaviour = behaviour
        self.sync_ids = list(behaviour.sync_ids)
        self.preferred = list(preferred)
        self.keys = keys
        self.engine = engine
        n = len(self.sync_ids)
        self.passed: list[float | None] = [None] * n
        self.order = order  # ties at one time are passed in planning order
        # (each of the three below is a list of its own, all False unless it is given: the solver gives them)
        self.tied = tied if tied is not None else [False] * n  # which keys share a peg with other sync points
        # which of those pegs are held by a time given from outside: a number, an anticipator, another block
        self.fixed = fixed if fixed is not None else [False] * n
        # which of those pegs get their time from this behaviour (what else hangs from them follows it)
        self.owns = owns if owns is not None else [False] * n
        self.heap_version = 0  # which of the player's heap entries for this behaviour is current
        self.next_index = 0
        self._state = PLANNED  # (what _enter(PLANNED) does from no state, without its call)
        if isinstance(run, BlockRun):
            run.live_count += 1
        self.stopped: float | None = None  # when it was dropped, cut or interrupted, if it was
        self.planned_start: float | None = None  # its start as first planned
        self.interrupted = False  # interrupted: what is left of it runs to its end whatever the timing
        # sync points an interruption means will never come (none: one empty set shared until there are)
        self.skipped: frozenset[int] | set[int] = _NONE_SKIPPED
        #: parameter changes (BMLA parametervaluechange) that apply to it, in the order they started
        self.parameters: list = []
        #: a speech's phonemes as it was spoken, ``(symbol, start, end)`` in seconds on its own timeline
        #: (the axis of ``preferred``), set by the speech engine when it starts: what the mouth shows
        self.phonemes: tuple = ()

    @property
    def id(self) -> str:
        return self.behaviour.id

    @property
    def block_id(self) -> str:
        return self.run.block.id

    @property
    def state(self) -> BehaviourState:
        """``planned`` -> ``active`` -> ``finished`` | ``dropped`` (changed by :meth:`activate`,
        :meth:`finish` and :meth:`drop` alone)."""
        return self._state

    def _enter(self, state: BehaviourState) -> None:
        was, now = self._state in _LIVE, state in _LIVE
        self._state = state
        if was != now and isinstance(self.run, BlockRun):
            self.run.live_count += 1 if now else -1

    def activate(self) -> None:
        """Its block started: its engine plays it."""
        self._enter(ACTIVE)

    def finish(self) -> None:
        """Its last sync point was passed."""
        self._enter(FINISHED)

    def drop(self, when: float | None = None) -> None:
        """It will not be played (on), from ``when`` (seconds) if it is given: the time it was stopped."""
        self._enter(DROPPED)
        if when is not None:
            self.stopped = when

    @property
    def live(self) -> bool:
        """Planned or playing (not finished, not dropped)."""
        return self._state in _LIVE

    def _anchor(self, i: int) -> float | None:
        passed = self.passed[i]
        if passed is not None:
            return passed
        key = self.keys[i]
        return None if key is None else key.time

    def time(self, i: int) -> float | None:
        """Global time of sync point ``i`` as planned now (or as it was passed)."""
        t = self.passed[i]  # (what _anchor(i) gives, without its call: the commonest answer)
        if t is not None:
            return t
        key = self.keys[i]
        if key is not None:
            t = key.peg.time
            if t is not None:
                return t + key.offset
        lo = i - 1
        while lo >= 0 and self._anchor(lo) is None:
            lo -= 1
        hi = i + 1
        while hi < len(self.keys) and self._anchor(hi) is None:
            hi += 1
        if lo < 0 or hi >= len(self.keys):
            return None
        t_lo, t_hi = self._anchor(lo), self._anchor(hi)
        p_lo, p_hi = self.preferred[lo], self.preferred[hi]
        if p_hi <= p_lo:
            return t_lo
        return t_lo + (self.preferred[i] - p_lo) / (p_hi - p_lo) * (t_hi - t_lo)

    def times(self) -> list[float | None]:
        """Global times of all sync points (one pass: tied keys, then warping between them)."""
        # (what _anchor gives for each key, without a call per key: the scheduler asks this of every
        # behaviour of a block several times over)
        times: list[float | None] = [
            passed if passed is not None or key is None
            else None if (peg_time := key.peg.time) is None else peg_time + key.offset
            for passed, key in zip(self.passed, self.keys)]
        pref = self.preferred
        lo = None
        for hi, t_hi in enumerate(times):
            if t_hi is None:
                continue
            if lo is not None and hi > lo + 1:
                t_lo, p_lo, p_hi = times[lo], pref[lo], pref[hi]
                if p_hi <= p_lo:
                    for i in range(lo + 1, hi):
                        times[i] = t_lo
                else:
                    # (t_lo + (pref[i] - p_lo) / (p_hi - p_lo) * (t_hi - t_lo), its two differences made once)
                    p_span, t_span = p_hi - p_lo, t_hi - t_lo
                    for i in range(lo + 1, hi):
                        times[i] = t_lo + (pref[i] - p_lo) / p_span * t_span
            lo = hi
        return times

    def sync_time(self, sync_id: str) -> float | None:
        return self.time(self.sync_ids.index(sync_id))

    @property
    def start(self) -> float | None:
        return self.time(0)

    @property
    def end(self) -> float | None:
        return self.time(len(self.sync_ids) - 1)

    def window(self, until: float) -> tuple[range, list[float | None]]:
        """The sync points not yet passed and due by ``until`` (global seconds), with their times: indices
        and times, up to and including the first one due later (or unknown)."""
        times: list[float | None] = []
        i = self.next_index
        while i < len(self.sync_ids):
            t = self.time(i)
            times.append(t)
            i += 1
            if t is None or t > until:
                break
        return range(self.next_index, i), times

    def next_time(self) -> float | None:
        """When the next sync point is due (None if not active, done, or not known to come)."""
        if self._state is not ACTIVE or self.next_index >= len(self.sync_ids):
            return None
        t = self.time(self.next_index)
        return t if t is not None and t < math.inf else None

    def own_pegs(self) -> Iterable[OffsetPeg]:
        for key in self.keys:
            if key is not None and isinstance(key.peg, OffsetPeg):
                yield key.peg

    def pegs_below(self) -> Iterator[TimePeg]:
        """Every peg this behaviour's timing hangs from: its keys' pegs, what they are tied to, and the pegs
        of behaviours whose sync points it is tied to (once each)."""
        seen: set[int] = set()
        todo = [key.peg for key in self.keys if key is not None]
        while todo:
            peg = todo.pop()
            if peg is None or id(peg) in seen:
                continue
            seen.add(id(peg))
            yield peg
            if isinstance(peg, OffsetPeg):
                todo.append(peg.base)
            elif isinstance(peg, SyncPeg):
                todo.extend(key.peg for key in peg.timed.keys if key is not None)

    def hangs_from(self, peg_ids: set[int]) -> bool:
        """Whether any peg this behaviour's timing hangs from is one of ``peg_ids`` (``id()`` of pegs)."""
        return any(id(peg) in peg_ids for peg in self.pegs_below())

    def __repr__(self) -> str:
        return f"TimedBehaviour({self.block_id}:{self.id}, {self.times()})"


class SyncPeg(ComputedPeg):
    """A read-only peg at one sync point of a timed behaviour, tied or placed by time warping.

    It lets other blocks tie their behaviours to any sync point of this one.
    """

    __slots__ = ("timed", "index")

    def __init__(self, timed: TimedBehaviour, index: int):
        super().__init__(None, name=f"{timed.block_id}:{timed.id}:{timed.sync_ids[index]}",
                         cache=timed.run.block_peg.cache)
        self.timed = timed
        self.index = index

    def compute(self) -> float | None:
        return self.timed.time(self.index)


@dataclass(eq=False)
class ParameterChange:
    """A change of one parameter of a behaviour over the span of the behaviour that makes it (BMLA's
    parametervaluechange): ``linear`` from ``initial`` to ``target`` between its start and end, or
    ``instant`` (the target from its start on)."""

    param: str
    maker: TimedBehaviour
    kind: str
    initial: float
    target: float

    @property
    def start(self) -> float | None:
        return self.maker.start

    @property
    def end(self) -> float | None:
        return self.maker.end

    def value(self, t: float) -> float | None:
        """The parameter at global time ``t`` (s): None before the change starts."""
        start, end = self.start, self.end
        if start is None or t < start:
            return None
        if self.kind == "instant" or end is None or end <= start or t >= end:
            return self.target
        return self.initial + (self.target - self.initial) * (t - start) / (end - start)


def parameter_at(timed: TimedBehaviour, param: str, t: float, default: float) -> float:
    """A behaviour's parameter at time ``t``: the latest change of it that has started, else ``default``."""
    value = default
    for change in timed.parameters:
        if change.param == param:
            v = change.value(t)
            if v is not None:
                value = v
    return value


@dataclass(eq=False)
class BlockRun:
    """One submitted block on its way: pending, running, ended (or refused).

    It owns its :attr:`state` and :attr:`ended_at` (:meth:`start`, :meth:`end`, :meth:`refuse`); the
    scheduler's parts fill in the rest as their docstrings say: the composer what it waits for and its wake
    event, the retimer what was predicted, the interrupter what was cut.
    ``predicted`` holds, for each behaviour, the times last sent in a predictionFeedback.
    """

    block: Block
    block_peg: TimePeg
    ended: simpy.Event
    state: BlockState = PENDING  # pending -> running -> ended, or refused
    timed: list[TimedBehaviour] = field(default_factory=list)
    predicted: dict[str, list[float | None]] = field(default_factory=dict)
    predicted_start: float | None = None
    ended_at: float | None = None
    #: runs whose end this one waits for before it starts (APPEND, APPEND-AFTER, prependBefore, interrupt)
    after: list["BlockRun"] = field(default_factory=list)
    #: runs whose subsiding this one waits for (CHUNK-AFTER, chunkBefore)
    chunk_after: list["BlockRun"] = field(default_factory=list)
    activated: bool = False  # a preplanned run that has been told to start
    interrupting: bool = False  # it has interrupted the blocks its bmla:interrupt names
    interrupted: bool = False  # an interruption (or a REPLACE) cut it short: its end says so
    #: behaviours removed since the last prediction (they are said to be gone in the next one)
    gone: list[TimedBehaviour] = field(default_factory=list)
    wake: simpy.Event | None = None  # succeeds when what this pending run waits for changes
    # the predicted ends of its behaviours, as a max-heap with lazy deletion: (-end, version, timed)
    _ends: list[tuple[float, int, TimedBehaviour]] = field(default_factory=list, repr=False)
    #: how many behaviours made for it are planned or playing (kept by :attr:`TimedBehaviour.state`)
    live_count: int = 0
    _end_version: dict[TimedBehaviour, int] = field(default_factory=dict, repr=False)
    _ends_noted: int = field(default=0, repr=False)  # how many predicted ends were noted: the next version

    @property
    def id(self) -> str:
        return self.block.id

    def note_end(self, timed: TimedBehaviour, end: float | None) -> None:
        """Remember the predicted end (global seconds) of one of its behaviours (None, inf: not known)."""
        version = self._ends_noted
        self._ends_noted += 1
        self._end_version[timed] = version
        if end is not None and math.isfinite(end):
            heapq.heappush(self._ends, (-end, version, timed))

    def note_ends(self, ends: Iterable[tuple[TimedBehaviour, float | None]]) -> None:
        """:meth:`note_end` of each ``(behaviour, end)`` in turn."""
        version = self._ends_noted
        versions, heap, isfinite = self._end_version, self._ends, math.isfinite
        for timed, end in ends:
            versions[timed] = version
            if end is not None and isfinite(end):
                heapq.heappush(heap, (-end, version, timed))
            version += 1
        self._ends_noted = version

    def predicted_end(self) -> float | None:
        """The latest predicted end of its live behaviours, as last noted (None if none is known)."""
        while self._ends:
            end, version, timed = self._ends[0]
            if timed.live and self._end_version.get(timed) == version:
                return -end
            heapq.heappop(self._ends)
        return None

    def live(self) -> list[TimedBehaviour]:
        """Its behaviours that are planned or playing, in document order."""
        return [t for t in self.timed if t.live] if self.live_count else []

    def has_live(self) -> bool:
        """Whether any of its behaviours is planned or playing (:attr:`live_count`, kept as they change)."""
        return self.live_count > 0

    @property
    def dormant(self) -> bool:
        """A preplanned block that nothing has activated yet: nobody waits for it."""
        return self.block.preplan and not self.activated and self.state is PENDING

    def start(self) -> None:
        """It starts (a pending run; its feedback is the scheduler's)."""
        self.state = RUNNING

    def end(self, time: float) -> None:
        """It ended at ``time`` (s). Its :attr:`ended` event is succeeded by whoever closes it, once its end
        has been said (what is told of the end may still see it not yet triggered)."""
        self.state = ENDED
        self.ended_at = time

    def refuse(self) -> None:
        """It was refused: it never starts, and whatever waits for its end goes on."""
        self.state = REFUSED
        self.ended.succeed()
