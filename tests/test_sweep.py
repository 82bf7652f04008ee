"""agentsim sweep: a 12-point grid on a real Dask LocalCluster of two worker processes, each row equal to the
point's command run alone; the cache (a rerun computes only what is missing); failed points as rows; bad
specs as one line before any work; the report's bootstrap intervals and its picture.

The points are 'eval speech-sync --tts builtin' on a short text: the built-in backend is deterministic, which
espeak-ng is not across calls in one process, so the rows can be compared exactly. The tests that start a
dask scheduler and dask worker processes, and kill them, are in tests/system/test_sweep_cluster.py.
"""

from __future__ import annotations

import io
import json
import math
import re
import shutil
from contextlib import contextmanager, redirect_stderr
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import (
    SWEEP_GRID,
    SWEEP_TEXT,
    row_differences,
    run_alone,
    sweep_points,
    write_sweep_spec,
)

from agentsim.cli import main
from agentsim.cli.sweep import runner, spec
from agentsim.cli.sweep.report import interval


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """The 12-point sweep on a LocalCluster of 2 workers, and what it printed on stderr."""
    folder = tmp_path_factory.mktemp("sweep")
    path = write_sweep_spec(folder / "spec")
    err = io.StringIO()
    with redirect_stderr(err):
        status = main(["sweep", str(path), "--workers", "2", "--out", str(folder / "out")])
    assert status == 0, err.getvalue()
    return folder / "out", path, err.getvalue()


@pytest.fixture(scope="module")
def alone(swept):
    """Each of the 12 points run alone, as its own agentsim process."""
    _, path, _ = swept
    return run_alone(path.parent, sweep_points())


def test_a_sweep_on_a_local_cluster_of_two_workers_equals_each_point_run_alone(swept, alone):
    out, _, err = swept
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 12
    assert table[list(SWEEP_GRID)].to_dict("records") == sweep_points()  # one row per point, in the grid's order
    assert (table["status"] == "ok").all() and table["error"].isna().all()
    for row, single in zip(table.to_dict("records"), alone):
        assert row_differences(row, single, SWEEP_GRID) == [], row["command"]
    assert table["error_ms.p95"].nunique() == 12  # the points differ: the comparison could fail
    assert table["worker"].nunique() == 2  # both workers computed points
    assert table["command"][0] == ("agentsim eval speech-sync --tts builtin --text "
                                   f"{out.parent / 'spec' / 'story.txt'} --strategy best --seed 1 --jitter 0.03 --json")
    csv = pd.read_csv(out / "results.csv")
    assert list(csv.columns) == list(table.columns)
    assert np.allclose(csv["error_ms.p95"], table["error_ms.p95"], rtol=1e-12, atol=0)
    # the progress bar (stderr): points done of all, failed ones, time left
    assert re.search(r"12/12 \[[0-9:]+<[0-9:]+", err) and "failed=0" in err
    assert "12 points of 'agentsim eval speech-sync': 12 computed, 0 from the cache, 0 failed" in err


def copy_of(out: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    return copy


def test_a_rerun_computes_only_what_is_missing(swept, alone, tmp_path, monkeypatch, capsys):
    out, path, _ = swept
    out = copy_of(out, tmp_path)
    before = pd.read_parquet(out / "results.parquet")
    files = sorted((out / "points").glob("*.json"))
    assert len(files) == 12
    # everything is cached: no cluster is started at all
    real_connect = runner.connect
    monkeypatch.setattr(runner, "connect", lambda *a: pytest.fail("a cluster was started for nothing missing"))
    assert main(["sweep", str(path), "--workers", "1", "--out", str(out), "--quiet"]) == 0
    assert "0 computed, 12 from the cache, 0 failed" in capsys.readouterr().err
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), before)
    # two points lost, one half written (a sweep killed while writing it): those three are computed again
    lost = {p.stem for p in files[:2]}
    for file in files[:2]:
        file.unlink()
    files[2].write_text('{"status": "ok", "res')
    kept = {p: p.stat().st_mtime_ns for p in files[3:]}
    monkeypatch.setattr(runner, "connect", real_connect)
    assert main(["sweep", str(path), "--workers", "1", "--out", str(out), "--quiet"]) == 0
    assert "3 computed, 9 from the cache, 0 failed" in capsys.readouterr().err
    assert {p: p.stat().st_mtime_ns for p in files[3:]} == kept
    after = pd.read_parquet(out / "results.parquet")
    redone = after["point"].isin(lost | {files[2].stem})
    assert redone.sum() == 3
    for column in ("worker", "seconds"):  # the cached rows are the old ones, not computed again
        assert after.loc[~redone, column].tolist() == before.loc[~redone, column].tolist()
    for row, single in zip(after.to_dict("records"), alone):
        assert row_differences(row, single, SWEEP_GRID) == []


