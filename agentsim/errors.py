"""The one exception type for errors a user can cause and fix."""

from __future__ import annotations


class AgentsimError(Exception):
    """An error the user can cause (bad BML, bad config, missing device or library).

    The message says what went wrong and what to do about it.
    """


class BMLError(AgentsimError):
    """A BML document or reference that cannot be used, with its position in the source."""

    def __init__(self, message: str, line: int | None = None, column: int | None = None):
        self.line = line
        self.column = column
        where = f" (line {line}, column {column})" if line is not None else ""
        super().__init__(f"{message}{where}")
        self.reason = message
