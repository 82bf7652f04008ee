"""Standalone SimPy evaluation of animator-time strategies: beat gestures on every content word.

:func:`run_sync_eval` speaks a text once, aims a beat-gesture stroke at every content word, plays the
utterance on a simulated clock with a :class:`~speech_timing.delivery.DeliveryModel`, drives one
strategy with the delivered progress events, and scores when the strokes land against when the words
are heard. A stroke strikes when the strategy's animator time ``t_A`` reaches the stroke's planned
speech time; its time is the exact crossing time of the piecewise-linear ``t_A``.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import asdict, replace
from typing import Any, Callable, Sequence

import numpy as np
import simpy

from speech_timing.animator_time import check_strategy, make_strategy
from speech_timing.backend import SpeechText, TTSBackend, Utterance, backend_key
from speech_timing.builtin import FUNCTION_WORDS
from speech_timing.delivery import DeliveryModel, deliver, delivery_process, true_events
from speech_timing.duration_model import for_plan
from speech_timing.linear_model import (LinearModel, default_linear_model, plan_from_linear,
                                         plan_from_utterance)
from speech_timing.metrics import DEFAULT_FRAME, evaluate, sync_errors
from speech_timing.plan import SpeechPlan

__all__ = ["run_sync_eval", "synthesize_cached", "stroke_targets", "is_content_word",
           "TIMINGS"]

#: Where the plan comes from: the backend's own timeline, or Chang's linear model.
TIMINGS = ("tts", "linear")

_UTTERANCES: dict[tuple, Utterance] = {}


def synthesize_cached(backend: TTSBackend, text: str) -> Utterance:
    """Synthesise ``text`` once per process and backend configuration; later calls return the same object.

    Every strategy and condition is scored on the same timeline, synthesised once.
    """
    key = (backend_key(backend), text)
    if key not in _UTTERANCES:
        _UTTERANCES[key] = backend.synthesize(SpeechText(text))
    return _UTTERANCES[key]


def is_content_word(word: str) -> bool:
    """Whether a written word is a content word (not in :data:`speech_timing.builtin.FUNCTION_WORDS`)."""
    core = word.lower().strip("'\u2019")
    return bool(core) and core not in FUNCTION_WORDS


def stroke_targets(utterance: Utterance, plan: SpeechPlan, stress: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beat-gesture targets: every content word that the plan has as a word of its own.

    Parameters
    ----------
    utterance : Utterance
        The true timeline.
    plan : SpeechPlan
        The plan strokes are scheduled on.
    stress : bool
        Aim at the onset of the word's stressed vowel (when the backend marks one) instead of the
        word onset.

    Returns
    -------
    word_indices : numpy.ndarray of int
        Indices of the target words in ``utterance.words``.
    true_speech_times : numpy.ndarray of float
        Speech time (s) of each target in the true timeline.
    planned_positions : numpy.ndarray of float
        Plan-axis time (s) at which each stroke is planned.
    """
    stressed: dict[int, float] = {}
    for ph in utterance.phonemes:
        if ph.stressed and ph.word_index not in stressed:
            stressed[ph.word_index] = ph.start
    plan_chars = {int(c): k for k, c in enumerate(plan.word_chars)} if plan.word_chars is not None else {}
    indices, truth, planned = [], [], []
    for word in utterance.words:
        if not is_content_word(word.text):
            continue
        k = plan_chars.get(word.char_start) if plan_chars else (word.index if word.index < plan.n_words else None)
        if k is None:
            continue
        indices.append(word.index)
        truth.append(stressed.get(word.index, word.start) if stress else word.start)
        planned.append(plan.stress_onsets[k] if stress else plan.word_onsets[k])
    return np.array(indices, dtype=int), np.array(truth, dtype=float), np.array(planned, dtype=float)


