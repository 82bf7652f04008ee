"""The repetition anticipator: key points found and predicted from a motion signal, its pegs in a realizer, and
``agentsim anticipate reps`` with its JSON and its one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agentsim.cli import main
from anticipators.beats.evaluation import beat_f_measure
from anticipators.reps import RepetitionAnticipator, RepetitionTracker, track
from scenarios.trainer.signal import acceleration

KEYS = [2.0 + 2.2 * k for k in range(12)]


def recording(tmp_path, rate=50.0, keys=KEYS, seconds=28.0):
    t = np.arange(0, seconds, 1 / rate)
    a = acceleration(t, keys, "squat", np.random.default_rng(3))
    path = tmp_path / "squat.csv"
    np.savetxt(path, np.column_stack([t, a]), delimiter=",", header="time,ax,ay,az", comments="", fmt="%.5f")
    return path


@pytest.mark.parametrize("rate", [12.5, 200.0])
def test_every_squat_is_found_within_140_ms_at_12_5_and_200_hz(rate):
    t = np.arange(0, 28.0, 1 / rate)
    found = track(t, acceleration(t, KEYS, "squat", np.random.default_rng(1)))
    assert found["count"] == len(KEYS)
    assert np.abs(np.array(found["repetitions"]) - KEYS).max() < 0.14
    assert abs(found["tempo_per_minute"] - 60 / 2.2) < 1.0


def test_committed_key_points_hit_within_150_ms_and_increase():
    t = np.arange(0, 28.0, 1 / 50)
    found = track(t, acceleration(t, KEYS, "squat", np.random.default_rng(2)), lookahead=0.2)
    committed = np.array(found["committed"])
    assert (np.diff(committed) > 0).all()
    assert beat_f_measure(np.array(KEYS[2:]), committed[committed < 27], 0.15) >= 0.9


def test_nothing_is_predicted_before_the_second_repetition():
    tracker = RepetitionTracker()
    t = np.arange(0, 5.5, 0.02)
    tracker.push(t, acceleration(t, KEYS, "squat", np.random.default_rng(4)))
    assert len(tracker.repetitions) == 2  # at 2.0 and 4.2 s
    assert tracker.key_point(3) is not None
    early = RepetitionTracker()
    early.push(t[t < 3.5], acceleration(t[t < 3.5], KEYS, "squat", np.random.default_rng(4)))
    assert len(early.repetitions) == 1 and early.predict() == [] and early.key_point(2) is None


def test_a_restart_after_a_pause_is_sensed_before_its_key_point_is_found():
    # jumping jacks a second apart, a pause of four seconds, and four more: the tracker senses the person slowing
    # into the first bottom after the pause before that key point, well before it can find it
    keys = [2.0 + k for k in range(8)] + [13.0 + k for k in range(4)]
    t = np.arange(0, 17.5, 0.02)
    a = acceleration(t, keys, "jumping-jack", np.random.default_rng(6))
    tracker = RepetitionTracker()
    sensed, found, seen = None, None, set()
    for i in range(0, len(t), 3):
        tracker.push(t[i:i + 3], a[i:i + 3])
        if len(tracker.repetitions) == 8:
            seen.add(tracker.restart)
            sensed = tracker.restart
        elif len(tracker.repetitions) == 9 and found is None:
            found, after = tracker.time, tracker.restart
    assert seen == {None, sensed} and 12.9 < sensed <= 13.0 and found > 13.3 and after is None
    assert len(tracker.repetitions) == 12 and abs(tracker.repetitions[8] - 13.0) < 0.05


def test_a_coordinate_counts_its_lowest_points():
    t = np.arange(0, 20.0, 0.04)
    height = np.cos(2 * np.pi * (t - 1.0) / 2.0 + np.pi)  # lowest at 1, 3, 5, ... s
    found = track(t, height[:, None])
    assert found["count"] == 10 and abs(found["repetitions"][0] - 1.0) < 0.05


def test_the_pegs_follow_the_signal_pushed_in_a_realizer():
    from agentsim.core.clock import make_environment
    from agentsim.core.pegboard import PegBoard

    env = make_environment(False)
    reps = RepetitionAnticipator("reps")
    reps.attach(env, PegBoard())
    peg = reps.peg("rep6")
    assert peg.time is None
    t = np.arange(0, 9.4, 0.02)
    a = acceleration(t, KEYS, "squat", np.random.default_rng(5))
    for i in range(0, len(t), 5):
        env.run(until=t[min(i + 4, len(t) - 1)] + 1e-9)
        reps.push(t[i:i + 5], a[i:i + 5])
    assert abs(peg.time - KEYS[5]) < 0.15 and abs(reps.peg("next1").time - KEYS[4]) < 0.15


def test_the_command_prints_the_json_of_its_contract(tmp_path, capsys):
    assert main(["anticipate", "reps", str(recording(tmp_path)), "--json", "--lookahead", "0.3"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert sorted(out) == ["committed", "count", "repetitions", "tempo_per_minute"]
    assert out["count"] == len(out["repetitions"]) == 12
    assert abs(out["tempo_per_minute"] - 27.27) < 0.5


@pytest.mark.parametrize("text, says", [
    ("t,ax,ay,az\n0,1,1,1\n0.02,1,2,1\n0.04,1,1,1\n", "no 'time' column"),
    ("time,ax,ay,az\n0,1,1,1\n0.02,1,2,1\n0.01,1,1,1\n", "time goes back"),
    ("time,ax,ay,az\n0,1,1,1\n0.02,1,1,1\n0.04,1,1,1\n", "one constant value"),
    ("time,ax,ay,az\n0,1,1,1\n1,1,2,1\n2,1,1,1\n", "sampled at 1 Hz"),
    ("time,ax,ay,az\n0,1,1,1\n0.001,1,2,1\n0.002,1,1,1\n", "sampled at 1e+03 Hz"),
])
def test_bad_recordings_are_one_line_and_exit_2(tmp_path, capsys, text, says):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    assert main(["anticipate", "reps", str(path)]) == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1


def test_column_names_one_coordinate(tmp_path, capsys):
    t = np.arange(0, 12.0, 0.04)
    path = tmp_path / "height.csv"
    np.savetxt(path, np.column_stack([t, np.cos(np.pi * t)]), delimiter=",", header="time,hip_y", comments="")
    assert main(["anticipate", "reps", str(path), "--column", "hip_y", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["count"] == 6  # lowest at 1, 3, ... 11 s


def test_live_motion_is_taken_or_refused_in_one_line():
    reps = RepetitionAnticipator("reps", input="ws")
    assert reps.offer("x", 0.0).startswith("motion must be a list of samples")
    assert reps.offer([[0, 1, 2], [1, 2, 3]], 0.0).startswith("each motion sample must be [t, ax, ay, az]")
    assert reps.offer([[0, 1, 1, "a"]], 0.0) == "motion samples must hold numbers only"
    assert reps.offer([[0, 1, 1, 1], [0.001, 1, 1, 2], [0.002, 1, 1, 1]], 0.0).startswith("motion sampled at 1e+03")
    still = [[k * 0.02, 0.0, 0.0, 9.81] for k in range(50)]
    assert reps.offer(still[:25], 1.0) is None
    assert reps.offer(still[25:], 1.5) is None  # 0.98 s of one value: not yet
    later = [[1.0 + k * 0.02, 0.0, 0.0, 9.81] for k in range(60)]
    assert reps.offer(later, 2.7).startswith("the motion signal has been one constant value for 2 s")
    assert reps.offer([[0.5, 0.0, 0.0, 9.8]], 3.0).startswith("motion samples' times must increase")
    assert reps.inbox.qsize() == 2


def test_a_pause_at_the_bottom_joins_its_two_bumps_into_one_repetition(tmp_path, capsys):
    # pause squats: 0.9 s down, 0.6 s still at the bottom, 0.9 s up, 0.6 s still at the top; the upward
    # acceleration has two bumps per repetition (stopping the descent, starting the rise) with rest between
    rate, move, period, count = 12.5, 0.9, 3.0, 8
    t = np.arange(0, 2.0 + count * period, 1 / rate)
    up = np.zeros_like(t)
    for k in range(count):
        for begin, sign in ((1.0 + k * period, -1.0), (1.0 + k * period + 1.5, 1.0)):
            s = (t - begin) / move
            inside = (s >= 0) & (s < 1)
            up[inside] += sign * 0.4 * (np.pi / move) ** 2 / 2 * np.cos(np.pi * s[inside])
    a = np.column_stack([np.zeros_like(t), 0.3 * (9.81 + up), 0.95 * (9.81 + up)])
    a += np.random.default_rng(6).normal(0.0, 0.15, a.shape)
    path = tmp_path / "pause-squats.csv"
    np.savetxt(path, np.column_stack([t, a]), delimiter=",", header="time,ax,ay,az", comments="", fmt="%.5f")
    assert main(["anticipate", "reps", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["count"] == count  # each bottom once, not once per bump
    bottoms = 1.0 + move + period * np.arange(count)  # the still bottom spans 0.6 s from here
    assert (np.array(out["repetitions"]) > bottoms - 0.3).all() and (np.array(out["repetitions"]) < bottoms + 0.9).all()
    assert abs(out["tempo_per_minute"] - 20.0) < 0.5
