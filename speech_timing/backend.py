"""The text-to-speech backend interface: text with sync marks in, timed words, phonemes and audio out."""

from __future__ import annotations

import bisect
import re
from dataclasses import MISSING, dataclass, field
from typing import TYPE_CHECKING, Protocol, Sequence, runtime_checkable

if TYPE_CHECKING:  # numpy is not needed to read or time a text
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
        """The value of attribute ``name`` as written (``default`` if the span has none)."""
        return dict(self.attrs).get(name, default)


@dataclass(frozen=True)
class SpeechText:
    """Plain text to speak, with named sync marks at character offsets.

    ``marks`` holds ``(offset, name)`` pairs: a mark at ``offset`` stands before the character at that
    offset, so it is realized at the onset of the first word that starts at or after it. ``rate`` speeds
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
    #: float32 mono in [-1, 1): an array, or 16-bit samples standing in for one
    #: (:class:`~speech_timing.samples.Pcm16`: length, dtype, slicing and ``np.asarray`` as the array's)
    audio: np.ndarray | None = None
    backend: str = ""

    def phonemes_by_word(self) -> list[list[Phoneme]]:
        """The phonemes of each word, in order (phonemes of no word are left out)."""
        groups: list[list[Phoneme]] = [[] for _ in self.words]
        for ph in self.phonemes:
            if 0 <= ph.word_index < len(groups):
                groups[ph.word_index].append(ph)
        return groups

    def _lookup(self) -> tuple:
        """The words' character starts and the phonemes of each word, made once (made again if the lists
        are replaced or change length)."""
        cache = self.__dict__.get("_cached_lookup")
        if (cache is None or cache[0] is not self.words or cache[1] is not self.phonemes
                or cache[2] != len(self.words) or cache[3] != len(self.phonemes)):
            cache = (self.words, self.phonemes, len(self.words), len(self.phonemes),
                     [w.char_start for w in self.words], self.phonemes_by_word())
            self.__dict__["_cached_lookup"] = cache  # not a field: replace(), == and asdict() do not see it
        return cache

    def word_after(self, offset: int) -> int | None:
        """Index of the first word starting at or after character ``offset`` (None: none)."""
        starts = self._lookup()[4]
        k = bisect.bisect_left(starts, offset)
        return k if k < len(starts) else None

    def phonemes_of(self, k: int) -> list[Phoneme]:
        """The phonemes of word ``k``, in order (do not change the list)."""
        groups = self._lookup()[5]
        if 0 <= k < len(groups):
            return groups[k]
        return [p for p in self.phonemes if p.word_index == k]

    def word_sounding(self, t: float) -> Word | None:
        """The first word sounding at ``t`` (s; from 1 ns before its onset to its end), else the first word
        starting from 1 ns before ``t`` on, else None."""
        words = self.words
        if self._words_in_order():
            # onsets and ends both in order: the words that start by t are a prefix, and those of them
            # still sounding at t its end
            prefix = bisect.bisect_right(words, t, key=lambda w: w.start - 1e-9)
            k = bisect.bisect_right(words, t, hi=prefix, key=lambda w: w.end)
            if k < prefix:
                return words[k]
            k = bisect.bisect_left(words, t - 1e-9, key=lambda w: w.start)
            return words[k] if k < len(words) else None
        inside = next((w for w in words if w.start - 1e-9 <= t < w.end), None)
        return inside if inside is not None else next((w for w in words if w.start >= t - 1e-9), None)

    def _words_in_order(self) -> bool:
        cache = self.__dict__.get("_cached_order")
        if cache is None or cache[0] is not self.words or cache[1] != len(self.words):
            w = self.words
            ordered = all(w[i].start <= w[i + 1].start and w[i].end <= w[i + 1].end for i in range(len(w) - 1))
            cache = (self.words, len(self.words), ordered)
            self.__dict__["_cached_order"] = cache
        return cache[2]

    def mark(self, name: str) -> Mark | None:
        """The first mark of this name (None if there is none)."""
        cache = self.__dict__.get("_cached_marks")
        if cache is None or cache[0] is not self.marks or cache[1] != len(self.marks):
            by_name: dict[str, Mark] = {}
            for mark in self.marks:
                by_name.setdefault(mark.name, mark)
            cache = (self.marks, len(self.marks), by_name)
            self.__dict__["_cached_marks"] = cache
        return cache[2].get(name)

    def mark_time(self, name: str) -> float:
        """Time of the named mark, in seconds from utterance start (KeyError if absent)."""
        mark = self.mark(name)
        if mark is None:
            raise KeyError(name)
        return mark.time


_new = object.__new__
_set = object.__setattr__


def words_of(rows: Sequence[list]) -> list[Word]:
    """The ``Word`` of each row of ``rows`` (one list a field, in the fields' order), made as ``Word.__init__``
    makes it, without a call of it each (a narration has thousands)."""
    made = []
    add = made.append
    for index, text, start, end, char_start, char_end in zip(*rows):
        word = _new(Word)
        _set(word, "__dict__", {"index": index, "text": text, "start": start, "end": end, "char_start": char_start,
                                "char_end": char_end})
        add(word)
    return made


def phonemes_of(rows: Sequence[list]) -> list[Phoneme]:
    """The ``Phoneme`` of each row of ``rows``, made as :func:`words_of` makes words."""
    made = []
    add = made.append
    for symbol, start, end, word_index, stressed in zip(*rows):
        phoneme = _new(Phoneme)
        _set(phoneme, "__dict__", {"symbol": symbol, "start": start, "end": end, "word_index": word_index,
                                   "stressed": stressed})
        add(phoneme)
    return made


class ColumnUtterance(Utterance):
    """An :class:`Utterance` whose ``words`` and ``phonemes`` are made from columns (one list a field) the first
    time they are asked for: scheduling a block asks its speeches for their lengths and marks only, and a
    thousand-behaviour block has thousands of words and phonemes. :meth:`_rows` gives the columns (here those
    it was made with, :meth:`of`).

    Otherwise it is an :class:`Utterance`: equal to one with the same fields, and ``dataclasses.replace``,
    ``copy`` and ``pickle`` treat it as one.
    """

    @classmethod
    def of(cls, fields: dict, words: list[Word] | None = None,
           rows: tuple[Sequence[list] | None, Sequence[list] | None] | None = None) -> "ColumnUtterance":
        """One with the other ``fields`` (text, duration, marks, sentences, sample_rate, audio, backend; those not
        given have their defaults), its words if they are made, and ``rows``: the words' and the phonemes'
        columns (None: :meth:`_rows` of the class gives them)."""
        made = _new(cls)
        for name, known in Utterance.__dataclass_fields__.items():
            if name not in fields and name not in ("words", "phonemes"):
                made.__dict__[name] = known.default_factory() if known.default is MISSING else known.default
        made.__dict__.update(fields)
        if rows is not None:
            made.__dict__["_timeline_rows"] = rows
        if words is not None:
            made.__dict__["_words"] = words
        return made

    def _made(key: str, make, column: int) -> property:  # (called in the class body, once for each list)
        def get(self) -> list:
            made = self.__dict__.get(key)
            if made is None:
                made = self.__dict__[key] = make(self._rows()[column])
                if "_words" in self.__dict__ and "_phonemes" in self.__dict__:  # (both made: columns let go)
                    self.__dict__.pop("_timeline_rows", None)
            return made

        def put(self, value: list) -> None:
            self.__dict__[key] = value

        return property(get, put)

    words = _made("_words", words_of, 0)
    phonemes = _made("_phonemes", phonemes_of, 1)
    del _made

    def _rows(self) -> tuple:
        """The words' and the phonemes' columns (times in seconds)."""
        return self.__dict__["_timeline_rows"]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Utterance):
            return NotImplemented
        return all(getattr(self, name) == getattr(other, name) for name in Utterance.__dataclass_fields__)

    __hash__ = None  # (as a dataclass's that compares its fields)


@runtime_checkable
class TTSBackend(Protocol):
    """A text-to-speech backend."""

    name: str

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech`` and return its timeline (and audio, if the backend makes sound)."""
        ...


class Spoken:
    """What a backend said, kept: the last ``size`` utterances by their :class:`SpeechText`, holding at most
    ``max_bytes`` of audio together (the oldest are forgotten first; one larger than that is not kept at all),
    looked up and added under a lock of their own (not the synthesiser's), so that a speech asked for again is
    answered at once, as it was said."""

    def __init__(self, size: int, max_bytes: int) -> None:
        import threading
        from collections import OrderedDict

        self.size = size
        self.max_bytes = max_bytes
        #: bytes of audio the kept utterances hold
        self.bytes = 0
        self._kept: "OrderedDict[SpeechText, Utterance]" = OrderedDict()
        self._lock = threading.Lock()

    def get(self, speech: SpeechText) -> "Utterance | None":
        with self._lock:
            spoken = self._kept.get(speech)
            if spoken is not None:
                self._kept.move_to_end(speech)
            return spoken

    def said(self, speech: SpeechText, synthesize) -> "Utterance":
        """What ``speech`` was: the utterance kept for it, or ``synthesize(speech)``, kept (synthesised outside
        this lock: a speech already kept is answered without waiting for the synthesiser)."""
        spoken = self.get(speech)
        return spoken if spoken is not None else self.keep(speech, synthesize(speech))

    def keep(self, speech: SpeechText, utterance: "Utterance") -> "Utterance":
        """Keep ``utterance`` as what ``speech`` was; returns what is kept (one kept before wins)."""
        with self._lock:
            if speech in self._kept:
                return self._kept[speech]
            self._kept[speech] = utterance
            self.bytes += audio_bytes(utterance)
            while self._kept and (len(self._kept) > self.size or self.bytes > self.max_bytes):
                _, forgotten = self._kept.popitem(last=False)
                self.bytes -= audio_bytes(forgotten)
            return utterance

    def forget(self, speech: SpeechText) -> None:
        with self._lock:
            forgotten = self._kept.pop(speech, None)
            if forgotten is not None:
                self.bytes -= audio_bytes(forgotten)


def audio_bytes(utterance: "Utterance") -> int:
    """Bytes of memory an utterance's audio holds (an array's, or the 16-bit samples a
    :class:`~speech_timing.samples.Pcm16` stands in for)."""
    audio = getattr(utterance, "audio", None)
    if audio is None:
        return 0
    held = getattr(audio, "held_bytes", None)
    return int(held if held is not None else audio.nbytes)


def check_marks(text: str, marks: Sequence[tuple[int, str]]) -> None:
    """ValueError if a mark's offset is outside ``text`` (a mark may sit at its very end)."""
    for offset, name in marks:
        if not 0 <= offset <= len(text):
            raise ValueError(f"mark {name!r} at offset {offset} is outside the text (length {len(text)})")


def spoken_text(speech: SpeechText) -> str:
    """The text of ``speech`` as a synthesiser is given it: every kind of white space (and NUL) a plain space,
    one character for one, so that offsets into it are offsets into the speech; its marks checked."""
    text = "".join(" " if ch.isspace() or ch == "\0" else ch for ch in speech.text)
    check_marks(text, speech.marks)
    return text


def check_prosody(speech: SpeechText) -> list[Prosody]:
    """The prosody spans of ``speech`` a backend can apply, properly nested, in the order they open.

    Spans of an unknown kind and empty spans other than breaks are left out, and so is a span that
    crosses one opened before it (it starts inside that span and ends after it): each span kept ends
    before, or inside, every span around it. Spans opening at one offset open the longest first (the
    first given, of equal ones), so that the inner one closes first.

    Raises
    ------
    ValueError
        For a span outside the text, a span that ends before it starts, or a break with ``end != start``.
    """
    n = len(speech.text)
    for span in speech.prosody:
        if not 0 <= span.start <= span.end <= n:
            raise ValueError(f"{span.kind} span {span.start}..{span.end} is outside the text (length {n}) "
                             f"or ends before it starts")
        if span.kind == "break" and span.end != span.start:
            raise ValueError(f"a break stands at one offset, not at {span.start}..{span.end}")
    return nest_spans([span for span in speech.prosody
                       if span.kind in PROSODY_KINDS and (span.kind == "break" or span.end > span.start)])


def nest_spans(spans: Sequence[Prosody]) -> list[Prosody]:
    """``spans`` in the order they open (longest first at one offset), leaving out any span that crosses
    one opened before it. Breaks (empty) are kept in their place: they cross nothing."""
    order = sorted(range(len(spans)), key=lambda i: (spans[i].start, -spans[i].end, i))
    kept: list[Prosody] = []
    open_ends: list[int] = []
    for i in order:
        span = spans[i]
        while open_ends and open_ends[-1] <= span.start:
            open_ends.pop()
        if open_ends and span.end > open_ends[-1]:
            continue  # it crosses the span it starts in
        kept.append(span)
        if span.kind != "break":
            open_ends.append(span.end)
    return kept


_TIME = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*(ms|s)\s*", re.IGNORECASE)


def parse_time(value: str) -> float | None:
    """Seconds of an SSML time designation (``"300ms"``, ``"0.3s"``, ``"2s"``); None if it is not one."""
    match = _TIME.fullmatch(value or "")
    if match is None:
        return None
    number = float(match.group(1))
    return number / 1000.0 if match.group(2).lower() == "ms" else number


_NUMBER = re.compile(r"\s*([+-]?)(\d+(?:\.\d*)?|\.\d+)\s*(%|st|db|hz)?\s*", re.IGNORECASE)


def parse_number(value: str) -> tuple[str, float, str] | None:
    """``(sign, magnitude, unit)`` of a number as SSML's prosody attributes write it, or None.

    ``"+20%"`` gives ``("+", 20.0, "%")``, ``"1.5"`` ``("", 1.5, "")``, ``"-2st"`` ``("-", 2.0, "st")``;
    the unit is one of ``""``, ``"%"``, ``"st"``, ``"db"``, ``"hz"`` (lower case).
    """
    match = _NUMBER.fullmatch(value or "")
    if match is None:
        return None
    sign, number, unit = match.groups()
    return sign, float(number), (unit or "").lower()


#: SSML's break strengths, weakest first.
BREAK_STRENGTHS = ("none", "x-weak", "weak", "medium", "strong", "x-strong")


def mark_times_from_words(speech: SpeechText, words: Sequence[Word], duration: float) -> list[Mark]:
    """Place each mark at the onset of the first word starting at or after its character offset.

    A mark after the last word is placed at the end of the utterance.
    """
    starts = [word.char_start for word in words]
    if any(b < a for a, b in zip(starts, starts[1:])):  # words out of text order: look at each
        return [Mark(name, next((w.start for w in words if w.char_start >= offset), duration))
                for offset, name in speech.marks]
    marks = []
    for offset, name in speech.marks:
        k = bisect.bisect_left(starts, offset)  # the first word starting at or after the mark
        marks.append(Mark(name, words[k].start if k < len(words) else duration))
    return marks


def backend_key(backend: TTSBackend) -> tuple:
    """Identity of a backend's configuration (its class, name and simple attributes), for caches."""
    simple = tuple(sorted((k, v) for k, v in vars(backend).items() if isinstance(v, (bool, int, float, str))))
    return type(backend).__qualname__, getattr(backend, "name", ""), simple
