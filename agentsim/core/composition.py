"""How blocks meet: what a pending block waits for (APPEND, APPEND-AFTER, CHUNK-AFTER, preplanning, the blocks
it interrupts), when it would start, when a block subsides, and how chunks coarticulate.

:class:`Composer` owns nothing but its collaborators. It writes what a run waits for (its ``after`` and
``chunk_after``, those of the blocks a new one is prepended or chunked before), its wake event (what its
waiting process looks at again) and, when chunks coarticulate, the keys of the earlier chunk's gestures; it
asks the :class:`~agentsim.core.book.BlockBook` for runs (and tells it when ties changed) and the
:class:`~agentsim.core.reporter.Reporter` to warn. Interrupting the blocks a block names (``bmla:interrupt``)
is the scheduler's, once the composer says that block may start.
"""

from __future__ import annotations

import simpy

from agentsim.core.book import BlockBook
from agentsim.core.interruption import hands
from agentsim.core.reporter import Reporter
from agentsim.core.timed import ENDED, EPSILON, OPEN, PENDING, BlockRun, KeyRef, SyncPeg, TimedBehaviour


class Composer:
    """Block composition for the scheduler.

    Parameters
    ----------
    env : simpy.Environment
        The clock (a block that may start starts now at the earliest).
    book : BlockBook
        The runs: which are open, which a block names.
    reporter : Reporter
        Where warnings about blocks named that cannot be waited for go.
    """

    def __init__(self, env: simpy.Environment, book: BlockBook, reporter: Reporter):
        self.env = env
        self.book = book
        self.reporter = reporter

    def link(self, run: BlockRun) -> None:
        """Find what a new block waits for (APPEND, APPEND-AFTER, CHUNK-AFTER and their BMLA forms), and make
        the blocks its prependBefore and chunkBefore name wait for it. Unknown blocks and circles are
        reported and left out. The blocks it interrupts and activates are looked up when it starts."""
        block = run.block
        warn = self.reporter.warn
        if block.composition == "APPEND":
            run.after.extend(r for r in self.book.runs if not r.dormant)
        for ids, found, what in ((block.append_after, run.after, "appendAfter"),
                                 (block.chunk_after, run.chunk_after, "chunkAfter")):
            for block_id in ids:
                other = self.book.find(block_id)
                if other is None:
                    warn(block.id, "NO_SUCH_TARGET", f"{what}: there is no block {block_id!r}; ignored",
                         block.character_id)
                elif other not in found and other.state in OPEN:
                    found.append(other)
        for ids, what in ((block.prepend_before, "prependBefore"), (block.chunk_before, "chunkBefore")):
            for block_id in ids:
                other = self.book.find(block_id)
                if other is None or other.state is not PENDING:
                    state = "there is no such block" if other is None else f"it is {other.state}"
                    warn(block.id, "NO_SUCH_TARGET", f"{what}: block {block_id!r} cannot wait for this one "
                         f"({state}); ignored", block.character_id)
                    continue
                if self.waits_for(run, other):
                    warn(block.id, "IMPOSSIBLE_TO_SCHEDULE", f"{what}: block {block_id!r} waits for this "
                         "one already, directly or not; ignored", block.character_id)
                    continue
                (other.after if what == "prependBefore" else other.chunk_after).append(run)
                self.wake(other)

    def waits_for(self, run: BlockRun, other: BlockRun) -> bool:
        """Whether ``run`` waits, directly or through others, for ``other`` to end or subside."""
        seen: set[int] = set()
        todo = [run]
        while todo:
            current = todo.pop()
            if current is other:
                return True
            if id(current) not in seen:
                seen.add(id(current))
                todo.extend(current.after + current.chunk_after)
        return False

    def predicted_end(self, run: BlockRun) -> float:
        if run.state is ENDED:
            return run.ended_at
        ends = [t.end for t in run.live()]
        return max([run.block_peg.time] + [e for e in ends if e is not None and e < float("inf")])

    def subsiding_time(self, run: BlockRun) -> float:
        """When a block subsides: every behaviour past its relax (the start of its retraction), or ended."""
        if run.state is ENDED:
            return run.ended_at
        times = [run.block_peg.time]
        for timed in run.live():
            t = timed.sync_time("relax") if "relax" in timed.sync_ids else timed.end
            if t is not None and t < float("inf"):
                times.append(t)
        return max(times)

    def awaited(self, run: BlockRun) -> float | None:
        """When what a pending block waits for ends or subsides, as things stand (None: it waits for none)."""
        times = [self.predicted_end(r) for r in run.after if not r.dormant]
        times += [self.subsiding_time(r) for r in run.chunk_after if not r.dormant]
        return max(times) if times else None

    def predicted_start(self, run: BlockRun) -> float:
        """When a pending block would start as things stand: now, or when what it waits for ends or subsides."""
        awaited = self.awaited(run)
        return self.env.now if awaited is None else max(self.env.now, awaited)

    @staticmethod
    def appended(run: BlockRun) -> bool:
        """Whether a run is pending and waits for others to end or subside (its start moves with theirs)."""
        return run.state is PENDING and not run.dormant and bool(run.after or run.chunk_after)

    def coarticulate(self, run: BlockRun) -> None:
        """A chunk follows the gestures of the chunks before it without a gap: a gesture of an earlier chunk
        whose hand a gesture of this one takes while it retracts skips its retraction and ends when the new
        gesture starts (so that its relax, its end and the new start meet)."""
        arm = ("gesture", "pointing")
        new = sorted((t for t in run.timed if t.behaviour.type in arm), key=lambda t: t.start or 0.0)
        for earlier in run.chunk_after:
            for old in earlier.live():
                if old.behaviour.type not in arm or "relax" not in old.sync_ids:
                    continue
                relax, end = old.sync_time("relax"), old.end
                follower = next((t for t in new if hands(t) & hands(old) and t.start is not None
                                 and relax - EPSILON <= t.start <= end + EPSILON), None)
                if follower is not None:
                    self.hold_relax(old)
                    old.keys[-1] = KeyRef(SyncPeg(follower, 0))
                    old.tied[-1] = old.fixed[-1] = True
                    old.owns[-1] = False
                    self.book.changed()

    @staticmethod
    def hold_relax(timed: TimedBehaviour) -> None:
        """Key a behaviour's relax where it is now, relative to the nearest keyed sync point before it, so
        that moving its end does not move it."""
        relax = timed.sync_ids.index("relax")
        if timed.keys[relax] is not None:
            return
        before = max(i for i in range(relax) if timed.keys[i] is not None)
        key = timed.keys[before]
        timed.keys[relax] = KeyRef(key.peg, key.offset + timed.time(relax) - timed.time(before))

    def waits(self, run: BlockRun) -> list[simpy.Event] | None:
        """What a pending block still waits for (events to wait on), or None if it may start now as far as
        the blocks it follows go (the blocks it names to interrupt are interrupted then: see
        :meth:`~agentsim.core.scheduler.Scheduler.waits`)."""
        now = self.env.now
        if run.block.preplan and not run.activated:
            return [self.wake_event(run)]
        ending = [r.ended for r in run.after if not r.ended.triggered and not r.dormant]
        if ending:
            return ending + [self.wake_event(run)]
        subsides = max([now] + [self.subsiding_time(r) for r in run.chunk_after if not r.dormant])
        if subsides > now + EPSILON:
            return [self.env.timeout(subsides - now), self.wake_event(run)]
        return None

    def wake_event(self, run: BlockRun) -> simpy.Event:
        """The event a pending run's process waits on besides what it waits for: it succeeds at :meth:`wake`
        (a new one once it has)."""
        if run.wake is None or run.wake.triggered:
            run.wake = self.env.event()
        return run.wake

    @staticmethod
    def wake(run: BlockRun) -> None:
        """What a pending block waits for changed (or it was started otherwise): its process looks again."""
        if run.wake is not None and not run.wake.triggered:
            run.wake.succeed()
