"""Anticipators: predictors of the world's timing (metronome, tap tempo, audio beat tracking) that own
time pegs and move them while a plan plays; plugins derive from :class:`Anticipator`."""

from agentsim.core.anticipator import Anticipator

__all__ = ["Anticipator"]
