"""The virtual conductor scenario: the musician model on hand-made numbers, the conductor's model of the
ensemble, the closed loop (headline result, determinism, output files, "play louder" and stopping), bad
configurations and live input through a PulseAudio null sink."""

from __future__ import annotations

import argparse
import io
import json
import math
import time
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
import soundfile

from agentsim.errors import AgentsimError
from agentsim.cli import build_parser
from scenarios.conductor import run as conductor_cli
from scenarios.conductor.config import ModelParams, config_from_dict, load_config, parse_meter
from scenarios.conductor.ensemble import Timekeeper
from scenarios.conductor.metrics import beats_to_recover, local_tempo
from scenarios.conductor.planning import ResponseEstimator
from scenarios.conductor.scenario import TIMELINE_WINDOW, collect_metrics, simulate

QUIET = dict(timekeeper_sd=0.0, motor_sd=0.0, ictus_sd=0.0, drag=0.0)


def args(**kw) -> argparse.Namespace:
    ns = build_parser().parse_args(["run", "conductor"])
    for k, v in kw.items():
        setattr(ns, k, v)
    return ns


# ------------------------------------------------------------------------------------- the musician model
def test_phase_correction_converges_at_its_rate():
    """Conductor and timekeeper share the period: the asynchrony shrinks by (1 - alpha) every beat."""
    alpha, period, a0 = 0.25, 0.5, 0.06
    keeper = Timekeeper(ModelParams(alpha_conductor=alpha, beta_conductor=0.0, **QUIET), period, period, a0)
    asynchronies = []
    for n in range(12):
        ictus = n * period
        asynchronies.append(keeper.onsets[-1] - ictus)
        keeper.next_onset(ictus=ictus)
    expected = a0 * (1 - alpha) ** np.arange(12)
    assert np.allclose(asynchronies, expected, atol=1e-12)
    assert keeper.period == period  # no period correction


def test_period_correction_adopts_the_conductors_period():
    """Period correction: T(n+1) = T(n) - beta A(n); the timekeeper ends up at the conductor's period, in phase."""
    alpha, beta, t0, p = 0.25, 0.1, 0.55, 0.5
    keeper = Timekeeper(ModelParams(alpha_conductor=alpha, beta_conductor=beta, **QUIET), t0, t0, 0.0)
    keeper.next_onset(ictus=-0.02)  # 20 ms late: the next onset comes earlier and the period shrinks
    assert keeper.onsets[1] == pytest.approx(0.0 + t0 - alpha * 0.02)
    assert keeper.period == pytest.approx(t0 - beta * 0.02)
    for n in range(1, 200):
        keeper.next_onset(ictus=n * p)
    assert keeper.period == pytest.approx(p, abs=1e-7)
    assert keeper.onsets[-1] - 200 * p == pytest.approx(0.0, abs=1e-6)  # no asynchrony left


def test_two_partners_close_their_gap_at_rate_one_minus_two_alpha():
    alpha = 0.15
    params = ModelParams(alpha_partner=alpha, **QUIET)
    a, b = Timekeeper(params, 0.5, 0.5, 0.0), Timekeeper(params, 0.5, 0.5, 0.04)
    gaps = []
    for _ in range(8):
        gaps.append(b.onsets[-1] - a.onsets[-1])
        ta, tb = a.onsets[-1], b.onsets[-1]
        a.next_onset(partners=[tb])
        b.next_onset(partners=[ta])
    assert np.allclose(gaps, 0.04 * (1 - 2 * alpha) ** np.arange(8), atol=1e-12)


def test_drag_pulls_the_period_back_to_the_comfortable_one():
    drag, t0, tc = 0.05, 0.5, 0.5556
    keeper = Timekeeper(ModelParams(**{**QUIET, "drag": drag}), t0, tc, 0.0)
    for _ in range(10):
        keeper.next_onset()
    assert keeper.period - tc == pytest.approx((t0 - tc) * (1 - drag) ** 10, abs=1e-12)


def test_an_ictus_half_a_beat_away_is_not_followed():
    keeper = Timekeeper(ModelParams(**QUIET), 0.5, 0.5, 0.0)
    keeper.next_onset(ictus=0.3)
    assert keeper.onsets[1] == pytest.approx(0.5) and keeper.period == 0.5


def test_noise_has_the_configured_spread():
    rng = np.random.default_rng(4)
    n = 4000
    params = ModelParams(timekeeper_sd=0.012, motor_sd=0.005, drag=0.0)
    keeper = Timekeeper(params, 0.5, 0.5, 0.0, rng.standard_normal(n + 1), rng.standard_normal(n + 1))
    for _ in range(n):
        keeper.next_onset()
    intervals = np.diff(keeper.onsets)
    # Wing-Kristofferson: var(I) = sd_T^2 + 2 sd_M^2, lag-one autocovariance -sd_M^2
    assert np.var(intervals) == pytest.approx(0.012 ** 2 + 2 * 0.005 ** 2, rel=0.1)
    cov = np.mean((intervals[1:] - intervals.mean()) * (intervals[:-1] - intervals.mean()))
    assert cov == pytest.approx(-0.005 ** 2, rel=0.35)


