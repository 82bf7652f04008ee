"""How long each phoneme of a text will last: true durations, and a calibrated phonetic model of them.

A strategy that maps progress events onto a plan made by Chang's linear model must predict when the
next words will be heard, from events that are a delivery delay and a jitter old. How well it can do
depends on how well it knows the durations of the phonemes in between. This module gives that
knowledge at three levels, all as arrays of phoneme durations per word (a phoneme lasts from its onset
to the next phoneme's; a word's last phoneme to the next word's onset, so the pause is included):

* :func:`true_durations`: what the text-to-speech engine really did (the yardstick's zero point);
* :func:`noisy_durations`: the truth with Gaussian error of a given size per phoneme, a stand-in for a
  text-to-duration model of that accuracy;
* :class:`PhonemeDurationModel`: a phonetic model calibrated like Chang's linear model, from
  calibration utterances: the mean duration of each phoneme in its context (its neighbours, stress,
  place in the word and in the clause, the break after its word), backing off to coarser contexts
  where the calibration data is thin.

:func:`for_plan` lines any of them up with the words of a :class:`~speech_timing.plan.SpeechPlan`, for
its :attr:`~speech_timing.plan.SpeechPlan.phoneme_durations`.
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from speech_timing.backend import Utterance
from speech_timing.builtin import FUNCTION_WORDS
from speech_timing.plan import BREAK_SENTENCE, SpeechPlan, word_breaks

__all__ = ["true_durations", "noisy_durations", "for_plan", "PhonemeDurationModel", "calibration_corpus"]

_VOWEL_LETTERS = frozenset("aeiouyɪʊəɛɒʌæɑɔɜɐ")


def true_durations(utterance: Utterance) -> list[np.ndarray]:
    """Each word's phoneme durations (s) as the engine spoke them (a word with no phoneme: one, its gap)."""
    words = utterance.words
    out = []
    for i, phonemes in enumerate(utterance.phonemes_by_word()):
        following = words[i + 1].start if i + 1 < len(words) else utterance.duration
        onsets = [p.start for p in phonemes] or [words[i].start]
        out.append(np.diff(np.append(onsets, following)))
    return out


def noisy_durations(utterance: Utterance, error: float, rng: np.random.Generator) -> list[np.ndarray]:
    """:func:`true_durations` with independent Gaussian error of ``error`` seconds each (kept at 5 ms or more)."""
    if not (math.isfinite(error) and error >= 0):
        raise ValueError("error must be a finite non-negative number of seconds")
    return [np.maximum(d + rng.normal(0.0, error, len(d)), 0.005) for d in true_durations(utterance)]


