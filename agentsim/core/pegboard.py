"""Time pegs and the PegBoard: symbolic times that behaviours are tied to, and that can move.

A :class:`TimePeg` holds a global time in seconds (or ``None`` while unknown). An :class:`OffsetPeg` is
tied to another peg at a fixed offset, so moving the base moves every peg tied to it. Block pegs stand
for the start of a BML block; anticipator pegs stand for predicted events in the world and are moved by
their anticipator. Sync points that constraints tie together share one peg. The pegs of one board share a
:class:`TimeCache`: the pegs of two realizers in one process never disturb each other's.
"""

from __future__ import annotations

import contextlib
from typing import Callable

class TimeCache:
    """Whether the times that offset pegs remember are still good: any change to a peg starts a new
    generation, and a remembered time is good in the generation it was computed in. Cheap to bump, and
    evaluation stays O(1) amortised for long chains of offset pegs.

    The pegs of one :class:`PegBoard` share its cache; a peg made without a board or a cache gets one of
    its own, and an offset peg shares its base's.
    """

    __slots__ = ("generation",)

    def __init__(self) -> None:
        self.generation = 0

    def invalidate(self) -> None:
        """Forget every time remembered so far."""
        self.generation += 1


class TimePeg:
    """A symbolic time: a global time in seconds, or ``None`` while it is not known yet.

    ``board``: the board told of its moves (None: nobody is told); ``cache``: the :class:`TimeCache` its
    changes invalidate (by default the board's, else one of its own).
    """

    __slots__ = ("name", "board", "cache", "_time", "_cached", "_cached_in")

    def __init__(self, time: float | None = None, name: str = "", board: "PegBoard | None" = None,
                 cache: TimeCache | None = None):
        self.name = name
        self.board = board
        if cache is None:
            cache = board.cache if board is not None else TimeCache()
        self.cache = cache
        self._time = time
        self._cached: float | None = None
        self._cached_in = -1

    @property
    def time(self) -> float | None:
        """Global time of the peg in seconds, ``None`` if unknown."""
        return self._time

    def set(self, time: float | None) -> None:
        """Move the peg to ``time`` (global seconds); everything tied to it moves along."""
        if time == self._time:
            return
        self._time = time
        self.cache.invalidate()
        if self.board is not None:
            self.board.moved(self)

    def root(self) -> "TimePeg":
        """The peg this one is ultimately tied to (itself for a plain peg)."""
        return self

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, {self.time!r})"


class OffsetPeg(TimePeg):
    """A peg tied to ``base`` at a fixed ``offset`` (seconds): its time is ``base.time + offset``.

    Setting an offset peg moves its base, as in Elckerlyc: the tie is kept. ``shift`` and ``rebase``
    change the tie itself (the scheduler uses them while planning).
    """

    __slots__ = ("base", "offset", "anchor")

    def __init__(self, base: TimePeg | None, offset: float = 0.0, name: str = "", anchor: bool = False,
                 board: "PegBoard | None" = None):
        cache = None if board is not None or base is None else base.cache
        super().__init__(None, name, board, cache)
        self.base = base
        self.offset = offset
        self.anchor = anchor

    @property
    def time(self) -> float | None:
        if self._cached_in == self.cache.generation:
            return self._cached
        # Walk up iteratively (chains can be long), then remember the times on the way back.
        chain: list[OffsetPeg] = []
        peg: TimePeg | None = self
        while isinstance(peg, OffsetPeg) and peg._cached_in != peg.cache.generation:
            chain.append(peg)
            peg = peg.base
        value = None if peg is None else peg.time
        for p in reversed(chain):
            value = None if value is None else value + p.offset
            p._cached, p._cached_in = value, p.cache.generation
        return value

    def set(self, time: float | None) -> None:
        if time is None or self.base is None:
            raise ValueError("an offset peg can only be set when its base is known")
        base_time = self.base.time
        if base_time is None:
            raise ValueError("an offset peg can only be set when its base is known")
        self.base.set(time - self.offset)

    def shift(self, delta: float) -> None:
        """Change the offset by ``delta`` seconds, moving this peg and all tied to it."""
        if delta:
            self.offset += delta
            self.cache.invalidate()
            if self.board is not None:
                self.board.moved(self)

    def rebase(self, base: TimePeg, offset: float) -> None:
        """Tie this peg to another ``base`` at ``offset``."""
        self.base = base
        self.offset = offset
        self.cache.invalidate()
        if self.board is not None:
            self.board.moved(self)

    def freeze(self, block_peg: TimePeg) -> None:
        """Detach from whatever this peg was tied to: keep its current time, relative to ``block_peg``."""
        t, b = self.time, block_peg.time
        if t is not None and b is not None and self.base is not block_peg:
            self.rebase(block_peg, t - b)

    def root(self) -> TimePeg:
        peg: TimePeg = self
        while isinstance(peg, OffsetPeg) and peg.base is not None:
            peg = peg.base
        return peg


