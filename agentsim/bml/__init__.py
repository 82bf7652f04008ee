"""BML 1.0: the document model, the behaviour vocabulary and the hardened parser."""

from agentsim.core.block import Behaviour, Block, Constraint, SyncRef
from agentsim.bml.parser import parse_bml, parse_ref

__all__ = ["Behaviour", "Block", "Constraint", "SyncRef", "parse_bml", "parse_ref"]
