"""What espeak-ng is sent: a text as SSML with a mark at every sync mark and its prosody spans, and the
mapping of espeak's positions back to the written words of the plain text."""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass
from xml.sax.saxutils import escape

from speech_timing.backend import (BREAK_STRENGTHS, Prosody, SpeechText, check_marks, check_prosody, nest_spans,
                                   parse_number, parse_time)

MARK_NAME = "m{}"
_MARK_ELEMENT = '<mark name="' + MARK_NAME + '"/>'

_WRITTEN_WORD = re.compile(r"[^\s\x00\u2012-\u2015\u2026/]+")  # not space, NUL, figure/en/em dash, bar, ellipsis, slash

# Characters at the edges of a written word that are not part of the word as spoken.
_SILENT_EDGE = frozenset('.,;:!?"\'()[]{}<>«»“”„‘’‚‹›…–—¡¿*_-')


def to_ssml(text: str, marks: tuple[tuple[int, str], ...], prosody: tuple[Prosody, ...] = ()
             ) -> tuple[str, list[int]]:
    """SSML for ``text`` with a mark element ``m<i>`` for ``marks[i]`` at its offset and an element for
    each prosody span espeak-ng can apply (see :func:`_prosody_markup`).

    Returns the SSML and, for each of its characters, the offset in ``text`` it stands for (a character
    of an escaped entity stands for the escaped character, markup for the character that follows it).
    Marks get generated names so that any name survives the round trip. At one offset, the elements
    that close come first (the inner before the outer), then breaks, marks, and the elements that open
    (the outer before the inner).
    """
    check_marks(text, marks)
    order = sorted(range(len(marks)), key=lambda i: (marks[i][0], i))
    opens: dict[int, list[str]] = {}
    closes: dict[int, list[str]] = {}
    breaks: dict[int, list[str]] = {}
    for span, (opening, closing) in _prosody_markup(text, prosody):
        if span.kind == "break":
            breaks.setdefault(span.start, []).append(opening)
        else:
            opens.setdefault(span.start, []).append(opening)
            closes.setdefault(span.end, []).insert(0, closing)  # opened later: inner, closes first
    pieces: list[str] = []
    origin: list[int] = []

    def emit(piece: str, offset: int) -> None:
        pieces.append(piece)
        origin.extend([offset] * len(piece))

    k = 0
    for offset in range(len(text) + 1):
        for piece in closes.get(offset, []) + breaks.get(offset, []):
            emit(piece, offset)
        while k < len(order) and marks[order[k]][0] == offset:
            emit(_MARK_ELEMENT.format(order[k]), offset)
            k += 1
        for piece in opens.get(offset, ()):
            emit(piece, offset)
        if offset < len(text):
            emit(escape(text[offset]) if text[offset] != "\0" else " ", offset)  # NUL would end the C string
    return "".join(pieces), origin


# What espeak-ng 1.51 reads (its ssml.c). A value it does not know is worse than left out: an unknown
# emphasis level is looked up at index -1 of a table, an unknown say-as makes it read the text as
# something else and report words inside the markup, and "0.3s" is read as 0 ms (it reads the digits
# before the first other character, then "s" for seconds).
_EMPHASIS_LEVELS = frozenset({"none", "reduced", "moderate", "strong", "x-strong"})
_PROSODY_LABELS = {
    "rate": frozenset({"x-slow", "slow", "medium", "fast", "x-fast", "default"}),
    "pitch": frozenset({"x-low", "low", "medium", "high", "x-high", "default"}),
    "range": frozenset({"x-low", "low", "medium", "high", "x-high", "default"}),
    "volume": frozenset({"silent", "x-soft", "soft", "medium", "loud", "x-loud", "default"}),
}
#: Units espeak reads in each prosody attribute ("st" and "db" only as a signed change).
_PROSODY_UNITS = {"rate": ("", "%"), "pitch": ("", "%", "st"), "range": ("", "%", "st"),
                  "volume": ("", "%", "db")}
#: say-as interpretations espeak reads, by the name given; SSML's "digits" is espeak's "tts:digits"
#: (digit by digit). Others ("cardinal", "date", ...) are left out: espeak reads numbers as cardinals.
_SAY_AS = {"characters": "characters", "tts:char": "tts:char", "tts:key": "tts:key",
           "tts:digits": "tts:digits", "digits": "tts:digits", "telephone": "telephone"}


def _prosody_value(name: str, value: str) -> str | None:
    """``value`` of prosody attribute ``name`` as espeak reads it, or None if espeak cannot read it.

    A label, a percentage (``"80%"``, ``"+20%"``), a number (for ``rate`` a factor: ``"1.5"``, ``"+0.5"``;
    for pitch, range and volume espeak's own 0-100 scale, or a change on it: ``"75"``, ``"+10"``), a signed
    number of semitones for pitch and range (``"+2st"``), of espeak's volume units for volume (``"+6dB"``).
    Values in Hz, unsigned semitones or decibels, rates below 1 % and percentages below zero are left
    out.
    """
    label = value.strip().lower()
    if label in _PROSODY_LABELS[name]:
        return label
    number = parse_number(value)
    if number is None:
        return None
    sign, magnitude, unit = number
    if unit not in _PROSODY_UNITS[name] or (unit in ("st", "db") and not sign):
        return None
    if unit == "%" or name == "rate":
        percent = magnitude * (1.0 if unit == "%" else 100.0)
        percent = percent if not sign else 100.0 + (percent if sign == "+" else -percent)
        if percent < (1.0 if name == "rate" else 0.0):
            return None
    return f"{sign}{magnitude:g}{'dB' if unit == 'db' else unit}"


