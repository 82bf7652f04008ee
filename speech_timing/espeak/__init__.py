"""espeak-ng backend: synthesised speech with word, phoneme and mark timing from the synthesiser's events.

The C library ``libespeak-ng.so.1`` is bound with ctypes and run in synchronous mode. Each text is sent
as SSML with a ``<mark/>`` element at every sync mark. espeak-ng reports WORD, PHONEME, MARK and SENTENCE
events at the sample where they occur in the audio it returns, so every time in the resulting
:class:`~speech_timing.backend.Utterance` is a position in that audio, not an estimate. Word onsets
agree with energy onsets in the audio within about 2 ms.

Observed behaviour of espeak-ng 1.51 that the code relies on or works around:

* ``text_position`` is a 1-based position in *characters* (code points, not UTF-8 bytes) of the SSML
  input, markup included. An entity such as ``&amp;`` is reported at its last character. After a full
  stop, or on a `` - `` before a word, the word is sometimes reported a character or two early.
* A written word that espeak expands (``1234``, ``AT&T``, ``Dr.``) gives several WORD events, all
  inside that word; they are merged into one :class:`~speech_timing.backend.Word`. Word pairs that
  espeak's dictionary pronounces as one word ("in the", "of a") give one WORD event for both; their
  phonemes are split between the two written words by each word's own transcription.
* WORD and MARK events come before the silent gap espeak puts in front of a word; the first PHONEME
  event, where the sound starts, follows 0-13 ms later and about 50 ms later before a voiceless stop.
  A MARK in front of the second word of a dictionary pair comes only at the word after the pair.
  Words therefore start at their first phoneme, and a mark gets the onset of the word it stands before.
* Phoneme names are espeak mnemonics by default (``h @ l oU``, pauses ``_`` and ``_:``) and IPA with
  the IPA option used here (``h ə l əʊ``, pauses as empty names). Neither form carries stress marks.
  Stress is read from ``espeak_TextToPhonemes`` on the same text: with a phoneme separator, it writes
  ``ˈ`` (primary) or ``ˌ`` (secondary) in front of the stressed vowel. Its phoneme sequence is aligned
  with the PHONEME events and ``Phoneme.stressed`` marks primary stress.
* The PHONEME event of a vowel after a nasal or liquid comes after the vowel's onset glide, which
  espeak synthesises as part of the vowel, so such a consonant's interval includes that glide.
* The library is initialised once per process: terminating and initialising again hangs the next
  synthesis. One process-wide engine, guarded by a lock, serves every :class:`EspeakBackend`.
* espeak-ng keeps state between syntheses (the phase of its pitch flutter, its gain control), so the
  same text spoken again in one process gives the same words and phonemes but times that differ by
  up to about 20 ms, and different audio samples. The first synthesis in a fresh process is exactly
  reproducible: every synthesis here is one, in a fork of an engine that has never spoken
  (:class:`~speech_timing.espeak.engine._Pristine`), so the same text gives the same samples and times in
  every process, whatever was said before.

Prosody spans (:class:`~speech_timing.backend.Prosody`) are sent as espeak-ng's SSML elements, with
the values it reads (``docs/markup.md`` and ``ssml.c`` of espeak-ng; others are left out, see
:func:`~speech_timing.espeak.ssml._prosody_markup`). Measured with espeak-ng 1.51 at 175 words per
minute:

* ``<break time=.../>`` widens the gap between its two words by the time given, within 0.05 s at 120
  to 420 words per minute (500 ms: 0.46-0.51 s). It ends a clause, so the word before it gets 0-50 ms
  longer (up to 0.11 s at 120 words per minute). Strengths: none, x-weak and weak add nothing there;
  medium (also a break without attributes) about 0.15 s, strong 0.3 s, x-strong 0.6 s.
* ``<prosody rate=...>``: the enclosed words last 1.54-1.67 times as long at x-slow (espeak: 60 % of the
  voice's rate), 1.19-1.25 at slow (80 %), 0.81-0.85 at fast (125 %), 0.63-0.71 at x-fast (160 %);
  percentages and factors likewise, within espeak's 80 to 450 words per minute. The words around keep
  their times.
* ``pitch`` and ``volume`` change the enclosed words' length by 2 % at most and no word moves by more
  than 30 ms; ``emphasis`` (moderate and up) makes the words 24-42 % longer, and louder.
* ``say-as interpret-as="characters"`` over a written word gives one WORD event for the whole span, so
  the spelled word stays one :class:`~speech_timing.backend.Word` with all its letters' phonemes.
* An SSML element is set apart from the text around it as if by a space, so an element inside a written
  word would split it in two: span edges inside a word are moved to the word's edges.

=============  ======================================================================================
module         what it holds
=============  ======================================================================================
``engine``     the C library bound with ctypes, the process-wide engine and its pristine forks
``ssml``       the SSML sent (marks, prosody spans) and the written words of the plain text
``alignment``  the events read into words, phonemes and stress
``backend``    :class:`~speech_timing.espeak.backend.EspeakBackend`
=============  ======================================================================================
"""

from speech_timing.espeak.backend import EspeakBackend
from speech_timing.espeak.engine import INSTALL_HINT, LIBRARY_NAME, REMEMBERED, REMEMBERED_BYTES
from speech_timing.espeak.ssml import core_span

__all__ = ["EspeakBackend", "INSTALL_HINT", "LIBRARY_NAME", "REMEMBERED", "REMEMBERED_BYTES", "core_span"]