def for_plan(utterance: Utterance, plan: SpeechPlan, durations: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
    """Per-word ``durations`` of ``utterance`` lined up with the words of ``plan`` by character offset.

    A plan word that the utterance does not have as a word of its own gets one duration: its plan gap.
    """
    by_char = {word.char_start: np.asarray(d, dtype=float) for word, d in zip(utterance.words, durations)}
    gaps = np.diff(np.append(plan.word_onsets, plan.duration))
    chars = plan.word_chars if plan.word_chars is not None else [w.char_start for w in utterance.words]
    out = []
    for k in range(plan.n_words):
        known = by_char.get(int(chars[k])) if k < len(chars) else None
        out.append(known if known is not None else np.array([max(float(gaps[k]), 0.0)]))
    return tuple(out)


def _is_vowel(symbol: str) -> bool:
    return bool(symbol) and symbol[0] in _VOWEL_LETTERS


def _contexts(utterance: Utterance) -> list[list[tuple]]:
    """For every phoneme, its context keys from the finest to the coarsest."""
    words = utterance.words
    breaks = word_breaks(utterance.text, [(w.char_start, w.char_end) for w in words])
    if breaks:
        breaks[-1] = BREAK_SENTENCE  # the end of an utterance counts as the end of a sentence
    flat = []  # (phoneme, word index, position in word, word length, break after word)
    for i, (phonemes, brk) in enumerate(zip(utterance.phonemes_by_word(), breaks)):
        for m, ph in enumerate(phonemes):
            flat.append((ph, i, m, len(phonemes), brk))
    # vowels and stressed vowels from each phoneme to the end of its clause (the next written break)
    to_clause = [(0, 0)] * len(flat)
    vowels = stressed = 0
    for j in range(len(flat) - 1, -1, -1):
        ph, _, m, n, brk = flat[j]
        if m == n - 1 and brk:
            vowels = stressed = 0
        to_clause[j] = (min(vowels, 3), min(stressed, 2))
        if _is_vowel(ph.symbol):
            vowels += 1
            stressed += int(ph.stressed)
    keys = []
    for j, (ph, i, m, n, brk) in enumerate(flat):
        final = m == n - 1
        after = flat[j + 1][0].symbol if j + 1 < len(flat) else "#"
        before = flat[j - 1][0].symbol if j > 0 else "#"
        next_word = words[i + 1].text.lower().strip("'\u2019") if final and i + 1 < len(words) else ""
        next_word = next_word if next_word in FUNCTION_WORDS else ("-" if not final else "*")
        brk = brk if final else -1
        vowels, stressed = to_clause[j]
        s, st = ph.symbol, bool(ph.stressed)
        after_class = "#" if after == "#" else ("V" if _is_vowel(after) else "C")
        keys.append([(s, st, brk, after, before, vowels, stressed, next_word),
                     (s, st, brk, after, vowels, stressed, next_word),
                     (s, st, brk, after, vowels),
                     (s, st, brk, after_class),
                     (s, st, brk),
                     (s, brk),
                     (brk,)])
    keys_by_word: list[list[tuple]] = [[] for _ in words]
    for (_, i, *_rest), k in zip(flat, keys):
        keys_by_word[i].append(k)
    return keys_by_word


class PhonemeDurationModel:
    """Mean phoneme duration by context, calibrated on utterances, backing off to coarser contexts.

    The contexts, from the finest: the phoneme's symbol and stress, the break after its word (for a
    word's last phoneme), the next and the previous phoneme, the vowels and stressed vowels left before
    the end of the clause, and the next word when it is a function word; then fewer of these, down to
    the symbol and the break alone, and the break alone (pauses are never mixed with phonemes inside a
    clause). A context's estimate is its mean shrunk towards the coarser one's with a weight of
    ``prior`` observations.

    Parameters
    ----------
    prior : float
        Weight (in observations) of the coarser context's estimate.
    """

    def __init__(self, prior: float = 2.0) -> None:
        if not (math.isfinite(prior) and prior > 0):
            raise ValueError("prior must be positive")
        self.prior = prior
        self.tables: list[dict[tuple, list[float]]] = [{} for _ in range(7)]
        self.mean = 0.08
        self.n = 0

    def fit(self, utterances: Iterable[Utterance]) -> "PhonemeDurationModel":
        """Add the phonemes of ``utterances`` (with their true durations) to the tables; returns self."""
        total = self.mean * self.n
        for utterance in utterances:
            for keys, durations in zip(_contexts(utterance), true_durations(utterance)):
                for levels, d in zip(keys, durations):
                    for table, key in zip(self.tables, levels):
                        cell = table.setdefault(key, [0.0, 0.0])
                        cell[0] += float(d)
                        cell[1] += 1.0
                    total += float(d)
                    self.n += 1
        self.mean = total / self.n if self.n else self.mean
        return self

    def predict(self, utterance: Utterance) -> list[np.ndarray]:
        """Predicted phoneme durations (s) of each word, from the utterance's phoneme symbols and text only."""
        out = []
        for keys in _contexts(utterance):
            durations = []
            for levels in keys:
                estimate = self.mean
                for table, key in zip(reversed(self.tables), reversed(levels)):
                    total, count = table.get(key, (0.0, 0.0))
                    estimate = (total + self.prior * estimate) / (count + self.prior)
                durations.append(estimate)
            out.append(np.array(durations or [self.mean], dtype=float))
        return out


def calibration_corpus() -> list[str]:
    """Texts to calibrate a :class:`PhonemeDurationModel` on: the bundled calibration utterances and the
    passages of ``texts/calibration/`` (about 12,000 words of prose in ten registers, none of them on
    the topics of the evaluation texts)."""
    from speech_timing.linear_model import TEXTS_DIR, calibration_texts

    passages = [p.read_text(encoding="utf-8") for p in sorted((TEXTS_DIR / "calibration").glob("*.txt"))]
    return calibration_texts() + passages
