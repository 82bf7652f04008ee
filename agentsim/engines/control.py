"""The control engine: BMLA behaviours that act on other blocks and behaviours when their start comes.

``<bmla:interrupt target include exclude>`` interrupts a block (or some of its behaviours),
``<bmla:activate target>`` starts a preplanned block, and ``<bmla:parametervaluechange target paramId>``
changes a parameter of a behaviour between its start and end, along a ``<bmla:trajectory type="linear|
instant" initialValue targetValue>``. Interrupt and activate take no time (their start is their end).
"""

from __future__ import annotations

import re

from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError
from agentsim.core.timed import ParameterChange, TimedBehaviour

#: The parameters a parametervaluechange can change, by the type of behaviour it targets: speech volume
#: (percent, 100 as synthesised), speech rate (a factor, 1 as synthesised) and the amplitude of gestures
#: and head movements (a factor, 1 as planned).
PARAMETERS = {"speech": ("volume", "rate"), "gesture": ("amplitude",), "pointing": ("amplitude",),
              "head": ("amplitude",)}
#: What a parameter is before any change.
DEFAULTS = {"volume": 100.0, "rate": 1.0, "amplitude": 1.0}


def ids(text: str) -> tuple[str, ...]:
    return tuple(x for x in re.split(r"[\s,]+", text.strip()) if x)


class ControlPlanner(Planner):
    """Times control behaviours: interrupt and activate are instants; a parameter change lasts one second
    unless its start and end are tied."""

    behaviour_types = ("interrupt", "activate", "parametervaluechange")

    def __init__(self, blocks) -> None:
        super().__init__()
        self.blocks = blocks

    def preferred(self, behaviour: Behaviour) -> list[float]:
        return [0.0, 1.0] if behaviour.type == "parametervaluechange" else [0.0, 0.0]

    def check_times(self, behaviour, preferred, times) -> None:
        if times[-1] < times[0] - 1e-9:
            raise ScheduleError("it would end before it starts")

    def admit(self, timed: TimedBehaviour) -> str | None:
        b = timed.behaviour
        if b.type in ("interrupt", "activate"):
            target = b.attributes.get("target", "").strip()
            if self.blocks.state(target) is None and target != timed.block_id:
                return f"there is no block {target!r} (yet) to {b.type}"
            return None
        target = self.target(timed)
        if target is None:
            return f"there is no behaviour {b.attributes.get('target')!r} to change"
        param = b.attributes.get("paramId", "")
        known = PARAMETERS.get(target.behaviour.type, ())
        if param not in known:
            return (f"{target.block_id}:{target.id} ({target.behaviour.type}) has no parameter {param!r}"
                    + (f"; it has {', '.join(known)}" if known else ""))
        try:
            self.trajectory(b)
        except ValueError as exc:
            return str(exc)
        return None

    def target(self, timed: TimedBehaviour) -> TimedBehaviour | None:
        """The behaviour a parameter change names (``block:behaviour``, or a behaviour of its own block)."""
        name = timed.behaviour.attributes.get("target", "").strip()
        block_id, _, behaviour_id = name.rpartition(":")
        return self.blocks.behaviour(block_id or timed.block_id, behaviour_id)

    @staticmethod
    def trajectory(behaviour: Behaviour) -> tuple[str, float, float]:
        """``(type, initial, target)`` of a parameter change (ValueError if it cannot be read)."""
        p = behaviour.params
        kind = p.get("trajectory.type", "instant").strip().lower()
        if kind not in ("linear", "instant"):
            raise ValueError(f"trajectory type {kind!r} is not linear or instant")
        try:
            target = float(p["trajectory.targetValue"])
            initial = float(p.get("trajectory.initialValue", target))
        except KeyError:
            raise ValueError("the trajectory has no targetValue") from None
        except ValueError:
            raise ValueError("the trajectory's values are not numbers") from None
        if not all(abs(v) < 1e9 for v in (initial, target)):
            raise ValueError("the trajectory's values are out of range")
        return kind, initial, target


class ControlEngine(Engine):
    """Carries out interrupt, activate and parameter changes when their start sync point is passed."""

    name = "control"

    def __init__(self, context: EngineContext):
        super().__init__(context, ControlPlanner(context.blocks))

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        if index == 0:
            self.act(timed)
        super().sync_passed(timed, index, time)

    def act(self, timed: TimedBehaviour) -> None:
        b = timed.behaviour
        by = f"{timed.block_id}:{timed.id}"
        blocks = self.context.blocks
        if b.type == "interrupt":
            blocks.interrupt(b.attributes["target"].strip(), ids(b.attributes.get("include", "")),
                             ids(b.attributes.get("exclude", "")), by=by)
        elif b.type == "activate":
            blocks.activate(b.attributes["target"].strip(), by=by)
        else:
            target = self.planner.target(timed)
            if target is None or not target.live:
                blocks.warn(by, "NO_SUCH_TARGET", f"{timed.id}: {b.attributes.get('target')!r} is no longer "
                            "planned or playing; nothing to change", [timed.id])
                return
            kind, initial, value = self.planner.trajectory(b)
            param = b.attributes["paramId"]
            if param == "rate" and target.passed[0] is not None:
                blocks.warn(by, "IMPOSSIBLE_TO_SCHEDULE", f"{timed.id}: the speech rate can change only before "
                            f"{target.id} starts (the backend speaks a whole utterance at one rate)", [timed.id])
                return
            target.parameters.append(ParameterChange(param, timed, kind, initial, value))
