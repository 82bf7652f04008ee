"""Tests of the causal beat tracker, its baselines and the evaluation of beat predictions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from anticipators.beats.evaluation import (
    committed_beats,
    score_beats,
    score_committed,
    time_to_correct,
    track_and_evaluate,
    track_file,
)
from anticipators.beats.baselines import IOIBaselineTracker
from anticipators.beats.envelope import SpectralFluxEnvelope
from anticipators.beats.tracking import CausalBeatTracker, make_tracker
from agentsim.music.ensemble import render_ensemble_full
from helpers import cached_render
from agentsim.music.events import SynthEvent
from agentsim.music.rendering import render_events

SR = 22050


def music_end(render) -> float:
    """A render's music ends with its last beat: committed beats in the decaying tail after it are not scored."""
    return float(render.beat_times[-1]) + 0.07


# ------------------------------------------------------------------------------ evaluation by hand

UPDATES = [(0.0, [0.5, 1.0, 1.5]), (0.9, [1.02, 1.52, 2.02]), (1.4, [1.5, 2.0, 2.5]), (2.0, [2.6, 3.1])]


def test_committed_sequence_takes_each_beat_from_the_update_in_force_lookahead_before_it():
    # 0.2 s ahead: update 0 commits [0.2, 1.1), update 1 [1.1, 1.6), update 2 [1.6, 2.2), update 3 from 2.2
    assert committed_beats(UPDATES, 0.2).tolist() == [0.5, 1.0, 1.52, 2.0, 2.6, 3.1]
    assert committed_beats(UPDATES, 0.2, end=3.0).tolist() == [0.5, 1.0, 1.52, 2.0, 2.6]
    # at lead 0 the beat at 2.0 is lost: update 2 is replaced at 2.0, and update 3 no longer predicts it
    assert committed_beats(UPDATES, 0.0).tolist() == [0.5, 1.02, 1.5, 2.6, 3.1]
    # 0.6 s ahead: update 0 commits [0.6, 1.5), update 1 [1.5, 2.0), update 2 [2.0, 2.6), update 3 from 2.6;
    # the performer plays both 2.5 (update 2) and 2.6 (update 3), as it would
    assert committed_beats(UPDATES, 0.6).tolist() == [1.0, 1.52, 2.0, 2.5, 2.6, 3.1]
    dict_updates = [{"t": t, "beats": b} for t, b in UPDATES]
    assert committed_beats(dict_updates, 0.2).tolist() == [0.5, 1.0, 1.52, 2.0, 2.6, 3.1]
    assert committed_beats([], 0.2).size == 0
    with pytest.raises(ValueError):
        committed_beats(UPDATES, -0.1)


def test_score_beats_known_numbers():
    ref = [4.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0]
    est = [4.0, 6.01, 7.05, 8.1, 9.0, 9.5, 10.0]
    res = score_beats(ref, est, skip=5.0)
    # trimmed at 5 s: 6 reference beats, 6 estimated; hits 6.01, 7.05, 9.0, 10.0 (8.1 is 100 ms off)
    assert res["n_reference"] == 6 and res["n_estimated"] == 6 and not res["silent"]
    assert res["f_measure"] == pytest.approx(2 / 3)
    assert res["mae_ms"] == pytest.approx(15.0) and res["mean_error_ms"] == pytest.approx(15.0)
    assert res["median_abs_error_ms"] == pytest.approx(5.0)
    ref = np.arange(5.0, 20.0, 0.5)
    exact = score_beats(ref, ref)
    assert (exact["f_measure"], exact["cmlt"], exact["amlt"], exact["p_score"]) == (1.0, 1.0, 1.0, 1.0)
    # twice the tempo: every reference beat hit, half the estimates extra; the right phase, the wrong level
    double = score_beats(ref, np.arange(5.0, 20.0, 0.25))
    assert double["f_measure"] == pytest.approx(2 * 0.5 * 1.0 / 1.5)
    assert double["cmlt"] == 0.0 and double["amlt"] > 0.95  # (mir_eval loses a beat at the end of a variant)
    # off-beat: nothing within 70 ms, but the metrical level is right
    off = score_beats(ref, ref + 0.25)
    assert off["f_measure"] == 0.0 and off["cmlt"] == 0.0 and off["amlt"] > 0.95
    silent = score_beats(ref, [1.0, 2.0])  # all trimmed away
    assert silent["silent"] and silent["f_measure"] == 0.0 and silent["cmlt"] == 0.0 and silent["n_estimated"] == 0


