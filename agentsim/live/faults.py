"""How the live service reports faults: one line on stderr for a fault it goes on after (:func:`note`), and
:class:`RealizerStopped` for the one it stops with."""

from __future__ import annotations

import sys

from agentsim.errors import AgentsimError


class RealizerStopped(AgentsimError):
    """The realizer's thread (or the reader's) died: the service stops with it (exit status 1)."""


def note(message: str) -> None:
    """One line on stderr about a fault the service goes on after."""
    print(f"agentsim serve: {message}", file=sys.stderr, flush=True)
