"""What the planner knows about an utterance before it is played: the :class:`SpeechPlan`.

A plan gives predicted word and phoneme onsets on a *plan axis* of speech time (seconds from the start
of the utterance's audio, as predicted). When the plan comes from the text-to-speech engine's own
timeline (``source="tts"``) the plan axis is the true speech-time axis; when it comes from Chang's
linear characters-to-time model (``source="linear"``) it is only an estimate of it, wrong per word.

Animator time ``t_A`` (see :mod:`speech_timing.animator_time`) is a position on the plan axis, and
gestures are scheduled at plan-axis times, so :meth:`SpeechPlan.event_position` maps a progress event
(word ``k`` started, phoneme ``m`` of word ``k`` started) to the plan-axis position it stands for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["SpeechPlan", "BREAK_NONE", "BREAK_CLAUSE", "BREAK_SENTENCE", "BREAK_PARAGRAPH", "break_after",
           "word_breaks"]

#: Classes of the written break after a word (:attr:`SpeechPlan.breaks`).
BREAK_NONE, BREAK_CLAUSE, BREAK_SENTENCE, BREAK_PARAGRAPH = 0, 1, 2, 3


def break_after(between: str) -> int:
    """Class of the written break in ``between`` (the text between two words).

    Parameters
    ----------
    between : str
        The characters between the end of one word and the start of the next.

    Returns
    -------
    int
        :data:`BREAK_PARAGRAPH` for a blank line, :data:`BREAK_SENTENCE` for ``.!?``,
        :data:`BREAK_CLAUSE` for ``,;:`` or a dash, :data:`BREAK_NONE` otherwise.
    """
    if between.count("\n") >= 2:
        return BREAK_PARAGRAPH
    if any(ch in ".!?" for ch in between):
        return BREAK_SENTENCE
    if any(ch in ",;:()\u2013\u2014" for ch in between) or " - " in between:
        return BREAK_CLAUSE
    return BREAK_NONE


def word_breaks(text: str, spans) -> list[int]:
    """Class of the written break after each word (:func:`break_after`); the last word's is that of the
    text after it.

    Parameters
    ----------
    text : str
        The text.
    spans : sequence of (int, int)
        Character ``(start, end)`` of each word, in order.
    """
    spans = list(spans)
    breaks = [break_after(text[spans[k][1]:spans[k + 1][0]]) for k in range(len(spans) - 1)]
    if spans:
        breaks.append(break_after(text[spans[-1][1]:]))
    return breaks


def _float_array(name: str, values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=float).reshape(-1)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array


@dataclass
class SpeechPlan:
    """What the planner knows about an utterance in advance.

    All times are seconds. Onsets are on the plan axis (predicted speech time, 0 = start of audio).

    Parameters
    ----------
    word_onsets, word_offsets : array_like of float
        Predicted onset and offset of each word; onsets non-decreasing.
    phoneme_onsets : array_like of float
        Predicted onset of each phoneme, word by word (the first ``phonemes_per_word[0]`` belong to
        word 0, and so on); non-decreasing.
    phonemes_per_word : array_like of int
        Number of phonemes predicted in each word (at least 1).
    delay : float
        Known base delay of the progress-event channel (calibrated; excludes the per-event jitter).
    latency : float
        Known nominal playback latency: audio requested at ``t_request`` starts at ``t_request + latency``.
    t_request : float
        Simulation time at which playback is requested. :meth:`AnimatorTime.reset
        <speech_timing.animator_time.AnimatorTime.reset>` takes the request time as an argument,
        which overrides this field.
    duration : float, optional
        Predicted end of the speech (plan axis); defaults to the last word's offset.
    word_chars : array_like of int, optional
        Character offset in the text at which each word starts; events are matched to plan words by it.
    word_texts : tuple of str, optional
        The written words.
    breaks : array_like of int, optional
        Class of the written break after each word (:func:`break_after`).
    stress_onsets : array_like of float, optional
        Predicted onset of each word's stressed vowel (defaults to the word onsets).
    source : {"tts", "linear"}
        Where the timeline comes from: the text-to-speech engine's own timeline, or the linear model.
    linear_model : LinearModel, optional
        A calibrated linear characters-to-time model, for strategies that schedule by it.
    phoneme_durations : sequence of array_like, optional
        Extra knowledge for strategies, beside the plan axis: for each word, the predicted duration (s)
        of each of its phonemes as it will really be spoken, from its onset to the next phoneme's (the
        last one to the next word's onset, so it includes the pause after the word). The plan axis is
        unchanged; :class:`~speech_timing.animator_time.BestTime` uses these to predict word onsets.
    """

    word_onsets: np.ndarray
    word_offsets: np.ndarray
    phoneme_onsets: np.ndarray
    phonemes_per_word: np.ndarray
    delay: float = 0.0
    latency: float = 0.0
    t_request: float = 0.0
    duration: float | None = None
    word_chars: np.ndarray | None = None
    word_texts: tuple[str, ...] | None = None
    breaks: np.ndarray | None = None
    stress_onsets: np.ndarray | None = None
    source: str = "tts"
    linear_model: Any = None
    phoneme_durations: tuple[np.ndarray, ...] | None = None
    _first_phoneme: np.ndarray = field(init=False, repr=False)
    _units: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.word_onsets = _float_array("word_onsets", self.word_onsets)
        self.word_offsets = _float_array("word_offsets", self.word_offsets)
        self.phoneme_onsets = _float_array("phoneme_onsets", self.phoneme_onsets)
        self.phonemes_per_word = np.asarray(self.phonemes_per_word, dtype=int).reshape(-1)
        n = len(self.word_onsets)
        if len(self.word_offsets) != n or len(self.phonemes_per_word) != n:
            raise ValueError("word_onsets, word_offsets and phonemes_per_word must have one entry per word")
        if n and np.any(np.diff(self.word_onsets) < 0):
            raise ValueError("word_onsets must be non-decreasing")
        if np.any(self.phonemes_per_word < 1):
            raise ValueError("every word needs at least one phoneme")
        if int(self.phonemes_per_word.sum()) != len(self.phoneme_onsets):
            raise ValueError("phonemes_per_word must add up to the number of phoneme onsets")
        if len(self.phoneme_onsets) and np.any(np.diff(self.phoneme_onsets) < 0):
            raise ValueError("phoneme_onsets must be non-decreasing")
        for name in ("delay", "latency", "t_request"):
            if not math.isfinite(getattr(self, name)) or (name != "t_request" and getattr(self, name) < 0):
                raise ValueError(f"{name} must be finite and non-negative")
        if self.duration is None:
            self.duration = float(self.word_offsets[-1]) if n else 0.0
        self.duration = float(self.duration)
        if self.word_chars is not None:
            self.word_chars = np.asarray(self.word_chars, dtype=int).reshape(-1)
            if len(self.word_chars) != n or (n and np.any(np.diff(self.word_chars) <= 0)):
                raise ValueError("word_chars must be increasing, one per word")
        if self.breaks is not None:
            self.breaks = np.asarray(self.breaks, dtype=int).reshape(-1)
            if len(self.breaks) != n:
                raise ValueError("breaks must have one entry per word")
        if self.stress_onsets is None:
            self.stress_onsets = self.word_onsets.copy()
        self.stress_onsets = _float_array("stress_onsets", self.stress_onsets)
        if len(self.stress_onsets) != n:
            raise ValueError("stress_onsets must have one entry per word")
        if self.word_texts is not None and len(self.word_texts) != n:
            raise ValueError("word_texts must have one entry per word")
        if self.phoneme_durations is not None:
            durations = tuple(np.asarray(d, dtype=float).reshape(-1) for d in self.phoneme_durations)
            if len(durations) != n or any(len(d) == 0 or not np.all(np.isfinite(d)) or np.any(d < 0)
                                           for d in durations):
                raise ValueError("phoneme_durations needs, for every word, one or more finite non-negative "
                                 "durations")
            self.phoneme_durations = durations
        if self.source not in ("tts", "linear"):
            raise ValueError('source must be "tts" or "linear"')
        self._first_phoneme = np.concatenate([[0], np.cumsum(self.phonemes_per_word)[:-1]]).astype(int)
        self._units = np.unique(np.concatenate([self.word_onsets, self.phoneme_onsets, [self.duration]]))

    # ------------------------------------------------------------------------------------------------
    @property
    def t0_pred(self) -> float:
        """Nominal playback start ``t_request + latency`` (simulation time)."""
        return self.t_request + self.latency

    @property
    def n_words(self) -> int:
        """Number of words."""
        return len(self.word_onsets)

    @property
    def first_phoneme(self) -> np.ndarray:
        """Index in :attr:`phoneme_onsets` of each word's first phoneme."""
        return self._first_phoneme

    @property
    def unit_onsets(self) -> np.ndarray:
        """Sorted distinct onsets of all words and phonemes, and the end (plan axis)."""
        return self._units

    def next_unit(self, position: float) -> float:
        """Plan-axis onset of the first unit (word, phoneme or end) strictly after ``position``.

        Returns :attr:`duration` at or after the end.
        """
        i = int(np.searchsorted(self._units, position + 1e-9, side="right"))
        return float(self._units[i]) if i < len(self._units) else float(self.duration)

    def word_of(self, event: Any) -> int | None:
        """Plan word that a word or phoneme event belongs to (None if it cannot be placed).

        The word is found by the character offset in the event's payload (``char_start``): the plan
        word that starts at or before it. Without character offsets, the event's word index is used.
        """
        payload = event.payload or {}
        if self.word_chars is not None and "char_start" in payload:
            k = int(np.searchsorted(self.word_chars, int(payload["char_start"]), side="right")) - 1
            return max(k, 0) if self.n_words else None
        k = payload.get("word_index", event.index if event.kind == "word" else None)
        if k is None or not 0 <= int(k) < self.n_words:
            return None
        return int(k)

    def event_position(self, event: Any) -> float | None:
        """Plan-axis position that a progress event announces (None for events with no position).

        A word event maps to its plan word's onset; phoneme ``m`` of word ``k`` (payload ``in_word``)
        to the plan onset of phoneme ``m`` of plan word ``k``, or of its last phoneme when the plan
        predicted fewer; the end event to :attr:`duration`. Sentence and mark events give None.
        """
        if event.kind == "end":
            return float(self.duration)
        if event.kind not in ("word", "phoneme"):
            return None
        k = self.word_of(event)
        if k is None:
            return None
        if event.kind == "word":
            return float(self.word_onsets[k])
        m = int((event.payload or {}).get("in_word", 0))
        m = min(max(m, 0), int(self.phonemes_per_word[k]) - 1)
        return float(self.phoneme_onsets[self._first_phoneme[k] + m])
