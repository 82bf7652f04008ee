"""Piper's phoneme symbols read into words and phonemes: which written word each symbol is the sound of, and the
symbols (one code point each) joined into the phonemes espeak-ng names (``aɪ``, ``tʃ``, ``iː``)."""

from __future__ import annotations

import bisect
import difflib
import unicodedata
from typing import Callable, Sequence

__all__ = ["PRIMARY", "SECONDARY", "JOINED", "is_sound", "word_groups", "owners", "join_symbols"]

#: espeak-ng's stress marks, written before the stressed syllable's vowel (or its onset).
PRIMARY, SECONDARY = "ˈ", "ˌ"
#: Pairs of symbols espeak-ng's English voices name as one phoneme: diphthongs and affricates.
JOINED = frozenset({"aɪ", "aʊ", "eɪ", "oʊ", "əʊ", "ɔɪ", "tʃ", "dʒ"})


def is_sound(symbol: str) -> bool:
    """Whether a symbol is part of a word (a letter, a mark or a modifier), not a space, punctuation (a pause)
    or Piper's sentence start ``^`` and end ``$``."""
    return bool(symbol) and unicodedata.category(symbol[0])[0] in "LM"


def _modifies(symbol: str) -> bool:
    """Whether a symbol belongs to the phoneme before it: a length mark, a diacritic, a modifier letter."""
    return (symbol not in (PRIMARY, SECONDARY)
            and (unicodedata.combining(symbol) > 0 or unicodedata.category(symbol) in ("Lm", "Sk", "Mn")))


def word_groups(symbols: Sequence[str]) -> list[list[int]]:
    """The indices of each run of sounding symbols (a word as espeak-ng transcribes it), in order."""
    groups: list[list[int]] = []
    inside = False
    for i, symbol in enumerate(symbols):
        if is_sound(symbol):
            if not inside:
                groups.append([])
            groups[-1].append(i)
            inside = True
        else:
            inside = False
    return groups


def _bare(symbols: Sequence[str]) -> list[str]:
    return [s for s in symbols if s not in (PRIMARY, SECONDARY)]


def owners(groups: list[list[str]], words: list[str], transcribe: Callable[[str], list[list[str]]]) -> list[list[int]]:
    """For each symbol of each transcribed word (``groups``, Piper's phonemes of a stretch of text), the index of
    the written word (``words``, the stretch's words in order) whose sound it is.

    When the words' own transcriptions (``transcribe(word)`` -> its groups) have as many groups as the stretch,
    the groups go to the words in order. Otherwise (espeak-ng says "of a" as one word, or a number or an
    abbreviation differently in its context) each symbol goes to the word of the transcription symbol it aligns
    with, stress marks aside; a symbol that aligns with none goes with the one before it in its group (the
    first ones of a group: with its first that aligns); a group that aligns nowhere goes to the next word if a
    word is left between the group before it and the next group that aligns ("a" said ``ɐ``, alone ``ˈeɪ``),
    else with the group before it; and a word never comes before one written before it.
    """
    if not groups:
        return []
    if not words:
        return [[-1] * len(group) for group in groups]
    own = [transcribe(word) for word in words]
    if sum(len(parts) for parts in own) == len(groups):
        counts = [len(parts) for parts in own]
        result, k = [], 0
        for word, count in enumerate(counts):
            for _ in range(count):
                result.append([word] * len(groups[k]))
                k += 1
        return result
    spoken = [(g, i) for g, group in enumerate(groups) for i, s in enumerate(group) if s not in (PRIMARY, SECONDARY)]
    said = [s for group in groups for s in _bare(group)]
    flat = [(s, k) for k, parts in enumerate(own) for part in parts for s in _bare(part)]
    labels: dict[tuple[int, int], int] = {}
    matcher = difflib.SequenceMatcher(None, said, [s for s, _ in flat], autojunk=False)
    for block in matcher.get_matching_blocks():
        for d in range(block.size):
            labels[spoken[block.a + d]] = flat[block.b + d][1]
    firsts = [min((labels[(g, i)] for i in range(len(group)) if (g, i) in labels), default=None)
              for g, group in enumerate(groups)]
    result, current = [], 0
    for g, group in enumerate(groups):
        found = [labels[(g, i)] for i in range(len(group)) if (g, i) in labels]
        if not found:  # a group that aligns nowhere: the next word, if one is left before the next group's
            following = next((f for f in firsts[g + 1:] if f is not None), len(words))
            said_before = any(r for r in result)
            candidate = current + 1 if said_before else current
            label = candidate if candidate < following else current
        else:
            label = max(current, found[0])
        row = []
        for i in range(len(group)):
            if (g, i) in labels:
                label = max(label, labels[(g, i)])
            row.append(label)
        current = label
        result.append(row)
    _share(groups, result, [sum(len(_bare(part)) for part in parts) for parts in own])
    return result


def _share(groups: list[list[str]], result: list[list[int]], lengths: list[int]) -> None:
    """Give the written words that got no symbol a share of the group their neighbour has, by the lengths of
    their own transcriptions (``lengths``): the last group of the word before them (the first group of the word
    after them, at the start), its symbols in order."""
    owned = {label for row in result for label in row}
    k = 0
    while k < len(lengths):
        if k in owned:
            k += 1
            continue
        m = k
        while m + 1 < len(lengths) and m + 1 not in owned:
            m += 1
        if k > 0:
            members = list(range(k - 1, m + 1))
            g = max(g for g, row in enumerate(result) if k - 1 in row)
        elif m + 1 < len(lengths):
            members = list(range(0, m + 2))
            g = min(g for g, row in enumerate(result) if m + 1 in row)
        else:
            break
        group, row = groups[g], result[g]
        spots = [i for i, label in enumerate(row) if label in members and group[i] not in (PRIMARY, SECONDARY)]
        counts = [lengths[j] for j in members]
        if len(set(row)) == 1 and sum(counts[:-1]) < len(spots):
            bounds, total = [], 0
            for count in counts[:-1]:
                total += count
                bounds.append(spots[total])  # the first symbol of the next member
            for i in range(len(row)):
                row[i] = members[bisect.bisect_right(bounds, i)]
        k = m + 1


def join_symbols(symbols: Sequence[str]) -> list[tuple[str, int, int, bool]]:
    """The phonemes of one transcribed word: ``(name, first, last, stressed)`` with ``first`` and ``last`` the
    indices of its first and last symbol. A stress mark belongs to the phoneme after it (which is stressed if
    the mark is primary), a length mark or diacritic to the one before it, and the pairs of :data:`JOINED` are
    one phoneme."""
    phonemes: list[list] = []
    stress_from: int | None = None
    stressed = False
    for i, symbol in enumerate(symbols):
        if symbol in (PRIMARY, SECONDARY):
            stress_from = i if stress_from is None else stress_from
            stressed = stressed or symbol == PRIMARY
            continue
        last = phonemes[-1] if phonemes else None
        if last is not None and stress_from is None and (
                _modifies(symbol) or (len(last[0]) == 1 and last[0] + symbol in JOINED)):
            last[0] += symbol
            last[2] = i
            continue
        phonemes.append([symbol, i if stress_from is None else stress_from, i, stressed])
        stress_from, stressed = None, False
    if stress_from is not None and phonemes:  # a stress mark last: it goes with the phoneme before
        phonemes[-1][2] = len(symbols) - 1
    return [(name, first, last, bool(stress)) for name, first, last, stress in phonemes]