def test_the_cache_key_is_the_command_line_the_files_it_names_and_the_project_version(tmp_path, monkeypatch):
    path = write_sweep_spec(tmp_path)
    keys = [p.key for p in spec.load(path).points]
    assert len(set(keys)) == 12 and [p.key for p in spec.load(path).points] == keys
    (tmp_path / "story.txt").write_text("A different story now.\n")  # the text the points read changed
    changed = [p.key for p in spec.load(path).points]
    assert not set(changed) & set(keys)
    monkeypatch.setattr(spec, "project_version", lambda: "0.0.0+other")  # another version of the project
    assert not {p.key for p in spec.load(path).points} & set(changed)


def test_a_point_that_fails_is_a_row_with_its_error_and_the_sweep_finishes(tmp_path, capsys):
    (tmp_path / "story.txt").write_text(SWEEP_TEXT)
    path = tmp_path / "spec.toml"
    path.write_text('command = ["eval", "speech-sync"]\n[grid]\nseed = [1, 2]\n[grid.source]\n'
                    'short = { text = "story.txt" }\ngone = { text = "gone.txt" }\n[fixed]\ntts = "builtin"\n')
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--workers", "1", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"agentsim: 2 of 4 points failed; their errors are in the 'error' column of {out / 'results.csv'}"
    table = pd.read_parquet(out / "results.parquet")
    assert table[["seed", "source", "status"]].values.tolist() == [
        [1, "short", "ok"], [1, "gone", "failed"], [2, "short", "ok"], [2, "gone", "failed"]]
    failed = table[table["status"] == "failed"]
    assert (failed["error"] == "no text file 'gone.txt'").all() and failed["error_ms.p95"].isna().all()
    assert table.loc[table["status"] == "ok", "error_ms.p95"].notna().all()
    assert len(list((out / "points").glob("*.json"))) == 2  # failures are not cached: a rerun tries them again


BAD_SPECS = [
    ('command = ["eval", "nope"]', ("unknown command 'eval nope'; a sweep runs one of: anticipate beats, "
                                    "anticipate reps, eval speech-sync, run conductor, run storytelling, run trainer")),
    ('command = ["realize"]', "'agentsim realize' prints no --json"),
    ('command = ["eval"]', "unknown command 'eval'"),
    ('command = ["eval", "speech-sync"]\n[grid]\njiter = [0.1]', "unknown option 'jiter' of 'agentsim eval speech-sync'"),
    ('command = ["eval", "speech-sync"]\n[fixed]\ntts = "flite"', "argument --tts: invalid choice: 'flite'"),
    ('command = ["eval", "speech-sync"]\n[grid]\nseed = [1, "two"]', "argument --seed: expected a whole number from 0, got 'two' (at seed=two)"),
    ('command = ["eval", "speech-sync"]\n[grid]\nseed = [1, -1]', "argument --seed: a seed is a whole number from 0, got -1 (at seed=-1)"),
    ('command = ["eval", "speech-sync"]\n[grid]\nseed = []', "grid key 'seed' must be a list of at least one value"),
    ('command = ["eval", "speech-sync"]\n[grid]\nseed = [1]\n[fixed]\nseed = 2', "option 'seed' is set both in [fixed] and in [grid]"),
    ('command = ["eval", "speech-sync"]\n[fixed]\njson = true', "option 'json' is the sweep's own"),
    ('command = ["run", "conductor"]\n[fixed]\nout = "x"', "option 'out' is the sweep's own"),
    ('command = ["eval", "speech-sync"]\n[grid.condition]\nA = { delay = 0.05, jitterr = 0.1 }', "unknown option 'jitterr'"),
    ('command = ["eval", "speech-sync"]\n[grid]\nseed = [1]\n[report]\naxis = "jitter"', "[report] axis = 'jitter' is no grid key"),
    ('command = ["eval", "speech-sync"]\ngird = 1', "unknown key 'gird'"),
    ('command = ["eval", "speech-sync"', "is not TOML"),
]


