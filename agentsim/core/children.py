"""The child processes of a command: where one may be forked, and what it does with a terminal's interrupt.

A terminal's Ctrl-C sends SIGINT to every process of the command: the command itself, the processes that
render its ensemble, simulate its physical body or draw its pictures. Python answers it in each with a
``KeyboardInterrupt`` and, in a child, a traceback of whatever the child was doing. The command ends on it
(exit status 130, no traceback) and ends its children with it (they see their pipe close), so the children
ignore it (:func:`leave_interrupts_to_the_parent`).

:func:`may_fork` says whether this process may start a child by forking.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
import threading

__all__ = ["leave_interrupts_to_the_parent", "may_fork", "end_quietly_when_the_parent_goes"]


def may_fork() -> bool:
    """Whether this process may start a child by forking: it can, it has no thread but its main one (a child
    forked then finds no lock held by a thread copied half-way), and it is not a daemonic process (such as a
    pool's worker, which may start none)."""
    return ("fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon
            and threading.active_count() == 1)


def leave_interrupts_to_the_parent() -> None:
    """Ignore SIGINT in this process (a child whose parent ends it), where this thread may say so."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def end_quietly_when_the_parent_goes() -> None:
    """In multiprocessing's fork server: a child it forks, which first reads what to run from the process that
    asked for it, ends without a traceback if that process has gone meanwhile (its pipe ends, early or half-way
    through: a Ctrl-C ended the command); any other error of a child is told as before. (The server tells what
    escapes a child through ``sys.excepthook``, which its children inherit.)"""
    import pickle
    import traceback

    told = sys.excepthook
    ended = (EOFError, pickle.UnpicklingError, BrokenPipeError, ConnectionResetError)

    def tell(kind, value, trace) -> None:
        reading = any(frame.f_code.co_name == "_main" and frame.f_code.co_filename.endswith("spawn.py")
                      for frame, _ in traceback.walk_tb(trace))
        if not (reading and issubclass(kind, ended)):
            told(kind, value, trace)

    sys.excepthook = tell
