"""Building many objects at once without the garbage collector's full passes over everything alive.

Reading a large BML block and scheduling it make tens of thousands of small objects that all live on
(tree nodes, references, pegs, timed behaviours). Each few hundred allocations trigger a collection, and
every tenth of those looks at all younger objects again; as the block grows, so does the work of each
pass, and the total grows faster than the block. None of those objects is garbage while the block is
being built, so :func:`paused_collection` holds the collector off for that stretch and lets it run again
afterwards (nested uses hold it off until the outermost one ends). Garbage made meanwhile is collected
by the next pass as usual.
"""

from __future__ import annotations

import contextlib
import gc
from typing import Iterator


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
        gc.enable()
