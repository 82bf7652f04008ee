"""A deterministic built-in speech timing model: words and phonemes timed by a phoneme-duration table.

It makes no sound. It stands in for a real text-to-speech engine where only timing matters (fast tests,
scheduling), with the same interface as the real backends.
"""

from __future__ import annotations

import re

from agentsim.speech.backend import Phoneme, SpeechText, Utterance, Word, mark_times_from_words

_WORD = re.compile(r"[\w']+")
_UNITS = re.compile(r"th|sh|ch|ng|ph|ck|qu|[aeiouy]+|[a-z]|\d|'", re.I)
_VOWELS = set("aeiouy")
FUNCTION_WORDS = frozenset(
    "a an the and or but of to in on at by for with from as is are was were be been am i you he she it we "
    "they me him her us them my your his its our their this that these those not no so if then than do does "
    "did have has had will would can could shall should may might must".split()
)


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
        text = speech.text
        scale = 1.0 / (self.rate * speech.rate)
        t = self.lead * scale
        words: list[Word] = []
        phonemes: list[Phoneme] = []
        sentences = [t]
        for match in _WORD.finditer(text):
            index = len(words)
            token = match.group(0)
            start = t
            content = token.lower() not in FUNCTION_WORDS
            stressed_done = False
            for unit in _UNITS.findall(token):
                vowel = unit[0].lower() in _VOWELS or unit.isdigit()
                stressed = vowel and content and not stressed_done
                stressed_done = stressed_done or stressed
                duration = (self.vowel if vowel else self.consonant) * (self.stress_factor if stressed else 1.0)
                phonemes.append(Phoneme(unit.lower(), t, t + duration * scale, index, stressed))
                t += duration * scale
            words.append(Word(index, token, start, t, match.start(), match.end()))
            following = text[match.end():match.end() + 2].strip()[:1]
            if following in ",;:":
                t += self.comma_pause * scale
            elif following in ".!?":
                t += self.sentence_pause * scale
                sentences.append(t)
        duration = t + self.tail * scale
        if sentences and sentences[-1] >= words[-1].end if words else False:
            sentences.pop()
        return Utterance(text, duration, words, phonemes, mark_times_from_words(speech, words, duration),
                         sentences, backend=self.name)
