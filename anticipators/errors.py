"""Exceptions raised by the anticipators package."""

from __future__ import annotations

__all__ = ["AnticipatorError"]


class AnticipatorError(RuntimeError):
    """An anticipator cannot do its work because of its environment or its input.

    Raised, for example, when the FluidSynth library or the General MIDI soundfont is missing, with a
    message that says how to install them.
    """
