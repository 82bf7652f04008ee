"""Festival backend: speech from the Festival Speech Synthesis System, timed by its utterance structure.

One long-lived ``festival --pipe`` process per Python process reads Scheme on its standard input. Each
text is synthesised as one utterance, module by module (Festival's ``Text`` utterance type), its wave
saved to a temporary RIFF file, and its ``Token``, ``Word``, ``SylStructure`` (syllables with their
lexical stress) and ``Segment`` relations printed with each segment's start and end. Every time in the
resulting :class:`~speech_timing.backend.Utterance` is therefore a position in the audio Festival made
from the same synthesis, not an estimate.

Voices (``voice=``, the command line's ``--voice``):

* ``us-slt-hts`` (``voice_cmu_us_slt_arctic_hts``, Debian ``festvox-us-slt-hts``): an HTS statistical
  parametric voice of a female US speaker, 32 kHz; the default when it is installed;
* ``kal`` (``voice_kal_diphone``, Debian ``festvox-kallpc16k``): a male US diphone voice, 16 kHz.

Both use Festival's US "radio" phone set; :data:`PHONES` maps it to the IPA symbols espeak-ng's backend
writes (``ð ə k æ t``), the ones the phoneme-duration model and the animator-time strategies read, and
pauses (``pau``) are left out as espeak's are. ``Phoneme.stressed`` marks the vowel of a syllable with
primary lexical stress (Festival's syllable feature ``stress`` = 1).

Words. Festival splits the text into tokens at whitespace (punctuation kept as token features) and
each token into words (``1234`` into four, ``well-known`` into two); the words of one written token make
one :class:`~speech_timing.backend.Word`, from the start of its first segment to the end of its last, on
the token's characters with the punctuation at its edges left off. A token the voice says nothing for
(punctuation alone, characters outside its language, such as 東京) is no word. A sync mark is passed at
the onset of the first word that starts at or after it (a mark after the last word: at the end of the
audio).

Onsets. Festival's segment boundary after a pause comes before the sound: the HTS voice's energy climbs
out of the silence over 5-30 ms of the first phone, and a stop's closure is silent. A word after a pause
therefore starts where its sound rises 15 dB over the pause (:func:`_sound_onsets`); measured against a
detector of its own (20 dB over the pause's median, ``tests/test_festival_backend.py``), 32 words after
pauses agree within 6 ms but for two: a word starting with /θ/, whose noise rises too slowly for either
(26 ms with the HTS voice, 60 ms with the diphone one), and, with the diphone voice, a voiced stop after a
pause, whose diphone voices the pause for about 100 ms before the burst (84 ms). Within running speech
the boundaries are Festival's.

What of SSML Festival applies here, and how:

* ``break``: silence of the time given (strengths: none, x-weak, weak nothing; medium or a break
  without attributes 0.15 s, strong 0.3 s, x-strong 0.6 s, as espeak-ng makes them) is put into the
  audio between the two words, in the middle of the pause Festival made there if it made one (else
  where the second word starts, with a 2 ms fade out and in), and everything after moves by that time.
  Festival's own phrase-break pauses stay.
* The text's ``rate`` (:attr:`SpeechText.rate`): the whole utterance, through the HTS engine's speed
  (``-r``) for the HTS voice and ``Duration_Stretch`` for the diphone voice.
* ``prosody rate`` spans: with the diphone voice, on the words inside the span, through the token
  feature ``dur_stretch`` that Festival's duration module reads (as its SABLE ``RATE`` does); labels as
  espeak-ng reads them (x-slow 60 %, slow 80 %, fast 125 %, x-fast 160 %), percentages and factors. The
  HTS engine takes one speed for a whole utterance, so with the HTS voice rate spans are left out.
* Not applied (left out, every word still spoken): ``emphasis``, ``prosody pitch``, ``range`` and
  ``volume``, and ``say-as``. Festival offers pitch only for a whole utterance (its intonation model's
  parameters; the HTS engine's half-tone shift) and emphasis only through SABLE, which makes utterances
  of its own that this backend does not read.
"""

from __future__ import annotations

import atexit
import bisect
import difflib
import os
import re
import shutil
import subprocess
import tempfile
import threading
import wave
from dataclasses import dataclass

