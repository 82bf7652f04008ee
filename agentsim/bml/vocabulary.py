"""What the BML 1.0 reader knows of the vocabulary besides the behaviour types: the namespace, the
children that are parameters and the attributes that are never sync references."""

from __future__ import annotations

#: MURML, the form language of gestures AsapRealizer reads inside BML (:mod:`agentsim.animation.murml_form`).
from agentsim.animation.murml_form import MURML_NAMESPACE
#: agentsim's own extension: emotions shown through camera, light and music (:mod:`agentsim.expression`).
from agentsim.expression.emotions import EXPRESSION_NAMESPACE

BML_NAMESPACE = "http://www.bml-initiative.org/bml/bml-1.0"
#: AsapRealizer's extensions: BMLA (continuous interaction) and BMLT (sound files, transitions, physical
#: controllers).
BMLA_NAMESPACE = "http://www.asap-project.org/bmla"
BMLT_NAMESPACE = "http://hmi.ewi.utwente.nl/bmlt"

#: The behaviour elements of each extension namespace (their types are in the core's BEHAVIOUR_TYPES).
EXTENSION_BEHAVIOURS = {
    BMLA_NAMESPACE: {"interrupt", "activate", "parametervaluechange"},
    BMLT_NAMESPACE: {"audiofile", "transition", "controller"},
    MURML_NAMESPACE: {"murmlgesture", "murmlface"},
    EXPRESSION_NAMESPACE: {"emotion"},
}

#: The elements of a BML 1.0 ``<constraint>``.
CONSTRAINT_KINDS = frozenset(("synchronize", "before", "after"))
#: Behaviour types that no BML namespace defines: only the lenient reader makes them, from other realizers'
#: elements (SmartBody's ``<lips>``, ``<curves>`` and ``<event>``).
DIALECT_BEHAVIOURS = {"lips", "curves", "event"}

#: The BMLA attributes of a <bml> block and the Block field each fills (lists of block ids, or a flag).
BMLA_BLOCK_ATTRIBUTES = {
    "interrupt": "interrupt", "onStart": "on_start", "chunkAfter": "chunk_after", "chunkBefore": "chunk_before",
    "appendAfter": "append_after", "prependBefore": "prepend_before", "preplan": "preplan",
}

# Children of behaviours that carry parameters, not behaviours of their own.
PARAMETER_CHILDREN = {"stance", "pose", "description", "text", "sync", "lexeme", "trajectory", "parameter",
                      "murml-description"}

#: Every plain (not namespaced) behaviour attribute some part of this realizer reads, besides the sync
#: points: BML 1.0's, and the parameters of agentsim's engines. Any other is ignored, with a warning.
READ_ATTRIBUTES = frozenset({
    # BML 1.0
    "id", "lexeme", "mode", "target", "influence", "amount", "repetition", "offsetAngle", "offsetDirection",
    "au", "side", "manner", "type", "part", "priority", "direction", "characterId", "composition",
    # BMLA/BMLT and agentsim's engines
    "include", "exclude", "paramId", "fileName", "value", "name", "alias", "approach", "duration", "hand",
    "tempo", "retract", "motion", "hold", "audio", "object", "dXRot", "dYRot", "x", "y", "z", "meter", "beats",
    "shape", "coord", "strength", "level", "rate", "time", "role", "importance", "format", "viseme", "detail",
    "articulation", "dynamics", "repeat", "args", "class", "start_", "xmlns", "intensity",
    # what other realizers write that the lenient reader takes as it comes (a voice, a language, an event)
    "language", "voice", "message", "ref", "text", "emotion",
})

# Attributes that are never sync references.
PLAIN_ATTRIBUTES = {
    "id", "lexeme", "mode", "target", "influence", "amount", "repetition", "offsetAngle",
    "offsetDirection", "au", "side", "manner", "type", "part", "priority", "start_", "xmlns",
    "include", "exclude", "paramId", "fileName", "class",
}
