"""Local plan-to-clock mappings for plans from the linear model: predicted word onsets from the events."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from speech_timing.animator_time.envelope import envelope_intercept
from speech_timing.builtin import FUNCTION_WORDS
from speech_timing.delivery import ProgressEvent
from speech_timing.linear_model import estimate_phonemes
from speech_timing.plan import BREAK_CLAUSE, BREAK_PARAGRAPH, BREAK_SENTENCE, SpeechPlan

__all__ = ["WordWarp", "PhoneticWarp", "coming_words", "estimate_units"]


def coming_words(plan: SpeechPlan, k: int, a: float, horizon: int) -> range:
    """Words after the current word ``k`` to predict: ``horizon`` words beyond ``k`` and beyond the word
    at the animation's position ``a``, within the plan."""
    last = int(np.searchsorted(plan.word_onsets, a, side="right")) + horizon
    return range(k + 1, min(max(k + 1 + horizon, last), plan.n_words))


class WordWarp:
    """Local plan-to-clock mapping for plans from the linear model, learned from the events.

    It estimates when the words heard so far started and predicts when the next ones will, on the
    clock. All learning is online, from the events of the current utterance.

    * **Word onsets.** Word ``k``'s own evidence is the minimum over its first phoneme events ``m``
      (and the word event) of ``y_m - sum_{i<m} d(symbol_i)``, less the expected minimum of the
      jitter; ``d`` are phoneme durations learned per symbol. A Kalman filter over the last words
      combines it with the previous onset plus the predicted word duration, and an onset is never
      later than its word event's ``y`` (:meth:`onset`).
    * **Jitter.** A word event and its first phoneme event are sent at the same instant; through a
      first-in-first-out channel the phoneme arrives ``z = max(j_phoneme - j_word, 0)`` later. For
      exponential jitter of mean ``J``, ``E[z] = J / 2``, so twice the mean of ``z`` (shrunk towards
      a prior of 20 ms) estimates the mean jitter.
    * **Phoneme durations.** Differences of the arrivals of consecutive phonemes of a word, each
      counted for the earlier phoneme's symbol, averaged per symbol (shrunk to the overall mean).
    * **Word durations.** The time from one word onset to the next is a linear function (recursive
      least squares with forgetting) of the plan's gap, the written break after the word (clause,
      sentence, paragraph), whether it is a function word and its spelling units, plus the mean
      residual of earlier occurrences of the same written word.
    * **Prediction.** The next onset is a weighted mean of (current word onset + its predicted
      duration) and (latest phoneme of the current word + its duration + the phonemes the plan still
      expects + the pause of the break), weighted by the inverse variances ``gap_error**2`` and the
      squared mean jitter; it is not put long before ``now - delay`` since none of the next word's
      events has arrived. Later words follow at their predicted durations.

    Parameters
    ----------
    plan : SpeechPlan
        A plan with word character offsets (from :func:`~speech_timing.linear_model.plan_from_linear`).
    t0_pred : float
        Nominal playback start.
    """

    #: Words predicted beyond the current one (and beyond the animation's position).
    horizon_words = 4
    #: Prior pauses (s) after a clause, a sentence and a paragraph, typical of speech synthesis.
    pause_prior = (0.15, 0.35, 0.6)
    #: Forgetting factor of the recursive least squares (an effective memory of ~200 words).
    forgetting = 0.995
    #: Mean jitter (s) assumed before any evidence.
    jitter_prior = 0.02
    #: Events (word event and first phonemes) that give a word's own onset evidence.
    onset_phonemes = 3
    #: How many mean jitters before ``now - delay`` the next word may be predicted, at the earliest.
    absence_margin = 0.5
    #: Typical error (s) of a predicted word duration.
    gap_error = 0.05
    #: Words over which the onset filter runs.
    filter_words = 8

    def __init__(self, plan: SpeechPlan, t0_pred: float) -> None:
        self.plan = plan
        self.t0_pred = t0_pred
        n = plan.n_words
        gaps = np.diff(np.append(plan.word_onsets, plan.duration))
        texts = plan.word_texts or tuple("" for _ in range(n))
        self.texts = [t.lower().strip(".,;:!?\"'()") for t in texts]
        breaks = plan.breaks if plan.breaks is not None else np.zeros(n, dtype=int)
        function = np.array([_is_function_word(t) for t in self.texts], dtype=float)
        units = np.array([estimate_units(t) for t in self.texts], dtype=float)
        self.features = np.column_stack([gaps, np.ones(n), breaks == BREAK_CLAUSE, breaks == BREAK_SENTENCE,
                                         breaks == BREAK_PARAGRAPH, function, units]).astype(float)
        self.beta = np.array([1.0, 0.0, *self.pause_prior, 0.0, 0.0])
        self.cov = np.diag([0.05, 0.01, 0.01, 0.01, 0.02, 0.01, 0.0005])
        mean_phoneme = float(np.sum(gaps) / max(int(np.sum(plan.phonemes_per_word)), 1))
        self.phoneme_mean = [mean_phoneme * 5.0, 5.0]  # sum and weight of the overall mean
        self.symbols: dict[str, list[float]] = {}
        self.memory: dict[str, list[float]] = {}
        self.events: dict[int, dict[int, tuple[float, str, bool]]] = {}  # word -> m -> (y, symbol, fresh)
        self.word_arrival: dict[int, float] = {}
        self.jitter_samples: list[float] = []
        self.last_arrival = -math.inf
        self.current = -1
        self.trained = -1

    # -- learning ---------------------------------------------------------------------------------------
    def duration(self, symbol: str) -> float:
        """Learned mean duration (s) of a phoneme ``symbol``."""
        total, weight = self.phoneme_mean
        overall = total / weight
        s, c = self.symbols.get(symbol, (0.0, 0.0))
        return (s + 3.0 * overall) / (c + 3.0)

    @property
    def jitter(self) -> float:
        """Estimated mean jitter (s)."""
        z = self.jitter_samples
        return (2.0 * sum(z) + 3.0 * self.jitter_prior) / (len(z) + 3.0)

    def observe(self, event: ProgressEvent, y: float, now: float) -> None:
        """Take in a word or phoneme event (``y = arrival - delay``)."""
        if event.kind not in ("word", "phoneme"):
            return
        k = self.plan.word_of(event)
        if k is None:
            return
        arrival = event.arrival_time if math.isfinite(event.arrival_time) else now
        fresh = arrival > self.last_arrival + 1e-9
        self.last_arrival = max(self.last_arrival, arrival)
        record = self.events.setdefault(k, {})
        if event.kind == "word":
            self.word_arrival[k] = arrival
            if 0 not in record or y < record[0][0]:
                record[0] = (y, record.get(0, (0.0, "", False))[1], fresh)
        else:
            m = int(event.payload.get("in_word", 0))
            symbol = str(event.payload.get("symbol", ""))
            if m == 0 and k in self.word_arrival:
                self.jitter_samples.append(min(arrival - self.word_arrival[k], 0.5))
            if m in record:
                y = min(y, record[m][0])
            record[m] = (y, symbol, fresh)
            previous = record.get(m - 1)
            if m >= 1 and previous is not None and previous[1] and fresh and previous[2]:
                sample = y - previous[0]
                if 0.0 < sample < 0.5:
                    s, c = self.symbols.get(previous[1], (0.0, 0.0))
                    self.symbols[previous[1]] = [s + sample, c + 1.0]
                    self.phoneme_mean[0] += sample
                    self.phoneme_mean[1] += 1.0
        if k > self.current:
            self.current = k
        self._train()

    def raw_onset(self, k: int) -> float | None:
        """Clock time at which word ``k`` started, from its own events only (None without any)."""
        record = self.events.get(k)
        if not record:
            return None
        candidates = []
        elapsed = 0.0
        for m in range(self.onset_phonemes):
            if m not in record:
                break
            y, symbol, _ = record[m]
            candidates.append(y - elapsed)
            elapsed += self.duration(symbol) if symbol else 0.0
        if not candidates:
            m = min(record)
            return record[m][0] - m * self.phoneme_mean[0] / self.phoneme_mean[1] - self.jitter
        return min(candidates) - self.jitter / len(candidates)

    def onset(self, k: int) -> float | None:
        """Estimated clock time at which word ``k`` started (None before any word was heard).

        A Kalman filter over the last ``filter_words`` words: each onset is predicted from the
        previous one plus the predicted word duration (variance ``gap_error**2``) and corrected by the
        word's own evidence (variance: squared mean jitter over the number of its first events).
        """
        first = max(k - self.filter_words, 0)
        while first < k and self.raw_onset(first) is None:
            first += 1
        estimate = self.raw_onset(first)
        if estimate is None:
            return None
        jitter2 = self.jitter ** 2 + 1e-6
        variance = jitter2
        for j in range(first + 1, k + 1):
            predicted = estimate + self.gap(j - 1)
            variance += self.gap_error ** 2
            measured = self.raw_onset(j)
            if measured is None:
                estimate = predicted
                continue
            n = min(len(self.events[j]), self.onset_phonemes)
            gain = variance / (variance + jitter2 / n)
            estimate = predicted + gain * (measured - predicted)
            variance *= 1.0 - gain
            if 0 in self.events[j]:  # a word is never heard after its event arrives (less the delay)
                estimate = min(estimate, self.events[j][0][0])
        return estimate

    def _train(self) -> None:
        """Fit the word-duration model on word pairs whose onsets are settled (two words back)."""
        while self.trained + 1 <= self.current - 2:
            j = self.trained + 1
            self.trained = j
            a, b = self.raw_onset(j), self.raw_onset(j + 1)
            if a is None or b is None:
                continue
            gap = b - a
            x = self.features[j]
            px = self.cov @ x
            gain = px / (self.forgetting + x @ px)
            residual = gap - x @ self.beta
            self.beta = self.beta + gain * residual
            self.cov = (self.cov - np.outer(gain, px)) / self.forgetting
            s, c = self.memory.get(self.texts[j], (0.0, 0.0))
            self.memory[self.texts[j]] = [s + (gap - x @ self.beta), c + 1.0]

    # -- prediction -------------------------------------------------------------------------------------
    def gap(self, k: int) -> float:
        """Predicted time (s) from the onset of word ``k`` to the next."""
        x = self.features[k]
        s, c = self.memory.get(self.texts[k], (0.0, 0.0))
        return max(float(x @ self.beta) + s / (c + 1.0), 0.02)

    def milestones(self, now: float, a: float) -> tuple[list[tuple[float, float]], float]:
        """Predicted ``(clock time, plan position)`` of the coming word onsets, and the rate after them.

        They reach at least ``horizon_words`` words beyond the current word and beyond the animation's
        position ``a``, so that an animation ahead of the speech slows down until the speech catches up.
        """
        plan = self.plan
        k = self.current
        if k < 0:
            return [(self.t0_pred + p, p) for p in plan.word_onsets[:self.horizon_words]], 1.0
        t_k = self.onset(k)
        out = [(t_k, float(plan.word_onsets[k]))]
        if k + 1 >= plan.n_words:
            return out, 1.0
        t_next = t_k + self.gap(k)
        record = self.events.get(k, {})
        phonemes = [m for m in record if record[m][1]]
        if phonemes:
            m = max(phonemes)
            y, symbol, _ = record[m]
            remaining = max(int(plan.phonemes_per_word[k]) - m - 1, 0)
            x = self.features[k]
            pause = float(x[2:5] @ self.beta[2:5])
            progress = (y - self.jitter + self.duration(symbol)
                        + remaining * self.phoneme_mean[0] / self.phoneme_mean[1] + max(pause, 0.0))
            # inverse-variance weights: word-duration error against the jitter of one event
            weight = self.gap_error ** 2 / (self.gap_error ** 2 + self.jitter ** 2)
            t_next = (1.0 - weight) * t_next + weight * progress
        # no event of the next word has arrived yet: it has hardly started long before now - delay
        t_next = max(t_next, now - plan.delay - self.absence_margin * self.jitter)
        t = t_next
        for j in coming_words(plan, k, a, self.horizon_words):
            out.append((t, float(plan.word_onsets[j])))
            if j + 1 < plan.n_words:
                t += self.gap(j)
        ratio = float(np.clip(self.beta[0], 0.5, 2.0))
        return out, 1.0 / ratio


