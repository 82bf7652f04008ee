"""The trainer scenario's parts that need no realizer run: the simulated user, the fixed plan, and the
command's one-line errors; and two short jumping-jack runs through the pause (whole runs of every strategy are in
tests/system/test_trainer_runs.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agentsim.cli import main
from scenarios.trainer.user import SimulatedUser, UserModel


@pytest.mark.parametrize("seed", range(1, 11))
def test_every_simulated_user_starts_17_to_25_percent_off_the_target_and_pauses_once(seed):
    model = UserModel.draw(2.4, seed)
    assert 0.17 <= abs(2.4 / model.start_period - 1) <= 0.25
    user = SimulatedUser(model, "squat", seed)
    times, samples = user.samples(200.0)
    assert len(user.keys) == 20 and user.pauses == [model.pause_after]
    gaps = np.diff(user.keys)
    assert gaps[model.pause_after - 1] > gaps.max() - 1e-9 and samples.shape == (len(times), 3)


def test_the_user_is_drawn_towards_a_trainer_together_with_them():
    alone = SimulatedUser(UserModel.draw(2.4, 3), "squat", 3)
    drawn = SimulatedUser(UserModel.draw(2.4, 3), "squat", 3)
    first = drawn.keys[0]
    drawn.see(first - 0.3)  # the trainer reached its key point 0.3 s before the user
    alone.samples(first + 1.0)
    drawn.samples(first + 1.0)
    assert drawn.keys[1] < alone.keys[1] - 0.1


@pytest.mark.parametrize("argv, says", [
    (["--target-tempo", "0"], "--target-tempo 0: give repetitions a minute, 5-120"),
    (["--user", "nosuch.csv"], "no motion recording 'nosuch.csv'"),
])
def test_bad_options_are_one_line_and_exit_2(tmp_path, capsys, argv, says):
    assert main(["run", "trainer", *argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1 and not (tmp_path / "out").exists()


def test_a_recording_without_time_is_refused_before_anything_runs(tmp_path, capsys):
    path = tmp_path / "phone.csv"
    path.write_text("t,ax,ay,az\n0,0,0,9.8\n0.02,0,0,9.9\n0.04,0,0,9.7\n")
    assert main(["run", "trainer", "--user", str(path), "--out", str(tmp_path / "out")]) == 2
    assert "no 'time' column" in capsys.readouterr().err


@pytest.mark.parametrize("seed", [0, 1])
def test_jumping_jacks_are_followed_and_counted_through_the_pause(tmp_path, capsys, seed):
    # seed 0: a person slower than the target, seed 1 a quicker one; each pauses once and hops again (as quickly
    # as before: a jump's ways take as long whatever the tempo), and the trainer counts that hop on it
    out = tmp_path / "out"
    assert main(["run", "trainer", "--exercise", "jumping-jack", "--seed", str(seed), "--no-pictures", "--json",
                 "--out", str(out)]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["user_repetitions"] == 20 and metrics["missed_counts"] == 0
    assert abs(metrics["asynchrony_ms"]["mean"]) <= 40 and metrics["asynchrony_ms"]["sd"] <= 60
    assert metrics["count_error_ms"]["p95"] <= 80
    [restart] = metrics["left_out_of_timing"]
    row = (out / "repetitions.csv").read_text().splitlines()[restart].split(",")
    assert 0 < float(row[5]) < 300  # the count on the hop after the pause, its stressed syllable in 0.3 s
