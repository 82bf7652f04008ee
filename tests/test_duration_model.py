"""Phoneme-duration knowledge for linear plans: true and noisy durations, the calibrated phonetic model,
and the best strategy using them."""

from __future__ import annotations

import numpy as np
import pytest

from speech_timing.backend import SpeechText
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import CONDITIONS, DeliveryModel
from speech_timing.duration_model import (PhonemeDurationModel, calibration_corpus, for_plan, noisy_durations,
                                          true_durations)
from speech_timing.harness import run_sync_eval
from speech_timing.linear_model import calibrate, plan_from_linear
from speech_timing.plan import SpeechPlan

TEXT = ("The keeper climbed the spiral stair every evening, counting the worn steps without meaning to. "
        "At the top he cleaned the great lens, checked the oil, and wound the gears that turned the light. "
        "In autumn storms the salt crusted the windows faster than he could wipe it away, and the tower hummed "
        "when the gusts came in from the west.")


@pytest.fixture(scope="module")
def utterance():
    return BuiltinBackend().synthesize(SpeechText(TEXT))


def test_true_durations_lay_out_every_phoneme_and_pause(utterance):
    durations = true_durations(utterance)
    assert len(durations) == len(utterance.words)
    onsets = [w.start for w in utterance.words] + [utterance.duration]
    for k, d in enumerate(durations):
        assert len(d) == sum(p.word_index == k for p in utterance.phonemes)
        assert d.sum() == pytest.approx(onsets[k + 1] - onsets[k], abs=1e-12)  # the pause is included
    # "evening," ends in a comma pause: its last phoneme lasts a consonant plus the 0.18 s pause
    k = next(i for i, w in enumerate(utterance.words) if w.text == "evening")
    assert durations[k][-1] == pytest.approx(0.06 + 0.18)


def test_noisy_durations_have_the_asked_error_and_are_seeded(utterance):
    truth = np.concatenate(true_durations(utterance))
    assert np.array_equal(np.concatenate(noisy_durations(utterance, 0.0, np.random.default_rng(1))), truth)
    a = np.concatenate(noisy_durations(utterance, 0.01, np.random.default_rng(1)))
    b = np.concatenate(noisy_durations(utterance, 0.01, np.random.default_rng(1)))
    assert np.array_equal(a, b) and a.min() >= 0.005
    assert np.sqrt(np.mean((a - truth) ** 2)) == pytest.approx(0.01, rel=0.3)
    with pytest.raises(ValueError):
        noisy_durations(utterance, -0.01, np.random.default_rng(1))


def test_for_plan_lines_up_words_by_character_offset(utterance):
    linear = calibrate(BuiltinBackend(), [TEXT[:150], TEXT[150:]])
    plan = plan_from_linear(TEXT, linear)
    known = for_plan(utterance, plan, true_durations(utterance))
    assert len(known) == plan.n_words
    assert [len(d) for d in known] == [sum(p.word_index == k for p in utterance.phonemes)
                                       for k in range(len(utterance.words))]
    with pytest.raises(ValueError, match="phoneme_durations"):
        SpeechPlan([0.0, 0.3], [0.2, 0.5], [0.0, 0.3], [1, 1], phoneme_durations=[[0.3], []])


def test_calibrated_model_recovers_a_table_driven_backend(utterance):
    # The built-in backend times phonemes by a table (vowel, consonant, stress, pauses), so a model
    # calibrated on other texts predicts every phoneme of a new one inside a clause exactly. Before a
    # break the means mix pauses the backend does and does not make (after a quote, a dash), within 40 ms.
    backend = BuiltinBackend()
    model = PhonemeDurationModel().fit(backend.synthesize(SpeechText(t)) for t in calibration_corpus()[:40])
    predicted, truth = model.predict(utterance), true_durations(utterance)
    assert [len(p) for p in predicted] == [len(t) for t in truth]
    before_break = np.concatenate([np.arange(len(t)) == len(t) - 1 if TEXT[w.char_end:w.char_end + 1] in ",.;"
                                   else np.zeros(len(t), bool) for w, t in zip(utterance.words, truth)])
    error = np.concatenate(predicted) - np.concatenate(truth)
    assert before_break.sum() == 7
    assert np.abs(error[~before_break]).max() < 1e-4
    assert np.abs(error[before_break]).max() < 0.04
    assert model.n > 1000


def test_calibrated_model_backs_off_to_coarser_contexts():
    backend = BuiltinBackend()
    model = PhonemeDurationModel().fit([backend.synthesize(SpeechText("Bad cats sat."))])
    # "zq" has no calibrated phoneme: the mean of all phonemes inside words; "tab" reuses what it knows
    unseen = model.predict(backend.synthesize(SpeechText("zq tab")))
    inside = model.tables[-1][(-1,)]
    assert unseen[0][0] == pytest.approx((inside[0] + 2 * model.mean) / (inside[1] + 2))
    assert 0.06 < unseen[1][0] < 0.09  # the "t" of "cats" (60 ms), not of "sat." with its pause (510 ms)
    with pytest.raises(ValueError):
        PhonemeDurationModel(prior=0.0)


def test_best_uses_phoneme_durations_on_a_linear_plan():
    # Chang's linear plan, events delayed 50 ms plus jitter and bursts: the durations the plan carries
    # decide how well the best strategy predicts each word. Exact durations do far better than learning
    # word durations online, and rough ones worse than exact ones.
    model = CONDITIONS["A"]
    backend = BuiltinBackend()
    linear = calibrate(backend, [TEXT[:150], TEXT[150:]])
    text = " ".join([TEXT] * 3)

    def run(error):
        durations = None if error is None else (lambda u, rng: noisy_durations(u, error, rng))
        return run_sync_eval(text, backend, "best", model, timing="linear", seed=4, linear_model=linear,
                             durations=durations)

    alone, exact, rough = run(None), run(0.0), run(0.02)
    for r in (alone, exact, rough):
        assert r["snaps"] == 0 and r["missed"] == 0
    assert exact["error_ms"]["p95"] < 30.0
    assert exact["error_ms"]["p95"] < rough["error_ms"]["p95"]
    assert exact["error_ms"]["p95"] < 0.6 * alone["error_ms"]["p95"]
    assert run(0.02) == rough  # the noise is seeded


def test_best_with_exact_durations_and_no_jitter_strikes_on_time():
    model = DeliveryModel(latency=0.08, delay=0.05)
    backend = BuiltinBackend()
    linear = calibrate(backend, [TEXT[:150], TEXT[150:]])
    r = run_sync_eval(TEXT, backend, "best", model, timing="linear", seed=1, linear_model=linear, traces=True,
                      durations=lambda u, rng: true_durations(u))
    assert r["snaps"] == 0
    late = r["true_onsets"] > r["true_onsets"][0] + 2.0
    assert late.sum() > 10 and np.abs(r["errors_s"][late]).max() < 1e-6