from agentsim.errors import SpeechBackendUnavailable
from speech_timing.backend import (Phoneme, Prosody, SpeechText, Spoken, Utterance, Word, check_prosody, spoken_text,
                                     mark_times_from_words, parse_time)
from speech_timing.builtin import rate_factor
from speech_timing.espeak import core_span

__all__ = ["FestivalBackend", "INSTALL_HINT", "VOICES", "PHONES", "available_voices"]

PACKAGES = ("festival", "festvox-us-slt-hts", "festvox-kallpc16k")
INSTALL_HINT = "apt-get install " + " ".join(PACKAGES)

#: Voices by the name ``--voice`` takes: (Festival's voice function without ``voice_``, Debian package).
VOICES = {"us-slt-hts": ("cmu_us_slt_arctic_hts", "festvox-us-slt-hts"),
          "kal": ("kal_diphone", "festvox-kallpc16k")}
#: Other names of the voices.
ALIASES = {"slt": "us-slt-hts", "cmu_us_slt_arctic_hts": "us-slt-hts", "kal_diphone": "kal", "kal16k": "kal"}
#: The voice taken when none is named, first installed first.
DEFAULT_VOICES = ("us-slt-hts", "kal")

#: Festival's US "radio" phones as IPA, written as espeak-ng's English voice writes them.
PHONES = {
    "aa": "ɑː", "ae": "a", "ah": "ʌ", "ao": "ɔː", "aw": "aʊ", "ax": "ə", "axr": "əɹ", "ay": "aɪ",
    "eh": "ɛ", "er": "ɜː", "ey": "eɪ", "ih": "ɪ", "iy": "iː", "ow": "əʊ", "oy": "ɔɪ", "uh": "ʊ", "uw": "uː",
    "b": "b", "ch": "tʃ", "d": "d", "dh": "ð", "dx": "ɾ", "el": "əl", "em": "əm", "en": "ən", "f": "f",
    "g": "ɡ", "hh": "h", "hv": "h", "jh": "dʒ", "k": "k", "l": "l", "m": "m", "n": "n", "ng": "ŋ",
    "nx": "ɾ̃", "p": "p", "r": "ɹ", "s": "s", "sh": "ʃ", "t": "t", "th": "θ", "v": "v", "w": "w", "y": "j",
    "z": "z", "zh": "ʒ",
}
#: Festival's silence phones (left out of the phonemes).
PAUSES = frozenset({"pau", "h#", "brth", "#"})

#: Seconds of silence a break of each strength adds (as espeak-ng makes them; a break without attributes: medium).
BREAK_SECONDS = {"none": 0.0, "x-weak": 0.0, "weak": 0.0, "medium": 0.15, "strong": 0.3, "x-strong": 0.6}
#: Seconds of the fade out and in around a break's silence put into the audio.
BREAK_FADE = 0.002
#: Speaking-rate factors of SSML's rate labels (as espeak-ng reads them).
RATE_LABELS = {"x-slow": 0.6, "slow": 0.8, "medium": 1.0, "default": 1.0, "fast": 1.25, "x-fast": 1.6}
#: How many utterances a backend keeps to say again as they were.
REMEMBERED = 64
#: and how many bytes of audio they may hold together
REMEMBERED_BYTES = 64 * 2 ** 20
#: Rate factors the backend takes (the text's rate times a span's).
RATE_RANGE = (0.25, 4.0)

_VOWEL_START = frozenset("aeiouɑɔəɛɜɪʊʌ")  # the first characters of the vowels of PHONES
_SENTENCE_END = re.compile(r"[.!?…][\"'”’»)\]]*$")
_END = "@@agentsim-end@@"
_ERROR = "@@agentsim-error@@"

