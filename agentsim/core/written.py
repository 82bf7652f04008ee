"""Files that cannot half-exist: written under a temporary name beside their place and renamed there once
whole, so that a full disk or an interrupted run leaves the old file (or none), never a truncated one.
Every writer of a run's outputs (WAV, BVH, npz, TextGrid, CSV, JSON) goes through :func:`written`."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path


@contextlib.contextmanager
def written(path: str | Path):
    """Write a file so that it cannot half-exist: the body writes to a temporary name beside ``path`` (with
    the same suffix), renamed to ``path`` once it is whole; if the writing fails (a full disk), the temporary
    file is removed and ``path`` is left as it was.

    >>> with written("out.txt") as tmp:  # doctest: +SKIP
    ...     tmp.write_text("whole")
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