def _attribute(name: str, value: str) -> str:
    """`` name="value"``, the value escaped for a double-quoted attribute."""
    return f' {name}="{escape(value, {chr(34): "&quot;"})}"'


def _markup(span: Prosody) -> tuple[str, str] | None:
    """The opening and closing markup of one span (a break: its empty element and ""), or None when
    espeak-ng can apply nothing of it."""
    if span.kind == "break":
        seconds = parse_time(span.attr("time")) if span.attr("time") else None
        strength = span.attr("strength").strip().lower()
        if seconds is not None:
            return "<break" + _attribute("time", f"{round(seconds * 1000)}ms") + "/>", ""
        if strength in BREAK_STRENGTHS:
            return "<break" + _attribute("strength", strength) + "/>", ""
        return ("<break/>", "") if not span.attrs else None
    if span.kind == "emphasis":
        level = span.attr("level").strip().lower()
        return "<emphasis" + (_attribute("level", level) if level in _EMPHASIS_LEVELS else "") + ">", "</emphasis>"
    if span.kind == "prosody":
        attributes = ""
        for name in ("rate", "pitch", "range", "volume"):
            value = _prosody_value(name, span.attr(name)) if span.attr(name) else None
            attributes += _attribute(name, value) if value is not None else ""
        return ("<prosody" + attributes + ">", "</prosody>") if attributes else None
    if span.kind == "say-as":
        interpret = _SAY_AS.get(span.attr("interpret-as").strip().lower())
        if interpret is None:
            return None
        attributes = _attribute("interpret-as", interpret)
        if interpret == "characters" and span.attr("format").strip().lower() == "glyphs":
            attributes += _attribute("format", "glyphs")
        if interpret == "tts:digits" and span.attr("detail").strip().isdigit():
            attributes += _attribute("detail", span.attr("detail").strip())
        return "<say-as" + attributes + ">", "</say-as>"
    return None


def _prosody_markup(text: str, prosody: tuple[Prosody, ...]) -> list[tuple[Prosody, tuple[str, str]]]:
    """The spans espeak-ng can apply, with their markup, on offsets moved to the edges of written words.

    espeak separates an SSML element from the text around it as if by a space, so an element inside a
    written word would split it: an offset strictly inside a word's spoken core moves out of it, to the
    core's start for a span's start and to its end for a span's end or a break. Spans the move makes
    cross are left out (the one opened later). In the order they open.
    """
    cores = [(token.core_start, token.core_end) for token in written_tokens(text)]
    starts = [start for start, _ in cores]

    def snap(offset: int, outward_to_end: bool) -> int:
        i = bisect.bisect_right(starts, offset) - 1
        if i >= 0 and cores[i][0] < offset < cores[i][1]:
            return cores[i][1] if outward_to_end else cores[i][0]
        return offset

    markup: dict[int, tuple[str, str]] = {}
    moved = []
    for span in check_prosody(SpeechText(text, prosody=tuple(prosody))):
        found = _markup(span)
        if found is None:
            continue
        if span.kind == "break":
            start = end = snap(span.start, True)
        else:
            start, end = snap(span.start, False), snap(span.end, True)
        span = Prosody(span.kind, start, end, span.attrs)
        markup[id(span)] = found
        moved.append(span)
    return [(span, markup[id(span)]) for span in nest_spans(moved)]


@dataclass(frozen=True)
class Token:
    """A written word: its run of ``text`` (``start``, ``end``) and its spoken core (``core_*``)."""

    start: int
    end: int
    core_start: int
    core_end: int


def written_tokens(text: str) -> list[Token]:
    """Written words of ``text``: runs between whitespace, dashes and slashes, trimmed of punctuation.

    A hyphen does not separate words: espeak reads "well-known" under one WORD event. Punctuation
    alone ("-", "...") is not a word.
    """
    tokens = []
    for match in _WRITTEN_WORD.finditer(text):
        start, end = match.span()
        core_start, core_end = core_span(text, start, end)
        if core_start < core_end:  # punctuation alone is not spoken
            tokens.append(Token(start, end, core_start, core_end))
    return tokens


def core_span(text: str, start: int, end: int) -> tuple[int, int]:
    """``text[start:end]`` without the punctuation at its edges (:data:`_SILENT_EDGE`): the written word as
    spoken (an empty span at the end of punctuation alone)."""
    while start < end and text[start] in _SILENT_EDGE:
        start += 1
    while end > start and text[end - 1] in _SILENT_EDGE:
        end -= 1
    return start, end


def token_index(tokens: list[Token], starts: list[int], offset: int) -> int | None:
    """Index of the token a word event at ``offset`` belongs to (None past the last token).

    An offset in whitespace or in a token's trailing punctuation belongs to the next token: espeak
    sometimes reports a word one character early after a full stop.
    """
    i = bisect.bisect_right(starts, offset) - 1
    if i >= 0 and offset < tokens[i].core_end:
        return i
    return i + 1 if i + 1 < len(tokens) else None