# The Scheme the process is given once. agentsim.say chunks TEXT into utterances as Festival's own text
# to speech does (its end-of-utterance tree: sentences), synthesises each with the diphone voice's global
# duration stretch GLOBAL, the HTS engine's speed SPEED and per-token stretches STRETCHES (a list of
# (token-index factor)), saves its wave to PREFIX<n>.wav and prints "=U file", then its tokens (numbered
# across the text), words, syllables (lexical stress) and segments (start, end).
_SCHEME = r"""
(define (agentsim.roots item)
  (let ((out nil))
    (while item (set! out (cons item out)) (set! item (item.next item)))
    (reverse out)))
(define (agentsim.print utt base)
  (let ((k base))
    (mapcar
     (lambda (tok)
       (format t "=T %d %s\n" k (item.name tok))
       (set! k (+ k 1))
       (mapcar
        (lambda (w)
          (format t "=W\n")
          (mapcar
           (lambda (syl)
             (format t "=Y %s\n" (item.feat syl "stress"))
             (mapcar
              (lambda (seg)
                (format t "=P %s %f %f\n" (item.name seg) (item.feat seg "segment_start") (item.feat seg "end")))
              (item.relation.daughters syl 'SylStructure)))
           (item.relation.daughters w 'SylStructure)))
        (item.relation.daughters tok 'Token)))
     (agentsim.roots (utt.relation.first utt 'Token)))))
(define (agentsim.utterance utt)
  (let ((tokens (agentsim.roots (utt.relation.first utt 'Token)))
        (wavfile (string-append agentsim.prefix (format nil "%d" agentsim.n) ".wav")))
    (mapcar
     (lambda (pair)
       (let ((i (- (car pair) agentsim.k)))
         (if (and (>= i 0) (< i (length tokens))) (item.set_feat (nth i tokens) "dur_stretch" (cadr pair)))))
     agentsim.stretches)
    (utt.synth utt)
    (utt.save.wave utt wavfile 'riff)
    (format t "=U %s\n" wavfile)
    (agentsim.print utt agentsim.k)
    (set! agentsim.n (+ agentsim.n 1))
    (set! agentsim.k (+ agentsim.k (length tokens)))))
(define (agentsim.say text prefix global speed stretches)
  (set! agentsim.prefix prefix)
  (set! agentsim.stretches stretches)
  (set! agentsim.n 0)
  (set! agentsim.k 0)
  (Parameter.set 'Duration_Stretch global)
  (if (boundp 'agentsim.hts_params)
      (set! hts_engine_params (append agentsim.hts_params (list (list "-r" speed)))))
  (set! tts_hooks (list agentsim.utterance))
  (tts_text text nil))
"""