@pytest.mark.parametrize("text, message", BAD_SPECS, ids=[m.split(":")[0][:40] for _, m in BAD_SPECS])
def test_a_bad_spec_is_one_line_naming_the_mistake_before_any_work(tmp_path, capsys, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n")
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--workers", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"agentsim: sweep spec {str(path)!r}")
    assert message in err
    assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["sweep", "nowhere.toml", "--out", "x"], "no sweep spec 'nowhere.toml'"),
    (["sweep", "SPEC", "--workers", "0", "--out", "x"], "--workers must be at least 1"),
    (["sweep", "SPEC"], "say where the sweep writes: --out DIR"),
    (["sweep", "SPEC", "--out", "x", "--markdown"], "--markdown is an option of 'agentsim sweep report DIR'"),
    (["sweep", "report"], "say which sweep: agentsim sweep report DIR"),
    (["sweep", "report", "nowhere"], "no sweep folder 'nowhere'"),
])
def test_bad_command_lines_are_one_line(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    write_sweep_spec(tmp_path)
    argv = [str(tmp_path / "spec.toml") if a == "SPEC" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"agentsim: {message}\n"
    assert not (tmp_path / "x").exists()


def test_without_dask_the_sweep_says_what_to_install(tmp_path, capsys, monkeypatch):
    path = write_sweep_spec(tmp_path)
    monkeypatch.setitem(__import__("sys").modules, "distributed", None)  # import distributed fails
    assert main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 1
    assert capsys.readouterr().err == "agentsim: agentsim sweep runs its points on Dask: pip install 'dask[distributed]'\n"
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_one_line(tmp_path, capsys, monkeypatch):
    import socket

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", 2.0)
    with socket.socket() as s:  # a port where nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = write_sweep_spec(tmp_path)
    assert main(["sweep", str(path), "--scheduler", f"tcp://127.0.0.1:{port}", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"agentsim: cannot reach the Dask scheduler at tcp://127.0.0.1:{port}: ")


def test_the_report_gives_means_with_bootstrap_intervals_per_strategy_and_draws_them(swept, tmp_path, capsys):
    out = copy_of(swept[0], tmp_path)
    assert main(["sweep", "report", str(out), "--metric", "error_ms.p95", "--metric", "snaps"]) == 0
    printed = capsys.readouterr()
    text = printed.out
    assert "12 points (12 ok, 0 failed); mean [95 % bootstrap interval] over seed" in text
    table = pd.read_parquet(out / "results.parquet")
    for strategy in ("best", "chang-naive"):
        block = text.split(f"strategy = {strategy}\n")[1].split("\n\n")[0].splitlines()
        assert block[0].split() == ["jitter", "n", "error_ms.p95", "snaps"]
        for line, jitter in zip(block[1:], (0.03, 0.1)):
            values = table[(table["strategy"] == strategy) & (table["jitter"] == jitter)]["error_ms.p95"]
            mean, low, high = (float(v) for v in re.findall(r"[-\d.]+", line.split(None, 2)[2])[:3])
            assert line.split()[:2] == [str(jitter), "3"]
            assert mean == pytest.approx(values.mean(), rel=1e-3)
            assert low < mean < high  # printed to 4 significant digits; a mean's interval lies within the data:
            assert values.min() * (1 - 5e-4) <= low and high <= values.max() * (1 + 5e-4)
    assert (out / "summary.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert printed.err.strip() == f"drawn: {out / 'summary.png'}"
    # one Markdown table, a column per metric and jitter
    assert main(["sweep", "report", str(out), "--markdown", "--metric", "error_ms.p95"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "| strategy | error_ms.p95 (jitter 0.03) | error_ms.p95 (jitter 0.1) | n |"
    assert [line.split(" | ")[0] for line in lines[2:]] == ["| best", "| chang-naive"]
    assert main(["sweep", "report", str(out), "--metric", "error_ms.p59"]) == 2
    assert capsys.readouterr().err.startswith("agentsim: no metric 'error_ms.p59' in this sweep's results")


def test_the_interval_is_scipys_bootstrap_of_the_mean():
    from scipy.stats import bootstrap

    values = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0]
    cell = interval(values, np.random.default_rng(0))
    ci = bootstrap((np.array(values),), np.mean, confidence_level=0.95, n_resamples=9999, method="BCa",
                   rng=np.random.default_rng(0)).confidence_interval
    assert (cell.mean, cell.low, cell.high, cell.n) == (np.mean(values), ci.low, ci.high, 8)
    assert interval([2.0, 2.0, 2.0], np.random.default_rng(0)).text() == "2 [2, 2]"  # no spread
    assert interval([2.0], np.random.default_rng(0)).text() == "2 (n=1)"  # one replicate: no interval
    assert interval([None, math.nan], np.random.default_rng(0)).text() == "none"  # null in every replicate
    assert interval([None, 4.0, None, 6.0], np.random.default_rng(0)).text().endswith(" (2 none)")
    assert interval([], np.random.default_rng(0)).text() == "-"


def test_spec_points_and_their_command_lines(tmp_path):
    path = tmp_path / "spec.toml"
    (tmp_path / "beats.wav").write_bytes(b"RIFF")
    path.write_text('command = "anticipate beats"\n[grid]\ntracker = ["causal", "baseline"]\n'
                    '[grid.speed]\nfine = { block = 256, lookahead = 0.1 }\ncoarse = { block = 1024 }\n'
                    '[fixed]\naudio = "beats.wav"\nskip = 4\n')
    checked = spec.load(path)
    assert [p.values for p in checked.points] == [
        {"tracker": t, "speed": s} for t in ("causal", "baseline") for s in ("fine", "coarse")]
    assert list(checked.points[0].argv) == ["anticipate", "beats", "--skip", "4", "--tracker", "causal", "--block",
                                            "256", "--lookahead", "0.1", "--json", str(tmp_path / "beats.wav")]
    assert not checked.takes_out
    conductor = tmp_path / "conductor.toml"
    conductor.write_text('command = ["run", "conductor"]\n[grid]\nstrategy = ["best"]\n[fixed]\ncompare = false\n')
    assert spec.load(conductor).takes_out and list(spec.load(conductor).points[0].argv) == [
        "run", "conductor", "--strategy", "best", "--json"]


def test_the_documented_example_spec_is_a_valid_spec(tmp_path):
    page = (Path(__file__).resolve().parent.parent / "docs" / "reference" / "sweep-spec.md").read_text()
    example = page.split("```toml\n")[1].split("```")[0]
    (tmp_path / "spec.toml").write_text(example)
    (tmp_path / "story.txt").write_text(SWEEP_TEXT)
    checked = spec.load(tmp_path / "spec.toml")
    assert len(checked.points) == 2 * 3 * 2 * 2
    assert checked.points[-1].values == {"strategy": "chang-naive", "seed": 3, "jitter": 0.1, "channel": "far"}
    assert "--loss" in checked.points[-1].argv and str(tmp_path / "story.txt") in checked.points[-1].argv


def test_kept_outputs_are_named_by_the_points_values(tmp_path, capsys):
    (tmp_path / "short.story").write_text("The clock struck nine.\n")
    long_name = "x" * 190
    path = tmp_path / "spec.toml"
    path.write_text('command = ["run", "storytelling"]\nkeep_outputs = true\n[grid]\nseed = [1, 2]\n'
                    '[grid.channel]\nnear = { delay = 0.05 }\n"far/away" = { delay = 0.2 }\n'
                    f'"far_away" = {{ delay = 0.3 }}\n{long_name} = {{ delay = 0.4 }}\n'
                    '[fixed]\ntts = "builtin"\nstory = "short.story"\nno-cache = true\n')
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--workers", "2", "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    keys = {(p.values["seed"], p.values["channel"]): p.key for p in spec.load(path).points}
    expected = set()
    for seed in (1, 2):
        expected.add(f"seed={seed},channel=near")
        # "far/away" made safe is "far_away", which the next name is: both end in their keys
        expected |= {f"seed={seed},channel=far_away~{keys[seed, name][:8]}" for name in ("far/away", "far_away")}
        name = f"seed={seed},channel={long_name}"  # 205 characters: shortened to 191 and the key
        expected.add(f"{name[:191]}~{keys[seed, long_name][:8]}")
    assert {p.name for p in (out / "outputs").iterdir()} == expected
    assert all(len(name) <= 200 for name in expected)
    for name in expected:  # each holds what that point's run wrote
        metrics = json.loads((out / "outputs" / name / "metrics.json").read_text())
        assert metrics["seed"] == int(name.split(",")[0].split("=")[1])
        assert (out / "outputs" / name / "story.bvh").is_file()
    table = pd.read_parquet(out / "results.parquet")
    assert (table["status"] == "ok").all() and len(table) == 8


def drawn_summaries(monkeypatch) -> list:
    """The figures 'sweep report' draws, kept as they were saved (instead of closed)."""
    import matplotlib.pyplot as plt

    figures = []
    monkeypatch.setattr(plt, "close", figures.append)
    return figures


def inside(fig, artist) -> bool:
    box, page = artist.get_window_extent(fig.canvas.get_renderer()), fig.bbox
    return page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1


@pytest.mark.parametrize("metrics", [["error_ms.p95"], ["error_ms.p95", "snaps"], []], ids=["one", "two", "all"])
def test_the_summary_pictures_title_lies_inside_it_above_the_plots(swept, tmp_path, monkeypatch, capsys, metrics):
    out = copy_of(swept[0], tmp_path)
    figures = drawn_summaries(monkeypatch)
    assert main(["sweep", "report", str(out)] + [a for m in metrics for a in ("--metric", m)]) == 0
    (fig,) = figures
    title = fig._suptitle
    renderer = fig.canvas.get_renderer()
    assert title.get_text().replace("\n", " ").replace("\xa0", " ") == (
        "agentsim eval speech-sync: mean and 95 % bootstrap interval over seed")
    assert inside(fig, title), (title.get_window_extent(renderer), fig.bbox)
    below = title.get_window_extent(renderer).y0
    assert all(ax.get_tightbbox(renderer).y1 <= below for ax in fig.axes if ax.get_visible())
    (legend,) = fig.legends
    assert inside(fig, legend)
    assert (title.get_text().count("\n") == 1) == (len(fig.axes) == 1)  # the one-metric picture is 5.2 in wide


def test_a_summary_of_many_lines_keeps_its_legend_inside_the_picture(tmp_path, monkeypatch):
    import itertools
    import json

    grid = {"strategy": ["best", "chang-naive", "skip-70ms"], "channel": ["near-and-clean", "far-and-lossy",
                                                                         "bursty-channel"],
            "seed": [1, 2, 3], "jitter": [0.03, 0.1]}
    rows = [dict(zip(grid, values), status="ok", error=None, **{"error_ms.p95": 10.0 + i % 7})
            for i, values in enumerate(itertools.product(*grid.values()))]
    pd.DataFrame(rows).to_csv(tmp_path / "results.csv", index=False)
    (tmp_path / "sweep.json").write_text(json.dumps({"command": ["eval", "speech-sync"], "grid": grid, "report": {}}))
    figures = drawn_summaries(monkeypatch)
    assert main(["sweep", "report", str(tmp_path), "--metric", "error_ms.p95", "--axis", "jitter"]) == 0
    (fig,) = figures
    (legend,) = fig.legends
    assert len(legend.get_texts()) == 9 and inside(fig, legend) and inside(fig, fig._suptitle)
    renderer = fig.canvas.get_renderer()
    above = legend.get_window_extent(renderer).y1
    assert all(ax.get_tightbbox(renderer).y0 >= above for ax in fig.axes if ax.get_visible())


def test_the_sweeps_help_names_everything_it_writes(swept, capsys):
    out, _, _ = swept
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    written = sorted(p.name + ("/" if p.is_dir() else "") for p in out.iterdir() if p.name != "summary.png")
    assert written == ["points/", "results.csv", "results.parquet", "sweep.json"]
    assert [name for name in written if f"DIR/{name}" not in text] == []
    assert "DIR/outputs/<its grid values>/" in text and "DIR/summary.png" in text


def million_point_spec(folder: Path, last: dict | None = None) -> Path:
    """A spec of 1,000 seeds x 1,000 jitters (10^6 points) of 'eval speech-sync --tts builtin'; ``last``: the
    last value of an axis instead of its own."""
    grid = {"seed": list(range(1000)), "jitter": [round(i / 1000, 3) for i in range(1000)]}
    for key, value in (last or {}).items():
        grid[key][-1] = value
    return write_sweep_spec(folder, grid=grid)


def counting(monkeypatch, name: str) -> list:
    """Count the calls of ``spec.<name>`` (the list grows by one a call)."""
    calls, real = [], getattr(spec, name)

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(spec, name, counted)
    return calls


def test_a_million_point_grid_is_checked_by_its_values_and_its_points_are_made_as_they_are_sent(
        tmp_path, monkeypatch):
    """The grid is checked value by value (1 + 999 + 999 command lines, not 10^6), no point is made before the
    cluster is asked for work, and the points are made one at a time as they are sent, a bounded number ahead
    of the results: the first is sent having made one point, and when the first result is in, only the
    points sent so far (MIN_AHEAD for one worker) have been made."""
    checked, made = counting(monkeypatch, "check_argv"), counting(monkeypatch, "point_key")
    loaded = spec.load(million_point_spec(tmp_path), max_points=10**6)
    assert (len(loaded.points), loaded.points.distinct, len(checked), len(made)) == (10**6, 10**6, 1999, 0)
    last = loaded.points[-1]  # any point is made on its own
    assert last.values == {"seed": 999, "jitter": 0.999} and last.argv[-5:] == (
        "--seed", "999", "--jitter", "0.999", "--json") and len(made) == 1
    made.clear()

    class Interrupted(Exception):
        pass

    submitted = []  # the points made when each point was sent
    real_connect = runner.connect

    @contextmanager
    def watched(workers, scheduler):
        with real_connect(workers, scheduler) as client:
            submit = client.submit

            def counted(*args, **kwargs):
                submitted.append(len(made))
                if len(submitted) > runner.MIN_AHEAD:  # sent once the first result is in: stop here
                    raise Interrupted
                return submit(*args, **kwargs)

            client.submit = counted
            yield client

    monkeypatch.setattr(runner, "connect", watched)
    with pytest.raises(Interrupted):
        runner.run(loaded, tmp_path / "out", workers=1, quiet=True)
    assert submitted == list(range(1, runner.MIN_AHEAD + 2))  # each point made just before it was sent
    finished = list((tmp_path / "out" / "points").glob("*.json"))
    assert finished and len(finished) <= runner.MIN_AHEAD  # real work was done, no point more was made
    assert json.loads(finished[0].read_text())["status"] == "ok"
    assert not (tmp_path / "out" / "results.csv").exists()  # an interrupted sweep writes no results


@pytest.mark.parametrize("last, message", [
    ({"jitter": "x"}, "argument --jitter: invalid float value: 'x' (at seed=0, jitter=x)"),
    ({"seed": -1}, "argument --seed: a seed is a whole number from 0, got -1 (at seed=-1, jitter=0.0)"),
    ({"seed": -1, "jitter": "x"}, "argument --jitter: invalid float value: 'x' (at seed=0, jitter=x)")],
    ids=["jitter", "seed", "both"])
def test_a_bad_value_last_in_a_million_point_grid_is_refused_before_any_work(tmp_path, capsys, monkeypatch, last,
                                                                             message):
    """As the first bad point in the grid's order would be, and with no point made."""
    made = counting(monkeypatch, "point_key")
    path = million_point_spec(tmp_path, last)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--max-points", "1000000", "--workers", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"agentsim: sweep spec {str(path)!r}: 1000000 points of 'agentsim eval speech-sync', checking "
                   f"the grid's values", f"agentsim: sweep spec {str(path)!r}: {message}"]
    assert not out.exists() and made == []


def test_results_written_a_batch_of_rows_at_a_time_are_the_tables_of_all_the_rows_at_once(tmp_path, monkeypatch):
    """Columns whose type shows only in a later batch: an error first in the last rows, whole numbers that a
    missing value makes decimal, a NaN before a flag and a decimal (text then), flags with a missing value,
    a whole number too large for 64 bits, a JSON null before numbers."""
    from agentsim.cli.sweep import results

    rows = []
    for i in range(7):
        row = {"seed": i, "status": "ok" if i < 5 else "failed", "error": None if i < 5 else "no text file 'x'"}
        row |= {"snaps": i} if i != 3 else {}
        row |= {"mixed": [math.nan, True, 0.25, False, math.nan, 1.5, True][i]}
        row |= {"flag": bool(i % 2)} if i < 6 else {}
        row |= {"huge": 2**70 if i == 6 else i}
        row |= {"beats_to_recover": None if i < 4 else 2.5}
        row |= {"seconds": 0.1 * i, "worker": "w", "attempts": 1, "point": f"k{i}", "command": "agentsim x"}
        rows.append(row)
    whole, batched = tmp_path / "whole", tmp_path / "batched"
    whole.mkdir(), batched.mkdir()
    results.write(results.frame(rows, ["seed"]), whole)
    monkeypatch.setattr(results, "BATCH_ROWS", 2)
    _, _, plan = results.write_rows(lambda: iter(rows), ["seed"], batched)
    assert (plan.rows, plan.failed) == (7, 2)
    assert (batched / "results.csv").read_bytes() == (whole / "results.csv").read_bytes()
    pd.testing.assert_frame_equal(pd.read_parquet(batched / "results.parquet"), pd.read_parquet(whole / "results.parquet"))
    assert pd.read_parquet(batched / "results.parquet")["mixed"].tolist()[:3] == ["nan", "True", "0.25"]
