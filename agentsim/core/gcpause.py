"""Building many objects at once without the garbage collector's passes over them, when a program asks.

Reading a large BML block and scheduling it make tens of thousands of small objects that all live on
(tree nodes, references, pegs, timed behaviours). Each few hundred allocations trigger a collection, and
every tenth of those looks at all younger objects again; as the block grows, so does the work of each
pass, and the total grows faster than the block. None of those objects is garbage while the block is
being built, so a :class:`CollectionPause` holds the collector off for that stretch.

When it ends, the objects made meanwhile would all be in the youngest generation, and the next
collection would look at every one of them, and the one after at them again, only to find them alive.
When there are many (more than :data:`FEW`), they are moved to the oldest generation at once instead
(``gc.freeze`` then ``gc.unfreeze``, which only relink lists): they are looked at by full collections
only. So that garbage among them (a block released later, with its cycles) cannot pile up, a full
collection is made here once the objects moved since the last one outnumber :data:`GROWTH` times those
alive after it (or made in the pause that called for it, if they were more). Nothing is moved while
objects are frozen by the program itself (``gc.freeze``, as the live service does once it has warmed
up): unfreezing would put those back among the collected.

The collector is the process's, so pausing it is the program's choice: the command line and the live
service each make one pause and hand it to their realizer (``Realizer(gc_pause=...)``); a realizer given
none leaves the collector alone.
"""

from __future__ import annotations

import contextlib
import gc
import threading
from typing import Iterator

#: Fewer new objects than this are left in the youngest generation as usual (their collection is cheap).
FEW = 5_000
#: A full collection is made when the objects moved since the last one exceed this many times those alive
#: after it, or made by the pause that called for it if they were more (counting at least :data:`FLOOR`).
GROWTH = 16
FLOOR = 100_000


def keep_out_of_collections() -> None:
    """Keep every object alive now out of the collector's later passes (``gc.freeze``), for the rest of the
    process.

    For a program that runs once and exits (a scenario's run, a worker that draws pictures): what it has
    imported and built by then (modules, classes, tables, a finished run) lives until it exits, yet each full
    collection would look at all of it again. A program that runs on (the live service) freezes only what it
    has warmed up. Objects frozen are never collected, garbage among them included: call this where what is
    alive is meant to stay.
    """
    gc.freeze()


def paused(pause: "CollectionPause | None") -> contextlib.AbstractContextManager:
    """``pause.paused()``, or a ``with`` that does nothing where a program chose no pause (None)."""
    return pause.paused() if pause is not None else contextlib.nullcontext()


class CollectionPause:
    """A program's policy of holding automatic garbage collection off while blocks are read and planned.

    ``with pause.paused():`` holds the collector off for the ``with`` block. A program has one pause, shared
    by its threads (the live service reads documents in one and plans them in another): the collector is off
    while any of them is inside and comes back on when the last one leaves. A pause that finds the collector
    off (the program turned it off) leaves it off. :attr:`moved` counts the objects moved to the oldest
    generation since the last full collection; :attr:`budget` is how many may be before the next one.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._inside = 0  # how many ``with`` blocks (of any thread) are running
        self._holding = False  # whether this pause turned the collector off
        self.moved = 0
        self.budget = GROWTH * FLOOR

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Hold automatic garbage collection off for the ``with`` block."""
        with self._lock:
            if self._inside == 0 and gc.isenabled():
                gc.disable()
                self._holding = True
            self._inside += 1
        try:
            yield
        finally:
            with self._lock:
                self._inside -= 1
                if self._inside == 0 and self._holding:
                    self._holding = False
                    try:
                        self._settle()
                    finally:
                        gc.enable()

    def _settle(self) -> None:
        """Move what the pause made to the oldest generation if it is much, collecting fully now and then."""
        young = gc.get_count()[0]
        if young < FEW or gc.get_freeze_count():
            return
        gc.freeze()
        gc.unfreeze()
        self.moved += young
        if self.moved > self.budget:
            gc.collect()
            gc.freeze()
            alive = gc.get_freeze_count()
            gc.unfreeze()
            self.moved, self.budget = 0, GROWTH * max(alive, young, FLOOR)