def _quote(text: str) -> str:
    """``text`` as a Scheme string literal."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


class _Process:
    """One ``festival --pipe`` process and the voice it has selected, used under :attr:`lock`."""

    def __init__(self) -> None:
        program = shutil.which("festival")
        if program is None:
            raise SpeechBackendUnavailable(f"Festival is not installed (no festival program on the PATH); "
                                           f"install it with: {INSTALL_HINT}")
        self.lock = threading.RLock()
        self.pid = os.getpid()
        self.folder = tempfile.mkdtemp(prefix="agentsim-festival-")
        self.process = subprocess.Popen([program, "--pipe"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, encoding="utf-8", errors="replace")
        self.voice: str | None = None
        self.count = 0
        self.ask(_SCHEME)
        listed = self.ask('(format t "%l\\n" (voice.list))')
        self.voices = frozenset(re.findall(r"[\w.-]+", " ".join(listed)))

    def ask(self, scheme: str) -> list[str]:
        """Run ``scheme``; the lines it printed. A Scheme error raises RuntimeError saying it."""
        with self.lock:
            self.count += 1
            end = f"{_END}{self.count}"
            request = (f'(unwind-protect (begin {scheme} nil) (format t "{_ERROR}\\n"))\n'
                       f'(format t "\\n{end}\\n") (fflush nil)\n')
            try:
                self.process.stdin.write(request)
                self.process.stdin.flush()
            except OSError as exc:
                raise RuntimeError(f"the festival process ended ({exc})") from None
            lines = []
            while True:
                line = self.process.stdout.readline()
                if not line:
                    raise RuntimeError("the festival process ended: " + " ".join(lines[-3:]).strip())
                line = line.rstrip("\n")
                if line == end:
                    break
                lines.append(line)
        if _ERROR in lines:
            said = [line for line in lines if "ERROR" in line and _ERROR not in line]
            raise RuntimeError(f"festival failed: {(said or ['a Scheme error'])[0].strip()}")
        return lines

    def select(self, voice: str) -> None:
        with self.lock:
            if voice != self.voice:
                self.ask(f"(voice_{VOICES[voice][0]})"
                         f"(if (boundp 'hts_engine_params) (set! agentsim.hts_params hts_engine_params))"
                         if voice == "us-slt-hts" else f"(voice_{VOICES[voice][0]})")
                self.voice = voice

    def close(self) -> None:
        if self.pid == os.getpid():
            try:
                self.process.kill()
                self.process.wait(timeout=5)
                self.process.stdin.close()
                self.process.stdout.close()
            except (OSError, subprocess.TimeoutExpired):
                pass
            shutil.rmtree(self.folder, ignore_errors=True)

    def __del__(self) -> None:
        if getattr(self, "process", None) is not None:
            self.close()


_PROCESS: _Process | None = None
_PROCESS_ERROR: SpeechBackendUnavailable | None = None
_PROCESS_LOCK = threading.Lock()


def _process() -> _Process:
    """The process-wide Festival process, started on first use (again in a forked child); a failure to
    start it is remembered."""
    global _PROCESS, _PROCESS_ERROR
    with _PROCESS_LOCK:
        if _PROCESS_ERROR is not None:
            raise _PROCESS_ERROR
        if _PROCESS is None or _PROCESS.pid != os.getpid() or _PROCESS.process.poll() is not None:
            try:
                _PROCESS = _Process()
                atexit.register(_PROCESS.close)  # the process ended and its folder removed, whatever happens
            except SpeechBackendUnavailable as exc:
                _PROCESS_ERROR = exc
                raise
            except (OSError, RuntimeError) as exc:
                raise SpeechBackendUnavailable(f"Festival could not be started ({exc}); install it with: "
                                               f"{INSTALL_HINT}") from None
        return _PROCESS


def available_voices() -> list[str]:
    """The voices of :data:`VOICES` installed here (SpeechBackendUnavailable if Festival is not)."""
    found = _process().voices
    return [name for name, (festival_name, _) in VOICES.items() if festival_name in found]


def voice_name(voice: str | None) -> str:
    """The name in :data:`VOICES` of ``voice`` (an alias, or None: the first installed of
    :data:`DEFAULT_VOICES`); ValueError for an unknown voice, SpeechBackendUnavailable for one not installed."""
    if voice is None:
        installed = available_voices()
        for name in DEFAULT_VOICES:
            if name in installed:
                return name
        raise SpeechBackendUnavailable(f"Festival has none of its voices {', '.join(DEFAULT_VOICES)} here; "
                                       f"install them with: {INSTALL_HINT}")
    name = ALIASES.get(voice.strip().lower(), voice.strip().lower())
    if name not in VOICES:
        raise ValueError(f"Festival has no voice {voice!r} here; choose {' or '.join(VOICES)}")
    if name not in available_voices():
        raise SpeechBackendUnavailable(f"the Festival voice {name} ({VOICES[name][0]}) is not installed; "
                                       f"install it with: apt-get install {VOICES[name][1]}")
    return name


@dataclass(frozen=True)
class _Chunk:
    """A written token: its run of the text and its spoken core (punctuation at the edges left off)."""

    start: int
    end: int
    core_start: int
    core_end: int


def _chunks(text: str) -> list[_Chunk]:
    """The whitespace-separated tokens of ``text``, as Festival's tokenizer splits it."""
    chunks = []
    for match in re.finditer(r"[^ \t\n\r]+", text):
        start, end = match.span()
        core_start, core_end = core_span(text, start, end)
        if core_start == core_end:
            core_start, core_end = start, end
        chunks.append(_Chunk(start, end, core_start, core_end))
    return chunks


def _break_seconds(span: Prosody) -> float | None:
    """Seconds of silence a break span adds (None: one Festival cannot apply)."""
    if span.attr("time"):
        return parse_time(span.attr("time"))
    strength = span.attr("strength").strip().lower()
    if strength:
        return BREAK_SECONDS.get(strength)
    return BREAK_SECONDS["medium"] if not span.attrs else None


