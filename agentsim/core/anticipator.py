"""The anticipator interface: an owner of time pegs that stand for predicted events in the world."""

from __future__ import annotations

import simpy

from agentsim.core.pegboard import PegBoard, TimePeg


class Anticipator:
    """Owns pegs named by sync ids (``beat1``, ``beat2``, ...) and moves them as its predictions change.

    BML refers to them as ``anticipators:<id>:<sync>``. Subclasses create pegs on demand in
    :meth:`make_peg`, move them with :meth:`move`, and may run a SimPy process (:meth:`run`) that consumes
    perceptions; :meth:`stop` ends it cleanly. ``confidence`` (0 to 1) says how much the predictions can be
    trusted.
    """

    def __init__(self, anticipator_id: str):
        self.id = anticipator_id
        self.pegs: dict[str, TimePeg] = {}
        self.confidence = 1.0
        self.env: simpy.Environment | None = None
        self.board: PegBoard | None = None
        self.process: simpy.Process | None = None

    def attach(self, env: simpy.Environment, board: PegBoard) -> None:
        """Join a realizer: pegs report their moves to ``board``; :meth:`run` starts if defined."""
        self.env = env
        self.board = board
        for peg in self.pegs.values():
            peg.board = board
        run = self.run()
        if run is not None:
            self.process = env.process(run)

    def peg(self, sync_id: str) -> TimePeg | None:
        """The peg for ``sync_id`` (created on first use), or None if this anticipator has no such sync."""
        peg = self.pegs.get(sync_id)
        if peg is None:
            time = self.make_peg(sync_id)
            if time is False:
                return None
            peg = TimePeg(time, name=f"anticipators:{self.id}:{sync_id}", board=self.board)
            self.pegs[sync_id] = peg
        return peg

    def make_peg(self, sync_id: str) -> float | None | bool:
        """Predicted time for a new peg ``sync_id`` (None if not known yet), or False if there is none."""
        return False

    def move(self, sync_id: str, time: float | None) -> None:
        """Move one of this anticipator's pegs; everything tied to it is re-timed."""
        self.peg(sync_id).set(time)

    def run(self):
        """A SimPy process consuming perceptions (None: this anticipator needs none)."""
        return None

    def stop(self) -> None:
        """End the process, if one runs."""
        if self.process is not None and self.process.is_alive:
            self.process.interrupt("stop")
