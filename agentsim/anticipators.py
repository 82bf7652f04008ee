"""The anticipator interface under its old name, for plugins written against it: ``from agentsim.anticipators
import Anticipator`` still works, with a DeprecationWarning. New code imports it as ``from anticipators
import Anticipator``; the built-in anticipators live in the top-level ``anticipators`` package."""

from __future__ import annotations

import warnings


def __getattr__(name: str):
    if name == "Anticipator":
        warnings.warn("agentsim.anticipators.Anticipator is deprecated: import it as "
                      "'from anticipators import Anticipator'", DeprecationWarning, stacklevel=2)
        from agentsim.core.anticipator import Anticipator

        return Anticipator
    raise AttributeError(f"module 'agentsim.anticipators' has no attribute {name!r} (the anticipators "
                         "moved to the top-level package 'anticipators')")