def run_sync_eval(text: str, backend: TTSBackend, strategy_name: str, delivery: DeliveryModel,
                  timing: str = "tts", seed: int = 0, linear_model: LinearModel | None = None, *,
                  stress: bool = False, t_request: float = 1.0, frame: float = DEFAULT_FRAME,
                  traces: bool = False,
                  durations: Callable[[Utterance, np.random.Generator], Sequence[np.ndarray]] | None = None
                  ) -> dict[str, Any]:
    """Score one strategy on one text under one delivery condition.

    Parameters
    ----------
    text : str
        Text to speak (synthesised once per process: :func:`synthesize_cached`).
    backend : TTSBackend
        Text-to-speech backend giving the true timeline.
    strategy_name : str
        A key of :data:`speech_timing.animator_time.STRATEGIES` (checked by
        :func:`~speech_timing.animator_time.check_strategy`).
    delivery : DeliveryModel
        Playback start, drift and event channel.
    timing : {"tts", "linear"}
        Plan from the backend's own timeline, or from Chang's linear model (the hard case: the plan
        is wrong per word and only the events tell the truth).
    seed : int
        Seed of the only random generator (playback start, then the channel). The same seed gives the
        same delivered events for every strategy, and identical numbers.
    linear_model : LinearModel, optional
        The linear model for ``timing="linear"`` and for the ``linear-model`` strategy; calibrated on
        the bundled calibration texts if not given (:func:`default_linear_model`).
    stress : bool
        Aim strokes at stressed-vowel onsets instead of word onsets.
    t_request : float
        Clock time at which playback is requested (s).
    frame : float
        Animation frame period (s) at which ``t_A`` is sampled for the snap and stall metrics.
    traces : bool
        Also return the signed errors (s), the sampled clock and ``t_A``, and the stroke times.
    durations : callable, optional
        ``durations(utterance, rng)`` gives per-word phoneme durations (:mod:`speech_timing.duration_model`)
        that the plan carries to the strategies as :attr:`~speech_timing.plan.SpeechPlan.phoneme_durations`;
        ``rng`` is a generator of its own, seeded with ``seed``. The plan axis is unchanged. With
        :func:`~speech_timing.duration_model.noisy_durations` it measures what a text-to-duration model
        of a given accuracy would be worth.

    Returns
    -------
    dict
        ``strategy``, ``timing``, ``seed``, ``words`` (in the utterance), ``gestures`` (strokes aimed),
        ``missed`` (strokes that never struck; left out of the errors), ``error_ms`` (p50, p95, max and
        mean absolute error, signed mean, n), ``snaps``, ``stall_s`` and ``rate`` (``min``, ``max``),
        all over the frames from the true start to the true end of the audio.
    """
    check_strategy(strategy_name)
    if timing not in TIMINGS:
        raise ValueError(f"timing must be one of {TIMINGS}, not {timing!r}")
    utterance = synthesize_cached(backend, text)
    if not utterance.words:
        raise ValueError("the text has no words")
    if linear_model is None and (timing == "linear" or strategy_name == "linear-model"):
        linear_model = default_linear_model(backend)
    known = dict(delay=delivery.delay, latency=delivery.latency, t_request=t_request)
    if timing == "tts":
        plan = plan_from_utterance(utterance, linear_model=linear_model, **known)
    else:
        plan = plan_from_linear(text, linear_model, **known)
    if durations is not None:
        per_word = durations(utterance, np.random.default_rng([seed, 1]))
        plan = replace(plan, phoneme_durations=for_plan(utterance, plan, per_word))

    rng = np.random.default_rng(seed)
    t0 = delivery.draw_start(t_request, rng)
    events = true_events(utterance, t0, delivery.drift_ppm)
    delivered = deliver(events, delivery, rng)
    scale = 1.0 + delivery.drift_ppm * 1e-6
    t_end = t0 + utterance.duration * scale

    _, truth_s, planned = stroke_targets(utterance, plan, stress)
    truth_t = t0 + truth_s * scale
    strokes = np.full(len(planned), math.nan)

    strategy = make_strategy(strategy_name)
    strategy.reset(plan, t_request)
    env = simpy.Environment(initial_time=t_request)
    state = {"news": env.event(), "done": False}

    def on_event(event, now):
        strategy.on_event(event, now)
        news, state["news"] = state["news"], env.event()
        news.succeed()

    def feeder():
        yield from delivery_process(env, delivered, on_event)
        state["done"] = True
        news, state["news"] = state["news"], env.event()
        news.succeed()

    def stroker():
        for i, s in enumerate(planned):
            while True:
                cross = strategy.crossing(s, env.now)
                if cross <= env.now:
                    strokes[i] = env.now
                    break
                if math.isinf(cross):
                    if state["done"]:
                        return  # never reached: the rest are missed
                    yield state["news"]
                    continue
                timer = env.timeout(cross - env.now)
                yield timer | state["news"]
                if timer.processed:
                    strokes[i] = cross
                    break

    first_frame = math.ceil((t0 - t_request) / frame)
    last_frame = math.floor((t_end - t_request) / frame)
    frames = t_request + frame * np.arange(first_frame, last_frame + 1)
    samples = np.full(len(frames), math.nan)

    def sampler():
        for i, t in enumerate(frames):
            if t > env.now:
                yield env.timeout(t - env.now)
            samples[i] = strategy.position(t)

    processes = [env.process(feeder()), env.process(stroker()), env.process(sampler())]
    env.run(until=env.all_of(processes))  # every stroke struck (or can never strike), every frame sampled

    hit = np.isfinite(strokes)
    result: dict[str, Any] = OrderedDict(
        strategy=strategy_name, timing=timing, seed=seed,
        words=len(utterance.words), gestures=int(len(planned)), missed=int((~hit).sum()),
        **evaluate(strokes[hit], truth_t[hit], frames, samples, frame),
    )
    if traces:
        result.update(errors_s=sync_errors(strokes[hit], truth_t[hit]), t=frames, t_A=samples, strokes=strokes,
                      true_onsets=truth_t, delivery=asdict(delivery))
    return result