class FestivalBackend:
    """Text-to-speech with Festival, timed by its utterance structure.

    Parameters
    ----------
    voice : str, optional
        ``"us-slt-hts"`` or ``"kal"`` (see :data:`VOICES`); by default the HTS voice when it is installed.
    rate : float
        Speaking-rate factor of the voice's own rate (0.25 to 4).

    Raises
    ------
    SpeechBackendUnavailable
        If Festival or the voice is not installed (the message names the Debian packages).
    ValueError
        For an unknown voice or a rate out of range.
    """

    name = "festival"
    #: it says a text it was asked for before as it said it then (Festival is deterministic; the last
    #: :data:`REMEMBERED` are kept, so that the live service can synthesise a block's speech ahead)
    remembers = True

    def __init__(self, voice: str | None = None, rate: float = 1.0) -> None:
        if not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
            raise ValueError(f"rate must be {RATE_RANGE[0]:g} to {RATE_RANGE[1]:g} times the voice's own, not {rate}")
        self.voice = voice_name(voice)
        self.rate = float(rate)
        self._spoken = Spoken(REMEMBERED, REMEMBERED_BYTES)

    @property
    def festival_voice(self) -> str:
        """Festival's name of the voice (its function without ``voice_``)."""
        return VOICES[self.voice][0]

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech``: its audio (float32 mono in [-1, 1]) with word, phoneme, mark and sentence times
        in seconds from the audio's first sample (a speech asked for again: as it was said)."""
        return self._spoken.said(speech, self._synthesize)

    def forget(self, speech: SpeechText) -> None:
        """Stop remembering what ``speech`` was; asked for again, it is synthesised again."""
        self._spoken.forget(speech)

    def _synthesize(self, speech: SpeechText) -> Utterance:
        import numpy as np

        text = spoken_text(speech)
        spans = check_prosody(speech)
        chunks = _chunks(text)
        rate = min(max(self.rate * speech.rate, RATE_RANGE[0]), RATE_RANGE[1])
        stretches = self._stretches(chunks, spans, rate)
        process = _process()
        with process.lock:
            process.select(self.voice)
            prefix = os.path.join(process.folder, f"u{process.count + 1}-")
            scheme = (f"(agentsim.say {_quote(text)} {_quote(prefix)} {1.0 / rate if self.voice == 'kal' else 1.0:.6f} "
                      f"{rate:.6f} (list {' '.join(f'(list {k} {s:.6f})' for k, s in stretches)}))")
            lines, pieces, sample_rate = [], [], 0
            try:
                offset = 0.0
                for line in process.ask(scheme):
                    if line.startswith("=U "):
                        with wave.open(line[3:], "rb") as file:
                            sample_rate = file.getframerate()
                            pieces.append(np.frombuffer(file.readframes(file.getnframes()), dtype="<i2"))
                        os.remove(line[3:])
                        lines.append(f"=O {offset!r}")
                        offset += len(pieces[-1]) / sample_rate
                    else:
                        lines.append(line)
            finally:
                for name in os.listdir(process.folder):
                    if name.startswith(os.path.basename(prefix)):
                        os.remove(os.path.join(process.folder, name))
        pcm = np.concatenate(pieces) if pieces else np.zeros(0, dtype="<i2")
        sample_rate = sample_rate or (32000 if self.voice == "us-slt-hts" else 16000)
        audio = pcm.astype(np.float32) / 32768.0
        words, phonemes = _sound_onsets(audio, sample_rate, *self._timeline(text, chunks, lines))
        audio, words, phonemes = _insert_breaks(audio, sample_rate, words, phonemes, spans, text)
        duration = len(audio) / sample_rate
        marks = mark_times_from_words(speech, words, duration)
        sentences = [w.start for i, w in enumerate(words)
                     if i == 0 or _SENTENCE_END.search(text[words[i - 1].char_start:_chunk_end(chunks, words[i - 1])])]
        return Utterance(text=speech.text, duration=duration, words=words, phonemes=phonemes, marks=marks,
                         sentences=sentences, sample_rate=sample_rate, audio=audio, backend=self.name)

    def _stretches(self, chunks: list[_Chunk], spans: list[Prosody], rate: float) -> list[tuple[int, float]]:
        """``(token index, duration stretch)`` of the tokens inside rate spans (the diphone voice only)."""
        if self.voice != "kal":
            return []
        factors = [1.0] * len(chunks)
        starts = [c.core_start for c in chunks]
        for span in spans:
            if span.kind != "prosody" or not span.attr("rate"):
                continue
            factor = rate_factor(span.attr("rate"), labels=RATE_LABELS)
            if factor is None:
                continue
            for k in range(bisect.bisect_left(starts, span.start), len(chunks)):
                if chunks[k].core_start >= span.end:
                    break
                factors[k] *= factor
        # Festival multiplies the global stretch (1 / rate) by the token's
        return [(k, rate / min(max(rate * f, RATE_RANGE[0]), RATE_RANGE[1])) for k, f in enumerate(factors) if f != 1.0]

    def _timeline(self, text: str, chunks: list[_Chunk], lines: list[str]) -> tuple[list[Word], list[Phoneme]]:
        """Words and phonemes from the lines :data:`_SCHEME`'s ``agentsim.print`` wrote."""
        tokens: list[list[tuple[str, float, float, bool]]] = []  # per Festival token: its segments
        names: list[str] = []
        stressed, offset = False, 0.0
        for line in lines:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "=O":
                offset = float(parts[1])
            elif parts[0] == "=T":
                tokens.append([])
                names.append(parts[2] if len(parts) > 2 else "")
            elif parts[0] == "=Y" and tokens:
                stressed = parts[1] == "1"
            elif parts[0] == "=P" and tokens and len(parts) == 4:
                tokens[-1].append((parts[1], offset + float(parts[2]), offset + float(parts[3]), stressed))
        owner = _token_chunks(text, chunks, names)
        words: list[Word] = []
        phonemes: list[Phoneme] = []
        by_chunk: dict[int, list[tuple[str, float, float, bool]]] = {}
        for k, segments in enumerate(tokens):
            if owner[k] is not None:
                by_chunk.setdefault(owner[k], []).extend(seg for seg in segments if seg[0] not in PAUSES)
        for c in sorted(by_chunk):
            segments = by_chunk[c]
            if not segments:
                continue
            chunk, index = chunks[c], len(words)
            words.append(Word(index, text[chunk.core_start:chunk.core_end], segments[0][1], segments[-1][2],
                              chunk.core_start, chunk.core_end))
            for name, start, end, stress in segments:
                symbol = PHONES.get(name, name)
                phonemes.append(Phoneme(symbol, start, end, index, stress and symbol[0] in _VOWEL_START))
        return words, phonemes


