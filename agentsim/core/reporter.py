"""The scheduler's voice: every warning, blockProgress, syncPointProgress and predictionFeedback it sends.

:class:`Reporter` owns the feedback log it sends to (``log``) and the count of each anticipator's faults
(``fault_counts``); it reads the clock, and the runs and behaviours it is told about, and changes nothing else.
"""

from __future__ import annotations

import simpy

from agentsim.core import feedback as fb
from agentsim.core.timed import BlockRun, TimedBehaviour


class Reporter:
    """Turns what happens to blocks and behaviours into BML feedback, stamped with the clock's time.

    Parameters
    ----------
    env : simpy.Environment
        The clock (the ``globalTime`` of a warning or prediction).
    log : FeedbackLog
        Where feedback goes.
    """

    #: Most warnings about one anticipator's faults; after them its faults are only counted.
    MAX_FAULT_WARNINGS = 100

    def __init__(self, env: simpy.Environment, log: fb.FeedbackLog):
        self.env = env
        self.log = log
        self.fault_counts: dict[str, int] = {}  # anticipator id -> faults refused

    def warn(self, target: str, kind: str, description: str, character: str, modified=(),
             line: int | None = None, column: int | None = None, adaptations=()) -> None:
        """A warningFeedback now about ``target`` (a block, ``block:behaviour``, an anticipator's peg)."""
        self.log.send(fb.warning(target, kind, description, self.env.now, character, modified, line, column,
                                 adaptations))

    def block_progress(self, run: BlockRun, which: str, time: float, interrupted: bool = False) -> None:
        """The ``start`` or ``end`` of a block at ``time`` (s); an end an interruption cut short says so."""
        self.log.send(fb.block_progress(run.id, which, time, run.block.character_id,
                                        fb.INTERRUPTED if interrupted else None))

    def sync_point(self, timed: TimedBehaviour, index: int, time: float, interrupted: bool = False) -> None:
        """Sync point ``index`` of ``timed`` was passed at ``time`` (s); ``interrupted``: it is the last one
        and an interruption cut the behaviour short."""
        run = timed.run
        self.log.send(fb.sync_point_progress(run.id, timed.id, timed.sync_ids[index], time - run.block_peg.time,
                                             time, run.block.character_id, fb.INTERRUPTED if interrupted else None))

    def prediction(self, run: BlockRun, start: float, end: float, entries: list) -> None:
        """A predictionFeedback of a block: its start and end (s) and the ``entries`` of its behaviours."""
        self.log.send(fb.prediction(run.id, self.env.now, run.block.character_id, start, end, entries))

    def anticipator_fault(self, anticipator, sync_id: str, description: str) -> None:
        """An anticipator did something that was refused (see :mod:`~agentsim.core.anticipator`): warn, up
        to :data:`MAX_FAULT_WARNINGS` times per anticipator."""
        counts = self.fault_counts
        n = counts[anticipator.id] = counts.get(anticipator.id, 0) + 1
        if n > self.MAX_FAULT_WARNINGS:
            return
        if n == self.MAX_FAULT_WARNINGS:
            description += f" (further faults of anticipator {anticipator.id!r} are not reported)"
        target = f"anticipators:{anticipator.id}" + (f":{sync_id}" if sync_id else "")
        self.warn(target, "IMPOSSIBLE_TO_SCHEDULE", description, "agent")
