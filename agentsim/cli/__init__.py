"""The ``agentsim`` command line: every command's parser, one dispatch, and the one place where errors
become a line on stderr and an exit status.

=====================  =================================================================================
module                 commands
=====================  =================================================================================
``realize``            ``realize``, ``plot timeline``, ``anticipators list``
``speech``             ``eval speech-sync``, ``speech calibrate``, ``speech export``
``beats``              ``anticipate beats``
``scenarios``          ``run conductor``, ``run storytelling``, ``demo``
``serve``              ``serve``
``sweep``              ``sweep``, ``sweep report``
``commands``           the parser of every command but ``sweep`` (which runs those commands)
``options``            the options several commands share (speech backend, event delivery, seed, ...)
=====================  =================================================================================
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from agentsim.errors import AgentsimError

#: Exit status of an error that is a bug (the message asks for a report).
INTERNAL_ERROR = 70


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command; each command's ``handler`` (set with ``set_defaults``) runs it."""
    from agentsim.cli import commands as work
    from agentsim.cli import sweep

    from agentsim import __version__

    parser = work.Parser(prog=work.PROG, description=work.DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"agentsim {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    work.add_parsers(commands)
    sweep.add_parsers(commands)
    return parser


def _quiet_stdout() -> None:
    """Make what is left in standard output's buffer go nowhere (it cannot be written: say nothing more)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, AttributeError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 done, 1 an error the user can fix, 2 a usage
    error, 70 a bug, 130 interrupted)."""
    if argv is None:
        # the program's own process, which draws nothing with MuJoCo (its bodies are shown in a browser):
        # MuJoCo is imported without looking for an OpenGL library, a tenth of a second, unless a backend
        # was chosen
        os.environ.setdefault("MUJOCO_GL", "disable")
    args = build_parser().parse_args(argv)
    try:
        return _run(args, argv)
    finally:
        if argv is None:
            _ending()


def _ending() -> None:
    """The program's own process has done its command and ends: a Ctrl-C from now on ends it at once with
    status 130, what it has to say said, instead of interrupting the interpreter's own clean-up (which would
    write a traceback from whatever it was doing there, and end with the command's status)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _ended)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass


def _ended(signum, frame) -> None:
    os._exit(130)


def _run(args: argparse.Namespace, argv: list[str] | None) -> int:
    """The command ``args`` asks for, its errors made exit statuses (see :func:`main`)."""
    try:
        status = args.handler(args) or 0
        if argv is None:
            _ending()  # (here, where a Ctrl-C that came before is still an interruption of the command)
        if argv is None and getattr(args, "done_at_exit", False):
            # the program's own command line, whose process ends now: what the command built (a block's
            # thousands of objects) is left for the process's end, not traversed and freed one by one at exit
            from agentsim.core.gcpause import keep_out_of_collections

            keep_out_of_collections()
        return status
    except AgentsimError as exc:
        print(f"agentsim: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader went away (``agentsim realize x.xml | head``): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as exc:  # the machine, not the program: a full disk, a read-only folder, a closed output
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"agentsim: cannot go on: {exc.strerror or exc}{where}", file=sys.stderr)
        _quiet_stdout()
        return 1
    except Exception as exc:  # a bug: one line for the user, the traceback on request
        if os.environ.get("AGENTSIM_DEBUG"):
            raise
        print(f"agentsim: internal error: {type(exc).__name__}: {exc} (set AGENTSIM_DEBUG=1 for the traceback; "
              "please report it)", file=sys.stderr)
        return INTERNAL_ERROR
