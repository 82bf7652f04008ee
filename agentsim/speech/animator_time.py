"""Animator time: where in the speech an animation should be, from late and noisy progress events.

Chang (2001, section 5.3.2) drives each gesture with an *animator time* ``t_A`` instead of the
system clock: ``t_A`` is a position in the speech (plan axis, seconds), updated from the speech
system's progress events, and a gesture whose stroke is planned at speech time ``s`` strikes when
``t_A`` reaches ``s``. This module defines one interface, :class:`AnimatorTime`, and several ways to
compute ``t_A``, registered in :data:`STRATEGIES`:

``open-loop``
    The planned timeline on the clock, ignoring events.
``linear-model``
    Chang's linear characters-to-time model on the clock, ignoring events.
``chang-naive``
    Chang's formula ``t_A = min(dt + sum of completed units, sum up to the next unit)``.
``chang-smooth``
    Chang's refinement: slow down as the expected phonemes of a word run out, speed up to catch up.
``skip-70ms``
    Elckerlyc's rule: keep the clock, jump to the events' estimate when they differ by over 70 ms.
``best``
    Clock synchronisation from the lower envelope of the delayed events, with bounded rates.

Every strategy keeps ``t_A`` piecewise linear in ``t`` between events, as a :class:`Path`, so that
:meth:`AnimatorTime.crossing` is exact. Times are seconds throughout.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from typing import Sequence

import numpy as np

from agentsim.speech.builtin import FUNCTION_WORDS
from agentsim.speech.delivery import ProgressEvent
from agentsim.speech.linear_model import LinearModel, estimate_phonemes, fit_linear
from agentsim.speech.plan import BREAK_CLAUSE, BREAK_PARAGRAPH, BREAK_SENTENCE, SpeechPlan

__all__ = ["AnimatorTime", "SpeechPlan", "Path", "OpenLoop", "LinearModelTime", "ChangNaive", "ChangSmooth",
           "Skip70ms", "BestTime", "WordWarp", "STRATEGIES", "make_strategy", "lower_envelope_line"]


class Path:
    """A continuous, piecewise-linear, non-decreasing function of time: the future of ``t_A``.

    It starts at time ``t`` at position ``p`` moving at ``rate``; :meth:`then` appends a change of
    rate. Before the first breakpoint the first segment is extended backwards.

    Parameters
    ----------
    t : float
        Start time (s).
    p : float
        Position at ``t`` (s of speech).
    rate : float
        Rate (speech seconds per clock second, at least 0) from ``t`` on.
    """

    __slots__ = ("times", "positions", "rates")

    def __init__(self, t: float, p: float, rate: float) -> None:
        if rate < 0:
            raise ValueError("a path may not run backwards")
        self.times = [float(t)]
        self.positions = [float(p)]
        self.rates = [float(rate)]

    def then(self, t: float, rate: float) -> "Path":
        """From time ``t`` (not before the last breakpoint) on, move at ``rate``; returns ``self``."""
        if rate < 0:
            raise ValueError("a path may not run backwards")
        if t < self.times[-1]:
            raise ValueError("breakpoints must be added in time order")
        if math.isinf(t):
            return self
        if t == self.times[-1]:
            self.rates[-1] = float(rate)
            return self
        self.positions.append(self.at(t))
        self.times.append(float(t))
        self.rates.append(float(rate))
        return self

    def _segment(self, t: float) -> int:
        return max(bisect.bisect_right(self.times, t) - 1, 0)

    def at(self, t: float) -> float:
        """Position at time ``t``."""
        i = self._segment(t)
        return self.positions[i] + self.rates[i] * (t - self.times[i])

    def rate_at(self, t: float) -> float:
        """Rate at time ``t`` (of the segment that starts at or before ``t``)."""
        return self.rates[self._segment(t)]

    def until(self, t: float, rate: float) -> "Path":
        """This path up to time ``t`` (not before its start), then at ``rate``; returns ``self``."""
        i = self._segment(t)
        p = self.at(t)
        del self.times[i + 1:], self.positions[i + 1:], self.rates[i + 1:]
        if t <= self.times[0]:
            self.positions[0], self.times[0], self.rates[0] = p, float(t), float(rate)
            return self
        return self.then(t, rate)

    def end(self) -> tuple[float, float, float]:
        """``(time, position, rate)`` of the last breakpoint."""
        return self.times[-1], self.positions[-1], self.rates[-1]

    def crossing(self, s: float, now: float) -> float:
        """Earliest time ``>= now`` at which the position reaches ``s`` (``math.inf`` if never)."""
        i = self._segment(now)
        p = self.at(now)
        if p >= s:
            return now
        t = now
        for j in range(i, len(self.times)):
            start = t if j == i else self.times[j]
            p_start = p if j == i else self.positions[j]
            stop = self.times[j + 1] if j + 1 < len(self.times) else math.inf
            rate = self.rates[j]
            if rate > 0:
                hit = start + (s - p_start) / rate
                if hit <= stop:
                    return max(hit, now)
        return math.inf


class AnimatorTime:
    """Interface of animator-time strategies.

    A strategy is reset with a :class:`SpeechPlan` when playback is requested, told about each
    progress event when it arrives, and asked for ``t_A`` at non-decreasing clock times.

    Attributes
    ----------
    name : str
        Registry name of the strategy.
    plan : SpeechPlan
        The plan of the current utterance.
    t0_pred : float
        Nominal playback start, ``t_request + plan.latency``.
    """

    name = "base"

    def __init__(self) -> None:
        self.plan: SpeechPlan | None = None
        self.t_request = 0.0
        self.t0_pred = 0.0
        self.path = Path(0.0, 0.0, 1.0)

    def reset(self, plan: SpeechPlan, t_request: float) -> None:
        """Start a new utterance: ``plan`` is what is known in advance, playback is requested at ``t_request``."""
        if not math.isfinite(t_request):
            raise ValueError("t_request must be finite")
        self.plan = plan
        self.t_request = float(t_request)
        self.t0_pred = self.t_request + plan.latency
        self.path = Path(self.t_request, self.t_request - self.t0_pred, 1.0)

    def on_event(self, event: ProgressEvent, now: float) -> None:
        """A progress event arrived at clock time ``now``."""

    def position(self, t: float) -> float:
        """``t_A`` at clock time ``t``: the speech time (plan axis) the animation shows."""
        return self.path.at(t)

    def crossing(self, s: float, now: float) -> float:
        """Earliest clock time ``>= now`` at which ``t_A`` reaches ``s`` if no further event arrives.

        ``math.inf`` if it never would.
        """
        return self.path.crossing(s, now)

    def _require_plan(self) -> SpeechPlan:
        if self.plan is None:
            raise RuntimeError("reset() must be called before events are given")
        return self.plan


class OpenLoop(AnimatorTime):
    """The planned timeline on the clock: ``t_A = t - t0_pred``; events are ignored.

    With a plan from the text-to-speech engine's own timeline its only errors are the unknown part of
    the playback latency and the audio clock drift.
    """

    name = "open-loop"


class LinearModelTime(AnimatorTime):
    """Chang's linear characters-to-time model on the clock; events are ignored.

    At clock time ``t`` the model says character ``c(t) = (t - t0_pred - offset) / multiplier`` is
    being spoken, and ``t_A`` is the plan position of that character, interpolated between the plan's
    word onsets at their character offsets. A stroke at plan word ``k`` therefore strikes at
    ``t0_pred + multiplier * char_start_k + offset``, whatever the plan says: this is how Chang
    scheduled gestures on Rea. With a plan made by the linear model (``timing="linear"``) it is the
    same as ``open-loop``; with the text-to-speech timeline as plan it shows what the linear model
    alone would achieve. The model is ``plan.linear_model``; a plan without one (but with word
    character offsets) gets the least-squares line through its own word onsets.
    """

    name = "linear-model"

    def reset(self, plan: SpeechPlan, t_request: float) -> None:
        super().reset(plan, t_request)
        if plan.word_chars is None or plan.n_words == 0:
            return  # nothing to map characters to: stay open-loop
        model = plan.linear_model
        if not isinstance(model, LinearModel):
            model = fit_linear(plan.word_chars, plan.word_onsets) if plan.n_words >= 2 else None
        if model is None:
            return
        times = self.t0_pred + model.onset(plan.word_chars)
        positions = plan.word_onsets
        start = min(self.t_request, float(times[0]))
        path = Path(start, positions[0] - (times[0] - start), 1.0)
        for k in range(len(times) - 1):
            dt = times[k + 1] - times[k]
            path.then(times[k], (positions[k + 1] - positions[k]) / dt if dt > 0 else 0.0)
        path.then(times[-1], 1.0)
        self.path = path


class ChangNaive(AnimatorTime):
    """Chang's naive formula: ``t_A = min(dt + sum_i t_s, sum_{i+1} t_s)``.

    Units are words and phonemes as their events arrive. ``sum_i t_s`` is the plan onset of the unit
    the latest event announced, ``sum_{i+1} t_s`` the plan onset of the next unit, and ``dt`` the time
    since the latest unit started, estimated as ``now - (arrival - delay)`` with the known base delay.
    So ``t_A`` runs at rate 1 from the latest unit, *sticks* at the next unit's onset until its event
    arrives, and *snaps* to it when an event arrives early, several arrive together, or one is lost.
    Before the first event it runs from ``t0_pred`` and sticks at the first unit. Sentence and mark
    events are ignored.
    """

    name = "chang-naive"

    def reset(self, plan: SpeechPlan, t_request: float) -> None:
        super().reset(plan, t_request)
        first = float(plan.unit_onsets[0]) if len(plan.unit_onsets) else 0.0
        self.path = self._capped(self.t_request, self.t_request - self.t0_pred, first)

    @staticmethod
    def _capped(t: float, p: float, cap: float) -> Path:
        if p >= cap:
            return Path(t, p, 0.0)
        return Path(t, p, 1.0).then(t + (cap - p), 0.0)

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self._require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        cap = plan.next_unit(p)
        start = now - plan.delay  # estimated time at which the unit started
        self.path = self._capped(now, min(p + (now - start), cap), cap)


class ChangSmooth(AnimatorTime):
    """Chang's smooth refinement: slow down as a word's expected phonemes run out, speed up to catch up.

    After an event for phoneme ``m`` of plan word ``k`` (or the word itself, ``m = 0``), the dead
    reckoning ``g(t) = p + (t - (arrival - delay))`` says where speech is. ``t_A`` is continuous; its
    rate until the next event is ``r_b * (1 + lag / 0.15 s)`` clipped to [0.2, 2], where ``lag`` is
    ``g(now) - t_A`` and ``r_b`` is 1 while at least two of the word's expected phonemes
    (``plan.phonemes_per_word[k]``) are still to come, 0.8 when one is, 0.6 when none is. Past the
    onset of the next word, whose event has not arrived, the rate drops to 0.2 (it slows down
    instead of halting). Sentence and mark events are ignored.
    """

    name = "chang-smooth"
    tau = 0.15
    max_rate = 2.0
    min_rate = 0.2

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self._require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        a = self.path.at(now)
        target = p + plan.delay
        if event.kind == "end":
            rate = 1.0 if a < p else 0.0
            self.path = Path(now, a, rate)
            return
        k = plan.word_of(event)
        m = int(event.payload.get("in_word", 0)) if event.kind == "phoneme" else 0
        remaining = int(plan.phonemes_per_word[k]) - 1 - m if k is not None else 2
        base = 1.0 if remaining >= 2 else 0.8 if remaining == 1 else 0.6
        rate = float(np.clip(base * (1.0 + (target - a) / self.tau), self.min_rate, self.max_rate))
        nxt = float(plan.word_onsets[k + 1]) if k is not None and k + 1 < plan.n_words else plan.duration
        path = Path(now, a, rate)
        if a < nxt and rate > self.min_rate:
            path.then(now + (nxt - a) / rate, self.min_rate)
        elif a >= nxt:
            path = Path(now, a, self.min_rate)
        self.path = path


class Skip70ms(AnimatorTime):
    """Elckerlyc's rule: run on the clock and jump to the events' estimate when drift exceeds 70 ms.

    ``t_A = t - t0_pred + c``. On each word, phoneme or end event the estimate of where speech is
    now is ``p + delay`` (the announced unit plus the known delay since it started); when it differs
    from ``t_A`` by more than 70 ms, ``c`` is changed so that ``t_A`` jumps to it.
    """

    name = "skip-70ms"
    threshold = 0.070

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self._require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        a = self.path.at(now)
        estimate = p + plan.delay
        if abs(estimate - a) > self.threshold:
            self.path = Path(now, estimate, 1.0)


def lower_envelope_line(p: np.ndarray, y: np.ndarray, p_ref: float) -> tuple[float, float]:
    """The line below all points ``(p_i, y_i)`` that is highest at ``p_ref``.

    This is the edge of the lower convex hull above ``p_ref`` and the solution of the linear
    programme ``max a + b * p_ref`` subject to ``a + b * p_i <= y_i``, which is the same as
    minimising the sum of the vertical distances to the points when ``p_ref`` is their mean. With
    delays that are never negative, it estimates the fastest-delivery line through noisy arrivals.

    Parameters
    ----------
    p, y : numpy.ndarray
        Abscissae and ordinates (any order; at least one point).
    p_ref : float
        Where the line should be highest.

    Returns
    -------
    (float, float)
        Intercept ``a`` and slope ``b``. A single point (or all at one abscissa) gives slope 1.
    """
    order = np.lexsort((y, p))
    p, y = np.asarray(p, float)[order], np.asarray(y, float)[order]
    hull: list[int] = []
    for i in range(len(p)):
        if hull and p[hull[-1]] == p[i]:
            continue  # same abscissa, higher ordinate: not on the lower hull
        while len(hull) >= 2:
            j, k = hull[-2], hull[-1]
            if (y[k] - y[j]) * (p[i] - p[j]) >= (y[i] - y[j]) * (p[k] - p[j]):
                hull.pop()  # k is on or above the segment j-i
            else:
                break
        hull.append(i)
    if len(hull) == 1:
        return float(y[hull[0]] - p[hull[0]]), 1.0
    xs = p[hull]
    e = int(np.clip(np.searchsorted(xs, p_ref) - 1, 0, len(hull) - 2))
    j, k = hull[e], hull[e + 1]
    slope = (y[k] - y[j]) / (p[k] - p[j])
    return float(y[j] - slope * p[j]), float(slope)


def envelope_intercept(residuals) -> float:
    """Lowest of ``residuals`` less a small-sample correction: the median excess over the lowest, divided by
    their number. With one-sided jitter, it estimates the offset of the fastest delivery."""
    r = np.asarray(residuals, dtype=float)
    low = float(r.min())
    return low - (float(np.median(r)) - low) / len(r)


def coming_words(plan: SpeechPlan, k: int, a: float, horizon: int) -> range:
    """Words after the current word ``k`` to predict: ``horizon`` words beyond ``k`` and beyond the word
    at the animation's position ``a``, within the plan."""
    last = int(np.searchsorted(plan.word_onsets, a, side="right")) + horizon
    return range(k + 1, min(max(k + 1 + horizon, last), plan.n_words))


