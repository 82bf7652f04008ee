"""The espeak-ng speech backend: :class:`EspeakBackend`."""

from __future__ import annotations

import bisect
import functools

# numpy is imported where audio is made: loading the backend does without it
from speech_timing.backend import Mark, Phoneme, SpeechText, Utterance, Word
from speech_timing.espeak.alignment import first_sound_after, mark_stress_by_clause, read_events, word_spans
from speech_timing.espeak.engine import EVENT_MARK, EVENT_SENTENCE, RATE_MAXIMUM, RATE_MINIMUM, shared_engine
from speech_timing.espeak.ssml import MARK_NAME, to_ssml, written_tokens


class EspeakBackend:
    """Text-to-speech with espeak-ng, timed by the synthesiser's own word, phoneme and mark events.

    Parameters
    ----------
    voice : str
        espeak-ng voice name, e.g. ``"en"``, ``"en-us"``, ``"de"``.
    rate : int
        Speaking rate in words per minute (80 to 450).

    Raises
    ------
    SpeechBackendUnavailable
        If the espeak-ng library or its data is not installed.
    ValueError
        For an unknown voice or a rate out of range.

    Notes
    -----
    A word starts with its first phoneme, where its sound starts, and ends where its last phoneme
    ends. espeak's WORD and MARK events come earlier, before the silent gap in front of the word (about
    12 ms, and about 50 ms before a voiceless stop), and a MARK in front of the second word of a pair
    espeak pronounces as one ("in <mark/>the") comes only at the word after the pair. So a mark is
    placed at the onset of the first word starting at or after its offset; a mark after the last word
    keeps the time of its MARK event (the end of the speech before the final pause).

    Phoneme names are IPA as espeak writes them (``ð ə k ˈa t`` without the stress marks); pauses are
    not listed. ``stressed`` marks the vowel of a syllable with primary stress.
    """

    name = "espeak"
    #: it says a text it was asked for before as it said it then (see :meth:`synthesize`)
    remembers = True

    def __init__(self, voice: str = "en", rate: int = 175) -> None:
        if not RATE_MINIMUM <= rate <= RATE_MAXIMUM:
            raise ValueError(f"rate must be {RATE_MINIMUM} to {RATE_MAXIMUM} words per minute, not {rate}")
        self._engine = shared_engine()
        self._engine.select(voice, int(rate))
        self.voice = voice
        self.rate = int(rate)
        # what was said, kept: the same text is said the same every time (each synthesis is a fresh
        # engine's, see _Pristine), and asked for again, of this backend or another of its voice and rate,
        # it is not synthesised again
        self._spoken = self._engine.spoken(voice, self.rate)

    @property
    def sample_rate(self) -> int:
        """Sample rate of the audio, in Hz."""
        return self._engine.sample_rate

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech`` and return its audio with word, phoneme, mark and sentence times.

        Parameters
        ----------
        speech : SpeechText
            Plain text, marks at character offsets (0 to ``len(text)``) and prosody spans.

        Returns
        -------
        Utterance
            Times in seconds from the start of ``audio`` (float32 mono in [-1, 1]). The same ``speech``
            asked for again gets the same utterance (the last :data:`REMEMBERED` are kept, up to
            :data:`REMEMBERED_BYTES` of audio).
        """
        # (what it said is looked up without waiting for the engine; _synthesize holds the engine's lock, one
        # for all threads)
        return self._spoken.said(speech, self._synthesize)

    @property
    def remembered_bytes(self) -> int:
        """Bytes of audio the remembered utterances hold."""
        return self._spoken.bytes

    def forget(self, speech: SpeechText) -> None:
        """Stop remembering what ``speech`` was (whoever asked keeps it, in a form of its own: the speech
        cache reads its samples from its file); asked for again, it is synthesised again."""
        self._spoken.forget(speech)

    def _synthesize(self, speech: SpeechText) -> Utterance:
        text = speech.text
        ssml, origin = to_ssml(text, speech.marks, speech.prosody)
        tokens = written_tokens(text)
        engine = self._engine
        words_per_minute = min(max(round(self.rate * speech.rate), RATE_MINIMUM), RATE_MAXIMUM)
        with engine.lock:
            buffer, events = engine.synth(ssml, self.voice, words_per_minute)
            pcm = buffer.samples()
            groups = read_events(text, origin, tokens, events, len(pcm))
            mark_stress_by_clause(groups, tokens, engine.transcribe_clauses(text, self.voice, words_per_minute))
            spans = word_spans(text, tokens, groups, functools.lru_cache(maxsize=None)(self._symbols))
        rate = self.sample_rate
        duration = len(pcm) / rate

        words, phonemes = [], []
        for index, (char_start, char_end, drafts) in enumerate(spans):
            words.append(Word(index, text[char_start:char_end], drafts[0].start / rate, drafts[-1].end / rate,
                              char_start, char_end))
            phonemes.extend(Phoneme(p.symbol, p.start / rate, p.end / rate, index, p.stressed) for p in drafts)

        mark_events = {event.name: event.sample for event in events if event.kind == EVENT_MARK}
        word_starts = [word.char_start for word in words]
        times = [0.0] * len(speech.marks)
        latest = 0.0
        # in text order: a mark is never before one that stands before it (espeak-ng's MARK events after the
        # last word can come a few samples out of order when many follow one another)
        for k in sorted(range(len(speech.marks)), key=lambda k: (speech.marks[k][0], k)):
            following = bisect.bisect_left(word_starts, speech.marks[k][0])
            if following < len(words):
                time = words[following].start
            else:  # after the last word
                time = mark_events.get(MARK_NAME.format(k), len(pcm)) / rate
            latest = times[k] = max(time, latest)
        marks = [Mark(name, t) for (_, name), t in zip(speech.marks, times)]

        sentences = []
        for i, event in enumerate(events):
            if event.kind == EVENT_SENTENCE:
                onset = first_sound_after(events, i)
                sentences.append((event.sample if onset is None else onset) / rate)

        # the 16-bit samples kept as they are (half the memory of their float32 array), read as float32 a
        # stretch at a time by whoever mixes them
        from speech_timing.samples import Pcm

        audio = Pcm(pcm)
        return Utterance(text=text, duration=duration, words=words, phonemes=phonemes, marks=marks,
                         sentences=sentences, sample_rate=rate, audio=audio, backend=self.name)

    def ssml(self, speech: SpeechText) -> str:
        """The SSML sent to espeak-ng for ``speech``: ``marks[i]`` as ``<mark name="m<i>"/>``, and the
        prosody spans espeak-ng can apply as its elements (see :func:`_prosody_markup`)."""
        return to_ssml(speech.text, speech.marks, speech.prosody)[0]

    def _symbols(self, word: str) -> list[str]:
        """Phoneme symbols of one written word on its own."""
        return [symbol for symbol, _ in self._engine.transcribe(word, self.voice, self.rate)]
