"""espeak-ng's events read into words, phonemes and stress: each written word gets the phonemes whose sound
it is, starting at its first phoneme, and the vowel of its stressed syllable."""

from __future__ import annotations

import bisect
import difflib
from dataclasses import dataclass, field

from speech_timing.espeak.engine import EVENT_PHONEME, EVENT_WORD, PRIMARY_STRESS, RawEvent
from speech_timing.espeak.ssml import Token, token_index


@dataclass
class _PhonemeDraft:
    """A sounding phoneme, in samples."""

    symbol: str
    start: int
    end: int
    stressed: bool = False


@dataclass
class _Group:
    """The sounding phonemes reported under one WORD event.

    ``token`` is the written word the event points to. espeak pronounces some word pairs from its
    dictionary as one word ("in the", "of a"); then the group also holds the next written word.
    """

    token: int
    phonemes: list[_PhonemeDraft] = field(default_factory=list)


def _phoneme_ends(events: list[RawEvent], total_samples: int) -> dict[int, int]:
    """End sample of each PHONEME event, keyed by its index in ``events``.

    A phoneme ends at the next PHONEME event, or earlier at a WORD event in between: espeak puts the
    silent gap before a word (up to about 50 ms before a voiceless stop) after the WORD event. A WORD
    event at the phoneme's own sample does not end it: a nasal or liquid before a vowel is sounded
    after that WORD event, as the start of the vowel.
    """
    ends: dict[int, int] = {}
    next_phoneme = total_samples
    word_between: int | None = None
    for i in range(len(events) - 1, -1, -1):
        event = events[i]
        if event.kind == EVENT_PHONEME:
            end = next_phoneme
            if word_between is not None and event.sample < word_between < next_phoneme:
                end = word_between
            ends[i] = max(event.sample, min(end, total_samples))
            next_phoneme, word_between = event.sample, None
        elif event.kind == EVENT_WORD:
            word_between = event.sample
    return ends


def read_events(text: str, origin: list[int], tokens: list[Token], events: list[RawEvent],
                total_samples: int) -> list[_Group]:
    """Group the sounding phonemes (pauses left out) by the written word espeak reports them under.

    Several WORD events inside one written word ("1234", "AT&T", "Dr.") make one group.
    """
    starts = [token.start for token in tokens]
    ends = _phoneme_ends(events, total_samples)
    groups: list[_Group] = []
    for i, event in enumerate(events):
        if event.kind == EVENT_WORD:
            position = event.text_position - 1
            offset = origin[position] if 0 <= position < len(origin) else len(text)
            token = token_index(tokens, starts, offset)
            if token is not None and (not groups or token > groups[-1].token):
                groups.append(_Group(token))
        elif event.kind == EVENT_PHONEME and event.name and groups:
            groups[-1].phonemes.append(_PhonemeDraft(event.name, event.sample, ends[i]))
    return groups


def _is_spoken(text: str, token: Token) -> bool:
    """Whether a written word has a letter or digit, so that espeak says something for it."""
    return any(ch.isalnum() for ch in text[token.start:token.end])


def _split_counts(symbols: list[str], parts: list[list[str]]) -> list[int]:
    """How many of a group's phoneme ``symbols`` belong to each of its written words.

    ``parts`` are the words' own transcriptions. When their lengths add up, they are used as they are;
    otherwise each phoneme goes to the word of the transcription phoneme it aligns with (a phoneme
    that aligns with none goes with the one before).
    """
    if sum(len(part) for part in parts) == len(symbols):
        return [len(part) for part in parts]
    flat = [symbol for part in parts for symbol in part]
    owner = [k for k, part in enumerate(parts) for _ in part]
    labels: list[int | None] = [None] * len(symbols)
    for block in difflib.SequenceMatcher(None, symbols, flat, autojunk=False).get_matching_blocks():
        for d in range(block.size):
            labels[block.a + d] = owner[block.b + d]
    counts = [0] * len(parts)
    current = 0
    for label in labels:
        current = max(current, label if label is not None else current)
        counts[current] += 1
    return counts


def word_spans(text: str, tokens: list[Token], groups: list[_Group], transcribe
                ) -> list[tuple[int, int, list[_PhonemeDraft]]]:
    """``(char_start, char_end, phonemes)`` for each word as spoken, in order.

    A group covering several written words is split between them by their own transcriptions
    (``transcribe(word) -> list of symbols``); a written word that gets no phoneme of its own is
    joined to its neighbour in the group.
    """
    spans: list[tuple[int, int, list[_PhonemeDraft]]] = []
    for g, group in enumerate(groups):
        if not group.phonemes:
            continue  # a word event with no sound
        following = groups[g + 1].token if g + 1 < len(groups) else len(tokens)
        members = [group.token] + [k for k in range(group.token + 1, following) if _is_spoken(text, tokens[k])]
        if len(members) == 1:
            counts = [len(group.phonemes)]
        else:
            parts = [transcribe(text[tokens[k].core_start:tokens[k].core_end]) for k in members]
            counts = _split_counts([p.symbol for p in group.phonemes], parts)
        position, first_of_group = 0, len(spans)
        pending_start: int | None = None
        for k, count in zip(members, counts):
            token = tokens[k]
            if count == 0:
                if len(spans) > first_of_group:  # join the previous word of this group
                    start, _, phonemes = spans[-1]
                    spans[-1] = (start, token.core_end, phonemes)
                elif pending_start is None:  # join the next one
                    pending_start = token.core_start
                continue
            start = token.core_start if pending_start is None else pending_start
            spans.append((start, token.core_end, group.phonemes[position:position + count]))
            position += count
            pending_start = None
    return spans


def mark_stress_by_clause(groups: list[_Group], tokens: list[Token],
                           clauses: list[tuple[int, list[tuple[str, str]]]]) -> None:
    """:func:`_mark_stress` clause by clause: the phonemes of the words that start in a clause of the
    transcription (``(end, phonemes)`` as :meth:`_Engine.transcribe_clauses` gives them) aligned with its
    phonemes, so that a long text costs in proportion to its length."""
    if not clauses:
        return
    ends = [end for end, _ in clauses]
    spoken: list[list[_PhonemeDraft]] = [[] for _ in clauses]
    for group in groups:
        if group.phonemes:
            start = tokens[group.token].core_start if group.token < len(tokens) else ends[-1]
            spoken[min(bisect.bisect_right(ends, start), len(clauses) - 1)].extend(group.phonemes)
    for phonemes, (_, transcription) in zip(spoken, clauses):
        _mark_stress(phonemes, transcription)


def _mark_stress(phonemes: list[_PhonemeDraft], transcription: list[tuple[str, str]]) -> None:
    """Set ``stressed`` on phonemes aligned with a primary-stressed phoneme of the transcription."""
    matcher = difflib.SequenceMatcher(None, [p.symbol for p in phonemes],
                                      [symbol for symbol, _ in transcription], autojunk=False)
    for block in matcher.get_matching_blocks():
        for k in range(block.size):
            phonemes[block.a + k].stressed = transcription[block.b + k][1] == PRIMARY_STRESS


def first_sound_after(events: list[RawEvent], index: int) -> int | None:
    """Sample of the first sounding PHONEME event after ``events[index]`` (None if there is none)."""
    for event in events[index + 1:]:
        if event.kind == EVENT_PHONEME and event.name:
            return event.sample
    return None
