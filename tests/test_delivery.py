"""Tests of progress events and the delivery channel (speech_timing.delivery)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import simpy

from speech_timing.backend import SpeechText
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import (
    DeliveryModel,
    ProgressEvent,
    deliver,
    delivery_process,
    draw_jitter,
    true_events,
)

TEXT = "The quick brown fox jumps over the lazy dog. Then it sleeps, quietly."


@pytest.fixture(scope="module")
def utterance():
    return BuiltinBackend().synthesize(SpeechText(TEXT, marks=((4, "quick"),)))


def _events(times):
    return [ProgressEvent("word", i, t, true_time=t) for i, t in enumerate(times)]


def test_true_events_cover_the_utterance(utterance):
    events = true_events(utterance, t0=2.0, drift_ppm=1000.0)
    kinds = [e.kind for e in events]
    assert kinds.count("word") == len(utterance.words)
    assert kinds.count("phoneme") == len(utterance.phonemes)
    assert kinds.count("sentence") == len(utterance.sentences)
    assert kinds.count("mark") == 1
    assert kinds.count("end") == 1 and kinds[-1] == "end"
    for e in events:
        assert e.true_time == pytest.approx(2.0 + e.speech_time * 1.001)
        assert math.isnan(e.arrival_time)
    times = [e.true_time for e in events]
    assert times == sorted(times)


def test_word_event_comes_before_its_first_phoneme(utterance):
    events = true_events(utterance, 0.0)
    first = {}
    for position, e in enumerate(events):
        key = (e.kind, e.payload.get("word_index", e.index))
        first.setdefault(key, position)
    for word in utterance.words:
        assert first[("word", word.index)] < first[("phoneme", word.index)]


def test_phoneme_payload_counts_positions_in_word(utterance):
    events = [e for e in true_events(utterance, 0.0) if e.kind == "phoneme"]
    by_word = {}
    for e in events:
        by_word.setdefault(e.payload["word_index"], []).append(e.payload["in_word"])
        assert e.payload["char_start"] == utterance.words[e.payload["word_index"]].char_start
    for positions in by_word.values():
        assert positions == list(range(len(positions)))


def test_noise_free_channel_adds_exactly_the_delay():
    events = _events([0.0, 0.1, 0.25, 0.4])
    out = deliver(events, DeliveryModel(delay=0.05), np.random.default_rng(0))
    assert [e.arrival_time for e in out] == pytest.approx([0.05, 0.15, 0.30, 0.45])
    assert all(math.isnan(e.arrival_time) for e in events)  # inputs untouched


def test_arrivals_are_late_and_in_order():
    rng = np.random.default_rng(5)
    times = np.sort(rng.uniform(0, 20, 400))
    model = DeliveryModel(delay=0.05, jitter=0.1, burst_probability=0.1, burst_hold=0.3)
    out = deliver(_events(times), model, np.random.default_rng(1))
    arrivals = np.array([e.arrival_time for e in out])
    true = np.array([e.true_time for e in out])
    assert np.all(arrivals >= true + 0.05 - 1e-12)
    assert np.all(np.diff(arrivals) >= 0)
    assert [e.index for e in out] == sorted(e.index for e in out)


def test_bursts_release_held_events_together():
    times = np.arange(0, 2.0, 0.02)
    model = DeliveryModel(delay=0.0, burst_probability=1.0, burst_hold=0.5)
    out = deliver(_events(times), model, np.random.default_rng(3))
    arrivals = np.array([e.arrival_time for e in out])
    _, counts = np.unique(arrivals, return_counts=True)
    assert counts.max() >= 5  # clusters of events arrive at one instant
    assert len(np.unique(arrivals)) < len(arrivals) / 3


def test_loss_removes_events_reproducibly():
    events = _events(np.arange(1000) * 0.01)
    model = DeliveryModel(delay=0.01, loss=0.3)
    a = deliver(events, model, np.random.default_rng(42))
    b = deliver(events, model, np.random.default_rng(42))
    assert [e.index for e in a] == [e.index for e in b]
    assert 600 < len(a) < 800
    assert deliver(events, DeliveryModel(loss=1.0), np.random.default_rng(0)) == []


def test_same_seed_same_arrivals_different_seed_different():
    events = _events(np.arange(200) * 0.05)
    model = DeliveryModel(delay=0.05, jitter=0.03, burst_probability=0.05, burst_hold=0.2)
    first = [e.arrival_time for e in deliver(events, model, np.random.default_rng(7))]
    again = [e.arrival_time for e in deliver(events, model, np.random.default_rng(7))]
    other = [e.arrival_time for e in deliver(events, model, np.random.default_rng(8))]
    assert first == again
    assert first != other


@pytest.mark.parametrize("shape", ["exponential", "gamma", "half-normal"])
def test_jitter_is_non_negative_with_the_given_mean(shape):
    model = DeliveryModel(jitter=0.03, jitter_distribution=shape)
    values = draw_jitter(model, np.random.default_rng(11), 50_000)
    assert values.min() >= 0.0
    assert values.mean() == pytest.approx(0.03, rel=0.03)


def test_draw_start_stays_in_the_start_window():
    model = DeliveryModel(latency=0.1, start_jitter=0.04)
    starts = [model.draw_start(1.0, np.random.default_rng(s)) for s in range(50)]
    assert all(1.1 <= t <= 1.14 for t in starts)


@pytest.mark.parametrize("bad", [dict(delay=-0.1), dict(jitter=math.nan), dict(loss=1.5),
                                 dict(burst_probability=-0.1), dict(jitter_distribution="cauchy"),
                                 dict(drift_ppm=math.inf)])
def test_model_rejects_bad_parameters(bad):
    with pytest.raises(ValueError):
        DeliveryModel(**bad)


def test_event_kind_is_checked():
    with pytest.raises(ValueError):
        ProgressEvent("syllable", 0, 0.0)


def test_delivery_process_hands_events_over_at_their_arrival():
    events = deliver(_events([0.0, 0.1, 0.1, 0.3]), DeliveryModel(delay=0.05), np.random.default_rng(0))
    env = simpy.Environment()
    seen = []
    env.process(delivery_process(env, events, lambda e, now: seen.append((e.index, now))))
    env.run()
    assert [i for i, _ in seen] == [0, 1, 2, 3]
    assert [t for _, t in seen] == pytest.approx([0.05, 0.15, 0.15, 0.35])
