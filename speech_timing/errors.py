"""Exceptions raised by the text-to-speech backends."""

from __future__ import annotations


class SpeechBackendUnavailable(RuntimeError):
    """A backend cannot run here, for instance because its system library is not installed.

    The message says what to install.
    """
