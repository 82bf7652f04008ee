"""Engines as Elckerlyc splits them: a Planner fills a Plan with timed behaviours, a Player plays it.

A :class:`TimedBehaviour` has one key per sync point. Keys tied to time pegs (:class:`KeyRef`) move when
their pegs move; the other keys are placed by linear time warping between their tied neighbours, using
the behaviour's preferred timing. The scheduler talks to planners only through the :class:`Planner`
interface (Elckerlyc section 5.2): resolve unknown times, add, remove, list invalid behaviours.
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterable, Sequence

import simpy

from agentsim.core.block import Behaviour
from agentsim.core.errors import ScheduleError
from agentsim.core.pegboard import OffsetPeg, TimePeg

if TYPE_CHECKING:  # pragma: no cover
    from agentsim.core.scheduler import BlockRun

#: Two times closer than this (seconds) are the same time.
EPSILON = 1e-9


@dataclass(frozen=True)
class KeyRef:
    """Where a key is tied: ``peg.time + offset`` (global seconds)."""

    peg: TimePeg
    offset: float = 0.0

    @property
    def time(self) -> float | None:
        t = self.peg.time
        return None if t is None else t + self.offset


_planned = itertools.count()


class TimedBehaviour:
    """A behaviour placed in time: its sync points, preferred timing, keys and what has been played."""

    def __init__(self, run: "BlockRun", behaviour: Behaviour, preferred: Sequence[float],
                 keys: list[KeyRef | None], engine: "Engine"):
        self.run = run
        self.behaviour = behaviour
        self.sync_ids = list(behaviour.sync_ids)
        self.preferred = list(preferred)
        self.keys = keys
        self.engine = engine
        self.passed: list[float | None] = [None] * len(self.sync_ids)
        self.order = next(_planned)  # ties at one time are passed in planning order
        self.tied = [False] * len(self.sync_ids)  # which keys share a peg with other sync points
        self.heap_version = 0  # which of the player's heap entries for this behaviour is current
        self.next_index = 0
        self.state = "planned"  # planned -> active -> finished | dropped

    @property
    def id(self) -> str:
        return self.behaviour.id

    @property
    def block_id(self) -> str:
        return self.run.block.id

    def _anchor(self, i: int) -> float | None:
        passed = self.passed[i]
        if passed is not None:
            return passed
        key = self.keys[i]
        return None if key is None else key.time

    def time(self, i: int) -> float | None:
        """Global time of sync point ``i`` as planned now (or as it was passed)."""
        t = self._anchor(i)
        if t is not None:
            return t
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
        times = [self._anchor(i) for i in range(len(self.keys))]
        pref = self.preferred
        lo = None
        for hi, t_hi in enumerate(times):
            if t_hi is None:
                continue
            if lo is not None and hi > lo + 1:
                t_lo, p_lo, p_hi = times[lo], pref[lo], pref[hi]
                for i in range(lo + 1, hi):
                    times[i] = t_lo if p_hi <= p_lo else t_lo + (pref[i] - p_lo) / (p_hi - p_lo) * (t_hi - t_lo)
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

    def next_time(self) -> float | None:
        """When the next sync point is due (None if not active, done, or not known to come)."""
        if self.state != "active" or self.next_index >= len(self.sync_ids):
            return None
        t = self.time(self.next_index)
        return t if t is not None and t < math.inf else None

    def own_pegs(self) -> Iterable[OffsetPeg]:
        for key in self.keys:
            if key is not None and isinstance(key.peg, OffsetPeg):
                yield key.peg

    def __repr__(self) -> str:
        return f"TimedBehaviour({self.block_id}:{self.id}, {self.times()})"


class SyncPeg(TimePeg):
    """A read-only peg at one sync point of a timed behaviour, tied or placed by time warping.

    It lets other blocks tie their behaviours to any sync point of this one.
    """

    __slots__ = ("timed", "index")

    def __init__(self, timed: TimedBehaviour, index: int):
        super().__init__(None, name=f"{timed.block_id}:{timed.id}:{timed.sync_ids[index]}")
        self.timed = timed
        self.index = index

    @property
    def time(self) -> float | None:
        return self.timed.time(self.index)

    def set(self, time: float | None) -> None:
        raise ValueError(f"{self.name} is placed by its behaviour and cannot be moved directly")


def stretch_times(preferred: Sequence[float], known: dict[int, float], start: float = 0.0) -> list[float]:
    """Times for every key given some known ones: linear stretch between known keys (Elckerlyc 5.4).

    Keys before the first and after the last known key keep the average stretch of the known span
    (1 with fewer than two known keys); with no known key the behaviour starts at ``start`` with its
    preferred timing. Raises :class:`ScheduleError` when known keys are out of order.
    """
    n = len(preferred)
    if not known:
        return [start + p - preferred[0] for p in preferred]
    order = sorted(known)
    for a, b in zip(order, order[1:]):
        if known[b] < known[a] - EPSILON:
            raise ScheduleError("sync points would happen out of order")
    first, last = order[0], order[-1]
    span_p = preferred[last] - preferred[first]
    stretch = (known[last] - known[first]) / span_p if len(order) > 1 and span_p > EPSILON else 1.0
    if stretch <= EPSILON:
        stretch = 1.0
    times = [0.0] * n
    for i in range(n):
        if i in known:
            times[i] = known[i]
        elif i < first:
            times[i] = known[first] - stretch * (preferred[first] - preferred[i])
        elif i > last:
            times[i] = known[last] + stretch * (preferred[i] - preferred[last])
    for a, b in zip(order, order[1:]):
        p_a, p_b = preferred[a], preferred[b]
        for i in range(a + 1, b):
            frac = (preferred[i] - p_a) / (p_b - p_a) if p_b > p_a else 0.0
            times[i] = known[a] + frac * (known[b] - known[a])
    return times


class Planner:
    """What the scheduler may ask of an engine's planner (Elckerlyc section 5.2)."""

    behaviour_types: tuple[str, ...] = ()
    #: Keys that are always tied to pegs (others are placed by time warping between them).
    rigid = False

    def __init__(self) -> None:
        self.plan: list[TimedBehaviour] = []

    def preferred(self, behaviour: Behaviour) -> list[float]:
        """Preferred time of each sync point, seconds after the behaviour's start."""
        raise NotImplementedError

    def resolve(self, behaviour: Behaviour, known: dict[str, float], start: float = 0.0,
                preferred: list[float] | None = None) -> list[float]:
        """Times (seconds after block start) for all sync points, given the ``known`` ones.

        Raises :class:`ScheduleError` if the behaviour cannot satisfy them. ``preferred`` saves asking
        for the preferred timing again.
        """
        pref = preferred if preferred is not None else self.preferred(behaviour)
        index = {s: i for i, s in enumerate(behaviour.sync_ids)}
        times = stretch_times(pref, {index[s]: t for s, t in known.items()}, start)
        self.check_times(behaviour, pref, times)
        return times

    def check_times(self, behaviour: Behaviour, preferred: Sequence[float], times: Sequence[float]) -> None:
        """Raise :class:`ScheduleError` unless ``times`` is a valid timing for ``behaviour``."""
        for a, b in zip(times, times[1:]):
            if b < a - EPSILON:
                raise ScheduleError("sync points would happen out of order")
        if times[-1] - times[0] <= EPSILON and preferred[-1] > preferred[0]:
            raise ScheduleError("the behaviour would have no duration")

    def add(self, timed: TimedBehaviour) -> None:
        self.plan.append(timed)

    def remove(self, timed: TimedBehaviour) -> None:
        if timed in self.plan:
            self.plan.remove(timed)

    def invalid_behaviours(self) -> list[tuple[TimedBehaviour, str]]:
        """Behaviours in the plan whose current timing (after pegs moved) is no longer valid."""
        invalid = []
        for timed in self.plan:
            if timed.state == "finished":
                continue
            times = timed.times()
            if any(t is None for t in times):
                invalid.append((timed, "a sync point lost its time"))
                continue
            try:
                self.check_times(timed.behaviour, timed.preferred, times)
            except ScheduleError as exc:
                invalid.append((timed, str(exc)))
        return invalid