class BestTime(AnimatorTime):
    """Clock synchronisation from the lower envelope of delayed events, with bounded rates.

    *Evidence.* Every word and phoneme event gives ``y = arrival - delay``, an upper bound of the
    clock time at which its unit was heard: jitter and stalls only ever add delay, so the
    earliest-arriving evidence (the lower envelope) is the most trustworthy.

    *Plans from the text-to-speech timeline* (``plan.source == "tts"``). Truth is a line on the plan
    axis, ``T(p) = t0 + p * (1 + drift)``. The slope is the lower-envelope line
    (:func:`lower_envelope_line`) of the points ``(p, y)`` of the last ``slope_window`` seconds once
    they span ``min_slope_span`` seconds (1 before), clipped to 1 +- ``max_drift``; the intercept is the
    minimum of ``y - slope * p`` over the last ``offset_window`` seconds less a small-sample correction
    (the median excess over that minimum divided by the number of points). ``t_A`` then steers onto
    ``(t - t0) / slope`` within ``settle`` seconds.

    *Plans from the linear model* (``plan.source == "linear"``). The plan is wrong per word, so the
    mapping from plan to clock is estimated locally (:class:`WordWarp`): the true onsets of the words
    heard so far from their earliest evidence, and the onsets of the next words from the last one
    plus word durations learned online from the events. ``t_A`` passes through the predicted onsets.
    When the plan also carries predicted phoneme durations (:attr:`SpeechPlan.phoneme_durations`), the
    onsets come from those instead (:class:`PhoneticWarp`).

    *Animation.* ``t_A`` never jumps: it follows a path through the predicted (time, plan position)
    milestones whose segment rates are clipped to [``min_rate``, ``max_rate``] (below 2, so no frame
    advances by two frames), so a correction is spread over time instead of snapping. Before any event
    it runs on the predicted timeline ``t - t0_pred``; in pauses it keeps following the estimate,
    which needs no events.
    """

    name = "best"
    #: Seconds of speech whose events estimate the drift (tts plans).
    slope_window = 60.0
    #: Span (s) the events must cover before the drift is estimated.
    min_slope_span = 8.0
    #: Seconds of speech whose earliest evidence gives the offset (tts plans).
    offset_window = 20.0
    #: Largest drift believed (1 %).
    max_drift = 0.01
    #: Seconds over which ``t_A`` steers onto the estimate (tts plans).
    settle = 0.12
    #: Slowest and fastest rate (tts plans); the fastest is also used for linear plans.
    min_rate = 0.5
    max_rate = 1.9
    #: Slowest rate for linear plans, which must slow down in pauses the plan does not know.
    warp_min_rate = 0.3

    def reset(self, plan: SpeechPlan, t_request: float) -> None:
        super().reset(plan, t_request)
        self._p: list[float] = []
        self._y: list[float] = []
        self._slope = 1.0
        self._slope_at = -math.inf
        self._intercept = self.t0_pred
        if plan.source != "linear":
            self._warp = None
        elif plan.phoneme_durations is not None:
            self._warp = PhoneticWarp(plan, self.t0_pred)
        else:
            self._warp = WordWarp(plan, self.t0_pred)

    @property
    def clock_estimate(self) -> tuple[float, float]:
        """Current ``(t0, 1 + drift)`` estimate of the line ``T(p) = t0 + p * (1 + drift)`` (tts plans)."""
        return self._intercept, self._slope

    def _fit_line(self) -> None:
        """Update the slope (at most once per second of speech) and the intercept."""
        latest = self._p[-1]
        if latest - self._p[0] > 1.5 * self.slope_window:  # forget what no window uses any more
            keep_from = bisect.bisect_left(self._p, latest - self.slope_window)
            del self._p[:keep_from], self._y[:keep_from]
        p = np.asarray(self._p)
        y = np.asarray(self._y)
        if latest - p[0] >= self.min_slope_span and latest - self._slope_at >= 1.0:
            keep = p >= latest - self.slope_window
            _, slope = lower_envelope_line(p[keep], y[keep], float(np.mean(p[keep])))
            self._slope = float(np.clip(slope, 1.0 - self.max_drift, 1.0 + self.max_drift))
            self._slope_at = latest
        keep = p >= latest - self.offset_window
        self._intercept = envelope_intercept(y[keep] - self._slope * p[keep])

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self._require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        y = (event.arrival_time if math.isfinite(event.arrival_time) else now) - plan.delay
        a = self.path.at(now)
        if self._warp is None:
            self._p.append(p)
            self._y.append(y)
            self._fit_line()
            rate = 1.0 / self._slope
            target = (now - self._intercept) * rate
            self.path = self._follow(now, a, [(now + self.settle, target + self.settle * rate)], rate,
                                      self.min_rate)
        else:
            self._warp.observe(event, y, now)
            milestones, rate = self._warp.milestones(now, a)
            path = self._follow(now, a, milestones, rate, self.warp_min_rate)
            self.path = path

    def _follow(self, now: float, a: float, milestones: Sequence[tuple[float, float]], final_rate: float,
                min_rate: float) -> Path:
        """A path from ``(now, a)`` through ``milestones`` (time, position), then at ``final_rate``.

        Milestones at or behind ``a`` are skipped; each segment's rate is clipped to
        [``min_rate``, ``max_rate``], so a milestone may be reached late or early.
        """
        segments: list[tuple[float, float]] = []  # (start time, rate)
        t, p = now, a
        for tm, pm in milestones:
            if pm <= p:
                continue
            rate = (pm - p) / (tm - t) if tm > t else self.max_rate
            rate = min(max(rate, min_rate), self.max_rate)
            segments.append((t, rate))
            t, p = t + (pm - p) / rate, pm
        segments.append((t, min(max(final_rate, min_rate), self.max_rate)))
        path = Path(now, a, segments[0][1])
        for start, rate in segments[1:]:
            path.then(start, rate)
        return path


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
        A plan with word character offsets (from :func:`~agentsim.speech.linear_model.plan_from_linear`).
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
    """Spelling units of a word (see :func:`agentsim.speech.linear_model.estimate_phonemes`)."""
    return estimate_phonemes(word, 1.0) if word else 1


def _is_function_word(word: str) -> bool:
    return word in FUNCTION_WORDS


#: Strategies by name.
STRATEGIES: dict[str, type] = {
    cls.name: cls for cls in (OpenLoop, LinearModelTime, ChangNaive, ChangSmooth, Skip70ms, BestTime)
}


def make_strategy(name: str) -> AnimatorTime:
    """A new strategy instance by its registry name (ValueError for an unknown name)."""
    try:
        return STRATEGIES[name]()
    except KeyError:
        raise ValueError(f"unknown animator-time strategy {name!r}; known: {sorted(STRATEGIES)}") from None
