"""The expression engine: ``ex:emotion`` behaviours, which hold an emotion between their start and end on the
run's clock; what the camera, the light and the music make of them is :mod:`agentsim.expression`'s."""

from __future__ import annotations

from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError


class EmotionPlanner(Planner):
    """An emotion lasts one second unless its start and end are tied; any non-negative duration is valid."""

    behaviour_types = ("emotion",)

    def preferred(self, behaviour) -> list[float]:
        return [0.0, 1.0]

    def check_times(self, behaviour, preferred, times) -> None:
        if times[-1] < times[0] - 1e-9:
            raise ScheduleError("the emotion would end before it starts")


class ExpressionEngine(Engine):
    name = "expression"

    def __init__(self, context: EngineContext):
        super().__init__(context, EmotionPlanner())
