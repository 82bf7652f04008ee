"""Building many objects at once without the garbage collector's passes over them.

Reading a large BML block and scheduling it make tens of thousands of small objects that all live on
(tree nodes, references, pegs, timed behaviours). Each few hundred allocations trigger a collection, and
every tenth of those looks at all younger objects again; as the block grows, so does the work of each
pass, and the total grows faster than the block. None of those objects is garbage while the block is
being built, so :func:`paused_collection` holds the collector off for that stretch (nested uses hold it
off until the outermost one ends).

When it ends, the objects made meanwhile would all be in the youngest generation, and the next
collection would look at every one of them, and the one after at them again, only to find them alive.
When there are many (more than :data:`FEW`), they are moved to the oldest generation at once instead
(``gc.freeze`` then ``gc.unfreeze``, which only relink lists): they are looked at by full collections
only. So that garbage among them (a block released later, with its cycles) cannot pile up, a full
collection is made here once the objects moved since the last one outnumber :data:`GROWTH` times those
alive after it (or made in the pause that called for it, if they were more). Nothing is moved while
objects are frozen by the program itself (``gc.freeze``, as the live service does once it has warmed
up): unfreezing would put those back among the collected.
"""

from __future__ import annotations

import contextlib
import gc
from typing import Iterator

#: Fewer new objects than this are left in the youngest generation as usual (their collection is cheap).
FEW = 5_000
#: A full collection is made when the objects moved since the last one exceed this many times those alive
#: after it, or made by the pause that called for it if they were more (counting at least :data:`FLOOR`).
GROWTH = 16
FLOOR = 100_000

_moved = 0
_budget = GROWTH * FLOOR


@contextlib.contextmanager
def paused_collection() -> Iterator[None]:
    """Hold automatic garbage collection off for the ``with`` block (a no-op if it is already off)."""
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        _settle()
        gc.enable()


def _settle() -> None:
    """Move what the pause made to the oldest generation if it is much, collecting fully now and then."""
    global _moved, _budget
    young = gc.get_count()[0]
    if young < FEW or gc.get_freeze_count():
        return
    gc.freeze()
    gc.unfreeze()
    _moved += young
    if _moved > _budget:
        gc.collect()
        gc.freeze()
        alive = gc.get_freeze_count()
        gc.unfreeze()
        _moved, _budget = 0, GROWTH * max(alive, young, FLOOR)
