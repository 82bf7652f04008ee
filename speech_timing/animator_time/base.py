"""The interface every animator-time strategy implements: reset with a plan, told events, asked for ``t_A``."""

from __future__ import annotations

import math

from speech_timing.animator_time.path import Path
from speech_timing.delivery import ProgressEvent
from speech_timing.plan import SpeechPlan

__all__ = ["AnimatorTime"]


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
    t_request : float
        Clock time (s) at which playback of the current utterance was requested.
    t0_pred : float
        Nominal playback start (s), ``t_request + plan.latency``.
    path : Path
        The future of ``t_A`` as planned now: speech time (s, plan axis) against clock time (s), from
        the latest reset or event on, until the next event replaces it. :meth:`position` and
        :meth:`crossing` read it; strategies assign a new one when they change their plan and never
        change one in place, so a path that is still the same object means an unchanged future.
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

    def require_plan(self) -> SpeechPlan:
        """The plan of the current utterance (RuntimeError before :meth:`reset`)."""
        if self.plan is None:
            raise RuntimeError("reset() must be called before events are given")
        return self.plan