class ComputedPeg(TimePeg):
    """A peg whose time is computed from something else (a behaviour's timing, a speech's animator time).

    Subclasses define :meth:`compute`; the peg cannot be set. Whoever changes its source invalidates the
    times of the board (:meth:`PegBoard.invalidate_times`) and reports the move (an engine through its
    context). :meth:`pin` ends the
    computing: the peg keeps one time from then on (an interrupted speech's end).
    """

    __slots__ = ("pinned",)

    def __init__(self, time: float | None = None, name: str = "", board: "PegBoard | None" = None,
                 cache: TimeCache | None = None):
        super().__init__(time, name, board, cache)
        self.pinned: float | None = None

    def compute(self) -> float | None:
        """The time as computed from the source."""
        raise NotImplementedError

    @property
    def time(self) -> float | None:
        return self.pinned if self.pinned is not None else self.compute()

    def pin(self, time: float) -> None:
        """Stop computing: the peg stays at ``time`` (global seconds) from now on."""
        self.pinned = float(time)
        self.cache.invalidate()

    def set(self, time: float | None) -> None:
        raise ValueError(f"{self.name} is computed from its source and cannot be moved directly")


class PegBoard:
    """The shared board of time pegs: block pegs, anticipator pegs and named behaviour sync pegs.

    Listeners registered with :meth:`on_move` are called whenever a peg is moved after planning, so that
    the scheduler can re-time what is tied to it. The board owns what its realizer's pegs and behaviours
    share: the :class:`TimeCache` of its pegs (:attr:`cache`) and the order in which behaviours are planned
    (:meth:`plan_order`).
    """

    def __init__(self) -> None:
        self.cache = TimeCache()
        #: how many behaviours were planned on this board (:meth:`plan_order`)
        self.planned = 0
        self.block_pegs: dict[str, TimePeg] = {}
        # block id -> {(behaviour id, sync id): (peg, offset)}, and block id -> {behaviour id: ...}
        self._sync_pegs: dict[str, dict[tuple[str, str], tuple[TimePeg, float]]] = {}
        self._behaviours: dict[str, dict[str, tuple[list[str], Callable[[int], TimePeg]]]] = {}
        self._listeners: list[Callable[[TimePeg], None]] = []
        self.muted = 0

    def invalidate_times(self) -> None:
        """Forget every time its pegs remember: call it when a :class:`ComputedPeg`'s source changed (a
        speech's animator time learnt something), since no ``set`` tells the pegs tied to it."""
        self.cache.invalidate()

    def plan_order(self) -> int:
        """The place of a behaviour planned now among those planned on this board (0, 1, 2, ...): ties at
        one time are passed in this order."""
        self.planned += 1
        return self.planned - 1

    def block_peg(self, block_id: str, time: float | None = None) -> TimePeg:
        """The peg standing for the start of block ``block_id`` (created on first use)."""
        peg = self.block_pegs.get(block_id)
        if peg is None:
            peg = self.new_block_peg(block_id, time)
        return peg

    def new_block_peg(self, block_id: str, time: float | None) -> TimePeg:
        """A new peg for the start of block ``block_id``, replacing any earlier block of that id."""
        peg = TimePeg(time, name=f"{block_id}:start", board=self)
        self.block_pegs[block_id] = peg
        return peg

    def register_behaviour(self, block_id: str, behaviour_id: str, sync_ids: list[str],
                           peg_for: Callable[[int], TimePeg]) -> None:
        """Make every sync point of a behaviour findable; ``peg_for(i)`` makes the peg of sync ``i`` when
        another block first asks for it."""
        self._behaviours.setdefault(block_id, {})[behaviour_id] = (sync_ids, peg_for)

    def find_sync(self, block_id: str, behaviour_id: str, sync_id: str) -> tuple[TimePeg, float] | None:
        """Where ``block:behaviour:sync`` is: a peg and an offset (time = ``peg.time + offset``)."""
        pegs = self._sync_pegs.setdefault(block_id, {})
        found = pegs.get((behaviour_id, sync_id))
        if found is None:
            registered = self._behaviours.get(block_id, {}).get(behaviour_id)
            if registered is not None and sync_id in registered[0]:
                sync_ids, peg_for = registered
                found = pegs[(behaviour_id, sync_id)] = (peg_for(sync_ids.index(sync_id)), 0.0)
        return found

    def handed_out(self, block_id: str, behaviour_id: str) -> dict[str, TimePeg]:
        """The pegs of a behaviour's sync points that other blocks asked for, by sync id."""
        pegs = self._sync_pegs.get(block_id, {})
        return {sync: peg for (beh, sync), (peg, _) in pegs.items() if beh == behaviour_id}

    def forget_behaviour(self, block_id: str, behaviour_id: str) -> None:
        """Forget where a removed behaviour's sync points are: later blocks cannot tie to it."""
        self._behaviours.get(block_id, {}).pop(behaviour_id, None)
        pegs = self._sync_pegs.get(block_id, {})
        for key in [k for k in pegs if k[0] == behaviour_id]:
            del pegs[key]

    def forget_block(self, block_id: str) -> None:
        """Forget where the sync points of a block are (pegs already handed out stay valid)."""
        self._sync_pegs.pop(block_id, None)
        self._behaviours.pop(block_id, None)

    def on_move(self, listener: Callable[[TimePeg], None]) -> None:
        """Call ``listener(peg)`` whenever a peg is moved (outside :meth:`quiet`)."""
        self._listeners.append(listener)

    @contextlib.contextmanager
    def quiet(self):
        """Peg moves made inside are not reported (whoever moves them takes care of the consequences)."""
        self.muted += 1
        try:
            yield
        finally:
            self.muted -= 1

    def moved(self, peg: TimePeg) -> None:
        """``peg`` was moved: tell the listeners (unless quiet)."""
        if self.muted:
            return
        for listener in self._listeners:
            listener(peg)