def test_time_to_correct_is_the_end_of_the_first_run_of_hits():
    ref = np.arange(1.0, 11.0)
    est = [1.0, 2.03, 3.2, 4.0, 5.0, 6.06, 7.0, 8.0]  # 3.0 missed: the run 4, 5, 6, 7 ends at 7
    assert time_to_correct(ref, est, 4) == 7.0
    assert time_to_correct(ref, est, 2) == 2.0
    assert time_to_correct(ref, est[:6], 4) is None
    assert time_to_correct(ref, est, 4, consecutive=False) == 5.0 and time_to_correct(ref, est[:6], 5, consecutive=False) == 6.0


def test_score_committed_scores_the_committed_sequence_not_the_nearest_prediction():
    ref = np.arange(5.0, 12.0, 1.0)
    # every update predicts the beats and, between them, extra ones: a nearest-prediction score would not
    # see them, the committed sequence plays them
    updates = [(t, [t + 0.5, t + 1.0]) for t in np.arange(4.0, 12.0, 0.5)]
    res = score_committed(updates, ref, lookahead=0.2, skip=5.0)
    committed = committed_beats(updates, 0.2)
    # each update commits its first beat; the last one, in force to the end, both
    assert committed.tolist() == pytest.approx(np.arange(4.5, 13.0, 0.5).tolist())
    assert res["n_reference"] == 7 and res["n_estimated"] == 16  # from 5 s
    assert res["f_measure"] == pytest.approx(2 * (7 / 16) * 1.0 / (7 / 16 + 1.0))
    assert res["time_to_4"] == 8.0 and res["lookahead"] == 0.2
    assert score_committed([], ref)["silent"]


# ---------------------------------------------------------------------------------- renders


@pytest.fixture(scope="module")
def render_44():
    # 4/4, 118 BPM, +10 % ramp over 16 bars, +-2 % rubato, about 30 s
    return cached_render(render_ensemble_full, 118, "4/4", 15, ramp=(2, 16, 0.10), rubato=0.02, seed=21, sample_rate=SR)


@pytest.fixture(scope="module")
def render_34():
    return cached_render(render_ensemble_full, 132, "3/4", 22, ramp=(2, 16, 0.10), rubato=0.02, seed=22, sample_rate=SR)


@pytest.mark.parametrize("which", ["render_44", "render_34"])
def test_tracker_predicts_beats_200ms_ahead(which, request):
    r = request.getfixturevalue(which)
    run = track_file(r.audio, "causal", 512, sample_rate=r.sample_rate)
    res = score_committed(run["updates"], r.beat_times, lookahead=0.2, skip=8.0, end=music_end(r))
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
        res = track_and_evaluate(r.audio, r.beat_times, "causal", bs, sample_rate=r.sample_rate, end=music_end(r))
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
    res = track_and_evaluate(y, r.beat_times, "causal", 1024, sample_rate=rate, end=music_end(r))
    assert res["f_measure"] >= 0.98 and res["mae_ms"] < 15.0


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_baselines_run_and_are_scored(render_44):
    r = render_44
    base = track_and_evaluate(r.audio, r.beat_times, "baseline", 512, sample_rate=SR, end=music_end(r))
    assert 0.0 <= base["f_measure"] <= 1.0 and base["n_reference"] > 0
    offline = track_file(r.audio, "librosa_offline", 512, sample_rate=SR)
    assert len(offline["updates"]) == 1 and offline["updates"][0]["t"] == 0.0
    res = score_committed(offline["updates"], r.beat_times, end=music_end(r))
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
    assert score_committed(run["updates"], render_34.beat_times, end=music_end(render_34))["f_measure"] >= 0.98


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
    assert conf.max() < 0.4