class PhoneticWarp:
    """Local plan-to-clock mapping for linear plans that carry predicted phoneme durations.

    The predicted durations (:attr:`SpeechPlan.phoneme_durations`) lay out a predicted speech timeline
    ``Q``: the predicted onset of every phoneme and word from the start of the utterance. Truth is
    ``T = Q + o`` on the clock, where the offset ``o`` wanders as the duration errors add up. Every
    word or phoneme event gives ``y - Q`` (``y = arrival - delay``), which is ``o`` plus a non-negative
    jitter; the offset is the lowest of these over the last ``window`` seconds of ``Q``, less a
    small-sample correction, as in the lower envelope of :class:`BestTime` for timelines from the
    engine, but over a window short enough for the wandering to stay small. The coming words are
    predicted at ``Q + o``, and no word whose events have not arrived is put long before
    ``now - delay``.

    Parameters
    ----------
    plan : SpeechPlan
        A plan with :attr:`~SpeechPlan.phoneme_durations`.
    t0_pred : float
        Nominal playback start.
    """

    #: Seconds of predicted speech whose earliest evidence gives the offset.
    window = 0.4
    #: Words predicted beyond the current one (and beyond the animation's position).
    horizon_words = 4
    #: How far (s) before ``now - delay`` a word none of whose events has arrived may be predicted.
    absence_margin = 0.01

    def __init__(self, plan: SpeechPlan, t0_pred: float) -> None:
        self.plan = plan
        self.t0_pred = t0_pred
        durations = plan.phoneme_durations
        self.word_q = np.concatenate([[0.0], np.cumsum([float(d.sum()) for d in durations])])
        self.phoneme_q = [self.word_q[k] + np.concatenate([[0.0], np.cumsum(d)[:-1]])
                          for k, d in enumerate(durations)]
        self.evidence: deque[tuple[float, float]] = deque(maxlen=64)  # latest (Q, y - Q)
        self.current = -1
        self.offset = t0_pred

    def observe(self, event: ProgressEvent, y: float, now: float) -> None:
        """Take in a word or phoneme event (``y = arrival - delay``)."""
        if event.kind not in ("word", "phoneme"):
            return
        k = self.plan.word_of(event)
        if k is None:
            return
        if event.kind == "word":
            q = float(self.word_q[k])
        else:
            m = int(event.payload.get("in_word", 0))
            onsets = self.phoneme_q[k]
            q = float(onsets[m]) if m < len(onsets) else float(self.word_q[k + 1])
        self.current = max(self.current, k)
        self.evidence.append((q, y - q))
        latest = max(q_ for q_, _ in self.evidence)
        self.offset = envelope_intercept([r for q_, r in self.evidence if q_ >= latest - self.window])

    def milestones(self, now: float, a: float) -> tuple[list[tuple[float, float]], float]:
        """Predicted ``(clock time, plan position)`` of the coming word onsets, and the rate after them."""
        plan = self.plan
        k = self.current
        if k < 0:
            return [(self.t0_pred + q, p) for q, p in zip(self.word_q, plan.word_onsets[:self.horizon_words])], 1.0
        out = [(self.offset + float(self.word_q[k]), float(plan.word_onsets[k]))]
        floor = now - plan.delay - self.absence_margin
        for j in coming_words(plan, k, a, self.horizon_words):
            out.append((max(self.offset + float(self.word_q[j]), floor), float(plan.word_onsets[j])))
        return out, 1.0


def estimate_units(word: str) -> int:
    """Spelling units of a word (see :func:`speech_timing.linear_model.estimate_phonemes`)."""
    return estimate_phonemes(word, 1.0) if word else 1


def _is_function_word(word: str) -> bool:
    return word in FUNCTION_WORDS
