"""What the child processes of a command do with a terminal's interrupt.

A terminal's Ctrl-C sends SIGINT to every process of the command: the command itself, the processes that
render its ensemble, simulate its physical body or draw its pictures. Python answers it in each with a
``KeyboardInterrupt`` and, in a child, a traceback of whatever the child was doing. The command ends on it
(exit status 130, no traceback) and ends its children with it (they see their pipe close), so the children
ignore it (:func:`leave_interrupts_to_the_parent`).
"""

from __future__ import annotations

import signal
import threading

__all__ = ["leave_interrupts_to_the_parent"]


def leave_interrupts_to_the_parent() -> None:
    """Ignore SIGINT in this process (a child whose parent ends it), where this thread may say so."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)

