"""A deterministic built-in speech timing model: words and phonemes timed by a phoneme-duration table.

It makes no sound. It stands in for a real text-to-speech engine where only timing matters (fast tests,
scheduling), with the same interface as the real backends.

Prosody spans (:class:`~speech_timing.backend.Prosody`) change the timing exactly:

* ``break``: a pause before the first word that starts at or after its offset (after the last word,
  before the final tail). ``time`` (``"300ms"``, ``"0.3s"``) is the pause as given, whatever the rate.
  A ``strength`` is a pause like punctuation's, scaled by the backend's rate and the text's, as
  :data:`BREAK_PAUSES` says; a break with no attribute is ``medium``. A break adds to the pause of any
  punctuation at its place. A break whose attributes are all unknown values adds nothing.
* ``prosody rate``: the phonemes of the words the span overlaps last ``1 / factor`` as long. The labels
  (:data:`RATE_LABELS`: x-slow 0.5, slow 0.75, medium 1, fast 1.5, x-fast 2) are factors on the
  backend's rate; a percentage (``"80%"``; ``"+20%"``, ``"-20%"`` a change), a number (``"1.5"``) or a
  signed number (``"+0.5"``, a change) multiplies the rate of the span around it. Other values, and
  values that come to zero or less, are left out. Pauses keep their lengths.
* ``emphasis``: the stressed vowel of each word the span overlaps (a function word's first vowel, as it
  has none) lasts longer by the factor of the level (:data:`EMPHASIS_FACTORS`: none 1, reduced 0.9,
  moderate 1.2, strong 1.4, x-strong 1.6); no level, or an unknown one, is moderate. The innermost
  emphasis of a word counts.
* ``say-as``, and ``prosody`` pitch and volume: no change in timing (this backend makes no sound).
"""

from __future__ import annotations

import functools
import math
import re

from speech_timing.backend import (ColumnUtterance, Prosody, SpeechText, Utterance, Word, check_prosody,
                                     mark_times_from_words, parse_number, parse_time)

_WORD = re.compile(r"[\w']+")
_UNITS = re.compile(r"th|sh|ch|ng|ph|ck|qu|[aeiouy]+|[a-z]|\d|'", re.I)
_VOWELS = set("aeiouy")
FUNCTION_WORDS = frozenset(
    "a an the and or but of to in on at by for with from as is are was were be been am i you he she it we "
    "they me him her us them my your his its our their this that these those not no so if then than do does "
    "did have has had will would can could shall should may might must".split()
)

#: Speed factors of the ``prosody rate`` labels, on the backend's own rate.
RATE_LABELS = {"x-slow": 0.5, "slow": 0.75, "medium": 1.0, "fast": 1.5, "x-fast": 2.0, "default": 1.0}
#: How much longer an emphasised word's stressed vowel lasts, by emphasis level.
EMPHASIS_FACTORS = {"none": 1.0, "reduced": 0.9, "moderate": 1.2, "strong": 1.4, "x-strong": 1.6}
#: Break pauses by strength, in units of the backend's ``(comma_pause, sentence_pause)``:
#: ``a * comma_pause + b * sentence_pause`` (0, 0.09, 0.18, 0.265, 0.35 and 0.7 s by default).
BREAK_PAUSES = {"none": (0.0, 0.0), "x-weak": (0.5, 0.0), "weak": (1.0, 0.0), "medium": (0.5, 0.5),
                "strong": (0.0, 1.0), "x-strong": (0.0, 2.0)}


def rate_factor(value: str, enclosing: float = 1.0, labels: dict[str, float] = RATE_LABELS) -> float | None:
    """The speed factor a ``prosody rate`` value gives inside a span of speed ``enclosing`` (see the
    module's docstring; ``labels``: the factor of each rate label); None for a value that is left out."""
    label = (value or "").strip().lower()
    if label in labels:
        return labels[label]
    number = parse_number(value)
    if number is None or number[2] not in ("", "%"):
        return None
    sign, magnitude, unit = number
    magnitude = magnitude / 100.0 if unit == "%" else magnitude
    factor = enclosing * (magnitude if not sign else 1.0 + (magnitude if sign == "+" else -magnitude))
    return factor if math.isfinite(factor) and factor > 0 else None


def _overlapping(span: Prosody, spans: list[tuple[int, int]]) -> range:
    """Indices of the word ``spans`` (char start, char end) that ``span`` overlaps."""
    first = next((i for i, (_, end) in enumerate(spans) if end > span.start), len(spans))
    last = first
    while last < len(spans) and spans[last][0] < span.end:
        last += 1
    return range(first, last)


@functools.lru_cache(maxsize=4096)
def _word_units(token: str) -> tuple[bool, tuple[tuple[str, bool, bool], ...]]:
    """Whether a word is a content word, and its units: (symbol, is a vowel, is the stressed vowel)."""
    content = token.lower() not in FUNCTION_WORDS
    units = []
    stressed_done = False
    for unit in _UNITS.findall(token):
        vowel = unit[0].lower() in _VOWELS or unit.isdigit()
        stressed = vowel and content and not stressed_done
        stressed_done = stressed_done or stressed
        units.append((unit.lower(), vowel, stressed))
    return content, tuple(units)


