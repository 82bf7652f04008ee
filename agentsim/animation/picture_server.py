"""The first module that the server of the picture workers imports (it leads
:data:`~agentsim.animation.pictures.PRELOADED`).

A terminal's Ctrl-C reaches every process of the command, this server too, which would stop with a
traceback of whatever it was importing. Imported in that server, this module makes it leave the interrupt
to the command, which ends the server and its workers as it ends (the workers forked from it inherit this);
a worker forked as the command ends, which finds no one to read its work from, ends without a traceback.
Imported anywhere else, it does nothing.
"""

from __future__ import annotations

import sys

from agentsim.core.children import end_quietly_when_the_parent_goes, leave_interrupts_to_the_parent


def in_the_server() -> bool:
    """Whether this process is multiprocessing's fork server (Python started with ``-c`` and its code)."""
    return sys.argv[:1] == ["-c"] and "multiprocessing.forkserver" in sys.modules


if in_the_server():
    leave_interrupts_to_the_parent()
    end_quietly_when_the_parent_goes()
