"""The wait engine: ``<wait>`` behaviours that only hold time between their start and end, and events (a sync
point without motion, from other realizers' ``<event>``) that only pass."""

from __future__ import annotations

from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError


class WaitPlanner(Planner):
    """A wait lasts one second unless its start and end are tied; an event takes no time unless they are;
    any non-negative duration is valid."""

    behaviour_types = ("wait", "event")

    def preferred(self, behaviour: Behaviour) -> list[float]:
        return [0.0, 0.0] if behaviour.type == "event" else [0.0, 1.0]

    def check_times(self, behaviour, preferred, times) -> None:
        if times[-1] < times[0] - 1e-9:
            raise ScheduleError(f"the {behaviour.type} would end before it starts")


class WaitEngine(Engine):
    name = "wait"

    def __init__(self, context: EngineContext):
        super().__init__(context, WaitPlanner())
