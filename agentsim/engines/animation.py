"""The animation engine: behaviours become timed motion units with phases separated by keys."""

from __future__ import annotations

from agentsim.animation.lexicon import Lexicon
from agentsim.animation.units import curves_duration, motion_unit, repetition
from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError
from agentsim.core.interruption import due_by, skip_until
from agentsim.core.timed import TimedBehaviour


#: How many bindings of a behaviour type and lexeme a planner keeps (it forgets them all beyond).
REMEMBERED = 4096
#: Behaviour types whose motion unit is made from their own MURML form (not bound by their type and lexeme).
_FORMS = ("murmlgesture", "murmlface")


class AnimationPlanner(Planner):
    """Binds behaviours to motion units and resolves their keys by linear stretch between constraints; a
    gesture lexeme that is a MURML form in ``lexicon`` (default: the built-in one) is timed as that form."""

    behaviour_types = ("gesture", "pointing", "head", "gaze", "gazeShift", "headDirectionShift", "faceLexeme",
                       "faceFacs", "face", "faceShift", "posture", "postureShift", "locomotion", "transition",
                       "lips", "curves", "murmlgesture", "murmlface")

    def __init__(self, lexicon: Lexicon | None = None):
        super().__init__()
        self.lexicon = lexicon if lexicon is not None else Lexicon.builtin()
        # what a behaviour type and lexeme are bound to (the lexicon does not change): its motion unit, and
        # (with the repetition as written) its preferred timing; a block asks for each many times over
        self._units: dict[tuple, object] = {}
        self._preferred: dict[tuple, tuple[float, ...]] = {}

    def unit(self, behaviour: Behaviour):
        """The motion unit ``behaviour`` is bound to (:func:`~agentsim.animation.units.motion_unit`)."""
        if behaviour.type in _FORMS:
            return motion_unit(behaviour, self.lexicon)
        key = (behaviour.type, behaviour.attributes.get("lexeme"))
        unit = self._units.get(key)
        if unit is None:
            if len(self._units) >= REMEMBERED:  # (lexemes as written: a live service is sent any number)
                self._units.clear()
            unit = self._units[key] = motion_unit(behaviour, self.lexicon)
        return unit

    def preferred(self, behaviour: Behaviour) -> list[float]:
        if behaviour.type == "curves":
            return [0.0, curves_duration(behaviour)]
        if behaviour.type in _FORMS:
            return motion_unit(behaviour, self.lexicon).preferred(repetition(behaviour))
        attributes = behaviour.attributes
        key = (behaviour.type, attributes.get("lexeme"), attributes.get("repetition"))
        keys = self._preferred.get(key)
        if keys is None:
            if len(self._preferred) >= REMEMBERED:
                self._preferred.clear()
            keys = self._preferred[key] = tuple(self.unit(behaviour).preferred(repetition(behaviour)))
        return list(keys)

    def check_times(self, behaviour, preferred, times) -> None:
        super().check_times(behaviour, preferred, times)
        unit = self.unit(behaviour)
        duration = times[-1] - times[0]
        if duration < unit.min_duration - 1e-9:
            raise ScheduleError(f"{duration:.3f} s is shorter than the shortest {unit.name} "
                                f"({unit.min_duration:g} s)")
        if duration > unit.max_duration + 1e-9:
            raise ScheduleError(f"{duration:.3f} s is longer than the longest {unit.name} "
                                f"({unit.max_duration:g} s)")


class AnimationEngine(Engine):
    """Plays motion units; an interrupted one goes into its retraction at once. ``lexicon``: what its
    lexemes play (default: the built-in :class:`~agentsim.animation.lexicon.Lexicon`)."""

    name = "animation"

    def __init__(self, context: EngineContext, lexicon: Lexicon | None = None):
        super().__init__(context, AnimationPlanner(lexicon))
        self.lexicon = self.planner.lexicon

    def interruption(self, timed: TimedBehaviour, now: float) -> tuple[set[int], dict[int, float]] | None:
        """A motion with a retraction (gestures, head movements, gaze, face, posture) relaxes now and ends
        when its preferred retraction is done; one already retracting goes on; one without a retraction
        (a shift) ends now."""
        if "relax" not in timed.sync_ids:
            return super().interruption(timed, now)
        relax, last = timed.sync_ids.index("relax"), len(timed.sync_ids) - 1
        if timed.next_index > relax or due_by(timed, relax, now):
            return None
        retraction = max(timed.preferred[last] - timed.preferred[relax], 0.0)
        return skip_until(timed, relax, now), {relax: now, last: now + retraction}