class Plan:
    """The timed behaviours an engine is playing, and how its player learns that times changed.

    :meth:`kick` with no argument says "anything may have moved"; with behaviours, only those moved.
    """

    def __init__(self, env: simpy.Environment):
        self.env = env
        self.behaviours: list[TimedBehaviour] = []
        self._changed = env.event()
        self.moved: set[TimedBehaviour] | None = set()  # None: everything

    def changed(self) -> simpy.Event:
        return self._changed

    def kick(self, moved: Iterable[TimedBehaviour] | None = None) -> None:
        """Tell the player that the times of ``moved`` behaviours (default: any) changed."""
        if moved is None:
            self.moved = None
        elif self.moved is not None:
            self.moved.update(moved)
        if not self._changed.triggered:
            self._changed.succeed()

    def renew(self) -> None:
        if self._changed.triggered:
            self._changed = self.env.event()


class Player:
    """Plays a plan: passes each sync point at the exact simulated time of its key.

    The next key of every active behaviour waits in a heap; an entry is checked against the behaviour's
    current timing before it is acted on, so moved pegs are honoured. ``on_sync`` is called for every sync
    point passed, in time order (ties: in the order the behaviours were planned), with the global time.
    """

    def __init__(self, env: simpy.Environment, plan: Plan, on_sync: Callable[[TimedBehaviour, int, float], None]):
        self.env = env
        self.plan = plan
        self.on_sync = on_sync
        self._heap: list[tuple[float, int, int, TimedBehaviour]] = []
        self.process = env.process(self.run())

    def _push(self, timed: TimedBehaviour) -> None:
        """(Re)enter a behaviour's next key; an earlier entry of the same behaviour becomes stale."""
        timed.heap_version += 1
        t = timed.next_time()
        if t is not None:
            heapq.heappush(self._heap, (t, timed.order, timed.heap_version, timed))

    def _refresh(self) -> None:
        moved = self.plan.moved
        self.plan.moved = set()
        if moved is None:
            self._heap = []
            for timed in self.plan.behaviours:
                self._push(timed)
        else:
            for timed in moved:
                self._push(timed)

    def _top(self) -> tuple[float, TimedBehaviour] | None:
        """The earliest next key, after discarding entries that no longer match their behaviour."""
        heap = self._heap
        while heap:
            t, order, version, timed = heap[0]
            if timed.state != "active" or timed.heap_version != version:
                heapq.heappop(heap)
                continue
            current = timed.next_time()
            if current is None:
                heapq.heappop(heap)
                continue
            if abs(current - t) > EPSILON:  # moved since it was pushed
                heapq.heapreplace(heap, (current, order, version, timed))
                continue
            return t, timed
        return None

    def next_time(self) -> float | None:
        top = self._top()
        return None if top is None else top[0]

    def run(self):
        while True:
            self.plan.renew()
            self._refresh()
            t_next = self.next_time()
            changed = self.plan.changed()
            if t_next is None:
                yield changed
            elif t_next > self.env.now + EPSILON:
                yield self.env.timeout(t_next - self.env.now) | changed
            self.pass_due()

    def pass_due(self) -> None:
        """Pass every sync point whose time has come, earliest first."""
        now = self.env.now
        while True:
            top = self._top()
            if top is None or top[0] > now + EPSILON:
                return
            t, timed = top
            heapq.heappop(self._heap)
            i = timed.next_index
            # A key that moved into the past is passed now: that is when it really happens.
            actual = t if t >= now - EPSILON else now
            previous = timed.passed[i - 1] if i > 0 else None
            if previous is not None and actual < previous:
                actual = previous
            timed.passed[i] = actual
            timed.next_index += 1
            self.on_sync(timed, i, actual)
            self._push(timed)


class Engine:
    """A Planner, its Plan and a Player, for one output channel (speech, animation, ...)."""

    name = "engine"

    def __init__(self, env: simpy.Environment, planner: Planner,
                 on_sync: Callable[[TimedBehaviour, int, float], None]):
        self.env = env
        self.planner = planner
        self.plan = Plan(env)
        self.planner.plan = self.plan.behaviours
        self.player = Player(env, self.plan, self.sync_passed)
        self._report = on_sync

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        """A sync point was passed: engine-specific work, then feedback."""
        self._report(timed, index, time)

    def activate(self, timed: TimedBehaviour) -> None:
        timed.state = "active"
        self.plan.kick([timed])

    def remove(self, timed: TimedBehaviour) -> None:
        self.planner.remove(timed)
        self.plan.kick()
