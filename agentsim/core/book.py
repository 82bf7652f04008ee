"""The block book: the blocks submitted, those still to end, the behaviours dropped, and how the set of
planned behaviours has changed.

:class:`BlockBook` owns ``runs`` (not yet ended, in submission order), ``all_runs`` (every run kept, refused
ones too), ``drops`` (the :class:`~agentsim.core.recording.DropRecord` of every behaviour dropped or cut),
``structure_version`` (bumped whenever behaviours are added or re-tied) and which ended runs it keeps
(``keep``). Only its methods change them; the others read them. The runs themselves own their states
(:class:`~agentsim.core.timed.BlockRun`).
"""

from __future__ import annotations

from typing import Iterable

from agentsim.core.recording import DropRecord
from agentsim.core.timed import REFUSED, BlockRun, TimedBehaviour


class BlockBook:
    """The record of the blocks submitted to one scheduler.

    Parameters
    ----------
    keep : int, optional
        How many ended blocks are kept (None: all): older ones, once nothing refers to them by name any more,
        are let go (:meth:`retire`, :meth:`release`).
    """

    def __init__(self, keep: int | None = None):
        self.runs: list[BlockRun] = []  # not yet ended, in submission order
        self.all_runs: list[BlockRun] = []
        self.drops: list[DropRecord] = []
        #: bumped whenever behaviours are added or re-tied, so that the retimer's dependants know to look again
        self.structure_version = 0
        self.keep = keep
        self._ended: list[BlockRun] = []  # ended or refused runs, oldest first (with ``keep``)

    # ------------------------------------------------------------------ runs
    def enter(self, run: BlockRun) -> None:
        """A block was submitted (even if it is refused): it can be found by its id."""
        self.all_runs.append(run)

    def open(self, run: BlockRun) -> None:
        """A block was planned: it is pending or running until it ends."""
        self.runs.append(run)

    def close(self, run: BlockRun) -> None:
        """A block ended: it is no longer among the open runs."""
        if run in self.runs:
            self.runs.remove(run)

    def is_open(self, block_id: str) -> bool:
        """Whether a block with this id is pending or running."""
        return any(r.id == block_id for r in self.runs)

    def find(self, block_id: str) -> BlockRun | None:
        """The latest run of a block with this id (pending, running or ended), or None."""
        return next((r for r in reversed(self.all_runs) if r.id == block_id and r.state is not REFUSED),
                    None)

    def live_behaviours(self) -> list[TimedBehaviour]:
        """Every behaviour of the open runs that is planned or playing."""
        return [t for r in self.runs for t in r.live()]

    def changed(self) -> None:
        """Behaviours were added, or their ties changed."""
        self.structure_version += 1

    # ------------------------------------------------------------------ drops
    def add_drop(self, record: DropRecord) -> None:
        self.drops.append(record)

    def add_drops(self, records: Iterable[DropRecord]) -> None:
        self.drops.extend(records)

    # ------------------------------------------------------------------ forgetting
    def retire(self, run: BlockRun) -> list[BlockRun]:
        """A run is over (ended or refused): with :attr:`keep`, the oldest ones beyond it that are to be let
        go now (in batches, so that each costs O(1) amortised; see :meth:`release`), else none."""
        if self.keep is None:
            return []
        self._ended.append(run)
        if len(self._ended) <= 2 * self.keep + 16:
            return []
        cut = len(self._ended) - self.keep
        gone = self._ended[:cut]
        del self._ended[:cut]
        return gone

    def release(self, runs: list[BlockRun]) -> set[str]:
        """Forget ended runs: they leave :attr:`all_runs`, and their drops go unless a later block of the same
        id is kept. Returns the ids of those no kept block has (whose names are free again)."""
        gone = {id(r) for r in runs}
        self.all_runs = [r for r in self.all_runs if id(r) not in gone]
        kept = {r.id for r in self.all_runs}
        released = {r.id for r in runs} - kept
        self.drops = [d for d in self.drops if d.block not in released]
        return released
