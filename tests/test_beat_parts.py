"""Tests of the beat tracker's parts on hand-made onset envelopes: tempo, phase, onset timing, follower."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from anticipators.beats.dbn import BeatPointerFilter
from anticipators.beats.envelope import ArrayEnvelope, SpectralFluxEnvelope
from anticipators.beats.follower import BeatFollower
from anticipators.beats.onsets import OnsetPicker, waveform_onset
from anticipators.beats.phase import COMB_DECAY, comb_phase, comb_score
from anticipators.beats.tempo import TempoEstimator, estimate_tempo
from anticipators.beats.tracking import CausalBeatTracker, make_tracker

FPS = 100.0  # frames per second of the hand-made envelopes


def impulses(n_frames: int, every: int, first: int = 0) -> np.ndarray:
    """Onset strength 1 at frames ``first, first + every, ...`` and 0 elsewhere."""
    o = np.zeros(n_frames)
    o[first::every] = 1.0
    return o


def at_frames(n_frames: int, frames) -> np.ndarray:
    o = np.zeros(n_frames)
    o[np.asarray(frames)] = 1.0
    return o


# ------------------------------------------------------------------------------------------- tempo


@pytest.mark.parametrize("every", [40, 50, 64, 75])
def test_tempo_of_impulses_is_their_spacing(every):
    # 6 s of impulses every `every` frames: within half an octave of the 120 BPM preference, so the
    # preference does not move the estimate to another metrical level
    est = estimate_tempo(impulses(600, every, first=7), FPS)
    # the candidates are half a frame apart: the best one is the spacing itself
    assert abs(est.lag - every) < 0.25
    assert est.period == pytest.approx(every / FPS, abs=0.25 / FPS)
    assert est.bpm == pytest.approx(60.0 * FPS / every, rel=0.25 / every)
    assert not est.fast_pulse
    assert est.periodicity_at(every) >= 0.99  # an impulse train is perfectly periodic
    # half the spacing falls between the impulses: a poor candidate
    assert est.score_at(every / 2) < 0.5 * est.score


def test_tempo_preference_chooses_the_metrical_level():
    o = impulses(600, 30, first=7)  # 200 BPM, also a pulse at 100 BPM
    assert abs(estimate_tempo(o, FPS).lag - 60) < 0.25  # 100 BPM lies nearer 120 BPM than 200 does
    assert abs(estimate_tempo(o, FPS, prior_bpm=200).lag - 30) < 0.25
    # the frame rate is explicit: the same frames at 200 frames per second are twice as fast
    fast = estimate_tempo(o, 2 * FPS, min_bpm=120, max_bpm=450, prior_bpm=400)
    assert fast.bpm == pytest.approx(400.0, rel=0.25 / 30)


def test_pulse_faster_than_the_range_is_flagged():
    assert estimate_tempo(impulses(600, 20), FPS, max_bpm=200).fast_pulse  # 300 BPM
    assert not estimate_tempo(impulses(600, 20), FPS, max_bpm=320).fast_pulse


def test_no_tempo_without_enough_periodic_onset_strength():
    estimator = TempoEstimator(FPS)
    assert estimator.estimate(np.zeros(600)) is None  # silence
    assert estimator.estimate(np.ones(600)) is None  # constant
    short = int(estimator.min_frames()) - 1
    assert estimator.estimate(impulses(short, 50)) is None
    assert estimator.estimate(impulses(short + 2, 50)) is not None


# ------------------------------------------------------------------------------------------- phase


@pytest.mark.parametrize("every, first", [(50, 23), (47, 5), (64, 0)])
def test_comb_finds_the_latest_impulse(every, first):
    o = impulses(400, every, first)
    latest = first + (o.size - 1 - first) // every * every
    phase = comb_phase(o, every)
    assert phase.frame == latest
    # every tooth of the comb sits on an impulse
    n_teeth = int((o.size - 1) / every)
    assert phase.score == pytest.approx(np.sum(COMB_DECAY ** np.arange(n_teeth)))
    assert phase.mean_score < phase.score / 10
    # absolute frame indices: the same values starting at frame 1000
    assert comb_phase(o, every, start=1000).frame == 1000 + latest
    # the grid through any impulse scores the same; half a period off scores nothing
    assert comb_score(o, every, first) == pytest.approx(phase.score)
    assert comb_score(o, every, first + every / 2) == 0.0


# ----------------------------------------------------------------------------------- onset timing


@pytest.mark.parametrize("rise", [300, 517, 800])
def test_waveform_onset_is_the_first_sample_of_the_rise(rise):
    sr, first = 22050, 1000
    rng = np.random.default_rng(rise)
    x = (1e-4 * rng.standard_normal(1600)).astype(np.float32)  # a quiet floor
    n = np.arange(x.size - rise)
    # a decaying tone that starts at its crest, with a noisy attack
    x[rise:] += (0.5 * np.cos(2 * np.pi * 440 * n / sr) * np.exp(-n / 2000)
                 + 0.1 * rng.standard_normal(n.size) * np.exp(-n / 300)).astype(np.float32)
    assert waveform_onset(x, sr, first) == (first + rise) / sr
    step = np.zeros(1600, np.float32)
    step[rise:] = 0.5
    assert waveform_onset(step, sr, first) == (first + rise) / sr
    assert np.isnan(waveform_onset(np.zeros(1600, np.float32), sr))  # no rise


def test_onset_picker_times_salient_peaks_between_frames():
    o = np.zeros(300)
    o[[99, 100, 101]] = [0.5, 1.0, 0.5]  # symmetric: the peak is frame 100
    o[[199, 200, 201]] = [0.0, 1.0, 1.0]  # the parabola puts the peak half a frame later
    envelope = ArrayEnvelope(o, FPS)
    envelope.push(np.zeros(300 * envelope.hop))
    picker = OnsetPicker(envelope, peak_bias=0.002)
    t, on_waveform, strength = picker.pick(1.04, 0.1)
    assert t == pytest.approx(1.0 - 0.002) and not on_waveform and strength == 1.0
    assert picker.pick(2.0, 0.1)[0] == pytest.approx(2.005 - 0.002)
    assert picker.pick(1.5, 0.1) is None  # nothing there
    picker.recent_mean = 0.5  # a peak must exceed twice the recent mean
    assert picker.pick(1.0, 0.1) is None


# -------------------------------------------------------------------------------------- envelopes


def test_array_envelope_reveals_frames_as_time_passes():
    envelope = ArrayEnvelope(np.arange(10.0), FPS, sample_rate=8000)
    assert envelope.hop == 80 and envelope.fps == FPS
    envelope.push(np.zeros(3 * 80 + 10))
    assert envelope.n_frames == 4  # frames at 0, 10, 20 and 30 ms have been heard by 31.25 ms
    np.testing.assert_array_equal(envelope.values(0, 100), [0.0, 1.0, 2.0, 3.0])
    assert envelope.frame_time(3) == pytest.approx(0.03) and envelope.frame_index(0.03) == pytest.approx(3)
    envelope.push(np.zeros(8000))
    assert envelope.n_frames == 10  # none beyond the array
    assert envelope.audio(0.0, 0.01) is None
    with pytest.raises(ValueError):
        ArrayEnvelope(np.zeros(10), 300.0, sample_rate=8000)  # 26.7 samples a frame


# --------------------------------------------------------------------------------------- follower

# Tolerance of the predicted beats: 1 ms, a tenth of a frame. The hand-made onsets are single-frame
# impulses, which the peak interpolation times exactly (the neighbours are equal), so every
# observation is exact and what remains is the filter's residual period error, which is microseconds
# after a dozen noise-free beats. A follower one frame off (10 ms), or one that did not subtract
# the peak bias (3 ms in the tracker), fails.
TOL = 0.001


def test_follower_converges_on_hand_made_onsets():
    truth = np.arange(23, 1500, 50) / FPS  # 120 BPM from 0.23 s
    envelope = ArrayEnvelope(at_frames(1500, np.arange(23, 1500, 50)), FPS)
    picker = OnsetPicker(envelope)
    follower = BeatFollower(picker.pick, ready_delay=2.0 / FPS + 0.002)
    assert follower.predict(0.0).size == 0 and not follower.locked
    follower.restart(0.23, 0.49, periodicity=1.0)  # the right beat, a period 2 % short
    for _ in range(1200):  # 12 s
        envelope.push(np.zeros(envelope.hop))
        follower.advance(envelope.n_samples / envelope.sample_rate)
    now = envelope.n_samples / envelope.sample_rate
    # every impulse since the restart was accepted, at its exact time
    np.testing.assert_allclose(follower.beats_observed, truth[(truth > 0.23) & (truth < now - 0.1)], atol=1e-9)
    assert follower.state[1] == pytest.approx(0.5, abs=1e-4)
    assert follower.hit_rate > 0.99 and follower.confidence == 1.0
    pred = follower.predict(now, 4)
    np.testing.assert_allclose(pred, truth[truth >= now][:4], atol=TOL)


def _track_envelope(o: np.ndarray, seconds: float, block: int = 400) -> tuple[CausalBeatTracker, list]:
    envelope = ArrayEnvelope(o, FPS)
    tracker = CausalBeatTracker(envelope.sample_rate, envelope=envelope)
    log = []
    for _ in range(int(seconds * envelope.sample_rate) // block):
        tracker.process(np.zeros(block))
        log.append((tracker.time, tracker.predict(3)))
    return tracker, log


def test_tracker_on_a_hand_made_envelope_predicts_the_impulses():
    frames = np.arange(23, 1500, 50)
    tracker, _ = _track_envelope(at_frames(1500, frames), 12.0)
    assert tracker.locked and tracker.confidence > 0.8
    assert tracker.tempo_bpm == pytest.approx(120.0, abs=0.01)
    # without a waveform onsets are envelope peaks, ODF_BIAS early
    expected = frames / FPS - CausalBeatTracker.ODF_BIAS
    np.testing.assert_allclose(tracker.beats_observed[-5:], expected[expected < tracker.time][-5:], atol=1e-9)
    np.testing.assert_allclose(tracker.predict(6), expected[expected >= tracker.time][:6], atol=TOL)


@pytest.mark.parametrize(
    "change, frames",
    [
        ("tempo 120 -> 150 BPM", np.concatenate([np.arange(23, 1024, 50), 1023 + np.arange(1, 35) * 40])),
        ("phase +80 ms", np.concatenate([np.arange(23, 1024, 50), 1031 + np.arange(1, 30) * 50])),
    ],
)
def test_tracker_follows_a_sudden_change_within_two_beats(change, frames):
    tracker, log = _track_envelope(at_frames(2500, frames), 16.0)
    expected = frames / FPS - CausalBeatTracker.ODF_BIAS
    first_new = expected[expected > 10.3][0]  # first beat after the change
    # from the second beat after the change on (it confirms the new grid), predictions are right
    for t, pred in log:
        if t > first_new + 2 * 0.5:
            np.testing.assert_allclose(pred, expected[expected >= t][:3], atol=TOL, err_msg=f"{change} at {t:.2f} s")
    assert tracker.confidence > 0.8


def test_tracker_checks_and_uses_its_envelope_source():
    with pytest.raises(ValueError):
        CausalBeatTracker(22050, envelope=ArrayEnvelope(np.zeros(10), FPS, sample_rate=8000))
    # an explicit default front end is the default
    rng = np.random.default_rng(3)
    sr = 22050
    clicks = np.zeros(12 * sr, np.float32)
    for t in np.arange(0.3, 11.5, 0.55):
        i = int(t * sr)
        clicks[i : i + 200] += (0.5 * rng.standard_normal(200) * np.exp(-np.arange(200) / 40)).astype(np.float32)
    a = CausalBeatTracker(sr)
    b = CausalBeatTracker(sr, envelope=SpectralFluxEnvelope(sr, keep_seconds=12.0))
    for start in range(0, clicks.size, 512):
        a.process(clicks[start : start + 512])
        b.process(clicks[start : start + 512])
        np.testing.assert_array_equal(a.predict(4), b.predict(4))
    assert a.locked and a.tempo_bpm == pytest.approx(60 / 0.55, rel=0.01)


# ------------------------------------------------------------------------------------------ layout

BEATS = Path(__file__).resolve().parent.parent / "anticipators" / "beats"
assert sorted(BEATS.glob("*.py")), f"no beat-tracking modules in {BEATS}"


@pytest.mark.parametrize("path", sorted(BEATS.glob("*.py")), ids=lambda p: p.name)
def test_beats_modules_use_only_the_core_and_each_others_public_names(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(("agentsim", "anticipators")):
            assert node.module.startswith(("agentsim.core", "agentsim.errors", "anticipators.beats")), node.module
            assert not any(a.name.startswith("_") for a in node.names), f"private import from {node.module}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith(("agentsim", "anticipators")):
                    assert alias.name.startswith(("agentsim.core", "agentsim.errors", "anticipators.beats")), alias.name
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            # private attributes only of the object itself
            assert isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"), (
                f"{path.name}:{node.lineno} reads {node.attr} of another object"
            )


def test_mel_filters_are_librosas():
    """The onset envelope's mel filters are librosa's, number for number (made without importing it)."""
    import math

    import librosa

    from anticipators.beats.envelope import mel_filters

    for sr in (8000, 22050, 44100, 48000):
        n_fft = int(2 ** round(math.log2(0.03 * sr)))
        expected = librosa.filters.mel(sr=sr, n_fft=n_fft, n_mels=40, fmin=30.0, fmax=min(16000.0, sr / 2))
        got = mel_filters(sr, n_fft, 40, 30.0, min(16000.0, sr / 2))
        assert got.dtype == expected.dtype and np.array_equal(got, expected)


def test_beat_f_measure_is_mir_evals():
    """The F-measure of the beat scores is mir_eval's, number for number, on beats near, far and on the edge
    of the window."""
    import warnings

    import mir_eval

    from anticipators.beats.evaluation import beat_f_measure

    rng = np.random.default_rng(0)
    for trial in range(600):
        nr, ne = rng.integers(0, 30, 2)
        ref = np.sort(np.cumsum(rng.uniform(0.3, 0.9, nr)))
        if trial % 3 == 0:
            est = np.sort(ref[:ne] + rng.normal(0, 0.06, min(ne, nr)))
        elif trial % 3 == 1:
            est = np.sort(rng.uniform(0, 20, ne))
        else:
            est = np.sort(np.concatenate([ref + rng.normal(0, 0.04, nr), rng.uniform(0, 20, ne // 3)]))
        if trial % 5 == 0:
            ref, est = np.round(ref, 2), np.round(est, 2)  # beats exactly on the window's edge
        est = est[est >= 0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            expected = mir_eval.beat.f_measure(ref, est, 0.07)
        assert beat_f_measure(ref, est, 0.07) == expected


# ------------------------------------------------------------------------------------------ joint tempo-phase filter


def _click_activation(frames: np.ndarray, n: int) -> np.ndarray:
    """A beat activation of 0.9, 0.6 and 0.3 from each of ``frames`` on (an onset's flux spreads over a few
    frames) and 0.01 elsewhere."""
    a = np.full(n, 0.01)
    for k, v in enumerate((0.9, 0.6, 0.3)):
        a[frames + k] = v
    return a


def test_beat_pointer_filter_locks_to_a_click_train_by_its_second_click():
    """100 BPM clicks at 100 frames per second: from the second click on, the most probable state is an
    interval of 60 frames, 4 frames after the click (the latest frame heard)."""
    f = BeatPointerFilter(100.0, 60, 200, n_tempi=None)
    clicks = np.arange(10, 1500, 60)
    a = _click_activation(clicks, 1500)
    for k, b in enumerate(clicks):
        f.step(a[f.n_frames : b + 5])
        assert f.p.sum() == pytest.approx(1.0)
        if k >= 1:
            assert f.best(marginal=True) == (60.0, 4.0), k
        if k >= 2:  # the most probable single state a click later
            assert f.best() == (60.0, 4.0), k


def test_beat_pointer_filter_relocks_a_tempo_step_by_the_second_new_beat():
    """100 BPM clicks, then 125 BPM from frame 1018: at the second click of the new tempo and after it, the
    most probable interval is 48 frames and the phase that of the clicks."""
    f = BeatPointerFilter(100.0, 60, 200, n_tempi=None)
    clicks = np.concatenate([np.arange(10, 1000, 60), 970 + np.arange(1, 20) * 48])
    a = _click_activation(clicks, 2000)
    new = np.flatnonzero(clicks > 1000)
    for k, b in enumerate(clicks):
        f.step(a[f.n_frames : b + 5])
        if k >= new[1]:
            assert f.best(marginal=True) == (48.0, 4.0), k
        elif 1 <= k < new[0]:
            assert f.best(marginal=True) == (60.0, 4.0), k


def test_default_tracker_is_the_joint_filter_and_the_comb_tracker_stays_available():
    a = make_tracker("causal", 22050)
    b = make_tracker("causal-comb", 22050)
    assert a.sync == "dbn" and a.dbn is not None
    assert b.sync == "comb" and b.dbn is None
    with pytest.raises(ValueError):
        CausalBeatTracker(22050, sync="other")


def _log_mel(env: SpectralFluxEnvelope, x: np.ndarray) -> np.ndarray:
    """The envelope's log-mel frames of ``x``, computed here frame by frame."""
    n = (x.size - env.n_fft) // env.hop + 1
    frames = np.stack([x[i * env.hop : i * env.hop + env.n_fft] for i in range(n)])
    spec = np.abs(np.fft.rfft(frames * env.window, axis=1)).astype(np.float32)
    return np.log1p(100.0 * (spec @ env.mel_t))


