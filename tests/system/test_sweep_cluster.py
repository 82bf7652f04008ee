"""agentsim sweep on real Dask processes: a ``dask scheduler`` and two ``dask worker`` processes (the
distributed package's own command lines) reached with --scheduler; one of those workers killed with SIGKILL
while it holds points, which the other computes; and a sweep killed with its whole local cluster, resumed
from its cache. Every row is checked against the point's command run alone.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import redirect_stderr
from pathlib import Path

import pandas as pd
import pytest
from helpers import (
    SWEEP_GRID,
    row_differences,
    run_alone,
    sweep_points,
    write_sweep_spec,
)

from agentsim.cli import main
from speech_timing.linear_model import TEXTS_DIR

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).parent / "dask"
#: A bundled text of 431 words: a point takes most of a second, so that a sweep can be killed midway.
LONG_TEXT = (TEXTS_DIR / "clocks.txt").read_text(encoding="utf-8")
#: Generous limits for a shared 2-core machine.
START_TIMEOUT = 90.0
SWEEP_TIMEOUT = 300.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def environment() -> dict:
    """The workers import this checkout's agentsim, wherever they start."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=15)


@pytest.fixture
def dask_processes(tmp_path):
    """A ``dask scheduler`` and two ``dask worker`` processes (no nanny, one thread each) on loopback ports;
    yields the scheduler's address and the workers' processes by address."""
    assert DASK.is_file(), f"no {DASK}: pip install 'dask[distributed]'"
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    with contextlib.ExitStack() as stack:
        files = [stack.enter_context(open(logs / f"{name}.log", "w")) for name in ("scheduler", "w0", "w1")]
        procs = [subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                   "--no-dashboard"], cwd=tmp_path, env=environment(), stdout=subprocess.DEVNULL,
                                  stderr=files[0])]
        for proc in procs:
            stack.callback(stop, proc)
        workers = {}
        for name, log in zip(("w0", "w1"), files[1:]):
            worker_port = free_port()
            proc = subprocess.Popen([str(DASK), "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                     "--host", "127.0.0.1", "--worker-port", str(worker_port), "--name", name,
                                     "--local-directory", str(tmp_path / name)],
                                    cwd=tmp_path, env=environment(), stdout=subprocess.DEVNULL, stderr=log)
            stack.callback(stop, proc)  # stopped before the scheduler (callbacks run last first)
            workers[f"tcp://127.0.0.1:{worker_port}"] = proc
        with Client(address, timeout=f"{START_TIMEOUT}s") as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT)
            assert set(client.scheduler_info()["workers"]) == set(workers)
        yield address, workers


@pytest.fixture(scope="module")
def short_alone(tmp_path_factory):
    folder = tmp_path_factory.mktemp("alone")
    write_sweep_spec(folder)
    return run_alone(folder, sweep_points())


@pytest.fixture(scope="module")
def long_alone(tmp_path_factory):
    folder = tmp_path_factory.mktemp("alone-long")
    write_sweep_spec(folder, text=LONG_TEXT)
    return run_alone(folder, sweep_points())


def check_rows(out: Path, alone: list[dict]) -> pd.DataFrame:
    table = pd.read_parquet(out / "results.parquet")
    assert table[list(SWEEP_GRID)].to_dict("records") == sweep_points()
    assert (table["status"] == "ok").all(), table[table["status"] != "ok"][["point", "error"]]
    for row, single in zip(table.to_dict("records"), alone):
        assert row_differences(row, single, SWEEP_GRID) == [], row["command"]
    return table


def test_a_sweep_through_a_dask_scheduler_and_two_dask_worker_processes(tmp_path, dask_processes, short_alone):
    address, workers = dask_processes
    path = write_sweep_spec(tmp_path / "spec")
    out = tmp_path / "out"
    err = io.StringIO()
    with redirect_stderr(err):
        assert main(["sweep", str(path), "--scheduler", address, "--out", str(out)]) == 0, err.getvalue()
    assert "12 computed, 0 from the cache, 0 failed" in err.getvalue()
    table = check_rows(out, short_alone)
    assert set(table["worker"]) == set(workers)  # both dask worker processes computed points


def test_a_worker_killed_mid_sweep_loses_no_point(tmp_path, dask_processes, long_alone):
    from distributed import Client

    address, workers = dask_processes
    path = write_sweep_spec(tmp_path / "spec", text=LONG_TEXT)
    out = tmp_path / "out"
    victim, survivor = list(workers)
    sweep = subprocess.Popen([sys.executable, "-m", "agentsim", "sweep", str(path), "--scheduler", address, "--out",
                              str(out), "--quiet"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with Client(address, timeout=f"{START_TIMEOUT}s") as client:
            deadline = time.monotonic() + SWEEP_TIMEOUT
            held = []
            while time.monotonic() < deadline and sweep.poll() is None:
                done = list((out / "points").glob("*.json")) if (out / "points").is_dir() else []
                held = list(client.processing().get(victim, ()))
                if done and held:  # the sweep is under way and the victim holds points
                    break
                time.sleep(0.05)
            assert held and sweep.poll() is None, "the sweep ended before a worker could be killed"
            os.kill(workers[victim].pid, signal.SIGKILL)
            workers[victim].wait(timeout=30)
            done_at_kill = len(list((out / "points").glob("*.json")))
        _, err = sweep.communicate(timeout=SWEEP_TIMEOUT)
    finally:
        if sweep.poll() is None:
            sweep.kill()
            sweep.wait()
    assert sweep.returncode == 0, err
    assert done_at_kill < 12 and "12 computed, 0 from the cache, 0 failed" in err
    table = check_rows(out, long_alone)  # no point lost, each as its command alone
    held = {key.removeprefix("agentsim-point-") for key in held}
    assert held <= set(table["point"])
    # what the killed worker held was computed by the other one
    assert (table[table["point"].isin(held)]["worker"] == survivor).any()
    assert (table["worker"] == survivor).sum() >= 12 - done_at_kill


def test_a_killed_sweep_resumes_from_what_it_finished(tmp_path, long_alone):
    path = write_sweep_spec(tmp_path / "spec", text=LONG_TEXT)
    out = tmp_path / "out"
    # the sweep and its local cluster in a process group of their own, killed together with SIGKILL
    sweep = subprocess.Popen([sys.executable, "-m", "agentsim", "sweep", str(path), "--workers", "2", "--out",
                              str(out), "--quiet"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    try:
        deadline = time.monotonic() + SWEEP_TIMEOUT
        while time.monotonic() < deadline and sweep.poll() is None:
            if (out / "points").is_dir() and len(list((out / "points").glob("*.json"))) >= 3:
                break
            time.sleep(0.05)
        assert sweep.poll() is None, "the sweep ended before it could be killed"
        os.killpg(sweep.pid, signal.SIGKILL)
        sweep.wait(timeout=30)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.wait()
    assert not (out / "results.parquet").exists()
    finished = {}
    for file in (out / "points").glob("*.json"):
        try:
            finished[file] = (json.loads(file.read_text()), file.stat().st_mtime_ns)
        except json.JSONDecodeError:
            pass  # killed while writing it: computed again
    assert 3 <= len(finished) < 12
    err = io.StringIO()
    with redirect_stderr(err):
        assert main(["sweep", str(path), "--workers", "2", "--out", str(out), "--quiet"]) == 0, err.getvalue()
    assert f"{12 - len(finished)} computed, {len(finished)} from the cache, 0 failed" in err.getvalue()
    assert {f: (json.loads(f.read_text()), f.stat().st_mtime_ns) for f in finished} == finished
    check_rows(out, long_alone)
