"""Words after a pause started where their sound rises out of the pause, within one alignment step of the time
Piper's alignments give.

Piper counts each phoneme's samples in whole frames of the model (256 samples, 11.6 ms at 22,050 Hz), and its
decoder spreads the sound of a frame over its neighbours: after a pause, a word's sound often rises a few
milliseconds before or after the frame boundary that starts its first phoneme (the breath before a
sentence's first word is made in the frames of the sentence start ``^``). Such a word is started where its sound
rises out of the pause, as heard in the audio, but never more than one frame from Piper's time: a word whose
sound rises earlier (or later) than that starts one frame before (after) it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from speech_timing.backend import Phoneme, Word

__all__ = ["PAUSE", "RISE_DB", "rise", "started_at_their_sound"]

#: A gap (s) this long before a word is a pause.
PAUSE = 0.1
#: How far over the pause's median energy (dB) the sound rises, in :data:`RUN` frames of :data:`FRAME` running.
RISE_DB = 20.0
#: Frames (s) of the energy measure, and how many running frames over the pause make a rise.
FRAME, RUN = 0.002, 3
#: The pause measured: at most this long (s), ending this long before the word's time (s).
PAUSE_MEASURED, PAUSE_END = 0.1, 0.04


def rise(pcm: np.ndarray, rate: int, t: float, pause_start: float) -> float | None:
    """Where the sound rises out of the pause before ``t`` (s): the first of :data:`RUN` frames running, from
    :data:`PAUSE_END` before ``t``, whose energy is :data:`RISE_DB` over the median energy of the pause (its last
    :data:`PAUSE_MEASURED` seconds up to :data:`PAUSE_END` before ``t``, from ``pause_start`` on); None if the
    pause is too short to measure or the sound does not rise within 0.12 s after ``t``."""
    hop = max(int(rate * FRAME), 1)
    first = int(round(max(pause_start, t - PAUSE_END - PAUSE_MEASURED) * rate))
    start = int(round((t - PAUSE_END) * rate))
    last = min(int(round((t + 0.12) * rate)), len(pcm))
    if start - first < 2 * hop or last <= start:
        return None
    quiet = np.asarray(pcm[first:start], dtype=np.float64)
    n = len(quiet) // hop
    floor = float(np.median(np.mean(quiet[len(quiet) - n * hop:].reshape(n, hop) ** 2, axis=1)))
    sound = np.asarray(pcm[start:last], dtype=np.float64)
    m = len(sound) // hop
    energy = np.mean(sound[:m * hop].reshape(m, hop) ** 2, axis=1)
    over = energy > max(floor, 1e-12) * 10.0 ** (RISE_DB / 10.0)
    for j in range(m - RUN + 1):
        if over[j:j + RUN].all():
            return (start + j * hop) / rate
    return None


def started_at_their_sound(words: list[Word], phonemes: list[Phoneme], pcm: np.ndarray, rate: int,
                           step: int) -> tuple[list[Word], list[Phoneme]]:
    """``words`` and ``phonemes`` with each word after a pause (the first word too) and its first phoneme started
    where the sound rises (:func:`rise`), moved at most ``step`` samples from its time, to the sample, and kept
    after the word before it and before its first phoneme's end."""
    firsts = {}
    for n, phoneme in enumerate(phonemes):
        firsts.setdefault(phoneme.word_index, n)
    words, phonemes = list(words), list(phonemes)
    for k, word in enumerate(words):
        before = words[k - 1].end if k else 0.0
        if k and word.start - before < PAUSE or k not in firsts:
            continue
        heard = rise(pcm, rate, word.start, before)
        if heard is None:
            continue
        at = int(round(word.start * rate))
        moved = min(max(int(round(heard * rate)), at - step), at + step)
        first = phonemes[firsts[k]]
        moved = min(max(moved, int(np.ceil(before * rate))), int(round(first.end * rate)) - 1)
        if moved == at:
            continue
        start = moved / rate
        words[k] = replace(word, start=start)
        phonemes[firsts[k]] = replace(first, start=start)
    return words, phonemes
