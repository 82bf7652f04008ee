"""The conductor scenario's names that the command line needs before anything runs: its strategies and
its default output folder (kept here, apart from the modules that use them, so that reading options
imports nothing heavy)."""

#: Where the strokes go (see :mod:`scenarios.conductor.strategies`).
STRATEGIES = ("follow", "target", "lead", "best")
#: Where ``agentsim run conductor`` writes by default.
DEFAULT_OUT = "out/conductor"
