"""The one root of every error a user can cause and fix, and its kinds.

Everything user-facing raises an :class:`AgentsimError` (or a subclass) whose message says what went
wrong and what to do about it; the command line turns it into one line on stderr and an exit status, in
one place (:func:`agentsim.cli.main`).
"""

from __future__ import annotations


class AgentsimError(Exception):
    """An error the user can cause (bad BML, bad config, missing device or library).

    The message says what went wrong and what to do about it.
    """

    #: Exit status of the command line for this kind of error.
    exit_status = 1


class UsageError(AgentsimError):
    """The command line itself is wrong: a missing file, contradictory options."""

    exit_status = 2


class BMLError(AgentsimError):
    """A BML document or reference that cannot be used, with its position in the source."""

    def __init__(self, message: str, line: int | None = None, column: int | None = None):
        self.line = line
        self.column = column
        where = f" (line {line}, column {column})" if line is not None else ""
        super().__init__(f"{message}{where}")
        self.reason = message


class ScheduleError(AgentsimError):
    """A behaviour cannot be given the timing asked of it (or what it refers to does not exist).

    ``warning_type`` is the BML warning it becomes (``IMPOSSIBLE_TO_SCHEDULE``, ``NO_SUCH_TARGET``, ...).
    """

    def __init__(self, message: str, warning_type: str = "IMPOSSIBLE_TO_SCHEDULE"):
        super().__init__(message)
        self.warning_type = warning_type


class Unavailable(AgentsimError):
    """Something the work needs is missing here: a system library, a program, a soundfont, a device.

    The message says what to install or set, and it is raised before the work starts.
    """


class SpeechBackendUnavailable(Unavailable):
    """A text-to-speech backend cannot run here, for instance because its system library is not installed."""


class SpeechExtraMissing(SpeechBackendUnavailable):
    """A speech backend whose Python packages, an extra of agentsim, are not installed here: the message names
    the extra. A usage error's status: what was asked for is not part of this installation."""

    exit_status = 2


class AnticipatorError(AgentsimError):
    """An anticipator cannot do its work because of its environment or its input.

    A missing library, program or soundfont is :class:`Unavailable` instead (for instance FluidSynth and
    the General MIDI soundfont of :mod:`agentsim.music.rendering`).
    """