def test_predictions_follow_the_grid_through_silence(render_44):
    """No last confident state is kept apart: through silence the filter advances without observations,
    and its predictions continue the grid the music left."""
    r = render_44
    n = int(20.0 * SR)
    tr = CausalBeatTracker(SR)
    conf = _feed(tr, r.audio[:n])
    assert conf[-1] > 0.8 and tr.confidence_threshold == 0.0
    before = tr.predict(24)  # what the tracker expected when the music stopped
    upcoming = r.beat_times[r.beat_times >= tr.time][:2]
    assert np.max(np.abs(before[:2] - upcoming)) < 0.03
    silence = np.zeros(6 * SR, np.float32)
    conf = _feed(tr, silence)
    assert conf[-1] < 0.4  # unsure, and still predicting
    pred = tr.predict(4)
    assert pred.size == 4 and pred[0] >= tr.time
    nearest = before[np.argmin(np.abs(before[:, None] - pred[None, :]), axis=0)]
    np.testing.assert_allclose(pred, nearest, atol=0.01)  # (5.2 ms apart after 6 s: the beats heard last moved it)


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
    res = track_and_evaluate(clipped, r.beat_times, "causal", 512, sample_rate=SR, end=music_end(r))
    assert res["f_measure"] >= 0.9
    base = IOIBaselineTracker(SR)
    _feed(base, x, block=1000)


def _clicks(bpm: float, seconds: float) -> np.ndarray:
    times = np.arange(0.5, seconds - 0.5, 60.0 / bpm)
    events = [e for t in times for e in (SynthEvent(t, "note_on", 9, 75, 100), SynthEvent(t + 0.1, "note_off", 9, 75))]
    return render_events(events, seconds, SR)


def test_a_pulse_slower_than_the_range_is_committed_at_twice_its_tempo_unsure():
    x = _clicks(40, 20.0)
    tr = CausalBeatTracker(SR, min_bpm=60, max_bpm=200)
    conf = _feed(tr, x)
    assert conf[int(6 * SR / 512) :].max() < 0.4  # the grid misses every other beat
    run = track_file(x, "causal", 512, sample_rate=SR)
    committed = committed_beats(run["updates"], 0.2, 20.0)
    clicks = np.arange(0.5, 19.5, 1.5)
    res = score_beats(clicks, committed)
    # every click committed, and a beat between each two: precision 1/2, recall 1
    assert res["f_measure"] == pytest.approx(2 / 3) and res["mae_ms"] < 5.0
    np.testing.assert_allclose(np.diff(committed[committed > 5.0]), 0.75, atol=0.01)


@pytest.mark.parametrize("tracker, every", [("causal", 2), ("causal-comb", 3)])
def test_a_pulse_faster_than_the_range_is_committed_at_a_level_within_it(tracker, every):
    """The fast-pulse flag is off: 260 BPM clicks are followed confidently, and never left silent, every
    other click (130 BPM) by the joint tempo-phase filter, every third (86.7 BPM) by the comb tracker."""
    x = _clicks(260, 20.0)
    tr = make_tracker(tracker, SR, min_bpm=60, max_bpm=200)
    conf = _feed(tr, x)
    assert conf[-1] > 0.8 and tr.tempo_bpm == pytest.approx(260 / every, rel=0.01)
    run = track_file(x, tracker, 512, sample_rate=SR)
    committed = committed_beats(run["updates"], 0.2, 20.0)
    clicks = np.arange(0.5, 19.5, 60 / 260)
    late = committed[(committed > 5.0) & (committed < 19.5)]  # (the clicks end at 19.5 s; the grid goes on)
    assert late.size > 15 and np.max(np.min(np.abs(late[:, None] - clicks[None, :]), axis=1)) < 0.01  # on clicks
    np.testing.assert_allclose(np.diff(late), every * 60 / 260, atol=0.01)
    # with the flag on, the tracker stays silent
    flagged = track_file(x, tracker, 512, sample_rate=SR, tracker_options={"fast_pulse_check": True})
    assert committed_beats(flagged["updates"], 0.2, 20.0).size == 0


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
