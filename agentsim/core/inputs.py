"""Inputs weighed before they are read: every file a command reads (BML, stories and their TextGrids, texts,
tap files, lexicons, linear models, sweep specs, configurations) and standard input are read with a limit,
``limit + 1`` bytes at most, and refused past it without reading the rest; audio files are weighed by the
samples their header declares and read no further than the limit either.

=====================  ==============================================================================
:data:`MAX_INPUT`      8 MB: the most a text input (BML document, story, text, spec, tap file) may hold
:data:`MAX_AUDIO`      the most samples of an audio file (an hour at 48 kHz, 691 MB as float32, mono)
=====================  ==============================================================================
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import BinaryIO

from agentsim.errors import UsageError

__all__ = ["MAX_INPUT", "MAX_AUDIO", "TooLarge", "read_limited", "read_stream", "read_text", "read_audio_limited"]

#: The most bytes of a text input (as the BML parser's ``MAX_DOCUMENT``).
MAX_INPUT = 8 * 1024 * 1024
#: The most samples (frames) of an audio input: an hour at 48 kHz.
MAX_AUDIO = 3600 * 48000


class TooLarge(UsageError):
    """An input past its limit (exit status 2: the command line names the wrong thing)."""


def _mb(n: int) -> str:
    return f"{n / 1048576:g} MB"


def read_stream(stream: BinaryIO, what: str, limit: int = MAX_INPUT) -> bytes:
    """At most ``limit`` bytes of ``stream``; :class:`TooLarge` (one line) if it holds more (only
    ``limit + 1`` bytes are ever read)."""
    data = stream.read(limit + 1)
    if len(data) > limit:
        raise TooLarge(f"{what} is longer than {_mb(limit)}: at most {_mb(limit)} is read")
    return data


def read_limited(path: str | Path, limit: int = MAX_INPUT, what: str | None = None) -> bytes:
    """The bytes of the file at ``path`` (``-``: standard input), if it holds at most ``limit``;
    :class:`TooLarge` otherwise, said from the file's size where it has one, before reading it."""
    if str(path) == "-":
        if sys.stdin is None:
            raise UsageError("standard input is closed: there is nothing to read")
        return read_stream(sys.stdin.buffer, what or "standard input", limit)
    path = Path(path)
    what = what or str(path)
    with open(path, "rb") as f:
        import os
        import stat

        info = os.fstat(f.fileno())
        if stat.S_ISREG(info.st_mode) and info.st_size > limit:
            raise TooLarge(f"{what} is {info.st_size / 1048576:.1f} MB long: at most {_mb(limit)} is read")
        return read_stream(f, what, limit)


def read_text(path: str | Path, limit: int = MAX_INPUT, what: str | None = None, errors: str = "strict") -> str:
    """:func:`read_limited` decoded as UTF-8 (a :class:`UnicodeDecodeError` if it is not, with ``errors``
    "strict")."""
    return read_limited(path, limit, what).decode("utf-8", errors)


def read_audio_limited(path: str | Path, limit: int = MAX_AUDIO):
    """The samples (float32, frames x channels) and the sample rate of an audio file, if its header declares
    at most ``limit`` frames (:class:`TooLarge` otherwise, before decoding); never more than ``limit + 1``
    frames are decoded, whatever the header says."""
    import soundfile

    path = str(path)
    info = soundfile.info(path)
    if info.frames > limit:
        raise TooLarge(f"{path} holds {info.frames / info.samplerate:.0f} s of audio: at most "
                       f"{limit / info.samplerate:.0f} s ({limit} samples) is read")
    data, rate = soundfile.read(path, frames=limit + 1, dtype="float32", always_2d=True)
    if len(data) > limit:
        raise TooLarge(f"{path} holds more than {limit} samples of audio: at most {limit} is read")
    return data, rate