def test_the_conductors_estimator_finds_the_ensembles_gains():
    """Aggregate ensemble with a = 0.3, g = 0.08, conducted by a wandering ictus: the estimate comes close."""
    rng = np.random.default_rng(2)
    a, g, e, t = 0.3, 0.08, 0.0, 0.55
    est = ResponseEstimator()
    est.start(0, e, t)
    for n in range(60):
        c = e - 0.05 + 0.04 * np.sin(n / 3.0)
        e, t = e + t - a * (e - c) + rng.normal(0, 0.004), t - g * (e - c)
        est.advance(c)
        est.update(e + rng.normal(0, 0.003))
    found = est.estimate()
    assert found["a"] == pytest.approx(a, abs=0.07) and found["g"] == pytest.approx(g, abs=0.04)


def test_tempo_and_recovery_on_hand_made_beats():
    beats = np.cumsum(np.r_[0.0, np.full(10, 0.6), np.full(30, 0.5)])
    tempo = local_tempo(beats)
    assert np.isnan(tempo[:4]).all() and tempo[20] == pytest.approx(120.0)
    target = np.full(beats.size, 120.0)
    k = beats_to_recover(tempo, target, 2)
    assert tempo[2 + k] == pytest.approx(120.0, rel=0.02) and abs(tempo[2 + k - 1] / 120 - 1) > 0.02
    assert beats_to_recover(np.full(20, 110.0), np.full(20, 120.0), 0) is None


# ------------------------------------------------------------------------------------- the closed loop
@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """The default scenario (best strategy, seed 1) through main(), with every output file."""
    out = tmp_path_factory.mktemp("conductor") / "out"
    started = time.perf_counter()
    printed, table = io.StringIO(), io.StringIO()
    with redirect_stdout(printed), redirect_stderr(table):
        assert conductor_cli.main(args(seed=1, out=str(out), json=True)) == 0
    DEFAULT_RUN_PRINTED.update(stdout=printed.getvalue(), stderr=table.getvalue())
    return out, json.loads((out / "metrics.json").read_text()), time.perf_counter() - started


#: What the default run printed (with --json).
DEFAULT_RUN_PRINTED: dict = {}


def test_json_prints_the_metrics_written_and_the_table_goes_to_stderr(default_run):
    out, metrics, _ = default_run
    assert json.loads(DEFAULT_RUN_PRINTED["stdout"]) == metrics  # stdout is the JSON alone
    assert DEFAULT_RUN_PRINTED["stdout"].count("\n") == 1
    assert "recovered" in DEFAULT_RUN_PRINTED["stderr"] and f"written to {out}" in DEFAULT_RUN_PRINTED["stderr"]


