"""One point of a sweep, as a Dask task: the command run in the worker's own process, its JSON captured.

:func:`run_point` parses the point's command line with the command's real parser and calls its handler,
as ``agentsim ...`` would, with stdout captured: what the command prints with ``--json`` is the point's
result. It never raises for the point's own faults: an error of the command (or a bug in it) is a failed
row with the message, so that Dask retries only points whose worker died. Points run one at a time in a
process (a lock), because a command's stdout is the process's and a speech library may not be shared by
threads; give workers one thread each (``dask worker --nthreads 1``).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import threading
import time
import traceback
from contextlib import redirect_stderr, redirect_stdout

from agentsim.cli.sweep.spec import project_version, work_parser
from agentsim.errors import AgentsimError
from agentsim.written import scratch_folder

_LOCK = threading.Lock()


def worker_name() -> str:
    """The address of the Dask worker running this (the process id outside a worker)."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"


def worker_info() -> dict:
    """What the sweep checks of a worker before it sends points: the project version it runs (and, by
    running this, that it can import agentsim and build the commands' parser)."""
    work_parser()
    return {"version": project_version(), "pid": os.getpid()}


def run_point(argv: list[str], out_at: int | None = None, keep: str | None = None) -> dict:
    """Run one point; returns ``{"status": "ok"|"failed", "error", "result", "seconds", "worker",
    "version"}``.

    ``out_at``: where in ``argv`` to give the command ``--out`` (None: it takes none); the folder is
    ``keep`` if given, else a temporary one removed afterwards (and then a command that draws pictures is
    run with ``--no-pictures``).
    """
    with _LOCK, contextlib.ExitStack() as scratch:
        folder = None
        argv = list(argv)
        if out_at is not None:  # a scratch folder a killed worker leaves is removed by the next point's
            folder = keep or str(scratch.enter_context(scratch_folder("agentsim-scratch-point-")))
            argv[out_at:out_at] = ["--out", folder]
        stdout, stderr = io.StringIO(), io.StringIO()
        started = time.perf_counter()
        error, result = None, None
        try:
            with redirect_stdout(stdout), redirect_stderr(stderr):
                args = work_parser().parse_args(argv)
                if keep is None and getattr(args, "no_pictures", None) is False:
                    args.no_pictures = True  # its folder is removed unseen: no picture is drawn for nobody
                status = args.handler(args) or 0
            if status:
                error = f"exit status {status}: {last_line(stderr.getvalue())}"
            else:
                result = json.loads(last_json(stdout.getvalue()))
        except AgentsimError as exc:
            error = str(exc)
        except SystemExit as exc:  # the parser refused the command line (checked before, so rare)
            error = f"exit status {exc.code}: {last_line(stderr.getvalue())}"
        except json.JSONDecodeError:
            error = f"printed no JSON: {last_line(stdout.getvalue()) or 'nothing'}"
        except Exception as exc:  # noqa: BLE001 - a bug in the command: one line and its last frame
            frame = traceback.extract_tb(exc.__traceback__)[-1]
            error = f"internal error: {type(exc).__name__}: {exc} ({frame.filename}:{frame.lineno})"
        return {"status": "failed" if error else "ok", "error": error, "result": result,
                "seconds": time.perf_counter() - started, "worker": worker_name(), "version": project_version()}


def last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def last_json(text: str) -> str:
    """The JSON a command printed: all of stdout, or (if something else was printed before it) its last line."""
    text = text.strip()
    try:
        json.loads(text)
        return text
    except json.JSONDecodeError:
        return last_line(text)
