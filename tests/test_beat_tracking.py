"""Tests of the causal beat tracker, its baselines and the evaluation of beat predictions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from anticipators.beats.evaluation import evaluate_predictions, select_predictions, track_and_evaluate, track_file
from anticipators.beats.baselines import IOIBaselineTracker
from anticipators.beats.envelope import SpectralFluxEnvelope
from anticipators.beats.tracking import CausalBeatTracker, make_tracker
from agentsim.music.ensemble import render_ensemble_full
from agentsim.music.events import SynthEvent
from agentsim.music.rendering import render_events

SR = 22050


# ------------------------------------------------------------------------------ evaluation by hand


def test_select_predictions_uses_last_update_before_lookahead():
    updates = [(0.0, [1.0, 2.0, 3.0]), (1.5, [2.01, 3.02]), (2.9, [3.5])]
    pred = select_predictions(updates, [1.0, 2.0, 3.0], lookahead=0.2)
    # beat 3.0: the update at 2.9 is too late (after 2.8), so the one at 1.5 counts
    np.testing.assert_allclose(pred, [1.0, 2.01, 3.02])
    # a beat with no update early enough has no prediction
    assert np.isnan(select_predictions([(0.5, [1.0])], [0.6], lookahead=0.2)[0])
    # dict-style updates are the same
    dict_updates = [{"t": t, "beats": b} for t, b in updates]
    np.testing.assert_allclose(select_predictions(dict_updates, [1.0, 2.0, 3.0]), pred)


def test_evaluate_predictions_known_numbers():
    true = np.array([9.0, 10.0, 11.0, 12.0])
    updates = [(0.0, [9.0]), (9.5, [10.01, 11.0]), (10.7, [11.02, 12.1])]
    res = evaluate_predictions(updates, true, lookahead=0.2, skip=8.0)
    # predictions: 9.0 (0 ms), 10.01 (+10 ms), 11.02 (+20 ms), 12.1 (+100 ms, outside 70 ms)
    assert res["n_beats"] == 4 and res["n_predicted"] == 4
    assert res["mae_ms"] == pytest.approx((0 + 10 + 20 + 100) / 4)
    assert res["mean_error_ms"] == pytest.approx((0 + 10 + 20 + 100) / 4)
    assert res["median_abs_error_ms"] == pytest.approx(15.0)
    assert res["f_measure"] == pytest.approx(0.75)  # precision 3/4, recall 3/4
    assert res["within_window"] == pytest.approx(0.75)


def test_evaluate_predictions_skip_missing_and_signs():
    true = np.array([1.0, 9.0, 10.0, 11.0])
    updates = [(8.5, [8.99, 9.98]), (10.5, [10.97])]
    res = evaluate_predictions(updates, true, lookahead=0.2, skip=8.0)
    # 1.0 is skipped; 9.0 -> 8.99? no: the update at 8.5 is at or before 8.8, so 8.99 (-10 ms);
    # 10.0 -> 9.98 (-20 ms); 11.0 -> 10.97 (-30 ms)
    assert res["n_beats"] == 3 and res["n_predicted"] == 3
    assert res["mean_error_ms"] == pytest.approx(-20.0)
    assert res["mae_ms"] == pytest.approx(20.0)
    assert res["f_measure"] == pytest.approx(1.0)
    # without any update in time: recall 2/3, precision 1 -> F = 0.8
    res = evaluate_predictions([(8.5, [8.99, 9.98])], [9.0, 10.0, 11.0], skip=8.0)
    assert res["n_predicted"] == 3  # 11.0 still uses the 8.5 update, nearest is 9.98 (a miss)
    assert res["f_measure"] == pytest.approx(2 * (2 / 3) * (2 / 3) / (4 / 3))
    res = evaluate_predictions([(10.5, [11.0])], [9.0, 10.0, 11.0], skip=8.0)
    assert res["n_predicted"] == 1
    assert res["f_measure"] == pytest.approx(2 * 1.0 * (1 / 3) / (1 + 1 / 3))
    assert evaluate_predictions([], [9.0], skip=8.0)["f_measure"] == 0.0


# ---------------------------------------------------------------------------------- renders


@pytest.fixture(scope="module")
def render_44():
    # 4/4, 118 BPM, +10 % ramp over 16 bars, +-2 % rubato, about 30 s
    return render_ensemble_full(118, "4/4", 15, ramp=(2, 16, 0.10), rubato=0.02, seed=21, sample_rate=SR)


@pytest.fixture(scope="module")
def render_34():
    return render_ensemble_full(132, "3/4", 22, ramp=(2, 16, 0.10), rubato=0.02, seed=22, sample_rate=SR)


@pytest.mark.parametrize("which", ["render_44", "render_34"])
def test_tracker_predicts_beats_200ms_ahead(which, request):
    r = request.getfixturevalue(which)
    run = track_file(r.audio, "causal", 512, sample_rate=r.sample_rate)
    res = evaluate_predictions(run["updates"], r.beat_times, lookahead=0.2, skip=8.0)
    assert res["f_measure"] >= 0.98
    assert res["mae_ms"] < 15.0
    assert abs(res["mean_error_ms"]) < 5.0
    assert run["wall_seconds"] / run["audio_seconds"] < 0.05  # generous: the machine may be busy
    # every update predicts beats at or after its time, in order
    for u in run["updates"]:
        b = np.asarray(u["beats"])
        assert np.all(b >= u["t"] - 1e-9) and np.all(np.diff(b) > 0)


def test_tracker_state_and_horizon(render_44):
    r = render_44
    tr = CausalBeatTracker(r.sample_rate)
    assert tr.predict(4).size == 0 and math.isnan(tr.tempo_bpm) and tr.confidence == 0.0
    n = int(20 * r.sample_rate)
    for a in range(0, n, 1000):
        tr.process(r.audio[a : min(a + 1000, n)])
    assert tr.time == pytest.approx(20.0)
    assert tr.confidence > 0.8
    true_tempo = 60.0 / np.diff(r.beat_times[(r.beat_times > 16) & (r.beat_times < 20)]).mean()
    assert tr.tempo_bpm == pytest.approx(true_tempo, rel=0.03)
    pred = tr.predict(horizon_beats=6)
    assert pred.size == 6 and pred[0] >= tr.time and pred[-1] - tr.time > 0.2
    upcoming = r.beat_times[r.beat_times >= tr.time][:6]
    assert np.max(np.abs(pred - upcoming)) < 0.03


def test_block_size_does_not_matter_much(render_34):
    r = render_34
    for bs in (64, 4096):
        res = track_and_evaluate(r.audio, r.beat_times, "causal", bs, sample_rate=r.sample_rate)
        assert res["f_measure"] >= 0.98 and res["mae_ms"] < 15.0


def test_same_input_same_predictions(render_34):
    a = track_file(render_34.audio, "causal", 700, sample_rate=SR)
    b = track_file(render_34.audio, "causal", 700, sample_rate=SR)
    assert a["updates"] == b["updates"]


def _block_by_block(tracker, audio, block, horizon=4):
    updates, last = [], None
    for a in range(0, audio.size, block):
        tracker.process(audio[a : a + block])
        pred = tracker.predict(horizon).tolist()
        if pred != last:
            updates.append({"t": tracker.time, "beats": pred})
            last = pred
    return updates


@pytest.mark.parametrize("block", [512, 700, 4096])
def test_track_gives_the_updates_of_process_and_predict(render_34, block):
    x = render_34.audio.copy()
    x[4 * SR : 4 * SR + 3000] = np.nan  # silence as NaNs, a lost grid and a new one
    x[12 * SR : 13 * SR] = 0.0
    want = _block_by_block(CausalBeatTracker(SR), x, block)
    got = CausalBeatTracker(SR).track(x, block)
    assert len(want) > 50 and got == want
    # and track_file (which uses track) records the same updates
    assert track_file(x, "causal", block, sample_rate=SR)["updates"] == want


def test_predict_until_holds_until_then(render_44):
    tr = CausalBeatTracker(SR)
    n = int(12 * SR)
    tr.process(render_44.audio[:n])
    follower = tr.follower
    beats, until = follower.predict_until(tr.time, 4)
    assert beats.size == 4 and tr.time < until <= beats[0]
    for t in np.linspace(tr.time, until, 50):
        np.testing.assert_array_equal(follower.predict(float(t), 4), beats)
    # past the first predicted beat, the predictions move on
    assert follower.predict(float(beats[0]) + 1e-6, 4)[0] == beats[1]
    assert CausalBeatTracker(SR).follower.predict_until(0.0, 4)[1] == math.inf


@pytest.mark.parametrize("rate", [16000, 48000])
def test_other_sample_rates(render_44, rate):
    r = render_44
    y = resample_poly(r.audio, rate, r.sample_rate).astype(np.float32)
    res = track_and_evaluate(y, r.beat_times, "causal", 1024, sample_rate=rate)
    assert res["f_measure"] >= 0.98 and res["mae_ms"] < 15.0


def test_baselines_run_and_are_scored(render_44):
    r = render_44
    base = track_and_evaluate(r.audio, r.beat_times, "baseline", 512, sample_rate=SR)
    assert 0.0 <= base["f_measure"] <= 1.0 and base["n_beats"] > 0
    offline = track_file(r.audio, "librosa_offline", 512, sample_rate=SR)
    assert len(offline["updates"]) == 1 and offline["updates"][0]["t"] == 0.0
    res = evaluate_predictions(offline["updates"], r.beat_times)
    assert res["f_measure"] > 0.9  # it sees the whole piece
    with pytest.raises(ValueError):
        make_tracker("nonsense", SR)


def test_track_file_reads_audio_files(tmp_path, render_34):
    import soundfile as sf

    path = tmp_path / "piece.wav"
    sf.write(path, np.stack([render_34.audio, render_34.audio], axis=1), SR)  # stereo file
    run = track_file(path, "causal", 512)
    assert run["tracker"] == "causal" and run["sample_rate"] == SR
    assert run["audio_seconds"] == pytest.approx(render_34.audio.size / SR)
    assert evaluate_predictions(run["updates"], render_34.beat_times)["f_measure"] >= 0.98


# --------------------------------------------------------------------------------------- bad input


def _feed(tracker, x, block=512):
    conf = []
    for a in range(0, x.size, block):
        tracker.process(x[a : a + block])
        conf.append(tracker.confidence)
        p = tracker.predict(4)
        assert np.all(np.isfinite(p)) and np.all(p >= tracker.time - 1e-9)
    return np.asarray(conf)


def test_silence_gives_no_confidence():
    tr = CausalBeatTracker(SR)
    conf = _feed(tr, np.zeros(15 * SR, np.float32))
    assert conf.max() == 0.0 and tr.predict(4).size == 0


def test_white_noise_gives_low_confidence():
    rng = np.random.default_rng(1)
    tr = CausalBeatTracker(SR)
    conf = _feed(tr, (0.3 * rng.standard_normal(20 * SR)).astype(np.float32))
    assert conf.max() < tr.confidence_threshold


def test_keeps_last_good_prediction_through_silence(render_44):
    r = render_44
    n = int(20.0 * SR)
    tr = CausalBeatTracker(SR)
    conf = _feed(tr, r.audio[:n])
    assert conf[-1] > 0.8
    before = tr.predict(24)  # what the tracker expected when the music stopped
    upcoming = r.beat_times[r.beat_times >= tr.time][:2]
    assert np.max(np.abs(before[:2] - upcoming)) < 0.03
    silence = np.zeros(6 * SR, np.float32)
    last_good = None
    for a in range(0, silence.size, 512):
        tr.process(silence[a : a + 512])
        if tr.confidence >= tr.confidence_threshold:
            last_good = tr.predict(24)
    assert tr.confidence < tr.confidence_threshold
    assert last_good is not None
    # the last confident grid is the one expected when the music stopped (up to its last onsets)
    match = before[np.argmin(np.abs(before[:, None] - last_good[None, :8]), axis=0)]
    np.testing.assert_allclose(last_good[:8], match, atol=0.01)
    # during the silence the predictions continue the last confident grid exactly
    pred = tr.predict(4)
    assert pred.size == 4 and pred[0] >= tr.time
    nearest = last_good[np.argmin(np.abs(last_good[:, None] - pred[None, :]), axis=0)]
    np.testing.assert_allclose(pred, nearest, atol=1e-6)


def test_nan_inf_clipped_and_odd_blocks(render_44):
    r = render_44
    x = r.audio.copy()
    x[5 * SR : 6 * SR] = np.nan
    x[7 * SR : 7 * SR + 100] = np.inf
    tr = CausalBeatTracker(SR)
    _feed(tr, x, block=333)
    tr.process(np.zeros(0, np.float32))  # empty block
    tr.process(np.zeros((256, 2), np.float32))  # stereo block
    tr.process([0.0] * 10)  # list
    assert np.isfinite(tr.confidence)
    clipped = np.clip(r.audio * 3.0, -1.0, 1.0)
    res = track_and_evaluate(clipped, r.beat_times, "causal", 512, sample_rate=SR)
    assert res["f_measure"] >= 0.9
    base = IOIBaselineTracker(SR)
    _feed(base, x, block=1000)


def _clicks(bpm: float, seconds: float) -> np.ndarray:
    times = np.arange(0.5, seconds - 0.5, 60.0 / bpm)
    events = [e for t in times for e in (SynthEvent(t, "note_on", 9, 75, 100), SynthEvent(t + 0.1, "note_off", 9, 75))]
    return render_events(events, seconds, SR)


@pytest.mark.parametrize("bpm", [40, 260])
def test_tempo_outside_range_gives_low_confidence(bpm):
    tr = CausalBeatTracker(SR, min_bpm=60, max_bpm=200)
    conf = _feed(tr, _clicks(bpm, 20.0))
    assert conf[int(6 * SR / 512) :].max() < tr.confidence_threshold


def test_clicks_in_range_are_tracked():
    tr = CausalBeatTracker(SR)
    conf = _feed(tr, _clicks(96, 15.0))
    assert conf[-1] > 0.8 and tr.tempo_bpm == pytest.approx(96, rel=0.01)


def test_onset_envelope_is_causal():
    rng = np.random.default_rng(0)
    x = (0.1 * rng.standard_normal(SR)).astype(np.float32)
    envelope = SpectralFluxEnvelope(SR)
    envelope.push(x[:10000])
    first = envelope.values(0, envelope.n_frames).copy()
    envelope.push(x[10000:])
    # later audio never changes frames already computed
    np.testing.assert_array_equal(envelope.values(0, first.size), first)
    # every frame ends at or before the audio heard
    assert (envelope.n_frames - 1) * envelope.hop + envelope.n_fft <= envelope.n_samples
    with pytest.raises(ValueError):
        CausalBeatTracker(SR, min_bpm=200, max_bpm=100)
