"""The BML 1.0 core behaviours: their default sync points (in order) and the body resource they hold."""

from __future__ import annotations

from dataclasses import dataclass

BML_NAMESPACE = "http://www.bml-initiative.org/bml/bml-1.0"

GESTURE_SYNCS = ("start", "ready", "strokeStart", "stroke", "strokeEnd", "relax", "end")
GAZE_SYNCS = ("start", "ready", "relax", "end")
FACE_SYNCS = ("start", "attackPeak", "relax", "end")
SHIFT_SYNCS = ("start", "end")


@dataclass(frozen=True)
class BehaviourType:
    """A behaviour element: its default sync points and, if it is exclusive, the resource it holds.

    Two behaviours holding the same ``resource`` cannot run at the same time (two gazes at once).
    """

    name: str
    syncs: tuple[str, ...]
    resource: str | None = None


BEHAVIOUR_TYPES: dict[str, BehaviourType] = {
    t.name: t
    for t in (
        BehaviourType("speech", ("start", "end")),
        BehaviourType("gesture", GESTURE_SYNCS),
        BehaviourType("pointing", GESTURE_SYNCS),
        BehaviourType("head", GESTURE_SYNCS),
        BehaviourType("gaze", GAZE_SYNCS, resource="gaze"),
        BehaviourType("gazeShift", SHIFT_SYNCS, resource="gazeShift"),
        BehaviourType("headDirectionShift", SHIFT_SYNCS, resource="headDirectionShift"),
        BehaviourType("faceLexeme", FACE_SYNCS),
        BehaviourType("faceFacs", FACE_SYNCS),
        BehaviourType("face", FACE_SYNCS),
        BehaviourType("faceShift", SHIFT_SYNCS),
        BehaviourType("posture", GAZE_SYNCS, resource="posture"),
        BehaviourType("postureShift", SHIFT_SYNCS, resource="postureShift"),
        BehaviourType("locomotion", SHIFT_SYNCS, resource="locomotion"),
        BehaviourType("wait", SHIFT_SYNCS),
    )
}

# Children of behaviours that carry parameters, not behaviours of their own.
PARAMETER_CHILDREN = {"stance", "pose", "description", "text", "sync", "lexeme"}

# Attributes that are never sync references.
PLAIN_ATTRIBUTES = {
    "id", "lexeme", "mode", "target", "influence", "amount", "repetition", "offsetAngle",
    "offsetDirection", "au", "side", "manner", "type", "part", "priority", "start_", "xmlns",
}
