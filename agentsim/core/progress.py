"""A progress bar on stderr for work that takes more than a couple of seconds (tqdm), silent when stderr is
not a terminal (a pipe, a file, a test)."""

from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")


def progress(items: Iterable[T], desc: str, total: int | None = None, unit: str = "run") -> Iterator[T]:
    """``items``, with a bar named ``desc`` counting them on a terminal's stderr."""
    if not sys.stderr.isatty():
        yield from items
        return
    from tqdm import tqdm

    yield from tqdm(items, desc=desc, total=total, unit=unit, file=sys.stderr, leave=False)
