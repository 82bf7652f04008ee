"""BestTime: clock synchronisation from the lower envelope of delayed events, with bounded rates."""

from __future__ import annotations

import bisect
import math
from typing import Sequence

import numpy as np

from speech_timing.animator_time.base import AnimatorTime
from speech_timing.animator_time.envelope import envelope_intercept, lower_envelope_line
from speech_timing.animator_time.path import Path
from speech_timing.animator_time.warps import PhoneticWarp, WordWarp
from speech_timing.delivery import ProgressEvent
from speech_timing.plan import SpeechPlan

__all__ = ["BestTime"]


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

    _due: tuple[float, float] | None = None  # (clock time, t_A then) of events not yet steered by

    def reset(self, plan: SpeechPlan, t_request: float) -> None:
        self._due = None
        super().reset(plan, t_request)
        # the evidence (p, y) of the window, kept in arrays (rows _first.._count of _py) rather than lists
        # turned into arrays at every fit
        self._py = np.empty((2, 1024))
        self._first = 0
        self._count = 0
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
        py, first, count = self._py, self._first, self._count
        latest = float(py[0, count - 1])
        if latest - float(py[0, first]) > 1.5 * self.slope_window:  # forget what no window uses any more
            first = self._first = bisect.bisect_left(py[0], latest - self.slope_window, first, count)
        p = py[0, first:count]
        y = py[1, first:count]
        if latest - p[0] >= self.min_slope_span and latest - self._slope_at >= 1.0:
            keep = p >= latest - self.slope_window
            _, slope = lower_envelope_line(p[keep], y[keep], float(np.mean(p[keep])))
            self._slope = float(np.clip(slope, 1.0 - self.max_drift, 1.0 + self.max_drift))
            self._slope_at = latest
        keep = p >= latest - self.offset_window
        self._intercept = envelope_intercept(y[keep] - self._slope * p[keep])

    @property
    def path(self) -> Path:
        if self._due is not None:
            self._steer()
        return self._path

    @path.setter
    def path(self, path: Path) -> None:
        self._path = path
        self._due = None

    def on_event(self, event: ProgressEvent, now: float) -> None:
        plan = self.require_plan()
        p = plan.event_position(event)
        if p is None:
            return
        y = (event.arrival_time if math.isfinite(event.arrival_time) else now) - plan.delay
        # Events that arrive at one instant are taken together: the path is steered once, when it is next
        # looked at (the path starts where t_A is now, which they do not change), so a storm of events at
        # one instant costs one fit, not one per event.
        if self._due is None or self._due[0] != now:
            a = self.path.at(now)
            self._due = (now, a)
        if self._warp is None:
            self._remember(p, y)
        else:
            self._warp.observe(event, y, now)

    def _remember(self, p: float, y: float) -> None:
        """Append one point of evidence (the window's oldest points move to the front when the arrays fill)."""
        if self._count == self._py.shape[1]:
            kept = self._count - self._first
            if kept * 2 > self._py.shape[1]:
                grown = np.empty((2, 2 * self._py.shape[1]))
                grown[:, :kept] = self._py[:, self._first:self._count]
                self._py = grown
            else:
                self._py[:, :kept] = self._py[:, self._first:self._count].copy()
            self._first, self._count = 0, kept
        self._py[0, self._count] = p
        self._py[1, self._count] = y
        self._count += 1

    def _steer(self) -> None:
        """Steer t_A from where it was when the pending events arrived."""
        now, a = self._due
        self._due = None
        if self._warp is None:
            self._fit_line()
            rate = 1.0 / self._slope
            target = (now - self._intercept) * rate
            self._path = self._follow(now, a, [(now + self.settle, target + self.settle * rate)], rate,
                                      self.min_rate)
        else:
            milestones, rate = self._warp.milestones(now, a)
            self._path = self._follow(now, a, milestones, rate, self.warp_min_rate)

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
