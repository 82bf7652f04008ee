"""Chang's linear characters-to-time model, and speech plans made from it or from a backend's timeline.

Chang (2001, section 8) could not use the Rea text-to-speech system's progress events, which arrived
late, dispersed and in clusters over the network. What worked was a linear relation between the
number of characters before a word and the time at which it is spoken,
``seconds = multiplier * characters + offset``, with multiplier and offset found experimentally.
:func:`calibrate` finds them by least squares from a backend: for every word of some calibration
texts, its character offset against its true onset. :func:`plan_from_linear` then predicts a
:class:`~speech_timing.plan.SpeechPlan` for any text without synthesising it.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from speech_timing.backend import SpeechText, TTSBackend, Utterance, backend_key
from speech_timing.plan import SpeechPlan, word_breaks

__all__ = ["LinearModel", "fit_linear", "calibrate", "default_linear_model", "plan_from_linear", "plan_from_utterance",
           "written_words", "estimate_phonemes", "calibration_texts", "TEXTS_DIR"]

#: Directory of the bundled texts (benchmark texts and ``calibration.txt``).
TEXTS_DIR = Path(__file__).resolve().parent / "texts"

_WRITTEN_WORD = re.compile(r"[^\s\u2012-\u2015\u2026/]+")
_SILENT_EDGE = frozenset('.,;:!?"\'()[]{}<>«»“”„‘’‚‹›…–—¡¿*_-')
_LETTER_UNITS = re.compile(r"th|sh|ch|ng|ph|ck|qu|wh|[aeiouy]+|[a-z]|\d", re.I)
_VOWEL = re.compile(r"[aeiouy]", re.I)


@dataclass(frozen=True)
class LinearModel:
    """Onset (s) of the word at character offset ``c``: ``multiplier * c + offset``.

    Parameters
    ----------
    multiplier : float
        Seconds per character.
    offset : float
        Seconds at character 0.
    phonemes_per_unit : float
        Phonemes per spelling unit (:func:`estimate_phonemes`), for guessing phoneme counts.
    n_points : int
        Number of (character, onset) pairs the model was fitted to.
    rms : float
        Root-mean-square residual of the fit (s).
    """

    multiplier: float
    offset: float
    phonemes_per_unit: float = 1.0
    n_points: int = 0
    rms: float = math.nan

    def __post_init__(self) -> None:
        if not (math.isfinite(self.multiplier) and self.multiplier > 0):
            raise ValueError("multiplier must be a positive number of seconds per character")
        if not math.isfinite(self.offset):
            raise ValueError("offset must be finite")
        if not (math.isfinite(self.phonemes_per_unit) and self.phonemes_per_unit > 0):
            raise ValueError("phonemes_per_unit must be positive")

    def onset(self, chars):
        """Predicted time (s) at character offset(s) ``chars`` (scalar or array)."""
        return self.multiplier * np.asarray(chars, dtype=float) + self.offset

    def characters(self, seconds):
        """Character offset(s) predicted to be reached at ``seconds`` (inverse of :meth:`onset`)."""
        return (np.asarray(seconds, dtype=float) - self.offset) / self.multiplier

    def to_json(self) -> str:
        """The model as a JSON object."""
        return json.dumps(asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str) -> "LinearModel":
        """A model from :meth:`to_json` output."""
        data = json.loads(text)
        return cls(**{k: data[k] for k in ("multiplier", "offset", "phonemes_per_unit", "n_points", "rms")
                      if k in data})

    def save(self, path: str | Path) -> None:
        """Write the model to a JSON file."""
        from agentsim.written import written

        with written(path) as tmp:
            tmp.write_text(self.to_json() + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> "LinearModel":
        """Read a model written by :meth:`save`."""
        return cls.from_json(Path(path).read_text(encoding="utf-8"))


def written_words(text: str) -> list[tuple[int, int]]:
    """``(start, end)`` character spans of the written words of ``text``.

    Words are runs between whitespace, dashes and slashes, trimmed of punctuation, and must contain a
    letter or digit (the same segmentation the espeak-ng backend reports words in).
    """
    spans = []
    for match in _WRITTEN_WORD.finditer(text):
        start, end = match.span()
        while start < end and text[start] in _SILENT_EDGE:
            start += 1
        while end > start and text[end - 1] in _SILENT_EDGE:
            end -= 1
        if start < end and any(ch.isalnum() for ch in text[start:end]):
            spans.append((start, end))
    return spans


def estimate_phonemes(word: str, phonemes_per_unit: float = 1.0) -> int:
    """Guess how many phonemes a written word has, from its spelling (at least 1).

    Spelling units are letters, with common digraphs (``th sh ch ng ph ck qu wh``) and vowel runs
    counting once; the count is scaled by ``phonemes_per_unit`` (calibrated by :func:`calibrate`).
    """
    units = len(_LETTER_UNITS.findall(word))
    return max(1, int(round(units * phonemes_per_unit)))


def fit_linear(chars, onsets, phonemes_per_unit: float = 1.0) -> LinearModel:
    """Least-squares fit of ``onsets = multiplier * chars + offset``.

    Parameters
    ----------
    chars : array_like of float
        Character offset of each word in its text.
    onsets : array_like of float
        True onset (s) of each word in its utterance.
    phonemes_per_unit : float
        Stored in the model.

    Returns
    -------
    LinearModel
    """
    c = np.asarray(chars, dtype=float).reshape(-1)
    s = np.asarray(onsets, dtype=float).reshape(-1)
    if len(c) != len(s) or len(c) < 2 or np.ptp(c) == 0:
        raise ValueError("need at least two words at different character offsets to fit the model")
    design = np.column_stack([c, np.ones_like(c)])
    (multiplier, offset), *_ = np.linalg.lstsq(design, s, rcond=None)
    rms = float(np.sqrt(np.mean((s - design @ np.array([multiplier, offset])) ** 2)))
    return LinearModel(float(multiplier), float(offset), phonemes_per_unit, int(len(c)), rms)


def calibration_texts() -> list[str]:
    """The bundled calibration utterances (``texts/calibration.txt``, one per line)."""
    lines = (TEXTS_DIR / "calibration.txt").read_text(encoding="utf-8").splitlines()
    return [line.strip() for line in lines if line.strip() and not line.lstrip().startswith("#")]


def calibrate(backend: TTSBackend, texts: Iterable[str] | None = None) -> LinearModel:
    """Fit the linear model to a backend by speaking calibration texts.

    Parameters
    ----------
    backend : TTSBackend
        The text-to-speech backend to characterise.
    texts : iterable of str, optional
        Calibration utterances; the bundled ones (:func:`calibration_texts`) by default.

    Returns
    -------
    LinearModel
        Fitted to every word's (character offset, onset); ``phonemes_per_unit`` is the ratio of the
        backend's phonemes to the spelling units of the words.
    """
    texts = calibration_texts() if texts is None else list(texts)
    chars, onsets = [], []
    phonemes = units = 0
    for text in texts:
        utterance = backend.synthesize(SpeechText(text))
        for word in utterance.words:
            chars.append(word.char_start)
            onsets.append(word.start)
            units += len(_LETTER_UNITS.findall(word.text)) or 1
        phonemes += len(utterance.phonemes)
    ratio = phonemes / units if units and phonemes else 1.0
    return fit_linear(chars, onsets, ratio)


_MODELS: dict[tuple, LinearModel] = {}


def default_linear_model(backend: TTSBackend) -> LinearModel:
    """The linear model calibrated on the bundled calibration texts for ``backend`` (once per process)."""
    key = backend_key(backend)
    if key not in _MODELS:
        _MODELS[key] = calibrate(backend)
    return _MODELS[key]


def _stress_fraction(word: str) -> float:
    """Where in a written word its first vowel letter is, as a fraction of its length."""
    match = _VOWEL.search(word)
    return match.start() / len(word) if match and len(word) else 0.0


def plan_from_linear(text: str, model: LinearModel, *, delay: float = 0.0, latency: float = 0.0,
                     t_request: float = 0.0) -> SpeechPlan:
    """A speech plan for ``text`` predicted by the linear model alone.

    Parameters
    ----------
    text : str
        The text to be spoken.
    model : LinearModel
        The calibrated model.
    delay, latency, t_request : float
        Known channel delay, nominal playback latency and request time (see
        :class:`~speech_timing.plan.SpeechPlan`).

    Returns
    -------
    SpeechPlan
        ``source="linear"``. Word ``k`` starts at ``model.onset(char_start_k)`` and ends at
        ``model.onset(char_end_k)``; its phoneme count is guessed from its spelling
        (:func:`estimate_phonemes`) and its phonemes share its span evenly; its stressed vowel is placed
        at the position of its first vowel letter. The end is ``model.onset(len(text))``.

    Notes
    -----
    The plan knows the text only: prosody spans (breaks, rate changes, emphasis) of the speech are not
    part of the linear model and are ignored here, so a plan for a speech with them is off by what they
    change.
    """
    spans = written_words(text)
    if not spans:
        raise ValueError("the text has no words")
    starts = np.array([a for a, _ in spans], dtype=float)
    ends = np.array([b for _, b in spans], dtype=float)
    onsets = np.maximum.accumulate(np.maximum(model.onset(starts), 0.0))
    offsets = np.maximum(model.onset(ends), onsets)
    words = tuple(text[a:b] for a, b in spans)
    counts = np.array([estimate_phonemes(w, model.phonemes_per_unit) for w in words], dtype=int)
    phoneme_onsets = np.concatenate([on + (off - on) * np.arange(n) / n
                                     for on, off, n in zip(onsets, offsets, counts)])
    stress = onsets + (offsets - onsets) * np.array([_stress_fraction(w) for w in words])
    breaks = word_breaks(text, spans)
    duration = max(float(model.onset(len(text))), float(offsets[-1]))
    return SpeechPlan(onsets, offsets, phoneme_onsets, counts, delay=delay, latency=latency,
                      t_request=t_request, duration=duration, word_chars=starts.astype(int), word_texts=words,
                      breaks=np.array(breaks), stress_onsets=stress, source="linear", linear_model=model)


def plan_from_utterance(utterance: Utterance, *, delay: float = 0.0, latency: float = 0.0,
                        t_request: float = 0.0, linear_model: LinearModel | None = None) -> SpeechPlan:
    """A speech plan from a backend's own timeline (``source="tts"``).

    Parameters
    ----------
    utterance : Utterance
        What the backend produced; its word and phoneme times become the plan.
    delay, latency, t_request : float
        Known channel delay, nominal playback latency and request time.
    linear_model : LinearModel, optional
        Carried along for strategies that schedule by the linear model.

    Returns
    -------
    SpeechPlan
        Word onsets and offsets and phoneme onsets of the utterance; a word's stressed-vowel onset is
        that of its first phoneme with primary stress (its onset if none is marked). A word the backend
        gave no phoneme gets one at its onset.
    """
    words: Sequence = utterance.words
    if not words:
        raise ValueError("the utterance has no words")
    phoneme_onsets, counts, stress = [], [], []
    for word, phs in zip(words, utterance.phonemes_by_word()):
        times = [p.start for p in phs] or [word.start]
        phoneme_onsets.extend(times)
        counts.append(len(times))
        stress.append(next((p.start for p in phs if p.stressed), word.start))
    text = utterance.text
    breaks = word_breaks(text, [(w.char_start, w.char_end) for w in words])
    return SpeechPlan(np.array([w.start for w in words]), np.array([w.end for w in words]),
                      np.array(phoneme_onsets), np.array(counts), delay=delay, latency=latency,
                      t_request=t_request, duration=utterance.duration,
                      word_chars=np.array([w.char_start for w in words]), word_texts=tuple(w.text for w in words),
                      breaks=np.array(breaks), stress_onsets=np.array(stress), source="tts",
                      linear_model=linear_model)
