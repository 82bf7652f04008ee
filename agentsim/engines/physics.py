"""The physics engine: BMLT ``<bmlt:controller class="..." start= end=>`` behaviours, physical controllers
timed by their pegs like any behaviour (a second unless their start and end are tied).

The engine only times them: what a controller does to the body is played after the run, by
:mod:`agentsim.physics.run` under ``--physics``. A controller of a class, part or parameter the body does not
have is refused when it is planned (one warning naming it; the rest of the block is realized).
"""

from __future__ import annotations

from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError
from agentsim.physics.controllers import controller_spec


class ControllerPlanner(Planner):
    """A controller lasts one second unless its start and end are tied; any positive duration is valid."""

    behaviour_types = ("controller",)

    def preferred(self, behaviour: Behaviour) -> list[float]:
        try:
            controller_spec(behaviour.attributes.get("class", ""), behaviour.params)
        except ValueError as exc:
            raise ScheduleError(str(exc), "NO_SUCH_TARGET") from None
        return [0.0, 1.0]


class ControllerEngine(Engine):
    name = "physics"

    def __init__(self, context: EngineContext):
        super().__init__(context, ControllerPlanner())
