"""What the BML 1.0 reader knows of the vocabulary besides the behaviour types: the namespace, the
children that are parameters and the attributes that are never sync references."""

from __future__ import annotations

BML_NAMESPACE = "http://www.bml-initiative.org/bml/bml-1.0"

# Children of behaviours that carry parameters, not behaviours of their own.
PARAMETER_CHILDREN = {"stance", "pose", "description", "text", "sync", "lexeme"}

# Attributes that are never sync references.
PLAIN_ATTRIBUTES = {
    "id", "lexeme", "mode", "target", "influence", "amount", "repetition", "offsetAngle",
    "offsetDirection", "au", "side", "manner", "type", "part", "priority", "start_", "xmlns",
}
