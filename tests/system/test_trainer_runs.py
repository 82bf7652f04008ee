"""``agentsim run trainer`` end to end: every strategy on one seed of the simulated user, the files of each, the
table, and the targets of follow and lead; a recording played as the user, with the physical body squatting."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agentsim.cli import main

pytestmark = pytest.mark.system

FIELDS = {"asynchrony_ms", "count_error_ms", "tempo_error_percent", "recovered_after", "user_repetitions",
          "missed_counts"}


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    out = tmp_path_factory.mktemp("trainer") / "all"
    assert main(["run", "trainer", "--strategy", "all", "--seed", "2", "--out", str(out)]) == 0
    return out, {m["strategy"]: m for m in json.loads((out / "compare.json").read_text())}


def test_every_strategy_writes_its_files_and_the_figures_of_the_contract(compared):
    out, rows = compared
    assert list(rows) == ["follow", "lead", "fixed"]
    for name, metrics in rows.items():
        folder = out / name
        for file in ("metrics.json", "trainer.bvh", "narration.wav", "motion.csv", "repetitions.csv", "signal.png",
                     "gestures.csv", "feedback.jsonl", "report.html"):
            assert (folder / file).stat().st_size > 0, (name, file)
        assert FIELDS <= set(metrics) and metrics["user_repetitions"] == 20
        assert set(metrics["asynchrony_ms"]) >= {"mean", "sd"} and set(metrics["count_error_ms"]) >= {"p50", "p95"}
    assert "HIERARCHY" in (out / "follow" / "trainer.bvh").read_text()[:20]


def test_follow_counts_on_the_user_and_lead_brings_them_to_the_target_before_fixed(compared):
    _, rows = compared
    follow = rows["follow"]
    assert abs(follow["asynchrony_ms"]["mean"]) <= 40 and follow["asynchrony_ms"]["sd"] <= 60
    assert follow["count_error_ms"]["p95"] <= 80 and follow["missed_counts"] == 0
    assert follow["recovered_after"] is None and abs(follow["tempo_error_percent"]) > 10  # it followed
    assert rows["lead"]["recovered_after"] is not None and rows["fixed"]["recovered_after"] is None
    assert abs(rows["lead"]["tempo_error_percent"]) <= 5


def test_the_report_shows_the_users_key_points_beside_the_trainers(compared):
    out, _ = compared
    rows = (out / "follow" / "repetitions.csv").read_text().splitlines()
    assert rows[0].split(",")[:4] == ["repetition", "user_key_s", "trainer_key_s", "asynchrony_ms"]
    assert len(rows) == 21
    assert "signal.png" in (out / "follow" / "report.html").read_text()


def test_a_recording_plays_as_the_user_and_the_physical_body_squats_without_falling(tmp_path):
    from scenarios.trainer.signal import acceleration

    t = np.arange(0, 24.0, 0.02)
    keys = [2.0 + 2.5 * k for k in range(9)]
    path = tmp_path / "phone.csv"
    np.savetxt(path, np.column_stack([t, acceleration(t, keys, "squat", np.random.default_rng(1))]), delimiter=",",
               header="time,ax,ay,az", comments="", fmt="%.5f")
    out = tmp_path / "out"
    assert main(["run", "trainer", "--user", str(path), "--out", str(out), "--no-pictures", "--physics"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["user"] == "recording" and metrics["user_repetitions"] == 9
    assert metrics["missed_counts"] == 0 and not Path(out / "signal.png").exists()
    assert metrics["physics"]["fallen"] is False and metrics["physics"]["com_inside"] >= 0.99
    rows = (out / "physics.csv").read_text().splitlines()
    assert rows[0].split(",")[-3:] == ["com_inside", "pelvis_height", "fallen"]
    heights = [float(row.split(",")[-2]) for row in rows[1:]]
    assert min(heights) < 0.7 < 0.85 < max(heights)  # it squats: the pelvis goes down about 0.28 m and up again


def test_a_quick_users_third_repetition_has_the_trainers_move_hurried_into_it(tmp_path):
    # an arm raise begins 0.85 periods before its key point: when the user's second repetition is found, the
    # third's move would have begun already; it is hurried, not dropped
    out = tmp_path / "out"
    assert main(["run", "trainer", "--exercise", "arm-raise", "--seed", "3", "--no-pictures", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["trainer_repetitions"] == 18 and metrics["warnings"] == 0  # a move on the 3rd to the 20th
    assert abs(metrics["asynchrony_ms"]["mean"]) <= 40 and metrics["asynchrony_ms"]["sd"] <= 60