def test_outputs_are_written_and_valid(default_run):
    out, metrics, seconds = default_run
    for key in ("target_bpm", "start_bpm", "strategy", "beats_to_recover", "final_tempo_error_pct",
                "ensemble_asynchrony_ms", "anticipator"):
        assert key in metrics
    assert metrics["strategy"] == "best" and metrics["target_bpm"] == 120 and metrics["start_bpm"] == 108
    assert set(metrics["ensemble_asynchrony_ms"]) >= {"mean", "sd"}
    assert metrics["anticipator"]["f_measure"] >= 0.9 and metrics["anticipator"]["mae_ms"] < 40
    audio, sr = soundfile.read(out / "ensemble.wav")
    assert sr == 22050 and audio.shape[0] / sr > 40 and np.abs(audio).max() > 0.01
    bvh = (out / "conductor.bvh").read_text()
    assert bvh.startswith("HIERARCHY") and "MOTION" in bvh and "Frame Time:" in bvh
    frames = int(bvh.split("Frames:")[1].split()[0])
    assert frames > 30 * 40
    feedback = [json.loads(line) for line in (out / "feedback.jsonl").read_text().splitlines()]
    strokes = [f for f in feedback if f["type"] == "syncPointProgress" and f["id"].endswith(":stroke")
               and ":b" in f["id"]]
    assert len(strokes) == metrics["beats_conducted"] > 60
    assert not [f for f in feedback if f["type"] == "warningFeedback"]
    for png in ("tempo.png", "timeline.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # timeline.png is the overview; each TIMELINE_WINDOW seconds of the run has its own picture
    windows = sorted(p.name for p in out.glob("timeline_*s.png"))
    assert len(windows) == math.ceil(metrics["simulated_seconds"] / TIMELINE_WINDOW) and len(windows) > 1
    assert windows[0] == f"timeline_0000-{TIMELINE_WINDOW:04.0f}s.png"
    assert seconds < 60


def test_best_recovers_faster_than_target_and_follow(default_run):
    """Headline: from 108 BPM toward 120 BPM, best is within 2 % in fewer beats, asynchrony sd <= 40 ms."""
    _, best, _ = default_run
    config = load_config()
    others = {name: collect_metrics(simulate(config, name, 1)) for name in ("target", "follow")}
    assert best["beats_to_recover"] is not None
    assert best["ensemble_asynchrony_ms"]["sd"] <= 40.0
    assert abs(best["final_tempo_error_pct"]) < 2.0
    for name, m in others.items():
        assert m["beats_to_recover"] is None or best["beats_to_recover"] < m["beats_to_recover"], name
    assert others["follow"]["beats_to_recover"] is None  # following a dragging ensemble never gets there


def test_same_seed_same_metrics(default_run):
    out, _, _ = default_run
    again = collect_metrics(simulate(load_config(), "best", 1))
    written = json.loads((out / "metrics.json").read_text())
    assert written.pop("time_axis").startswith("simulated time")
    assert written.pop("glossary") == "README.md#glossary"
    assert json.dumps(again, indent=2) == json.dumps(written, indent=2)


def test_too_soft_ensemble_gets_a_play_louder_gesture(default_run):
    out, metrics, _ = default_run
    assert metrics["louder_gestures"]
    levels = metrics["bar_levels_db"]
    first, last = levels[0], levels[-1]
    assert first["heard_db"] < first["expected_db"] - 3.0  # 6 dB too soft at first
    assert last["heard_db"] > last["expected_db"] - 3.0  # as marked after the gestures
    feedback = (out / "feedback.jsonl").read_text()
    assert '"louder1:louder1:stroke"' in feedback


def test_an_ensemble_that_falls_apart_is_stopped(tmp_path):
    from helpers import FALLS_APART

    config = config_from_dict(FALLS_APART)
    run = simulate(config, "best", 1)
    metrics = collect_metrics(run)
    assert metrics["stopped"] and metrics["ensemble_stopped_at_beat"] is not None
    stop = [f for f in run.realizer.feedback.items if f["id"] == "stop:stop:stroke"]
    assert stop and stop[0]["globalTime"] > metrics["stopped_at_s"]
    assert metrics["beats_conducted"] < config.piece.n_beats - 4


# ------------------------------------------------------------------------------------- bad configurations
@pytest.mark.parametrize("text, message", [
    ('[[ensemble.musicians]]\ninstrument = "kazoo"\n', "unknown instrument 'kazoo'"),
    ('piece = {meter = "4/3"}\n', "meter '4/3' is impossible"),
    ('piece = {meter = "5/4"}\n', "no conducting pattern"),
    ('piece = {tempo = 0}\n', "tempo must be > 0"),
    ('piece = {tempo = -60}\n', "tempo must be > 0"),
    ('[ensemble]\nstart_bpm = 0\n', "start_bpm must be > 0"),
    ('piece = {tempo_changes = [{bar = 2, bpm = -1}]}\n', "bpm must be > 0"),
    ('[conductor]\nstrategy = "wave"\n', "unknown strategy 'wave'"),
    ('[ensemble]\nvisual_dealy = 0.1\n', "unknown key(s) visual_dealy"),
    ('piece = "no_such_piece"\n', "no piece 'no_such_piece'"),
])
def test_bad_configs_fail_with_one_clear_message_before_running(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    with pytest.raises(AgentsimError) as info:
        conductor_cli.main(args(config=str(path), out=str(out)))
    assert message in str(info.value) and str(path) in str(info.value)
    assert "\n" not in str(info.value)
    assert not out.exists()


def test_meters_and_shipped_pieces():
    assert parse_meter("3/4") == (3, 4) and parse_meter("2/4") == (2, 4)
    for piece in ("steady_4_4", "waltz_3_4", "march_2_4"):
        config = config_from_dict({"piece": piece})
        assert config.piece.n_beats > 0
    waltz = config_from_dict({"piece": "waltz_3_4"}).piece
    assert waltz.tempo_at(1) == 132 and waltz.tempo_at(waltz.first_beat(21)) == 120
    assert waltz.tempo_at(waltz.first_beat(19)) == pytest.approx(126)




def test_the_ears_score_ends_with_the_piece():
    """Beats the ears commit after the piece's last beat (the ensemble has stopped) are not scored; an extra
    beat inside the piece is."""
    from scenarios.conductor.metrics import anticipator_scores

    truth = [0.5 * k for k in range(1, 41)]  # 20 s at 120 BPM
    late = [{"t": 0.0, "beats": [0.5 * k for k in range(1, 60)]}]  # right, and on for ten seconds more
    assert anticipator_scores(late, truth, skip=5.0)["f_measure"] == 1.0
    extra = [{"t": 0.0, "beats": sorted([0.5 * k for k in range(1, 41)] + [10.25, 12.25])}]
    assert anticipator_scores(extra, truth, skip=5.0)["f_measure"] < 1.0
