"""Tests of animator-time strategies, plans, the linear model and the evaluation harness.

Hand-built plans and event sequences have known answers; runs on the deterministic built-in
backend are fast and reproducible.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agentsim.errors import AgentsimError
from speech_timing.animator_time import (
    STRATEGIES,
    AnimatorTime,
    BestTime,
    ChangNaive,
    ChangSmooth,
    LinearModelTime,
    OpenLoop,
    Path,
    Skip70ms,
    SpeechPlan,
    check_strategy,
    lower_envelope_line,
    make_strategy,
)
from speech_timing.backend import SpeechText
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import CONDITIONS, DeliveryModel, ProgressEvent, deliver, true_events
from speech_timing.harness import run_sync_eval, stroke_targets
from speech_timing.linear_model import (
    LinearModel,
    calibrate,
    estimate_phonemes,
    fit_linear,
    plan_from_linear,
    plan_from_utterance,
    written_words,
)

TEXT = ("The keeper climbed the spiral stair every evening, counting the worn steps without meaning to. "
        "At the top he cleaned the great lens, checked the oil, and wound the clockwork that turned the light. "
        "In autumn storms the salt crusted the windows faster than he could wipe it away, and the tower hummed "
        "when the gusts came in from the west. He wrote short notes in a leather book about the wind, the sea, "
        "the ships he could see, and the birds that rested on the rail before flying on to the south.")


def simple_plan(delay=0.05, latency=0.1, t_request=0.0, **extra):
    """Three one-phoneme words at 0.0, 0.3 and 0.6 s; the speech ends at 0.9 s."""
    return SpeechPlan(word_onsets=[0.0, 0.3, 0.6], word_offsets=[0.25, 0.55, 0.85], phoneme_onsets=[0.0, 0.3, 0.6],
                      phonemes_per_word=[1, 1, 1], delay=delay, latency=latency, t_request=t_request,
                      duration=0.9, **extra)


def word(k):
    return ProgressEvent("word", k, 0.3 * k)


# -- Path ------------------------------------------------------------------------------------------------

def test_path_positions_and_exact_crossings():
    path = Path(1.0, 0.0, 1.0).then(1.5, 0.5).then(2.0, 0.0)
    assert path.at(1.25) == pytest.approx(0.25)
    assert path.at(1.75) == pytest.approx(0.625)
    assert path.at(3.0) == pytest.approx(0.75)
    assert path.crossing(0.6, 1.0) == pytest.approx(1.7)
    assert path.crossing(0.1, 1.6) == 1.6  # already reached
    assert path.crossing(0.8, 1.0) == math.inf  # stuck at 0.75
    assert path.at(path.crossing(0.6, 1.0)) == pytest.approx(0.6)


def test_path_until_cuts_and_changes_rate():
    path = Path(0.0, 0.0, 1.0).then(1.0, 2.0).until(0.5, 0.5)
    assert path.at(1.5) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        Path(0.0, 0.0, -1.0)


# -- plans -----------------------------------------------------------------------------------------------

def test_plan_maps_events_to_plan_positions():
    plan = simple_plan()
    assert plan.t0_pred == pytest.approx(0.1)
    assert plan.event_position(word(1)) == pytest.approx(0.3)
    assert plan.event_position(ProgressEvent("end", 0, 0.9)) == pytest.approx(0.9)
    assert plan.event_position(ProgressEvent("sentence", 0, 0.0)) is None
    assert plan.next_unit(0.3) == pytest.approx(0.6)
    assert plan.next_unit(0.6) == pytest.approx(0.9)


def test_plan_validates():
    with pytest.raises(ValueError):
        SpeechPlan([0.0, 0.3], [0.2, 0.5], [0.0], [1, 1])  # counts do not add up
    with pytest.raises(ValueError):
        SpeechPlan([0.3, 0.0], [0.5, 0.2], [0.3, 0.0], [1, 1])  # decreasing onsets
    with pytest.raises(ValueError):
        SpeechPlan([0.0], [0.2], [0.0], [1], delay=-1.0)


def test_registry_names():
    assert list(STRATEGIES) == ["open-loop", "linear-model", "chang-naive", "chang-smooth", "skip-70ms", "best"]
    for name, cls in STRATEGIES.items():
        assert issubclass(cls, AnimatorTime) and cls.name == name
        assert make_strategy(name).name == name
    with pytest.raises(ValueError):
        make_strategy("psychic")


def test_an_unknown_name_is_an_agentsim_error_naming_every_known_strategy():
    for check in (check_strategy, make_strategy,
                  lambda name: run_sync_eval(TEXT, BuiltinBackend(), name, DeliveryModel())):
        with pytest.raises(AgentsimError, match="unknown strategy 'psychic'") as caught:
            check("psychic")
        assert all(name in str(caught.value) for name in STRATEGIES)
    for name in STRATEGIES:
        assert check_strategy(name) == name


# -- baselines on hand-built sequences -------------------------------------------------------------------

def test_open_loop_runs_from_the_predicted_start():
    s = OpenLoop()
    s.reset(simple_plan(), t_request=2.0)
    assert s.position(2.1) == pytest.approx(0.0)
    s.on_event(word(1), 2.5)
    assert s.position(2.7) == pytest.approx(0.6)
    assert s.crossing(0.6, 2.7) == pytest.approx(2.7)
    assert s.crossing(0.8, 2.7) == pytest.approx(2.9)


def test_chang_naive_sticks_and_snaps():
    s = ChangNaive()
    s.reset(simple_plan(), 0.0)  # t0_pred = 0.1; sticks at the first unit (0.0) until an event
    assert s.position(0.05) == pytest.approx(-0.05)
    assert s.position(0.2) == pytest.approx(0.0)
    s.on_event(word(0), 0.2)  # unit 0 started at 0.2 - 0.05
    assert s.position(0.2) == pytest.approx(0.05)
    assert s.position(0.3) == pytest.approx(0.15)
    assert s.position(0.45) == pytest.approx(0.3)  # reached the next unit's onset
    assert s.position(0.5) == pytest.approx(0.3)  # ...and sticks there
    assert s.crossing(0.31, 0.5) == math.inf
    s.on_event(word(1), 0.5)
    assert s.position(0.5) == pytest.approx(0.35)
    assert s.crossing(0.6, 0.5) == pytest.approx(0.75)
    s.on_event(word(2), 0.55)  # early: snaps forward from 0.4 to 0.65
    assert s.position(0.55) == pytest.approx(0.65)
    assert s.crossing(0.6, 0.55) == pytest.approx(0.55)


def test_skip_70ms_jumps_only_beyond_the_threshold():
    s = Skip70ms()
    s.reset(simple_plan(), 0.0)
    s.on_event(word(0), 0.19)  # estimate 0.05, clock says 0.09: within 70 ms
    assert s.position(0.19) == pytest.approx(0.09)
    s.on_event(word(1), 0.3)  # estimate 0.35, clock says 0.2: jump
    assert s.position(0.3) == pytest.approx(0.35)
    assert s.position(0.4) == pytest.approx(0.45)


def test_chang_smooth_is_continuous_and_catches_up():
    s = ChangSmooth()
    s.reset(simple_plan(), 0.0)
    before = s.position(0.3)
    s.on_event(word(0), 0.3)  # speech is at 0.05, animation at 0.2: slow down
    assert s.position(0.3) == pytest.approx(before)
    assert s.position(0.4) - s.position(0.3) < 0.1
    late = ChangSmooth()
    late.reset(simple_plan(latency=0.3), 0.0)  # the animation starts 0.2 s behind
    late.on_event(word(1), 0.5)  # speech at 0.35, animation at 0.2: speed up
    assert late.position(0.55) - late.position(0.5) > 0.05


def test_linear_model_strategy_strikes_at_the_model_times():
    model = LinearModel(multiplier=0.06, offset=0.02)
    plan = simple_plan(word_chars=[0, 4, 9], linear_model=model)
    s = LinearModelTime()
    s.reset(plan, 1.0)
    for chars, onset in zip([0, 4, 9], [0.0, 0.3, 0.6]):
        assert s.crossing(onset, 1.0) == pytest.approx(1.1 + 0.06 * chars + 0.02)


# -- best ------------------------------------------------------------------------------------------------

def test_lower_envelope_line_recovers_the_fastest_line():
    rng = np.random.default_rng(0)
    p = np.sort(rng.uniform(0, 30, 300))
    y = 0.7 + 1.0005 * p + rng.exponential(0.03, 300)
    a, b = lower_envelope_line(p, y, float(p.mean()))
    assert b == pytest.approx(1.0005, abs=2e-4)
    assert a + b * 15 == pytest.approx(0.7 + 1.0005 * 15, abs=0.003)
    assert np.all(y >= a + b * p - 1e-9)
    assert lower_envelope_line(np.array([1.0]), np.array([3.0]), 1.0) == (2.0, 1.0)


def test_best_converges_on_noise_free_delayed_events():
    utterance = BuiltinBackend().synthesize(SpeechText(TEXT))
    plan = plan_from_utterance(utterance, delay=0.05, latency=0.1)
    t0, scale = 0.1 + 0.03, 1.0008  # 30 ms unknown start latency, 800 ppm drift
    events = deliver(true_events(utterance, t0, drift_ppm=800.0), DeliveryModel(delay=0.05),
                     np.random.default_rng(0))
    # the drift is estimated once the events span 8 s; from 10 s on every word is shown when heard
    heard = [(t0 + w.start * scale, w.start) for w in utterance.words if w.start > 10.0]
    s = BestTime()
    s.reset(plan, 0.0)
    previous = s.position(0.0)
    shown = []
    for e in events:
        while heard and heard[0][0] <= e.arrival_time:
            t, speech = heard.pop(0)
            shown.append(s.position(t) - speech)
        before = s.position(e.arrival_time)
        assert before >= previous - 1e-12  # never runs backwards
        s.on_event(e, e.arrival_time)
        assert s.position(e.arrival_time) == pytest.approx(before)  # never jumps
        previous = before
    intercept, slope = s.clock_estimate
    assert intercept == pytest.approx(t0, abs=1e-6)
    assert slope == pytest.approx(scale, abs=1e-6)
    assert len(shown) > 40 and max(abs(x) for x in shown) < 1e-6


def test_best_in_the_harness_noise_free_has_zero_error_and_no_snaps():
    model = DeliveryModel(latency=0.1, start_jitter=0.04, drift_ppm=300.0, delay=0.05)
    r = run_sync_eval(TEXT, BuiltinBackend(), "best", model, seed=3, traces=True)
    assert r["snaps"] == 0 and r["missed"] == 0
    assert r["error_ms"]["p95"] < 3.0
    late = r["true_onsets"] > r["true_onsets"][0] + 10.0
    assert late.sum() > 20 and np.abs(r["errors_s"][late]).max() < 1e-6


def test_best_beats_the_baselines_with_jitter_and_bursts():
    model = CONDITIONS["A"]
    backend = BuiltinBackend()
    results = {name: run_sync_eval(TEXT, backend, name, model, seed=1) for name in STRATEGIES}
    best = results["best"]
    assert best["snaps"] == 0
    assert best["error_ms"]["p95"] < 15.0
    for name, r in results.items():
        if name != "best":
            assert best["error_ms"]["p95"] < r["error_ms"]["p95"], name
    assert results["chang-naive"]["snaps"] > 0


def test_best_with_a_linear_plan_is_smooth_and_better_than_open_loop():
    model = DeliveryModel(latency=0.08, delay=0.05, jitter=0.03, burst_probability=0.03, burst_hold=0.25)
    backend = BuiltinBackend()
    linear = calibrate(backend, [TEXT[:120], TEXT[120:260]])
    best = run_sync_eval(TEXT, backend, "best", model, timing="linear", seed=2, linear_model=linear)
    naive = run_sync_eval(TEXT, backend, "open-loop", model, timing="linear", seed=2, linear_model=linear)
    assert best["snaps"] == 0 and best["missed"] == 0
    assert best["error_ms"]["p95"] < naive["error_ms"]["p95"]


# -- harness ---------------------------------------------------------------------------------------------

def test_same_seed_reproduces_numbers():
    model = DeliveryModel(latency=0.08, start_jitter=0.04, drift_ppm=500.0, delay=0.05, jitter=0.05,
                      burst_probability=0.05, burst_hold=0.2, loss=0.02)
    backend = BuiltinBackend()
    for name in ("best", "chang-smooth"):
        a = run_sync_eval(TEXT, backend, name, model, seed=11)
        b = run_sync_eval(TEXT, backend, name, model, seed=11)
        c = run_sync_eval(TEXT, backend, name, model, seed=12)
        assert a == b
        assert a["error_ms"] != c["error_ms"]
    assert list(a) == ["strategy", "timing", "seed", "words", "gestures", "missed", "error_ms", "snaps",
                       "stall_s", "rate"]


def test_stroke_targets_are_content_words():
    utterance = BuiltinBackend().synthesize(SpeechText("The old lighthouse and the sea."))
    plan = plan_from_utterance(utterance)
    indices, truth, planned = stroke_targets(utterance, plan)
    assert [utterance.words[i].text for i in indices] == ["old", "lighthouse", "sea"]
    assert truth == pytest.approx(planned)
    _, stressed, _ = stroke_targets(utterance, plan, stress=True)
    assert np.all(stressed >= truth)


def test_harness_rejects_unknown_names():
    with pytest.raises(ValueError):
        run_sync_eval(TEXT, BuiltinBackend(), "nope", DeliveryModel())
    with pytest.raises(ValueError):
        run_sync_eval(TEXT, BuiltinBackend(), "best", DeliveryModel(), timing="exact")


# -- linear model ----------------------------------------------------------------------------------------

def test_fit_linear_recovers_a_line_and_round_trips(tmp_path):
    chars = np.arange(0, 200, 7)
    model = fit_linear(chars, 0.055 * chars + 0.03, phonemes_per_unit=0.9)
    assert model.multiplier == pytest.approx(0.055) and model.offset == pytest.approx(0.03)
    assert model.rms == pytest.approx(0.0, abs=1e-9)
    path = tmp_path / "linear.json"
    model.save(path)
    assert LinearModel.load(path) == model
    with pytest.raises(ValueError):
        fit_linear([3], [0.1])


def test_plan_from_linear_follows_characters():
    model = LinearModel(multiplier=0.05, offset=0.1, phonemes_per_unit=1.0)
    text = "Well-known facts, said the keeper. Then he slept."
    plan = plan_from_linear(text, model, delay=0.05, latency=0.1)
    spans = written_words(text)
    assert [text[a:b] for a, b in spans] == ["Well-known", "facts", "said", "the", "keeper", "Then", "he", "slept"]
    assert plan.word_onsets == pytest.approx(0.05 * np.array([a for a, _ in spans]) + 0.1)
    assert plan.source == "linear" and plan.linear_model is model
    assert list(plan.breaks) == [0, 1, 0, 0, 2, 0, 0, 2]
    assert plan.phonemes_per_word[2] == estimate_phonemes("said") == 3
    assert len(plan.phoneme_onsets) == plan.phonemes_per_word.sum()


def test_calibrate_on_the_builtin_backend():
    backend = BuiltinBackend()
    model = calibrate(backend, [TEXT[:150], TEXT[150:]])
    assert 0.02 < model.multiplier < 0.1
    assert model.n_points > 20 and model.rms < 0.5
