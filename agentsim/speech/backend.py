"""The text-to-speech backend interface: text with sync marks in, timed words, phonemes and audio out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence, runtime_checkable

import numpy as np


#: The kinds of :class:`Prosody` span, as in SSML.
PROSODY_KINDS = ("emphasis", "prosody", "break", "say-as")


@dataclass(frozen=True)
class Prosody:
    """How a stretch of the text is to be spoken (SSML's elements, on plain-text offsets).

    ``kind`` is one of :data:`PROSODY_KINDS`; the span covers ``text[start:end]`` (a ``break`` stands at
    ``start`` = ``end``). ``attrs`` are the SSML attributes as written, e.g. ``(("rate", "slow"),)``,
    ``(("level", "strong"),)``, ``(("time", "300ms"),)``, ``(("interpret-as", "characters"),)``.
    A backend applies what it can and leaves the rest; it never drops a word.
    """

    kind: str
    start: int
    end: int
    attrs: tuple[tuple[str, str], ...] = ()

    def attr(self, name: str, default: str = "") -> str:
        return dict(self.attrs).get(name, default)


@dataclass(frozen=True)
class SpeechText:
    """Plain text to speak, with named sync marks at character offsets.

    ``marks`` holds ``(offset, name)`` pairs: a mark at ``offset`` stands before the character at that
    offset, so it is realised at the onset of the first word that starts at or after it. ``rate`` speeds
    the backend's own rate up (above 1) or slows it down. ``prosody`` holds SSML-like spans (emphasis,
    rate/pitch/volume, breaks, say-as), nested properly (a span ends before, or inside, the one around it).
    """

    text: str
    marks: tuple[tuple[int, str], ...] = ()
    rate: float = 1.0
    prosody: tuple[Prosody, ...] = ()


@dataclass(frozen=True)
class Word:
    """A word as it sounds: onset and offset in seconds from the start of the utterance."""

    index: int
    text: str
    start: float
    end: float
    char_start: int
    char_end: int


@dataclass(frozen=True)
class Phoneme:
    """A phoneme as it sounds, in seconds from the start of the utterance."""

    symbol: str
    start: float
    end: float
    word_index: int
    stressed: bool = False


@dataclass(frozen=True)
class Mark:
    """A named sync mark and the time (seconds from utterance start) at which it is passed."""

    name: str
    time: float


@dataclass
class Utterance:
    """What a backend produced for one text: the timeline and, when the backend makes sound, the audio."""

    text: str
    duration: float
    words: list[Word]
    phonemes: list[Phoneme] = field(default_factory=list)
    marks: list[Mark] = field(default_factory=list)
    sentences: list[float] = field(default_factory=list)
    sample_rate: int = 22050
    audio: np.ndarray | None = None
    backend: str = ""

    def phonemes_by_word(self) -> list[list[Phoneme]]:
        """The phonemes of each word, in order (phonemes of no word are left out)."""
        groups: list[list[Phoneme]] = [[] for _ in self.words]
        for ph in self.phonemes:
            if 0 <= ph.word_index < len(groups):
                groups[ph.word_index].append(ph)
        return groups

    def mark_time(self, name: str) -> float:
        """Time of the named mark, in seconds from utterance start (KeyError if absent)."""
        for mark in self.marks:
            if mark.name == name:
                return mark.time
        raise KeyError(name)


@runtime_checkable
class TTSBackend(Protocol):
    """A text-to-speech backend."""

    name: str

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech`` and return its timeline (and audio, if the backend makes sound)."""
        ...


def mark_times_from_words(speech: SpeechText, words: Sequence[Word], duration: float) -> list[Mark]:
    """Place each mark at the onset of the first word starting at or after its character offset.

    A mark after the last word is placed at the end of the utterance.
    """
    marks = []
    for offset, name in speech.marks:
        time = duration
        for word in words:
            if word.char_start >= offset:
                time = word.start
                break
        marks.append(Mark(name, time))
    return marks


def backend_key(backend: TTSBackend) -> tuple:
    """Identity of a backend's configuration (its class, name and simple attributes), for caches."""
    simple = tuple(sorted((k, v) for k, v in vars(backend).items() if isinstance(v, (bool, int, float, str))))
    return type(backend).__qualname__, getattr(backend, "name", ""), simple
