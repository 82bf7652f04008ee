"""The baseline strategies: open-loop, linear-model, chang-naive, chang-smooth and skip-70ms."""

from __future__ import annotations


from speech_timing.animator_time.base import AnimatorTime
from speech_timing.animator_time.path import Path
from speech_timing.delivery import ProgressEvent
from speech_timing.linear_model import LinearModel, fit_linear
from speech_timing.plan import SpeechPlan

__all__ = ["OpenLoop", "LinearModelTime", "ChangNaive", "ChangSmooth", "Skip70ms"]


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
    arrives, and *snaps* to it when an event arrives early, several arrive together, or one is lost. It
    never goes back: an event that arrives out of order, behind what ``t_A`` shows, holds it there.
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
        plan = self.require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        cap = plan.next_unit(p)
        start = now - plan.delay  # estimated time at which the unit started
        # t_A never goes back: an event older than what t_A has shown already (it came out of order) holds
        # t_A where it is until the next one
        a = self.path.at(now)
        self.path = self._capped(now, max(min(p + (now - start), cap), a), max(cap, a))


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
        plan = self.require_plan()
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
        rate = min(max(float(base * (1.0 + (target - a) / self.tau)), self.min_rate), self.max_rate)
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
    from ``t_A`` by more than 70 ms, ``c`` is changed so that ``t_A`` jumps to it, forward; ahead of
    the estimate by as much, ``t_A`` stands still until the estimate has caught up (it never goes back).
    """

    name = "skip-70ms"
    threshold = 0.070

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self.require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        a = self.path.at(now)
        estimate = p + plan.delay
        if estimate - a > self.threshold:
            self.path = Path(now, estimate, 1.0)
        elif a - estimate > self.threshold:
            # ahead of the speech: t_A never goes back; it stands still until the clock has caught up
            self.path = Path(now, a, 0.0).then(now + (a - estimate), 1.0)
