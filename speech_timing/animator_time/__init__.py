"""Animator time: where in the speech an animation should be, from late and noisy progress events.

Chang (2001, section 5.3.2) drives each gesture with an *animator time* ``t_A`` instead of the
system clock: ``t_A`` is a position in the speech (plan axis, seconds), updated from the speech
system's progress events, and a gesture whose stroke is planned at speech time ``s`` strikes when
``t_A`` reaches ``s``. This package defines one interface, :class:`AnimatorTime`, and several ways to
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

Modules
-------
path
    :class:`Path`, the piecewise-linear future of ``t_A`` on the clock.
base
    :class:`AnimatorTime`, the interface of every strategy.
baselines
    The strategies to compare against: open-loop, linear-model, chang-naive, chang-smooth, skip-70ms.
envelope
    Lower-envelope estimates from one-sided delays: :func:`lower_envelope_line`, :func:`envelope_intercept`.
warps
    :class:`WordWarp` and :class:`PhoneticWarp`, which predict word onsets for plans from the linear model.
best
    :class:`BestTime`, the ``best`` strategy.

The registry, :data:`STRATEGIES`, :func:`check_strategy` and :func:`make_strategy`, is here.
"""

from __future__ import annotations

from agentsim.errors import AgentsimError
from speech_timing.animator_time.base import AnimatorTime
from speech_timing.animator_time.baselines import ChangNaive, ChangSmooth, LinearModelTime, OpenLoop, Skip70ms
from speech_timing.animator_time.best import BestTime
from speech_timing.animator_time.envelope import envelope_intercept, lower_envelope_line
from speech_timing.animator_time.path import Path
from speech_timing.animator_time.warps import PhoneticWarp, WordWarp, coming_words, estimate_units
from speech_timing.plan import SpeechPlan

__all__ = ["AnimatorTime", "SpeechPlan", "Path", "OpenLoop", "LinearModelTime", "ChangNaive", "ChangSmooth",
           "Skip70ms", "BestTime", "WordWarp", "PhoneticWarp", "STRATEGIES", "UnknownStrategy", "check_strategy",
           "make_strategy", "lower_envelope_line", "envelope_intercept", "coming_words", "estimate_units"]


#: Strategies by name.
STRATEGIES: dict[str, type] = {
    cls.name: cls for cls in (OpenLoop, LinearModelTime, ChangNaive, ChangSmooth, Skip70ms, BestTime)
}


class UnknownStrategy(AgentsimError, ValueError):
    """A name that is not a key of :data:`STRATEGIES`.

    An :class:`~agentsim.errors.AgentsimError`, and a :class:`ValueError` as the unknown names
    were before, so callers that catch either keep working.
    """


def check_strategy(name: str) -> str:
    """The registry name ``name`` itself if it is a key of :data:`STRATEGIES`.

    Parameters
    ----------
    name : str
        A strategy's registry name, such as ``"best"``.

    Returns
    -------
    str
        ``name``, unchanged.

    Raises
    ------
    UnknownStrategy
        An :class:`~agentsim.errors.AgentsimError` whose message names every known strategy.
    """
    if name not in STRATEGIES:
        raise UnknownStrategy(f"unknown strategy {name!r}; known: {', '.join(sorted(STRATEGIES))}")
    return name


def make_strategy(name: str) -> AnimatorTime:
    """A new strategy instance by its registry name (:class:`UnknownStrategy` for an unknown name)."""
    return STRATEGIES[check_strategy(name)]()
