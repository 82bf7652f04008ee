"""Progress on stderr for work that takes more than a couple of seconds (tqdm), silent when stderr is not a
terminal (a pipe, a file, a test).

* :func:`progress`: a bar over an iterable.
* :class:`Stages`: the stages of a long command. Alone, each stage is a line, ``poses/BVH ...`` while it
  runs and its wall seconds when it ends; a stage that knows its total (the simulated seconds of a
  simulation) is a bar meanwhile. Over a list (:meth:`Stages.over`: ``--compare``'s strategies) there is
  one bar counting the items whose description names the item and the stage under way.

Nothing here goes to stdout, and off a terminal nothing is written at all, so what a command prints is the
same with or without it.
"""

from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator, Sequence, TypeVar

T = TypeVar("T")

__all__ = ["on_terminal", "progress", "Stages"]

#: Wall seconds between two redraws of a bar.
REDRAW = 0.1


def on_terminal() -> bool:
    """Whether stderr is a terminal (where progress is shown)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # no stderr, or a closed one
        return False


def _columns() -> int:
    """The terminal's width; 80 where it reports none (a new pseudo-terminal says 0, and tqdm would draw an
    empty bar)."""
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns or 80
    except (AttributeError, OSError, ValueError):
        return 80


def _bar(**options):
    from tqdm import tqdm

    return tqdm(file=sys.stderr, leave=False, ncols=_columns(), mininterval=REDRAW, **options)


def progress(items: Iterable[T], desc: str, total: int | None = None, unit: str = "run") -> Iterator[T]:
    """``items``, with a bar named ``desc`` counting them on a terminal's stderr."""
    if not on_terminal():
        yield from items
        return
    bar = _bar(total=total if total is not None else _length(items), desc=desc, unit=unit)
    try:
        for item in items:
            yield item
            bar.update(1)
    finally:
        bar.close()


def _length(items) -> int | None:
    try:
        return len(items)
    except TypeError:
        return None


def _nothing(_done: float) -> None:
    pass


class Stages:
    """Says on a terminal's stderr which stage of a long command is under way; says nothing elsewhere.

    ``stages("poses/BVH")`` is a context manager around a stage; ``stages("simulating", total=405.0)``
    yields a function to call with how far the stage has come (here: the simulated time), drawn as a bar.
    ``enabled``: force it on or off (default: whether stderr is a terminal).
    """

    def __init__(self, enabled: bool | None = None):
        self.enabled = on_terminal() if enabled is None else enabled
        self._outer = None  # the bar of :meth:`over`, while it runs
        self._item = ""

    @classmethod
    def off(cls) -> "Stages":
        """Stages that say nothing (for a caller that passed none)."""
        return cls(enabled=False)

    def over(self, items: Sequence[T], desc: str, unit: str) -> Iterator[T]:
        """``items``, with one bar counting them (``strategies 3/6 |...| 00:04  chang-smooth: simulating``):
        ``desc`` names what they are; after the bar come the item and its stage under way."""
        if not self.enabled:
            yield from items
            return
        # the count first and the stage last, so that the bar stays where it is while the stage changes
        self._outer = _bar(total=len(items), desc="", unit=unit,
                           bar_format=desc + " {n_fmt}/{total_fmt} |{bar:24}| {elapsed}  {desc}")
        try:
            for item in items:
                self._item = str(item)
                self._describe("")
                yield item
                self._outer.update(1)
        finally:
            self._outer.close()
            self._outer = None
            self._item = ""

    def _describe(self, stage: str, postfix: str = "") -> None:
        text = f"{self._item}{': ' + stage if stage else ''}{', ' + postfix if postfix else ''}"
        self._outer.set_description_str(text, refresh=True)

    @contextmanager
    def __call__(self, name: str, total: float | None = None, unit: str = "s") -> Iterator[Callable[[float], None]]:
        """Around the stage ``name``; yields ``advance(done)``, to call with how far it has come of ``total``
        (which grows if ``done`` passes it)."""
        if not self.enabled:
            yield _nothing
            return
        started = time.perf_counter()
        if self._outer is not None:
            self._describe(name)
            yield self._postfix(name, total, unit) if total else _nothing
            return
        if total:
            bar = _bar(total=max(1, round(total)), desc=name,
                       bar_format="{desc}  {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} " + unit + " [{elapsed}]")

            def advance(done: float) -> None:
                if done > bar.total:  # it runs on past where it was expected to end: the bar grows
                    bar.total = int(done) + 1
                bar.update(max(0, int(done) - bar.n))

            try:
                yield advance
                bar.update(bar.total - bar.n)  # done: the last frame is full
                bar.refresh()
            finally:
                bar.close()
                self._line(f"{name} ... {time.perf_counter() - started:.1f} s\n")
            return
        self._line(f"{name} ...")
        try:
            yield _nothing
        finally:
            self._line(f" {time.perf_counter() - started:.1f} s\n")

    def _postfix(self, name: str, total: float, unit: str) -> Callable[[float], None]:
        last = [0.0]

        def advance(done: float) -> None:
            now = time.perf_counter()
            if now - last[0] >= REDRAW:
                last[0] = now
                self._describe(name, f"{min(done, total):.0f}/{total:.0f} {unit}")

        return advance

    def write(self, text: str) -> None:
        """A line for stderr whatever it is (not only on a terminal), written above the bar if one is drawn."""
        if self._outer is not None:
            self._outer.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr)

    @staticmethod
    def _line(text: str) -> None:
        sys.stderr.write(text)
        sys.stderr.flush()