def test_joint_filter_observes_the_flux_mixed_with_the_increase_over_four_frames():
    rng = np.random.default_rng(7)
    sr = 22050
    t = np.arange(3 * sr) / sr
    # a tone swelling over 80 ms every 0.5 s, over quiet noise: an onset that rises over several frames
    swell = np.clip((t % 0.5) / 0.08, 0.0, 1.0) * np.exp(-(t % 0.5) * 4.0)
    x = (0.5 * swell * np.sin(2 * np.pi * 440.0 * t) + 0.01 * rng.standard_normal(t.size)).astype(np.float32)
    env = SpectralFluxEnvelope(sr, far_lag=4, far_weight=0.3, keep_seconds=1.0)
    for a in range(0, x.size, 1000):  # blocks that do not line up with frames; history shifted (1 s kept)
        env.push(x[a : a + 1000])
    s = _log_mel(env, x)
    prev = np.vstack([s[:1], s[:-1]])
    far = np.vstack([np.repeat(s[:1], 4, axis=0), s[:-4]])
    flux = np.maximum(s - prev, 0).sum(axis=1)
    expected = (flux + 0.3 * np.maximum(s - far, 0).sum(axis=1)) / 1.3
    start = env.first_kept
    assert start > 0 and env.n_frames == s.shape[0]
    np.testing.assert_allclose(env.values(start, env.n_frames), flux[start:], rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(env.observation_values(start, env.n_frames), expected[start:], rtol=1e-4, atol=1e-4)
    # the swell's onset counts more in the observation than in the flux: its increase spans frames
    rising = np.rint(env.frame_index(np.arange(0.5, 3.0, 0.5)[:, None] + np.arange(0.03, 0.075, 0.01))).astype(int)
    assert np.all(expected[rising] > flux[rising]) and np.mean(expected[rising] / flux[rising]) > 1.2
    # without far_lag the observation is the onset strength
    plain = SpectralFluxEnvelope(sr)
    plain.push(x)
    assert plain.observation_values(0, plain.n_frames) is not None
    np.testing.assert_array_equal(plain.observation_values(0, plain.n_frames), plain.values(0, plain.n_frames))
    with pytest.raises(ValueError):
        SpectralFluxEnvelope(sr, far_lag=-1)


def test_default_tracker_observes_the_four_frame_flux_and_the_comb_tracker_does_not():
    assert CausalBeatTracker(22050).envelope.far_lag == 4
    assert make_tracker("causal-comb", 22050).envelope.far_lag == 0
    assert CausalBeatTracker(22050, far_lag=0).envelope.far_lag == 0


# -------------------------------------------------------------------------------------- grid arbitration


class _Estimate:
    """A tempo estimate of one period (``lag`` frames) as periodic as ``periodicity`` everywhere."""

    def __init__(self, lag: float, periodicity: float = 0.9):
        self.lag, self.score, self._periodicity = lag, 1.0, periodicity

    def periodicity_at(self, lag: float) -> float:
        return self._periodicity

    def score_at(self, lag: float) -> float:
        return 1.0 if abs(lag - self.lag) < 0.5 else 0.1


def _heard(envelope: ArrayEnvelope, frames: int) -> float:
    envelope.push(np.zeros(frames * envelope.hop))
    return envelope.n_samples / envelope.sample_rate


def test_comb_resync_sets_the_first_grid_on_the_latest_beat_old_enough_to_time():
    from anticipators.beats.arbitration import CombResync

    envelope = ArrayEnvelope(impulses(1000, 50, first=23), FPS)  # 120 BPM from 0.23 s
    follower = BeatFollower(OnsetPicker(envelope).pick)
    follower.periodicity = 0.9
    grid = CombResync(envelope, follower, OnsetPicker(envelope), lambda: _Estimate(50.0), init_frames=300)
    grid.sync(_heard(envelope, 250))
    assert not follower.locked  # before init_frames
    now = _heard(envelope, 152)  # 4.02 s: the beat at 3.73 s is the latest heard at least 60 ms ago
    grid.sync(now)
    assert follower.locked
    assert follower.state[0] == pytest.approx(3.73, abs=1e-9) and follower.state[1] == pytest.approx(0.5)


def test_comb_resync_restarts_a_grid_whose_phase_the_comb_keeps_refusing():
    from anticipators.beats.arbitration import CombResync

    envelope = ArrayEnvelope(impulses(1200, 50, first=23), FPS)
    follower = BeatFollower(OnsetPicker(envelope).pick)
    grid = CombResync(envelope, follower, OnsetPicker(envelope), lambda: _Estimate(50.0), init_frames=0)
    now = _heard(envelope, 500)
    follower.restart(4.48, 0.5, periodicity=0.9)  # the right tempo, half a beat off the clicks
    for k in range(3):  # three estimates that refuse the phase: the grid stays
        grid.sync(now)
        assert follower.state[0] == pytest.approx(4.48), k
    grid.sync(now)  # the fourth restarts it on the clicks, keeping the period
    assert follower.state[0] == pytest.approx(4.73, abs=1e-9) and follower.state[1] == pytest.approx(0.5)


def test_joint_filter_grid_restarts_the_follower_on_the_filters_tempo_and_phase():
    from anticipators.beats.arbitration import JointFilterGrid

    envelope = ArrayEnvelope(impulses(1000, 48, first=10), FPS)  # 125 BPM from 0.1 s
    follower = BeatFollower(OnsetPicker(envelope).pick)
    grid = JointFilterGrid(envelope, follower, OnsetPicker(envelope), lambda: None, min_bpm=60.0, max_bpm=200.0,
                           odf_bias=0.0, init_frames=100)
    now = 0.0
    for _ in range(30):  # 3 s, stepped as the tracker steps it
        now = _heard(envelope, 10)
        grid.hear()
    assert grid.dbn.n_frames == envelope.n_frames  # every frame heard is stepped
    t_dbn, period = grid.beat()
    assert period == pytest.approx(0.48) and t_dbn == pytest.approx(2.98, abs=1e-9)  # the latest click
    grid.sync(now)
    assert grid.active and follower.locked
    assert follower.state[0] == pytest.approx(2.50, abs=1e-9) and follower.state[1] == pytest.approx(0.48)
    assert not grid.wins()  # the follower now agrees with the filter: its grid is predicted
    np.testing.assert_allclose(grid.predict(now, 3), follower.predict(now, 3))
