"""Reading BML 1.0: the hardened parser that turns XML into the core's block model, and its vocabulary."""

from agentsim.core.block import Behaviour, Block, Constraint, SyncRef
from agentsim.bml.parser import parse_bml, parse_ref

__all__ = ["Behaviour", "Block", "Constraint", "SyncRef", "parse_bml", "parse_ref"]