class BuiltinBackend:
    """Times text with fixed phoneme durations (seconds), scaled by ``rate`` (1 = normal)."""

    name = "builtin"

    def __init__(self, rate: float = 1.0, vowel: float = 0.085, consonant: float = 0.06,
                 stress_factor: float = 1.4, lead: float = 0.05, tail: float = 0.1,
                 comma_pause: float = 0.18, sentence_pause: float = 0.35):
        if rate <= 0:
            raise ValueError("rate must be positive")
        self.rate = rate
        self.vowel, self.consonant, self.stress_factor = vowel, consonant, stress_factor
        self.lead, self.tail = lead, tail
        self.comma_pause, self.sentence_pause = comma_pause, sentence_pause

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Time the words of ``speech`` (its prosody spans as the module's docstring says); no audio."""
        text = speech.text
        scale = 1.0 / (self.rate * speech.rate)
        matches = list(_WORD.finditer(text))
        speed, emphasis, pauses = self._prosody(speech, [m.span() for m in matches], scale)
        t = self.lead * scale
        words: list[Word] = []
        # the phonemes as columns (symbol, start, end, word index, stressed): made into Phoneme objects only when
        # asked for (scheduling asks for the words' times and the marks)
        symbols: list[str] = []
        starts: list[float] = []
        ends: list[float] = []
        indices: list[int] = []
        stresses: list[bool] = []
        sentences: list[float] = []
        sentence_starts = True
        k = 0  # the next pause
        vowel_time, consonant_time, stress_factor = self.vowel, self.consonant, self.stress_factor
        new, set_fields = object.__new__, object.__setattr__
        add_symbol, add_start, add_end, add_index, add_stress = (symbols.append, starts.append, ends.append,
                                                                 indices.append, stresses.append)
        for match in matches:
            while k < len(pauses) and pauses[k][0] <= match.start():
                t += pauses[k][1]
                k += 1
            index = len(words)
            token = match.group(0)
            start = t
            if sentence_starts:
                sentences.append(start)
                sentence_starts = False
            content, units = _word_units(token)
            emphasised_done = False
            word_scale = scale / speed[index]
            emphasised = emphasis[index]
            for symbol, vowel, stressed in units:
                duration = (vowel_time if vowel else consonant_time) * (stress_factor if stressed else 1.0)
                if emphasised != 1.0 and vowel and not emphasised_done and (stressed or not content):
                    duration *= emphasised
                    emphasised_done = True
                add_symbol(symbol)
                add_start(t)
                t += duration * word_scale
                add_end(t)
                add_index(index)
                add_stress(stressed)
            # (Word(index, token, start, t, char start, char end), made without the frozen dataclass's __init__)
            word = new(Word)
            set_fields(word, "__dict__", {"index": index, "text": token, "start": start, "end": t,
                                          "char_start": match.start(), "char_end": match.end()})
            words.append(word)
            following = text[match.end():match.end() + 2].strip()[:1]
            if following in ",;:":
                t += self.comma_pause * scale
            elif following in ".!?":
                t += self.sentence_pause * scale
                sentence_starts = True
        t += sum(pause for _, pause in pauses[k:])
        duration = t + self.tail * scale
        if not words:
            sentences = [self.lead * scale]
        return ColumnUtterance.of({"text": text, "duration": duration, "sentences": sentences, "backend": self.name,
                                   "marks": mark_times_from_words(speech, words, duration)},
                                  words=words, rows=(None, (symbols, starts, ends, indices, stresses)))

    def _prosody(self, speech: SpeechText, word_spans: list[tuple[int, int]], scale: float
                 ) -> tuple[list[float], list[float], list[tuple[int, float]]]:
        """Per word its speed factor and emphasis factor; the pauses of the breaks as ``(offset, seconds)``."""
        speed = [1.0] * len(word_spans)
        emphasis = [1.0] * len(word_spans)
        pauses: list[tuple[int, float]] = []
        for span in check_prosody(speech):  # outer spans first
            if span.kind == "break":
                pause = self._break_pause(span, scale)
                if pause is not None:
                    pauses.append((span.start, pause))
            elif span.kind == "prosody" and span.attr("rate"):
                for i in _overlapping(span, word_spans):
                    factor = rate_factor(span.attr("rate"), speed[i])
                    speed[i] = speed[i] if factor is None else factor
            elif span.kind == "emphasis":
                factor = EMPHASIS_FACTORS.get(span.attr("level", "moderate").strip().lower(),
                                              EMPHASIS_FACTORS["moderate"])
                for i in _overlapping(span, word_spans):
                    emphasis[i] = factor
        pauses.sort(key=lambda pause: pause[0])  # stable: breaks at one offset keep their order
        return speed, emphasis, pauses

    def _break_pause(self, span: Prosody, scale: float) -> float | None:
        """Seconds of pause of a break (None if none of its attributes has a known value)."""
        if not span.attrs:
            a, b = BREAK_PAUSES["medium"]
            return (a * self.comma_pause + b * self.sentence_pause) * scale
        if span.attr("time"):
            seconds = parse_time(span.attr("time"))
            if seconds is not None:
                return seconds
        strength = span.attr("strength").strip().lower()
        if strength in BREAK_PAUSES:
            a, b = BREAK_PAUSES[strength]
            return (a * self.comma_pause + b * self.sentence_pause) * scale
        return None