#: A word this long (s) after the previous one's end, or the first of the text, follows a pause.
PAUSE = 0.03
#: Frames (s) of the energy in which a word's sound is found rising out of the pause before it.
ONSET_FRAME = 0.002
#: The sound rises out of a pause where its energy is this many times (15 dB) the pause's, ...
ONSET_OVER_PAUSE = 10 ** 1.5
#: ... and above this fraction (-60 dB) of the utterance's loudest frame, for this many frames running.
ONSET_FLOOR, ONSET_FRAMES = 1e-6, 3


def _sound_onsets(audio, sample_rate: int, words: list[Word], phonemes: list[Phoneme]
                  ) -> tuple[list[Word], list[Phoneme]]:
    """The words with each word after a pause starting where its sound rises out of that pause.

    Festival's segment boundary after a pause comes before the sound: the HTS engine's smoothed energy
    climbs out of the silence over 5-30 ms of the first phone, and a stop's closure is silent (30-90 ms
    before its burst). A word after a pause (see :data:`PAUSE`) therefore starts at the first of
    :data:`ONSET_FRAMES` frames running whose energy is :data:`ONSET_OVER_PAUSE` times the pause's (its
    90th percentile over the pause's second half, at most its last 100 ms) and above :data:`ONSET_FLOOR`
    of the loudest frame, looked for from 10 ms before Festival's boundary to the end of the word's first
    phone; its first phone starts there too. Elsewhere Festival's boundaries are kept.
    """
    import numpy as np
    from dataclasses import replace

    if not words or len(audio) == 0:
        return words, phonemes
    hop = max(int(sample_rate * ONSET_FRAME), 1)
    frames = len(audio) // hop
    energy = np.mean(np.square(audio[:frames * hop].astype(np.float64)).reshape(frames, hop), axis=1)
    floor = ONSET_FLOOR * float(energy.max()) if frames else 0.0
    first = {p.word_index: i for i, p in reversed(list(enumerate(phonemes)))}
    words, phonemes = list(words), list(phonemes)
    previous_end = 0.0
    for k, word in enumerate(words):
        gap = word.start - previous_end
        previous_end = word.end
        if (k > 0 and gap < PAUSE) or k not in first:
            continue
        head = phonemes[first[k]]
        quiet_from = max(word.start - gap / 2, word.start - 0.1, 0.0)
        a, b = int(quiet_from * sample_rate) // hop, int((word.start - 0.005) * sample_rate) // hop
        if b - a < 3:
            continue
        threshold = max(ONSET_OVER_PAUSE * float(np.percentile(energy[a:b], 90)), floor)
        lo = max(int((word.start - 0.01) * sample_rate) // hop, b)
        hi = min(int(head.end * sample_rate) // hop, frames - ONSET_FRAMES)
        loud = energy[lo:hi + ONSET_FRAMES] > threshold
        run = np.ones(max(hi - lo, 0), dtype=bool)
        for j in range(ONSET_FRAMES):
            run &= loud[j:j + len(run)]
        if run.any():
            onset = min((lo + int(np.argmax(run))) * hop / sample_rate, head.end)
            words[k] = replace(word, start=onset)
            phonemes[first[k]] = replace(head, start=onset)
    return words, phonemes


def _chunk_end(chunks: list[_Chunk], word: Word) -> int:
    """End of the whole written token (punctuation included) of ``word``."""
    k = bisect.bisect_right([c.core_start for c in chunks], word.char_start) - 1
    return chunks[k].end if k >= 0 else word.char_end


def _token_chunks(text: str, chunks: list[_Chunk], names: list[str]) -> list[int | None]:
    """For each Festival token (by its name), the index of the written token it is: by order when their
    numbers agree, else aligned by their letters (a token that aligns with none goes with the one before)."""
    if len(names) == len(chunks):
        return list(range(len(names)))
    written = [text[c.core_start:c.core_end].lower() for c in chunks]
    owner: list[int | None] = [None] * len(names)
    matcher = difflib.SequenceMatcher(None, [n.lower() for n in names], written, autojunk=False)
    for block in matcher.get_matching_blocks():
        for d in range(block.size):
            owner[block.a + d] = block.b + d
    current = None
    for i, found in enumerate(owner):
        current = found if found is not None else current
        owner[i] = current
    return owner


def _insert_breaks(audio, sample_rate: int, words: list[Word], phonemes: list[Phoneme], spans: list[Prosody],
                   text: str):
    """The audio with each break's silence put in between its two words, and the times after it moved."""
    import numpy as np
    from dataclasses import replace

    inserts: list[tuple[int, float, int]] = []  # (first word after, seconds, sample)
    starts = [w.char_start for w in words]
    for span in spans:
        if span.kind != "break":
            continue
        seconds = _break_seconds(span)
        if not seconds:
            continue
        k = bisect.bisect_left(starts, span.start)
        if k < len(words) and words[k].char_start < span.start:  # inside a word: after it
            k += 1
        if not words:
            at = len(audio) / sample_rate
        elif k == 0:
            at = words[0].start
        elif k >= len(words):
            at = words[-1].end
        else:
            at = (words[k - 1].end + words[k].start) / 2
        inserts.append((k, seconds, min(int(round(at * sample_rate)), len(audio))))
    if not inserts:
        return audio, words, phonemes
    inserts.sort(key=lambda item: item[2])
    audio = np.array(audio, dtype=np.float32)
    fade = max(int(sample_rate * BREAK_FADE), 1)
    ramp = (0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, fade))).astype(np.float32)
    for _, _, sample in inserts:  # no click where sound is cut: a short fade out and in around the silence
        before = audio[max(sample - fade, 0):sample]
        before *= ramp[::-1][fade - len(before):]
        after = audio[sample:sample + fade]
        after *= ramp[:len(after)]
    pieces, previous = [], 0
    for _, seconds, sample in inserts:
        pieces += [audio[previous:sample], np.zeros(int(round(seconds * sample_rate)), dtype=audio.dtype)]
        previous = sample
    pieces.append(audio[previous:])
    shift = [0.0] * (len(words) + 1)
    for k, seconds, _ in inserts:
        for j in range(k, len(words) + 1):
            shift[j] += round(seconds * sample_rate) / sample_rate
    words = [replace(w, start=w.start + shift[w.index], end=w.end + shift[w.index]) for w in words]
    phonemes = [replace(p, start=p.start + shift[p.word_index], end=p.end + shift[p.word_index]) for p in phonemes]
    return np.concatenate(pieces), words, phonemes
