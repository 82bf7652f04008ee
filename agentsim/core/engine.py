"""Engines as Elckerlyc splits them: a Planner fills a Plan with timed behaviours, a Player plays it.

The scheduler talks to planners only through the :class:`Planner` interface (Elckerlyc section 5.2):
preferred timing, resolve unknown times, add, remove, list invalid behaviours. An :class:`Engine` is
handed its collaborators at construction in an :class:`EngineContext`, as AsapRealizer's
``DefaultEngine(planner, player, planManager)`` is.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import simpy

from agentsim.core.block import Behaviour
from agentsim.errors import ScheduleError
from agentsim.core.interruption import due_by, skip_until
from agentsim.core.pegboard import PegBoard
from agentsim.core.timed import ACTIVE, EPSILON, FINISHED, TimedBehaviour


def stretch_times(preferred: Sequence[float], known: dict[int, float], start: float = 0.0) -> list[float]:
    """Times for every key given some known ones: linear stretch between known keys (Elckerlyc 5.4).

    Keys before the first and after the last known key keep the average stretch of the known span
    (1 with fewer than two known keys); with no known key the behaviour starts at ``start`` with its
    preferred timing. Raises :class:`ScheduleError` when known keys are out of order.
    """
    n = len(preferred)
    if not known:
        p_first = preferred[0]
        return [start + p - p_first for p in preferred]
    if len(known) == 1:  # (the commonest case, at its preferred timing from the one known key)
        (first, t_first), = known.items()
        p_first = preferred[first]
        # (``t_first - (p_first - p)`` before the key, as below, is this same number)
        times = [t_first + (p - p_first) for p in preferred]
        times[first] = t_first
        return times
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
        #: the behaviours in this planner's plan, in the order they were added (a dict used as an ordered set)
        self.plan: dict[TimedBehaviour, None] = {}

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
        sync_ids = behaviour.sync_ids
        at: dict[int, float] | None = {}
        if len(known) <= 2:  # (a key or two, found in the list: no table of every sync point made)
            try:
                for s, t in known.items():
                    at[sync_ids.index(s)] = t
            except ValueError:  # (not one of its sync points: the KeyError below says which)
                at = None
        else:
            at = None
        if at is None:
            index = {s: i for i, s in enumerate(sync_ids)}
            at = {index[s]: t for s, t in known.items()}
        times = stretch_times(pref, at, start)
        self.check_times(behaviour, pref, times)
        return times

    def check_times(self, behaviour: Behaviour, preferred: Sequence[float], times: Sequence[float]) -> None:
        """Raise :class:`ScheduleError` unless ``times`` is a valid timing for ``behaviour``."""
        try:
            total = sum(times)  # (not a number only if one of them is not, or they hold both infinities)
        except TypeError:
            total = math.nan
        if total != total and any(t != t for t in times):
            raise ScheduleError("a sync point's time is not a number (NaN)")
        try:
            in_order = times == sorted(times)  # (the usual case, told at once)
        except TypeError:  # (what is not a number: the comparisons below say so)
            in_order = False
        if not in_order:
            for a, b in zip(times, times[1:]):
                if b < a - EPSILON:
                    raise ScheduleError("sync points would happen out of order")
        if times[-1] - times[0] <= EPSILON and preferred[-1] > preferred[0]:
            raise ScheduleError("the behaviour would have no duration")

    def admit(self, timed: TimedBehaviour) -> str | None:
        """A last check once the behaviour is timed in its block: why it cannot be played (what it refers to
        does not exist), or None."""
        return None

    def add(self, timed: TimedBehaviour) -> None:
        self.plan[timed] = None

    def remove(self, timed: TimedBehaviour) -> None:
        self.plan.pop(timed, None)

    def judges(self, timed: TimedBehaviour) -> bool:
        """Whether ``timed``'s timing is judged at all (False: it is valid whatever its times are: it has
        finished, or it was interrupted and plays out what is left of it)."""
        return timed.state is not FINISHED and not timed.interrupted

    def invalid(self, timed: TimedBehaviour, times: list[float | None] | None = None) -> str | None:
        """Why ``timed``'s current timing (after pegs moved) is no longer valid, or None if it is.

        ``times``: its current times, if the caller has them already.
        """
        if not self.judges(timed):
            return None
        times = timed.times() if times is None else times
        if any(t is None for t in times):
            return "a sync point lost its time"
        if any(t == math.inf for t in times):
            return None  # waiting for the world (speech that has not got there yet): nothing to judge now
        try:
            self.check_times(timed.behaviour, timed.preferred, times)
        except ScheduleError as exc:
            return str(exc)
        return None

    def invalid_behaviours(self) -> list[tuple[TimedBehaviour, str]]:
        """Behaviours in the plan whose current timing (after pegs moved) is no longer valid."""
        found = ((timed, self.invalid(timed)) for timed in self.plan)
        return [(timed, reason) for timed, reason in found if reason is not None]


class Plan:
    """The timed behaviours an engine is playing, and how its player learns that times changed.

    :meth:`kick` with no argument says "anything may have moved"; with behaviours, only those moved.
    """

    def __init__(self, env: simpy.Environment):
        self.env = env
        self.behaviours: dict[TimedBehaviour, None] = {}  # shared with the planner's plan
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
            if timed.state is not ACTIVE or timed.heap_version != version:
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


@dataclass(frozen=True)
class EngineContext:
    """What an engine is handed at construction: the clock, the PegBoard, and three ways to talk back.

    Attributes
    ----------
    env : simpy.Environment
        The clock.
    board : PegBoard
        The shared time pegs.
    sync_passed : callable
        ``sync_passed(timed, index, time)``: sync point ``index`` of ``timed`` was passed at global
        ``time`` (seconds); the scheduler sends its feedback and ends what is done.
    pegs_moved : callable
        ``pegs_moved(pegs, horizon=None)``: these pegs moved (or their computed times changed). ``pegs``
        is an iterable of pegs or what :attr:`dependants_of` returned for them. With ``horizon``
        (seconds), only the dependants whose next sync point is that near are re-timed now; the caller
        reports again as time goes on.
    dependants_of : callable
        ``dependants_of(pegs, planned_now=None)``: the live behaviours whose timing hangs from ``pegs``,
        kept up to date as blocks come and go, ordered by planned start; ``planned_now()`` says which
        planned time the owner of the pegs has reached (default: the clock), to judge which are near.
    blocks : object
        What behaviours that act on other blocks may ask (BMLA): ``interrupt(block_id, include, exclude,
        by)``, ``activate(block_id, by)``, ``behaviour(block_id, behaviour_id)`` and ``state(block_id)``.
    """

    env: simpy.Environment
    board: PegBoard
    sync_passed: Callable[[TimedBehaviour, int, float], None]
    pegs_moved: Callable[..., None]
    dependants_of: Callable[..., object]
    blocks: object = None


class Engine:
    """A Planner, its Plan and a Player, for one output channel (speech, animation, ...)."""

    name = "engine"

    def __init__(self, context: EngineContext, planner: Planner):
        self.context = context
        self.env = context.env
        self.planner = planner
        self.plan = Plan(self.env)
        self.planner.plan = self.plan.behaviours
        self.player = Player(self.env, self.plan, self.sync_passed)

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        """A sync point was passed: engine-specific work, then feedback."""
        self.context.sync_passed(timed, index, time)

    def activate(self, timed: TimedBehaviour) -> None:
        timed.activate()
        self.plan.kick([timed])

    def activate_all(self, behaviours: list[TimedBehaviour]) -> None:
        """:meth:`activate` each of ``behaviours`` in turn (their block started), its player told once."""
        if type(self).activate is not Engine.activate:  # (an engine that does more for each)
            for timed in behaviours:
                self.activate(timed)
            return
        for timed in behaviours:
            timed.activate()
        self.plan.kick(behaviours)

    def interruption(self, timed: TimedBehaviour, now: float) -> tuple[set[int], dict[int, float]] | None:
        """What interrupting a started behaviour at ``now`` leaves of it: the sync points it skips and new
        times for some of the rest (None: nothing to change). By default it ends at once; sync points due
        by ``now`` still pass."""
        last = len(timed.sync_ids) - 1
        if timed.next_index > last or due_by(timed, last, now):
            return None
        return skip_until(timed, last, now), {last: now}

    def stopped(self, timed: TimedBehaviour, now: float) -> None:
        """``timed`` was interrupted at ``now``: stop what it makes (sound, say). Nothing by default."""

    def remove(self, timed: TimedBehaviour) -> None:
        self.planner.remove(timed)
        self.plan.kick()

    def forget(self, block_ids: set[str]) -> None:
        """The scheduler released these ended blocks: forget what is kept of them (what was heard, say)."""
