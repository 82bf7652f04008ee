"""The animation engine: behaviours become timed motion units with phases separated by keys."""

from __future__ import annotations

from agentsim.animation.units import motion_unit, repetition
from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.core.errors import ScheduleError


class AnimationPlanner(Planner):
    """Binds behaviours to motion units and resolves their keys by linear stretch between constraints."""

    behaviour_types = ("gesture", "pointing", "head", "gaze", "gazeShift", "headDirectionShift", "faceLexeme",
                       "faceFacs", "face", "faceShift", "posture", "postureShift", "locomotion")

    def preferred(self, behaviour: Behaviour) -> list[float]:
        return motion_unit(behaviour).preferred(repetition(behaviour))

    def check_times(self, behaviour, preferred, times) -> None:
        super().check_times(behaviour, preferred, times)
        unit = motion_unit(behaviour)
        duration = times[-1] - times[0]
        if duration < unit.min_duration - 1e-9:
            raise ScheduleError(f"{duration:.3f} s is shorter than the shortest {unit.name} "
                                f"({unit.min_duration:g} s)")
        if duration > unit.max_duration + 1e-9:
            raise ScheduleError(f"{duration:.3f} s is longer than the longest {unit.name} "
                                f"({unit.max_duration:g} s)")


class AnimationEngine(Engine):
    name = "animation"

    def __init__(self, context: EngineContext):
        super().__init__(context, AnimationPlanner())
