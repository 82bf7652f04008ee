"""A terminal's Ctrl-C during a scenario's run: the command ends with exit status 130 (or by the signal, which a
shell reports as 130 too) and no process of the command writes a traceback: neither the command, nor the process that renders its ensemble, the one that
simulates its physical body, nor the server its picture workers are forked from or those workers. Each run
is interrupted once a file of the folder it writes its outputs into (its staging folder, put in place at its end)
shows which stage it is in, or once its folder is in place and it ends (a time would be a race with Python's own
start, which a Ctrl-C stops with a fatal error in any program)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.system


def the_server_is_ready(group: int) -> bool:
    """Whether the command's group holds the server of the picture workers, its imports done (it then ignores
    SIGINT: a Ctrl-C in the first milliseconds of a Python process stops it with a fatal error whatever it
    runs)."""
    pids = subprocess.run(["pgrep", "-g", str(group)], capture_output=True, text=True).stdout.split()
    for pid in pids:
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes()
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            continue
        ignored = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigIgn:")), 16)
        if b"multiprocessing.forkserver" in command and ignored >> (signal.SIGINT - 1) & 1:
            return True
    return False


def the_moment_came(moment: str, group: int, out: Path) -> bool:
    """Whether the command is where ``moment`` says: the picture server ready (``simulating``), a file written
    into the staging folder it writes its outputs into (``metrics.json``, ``physics.csv``), or its folder put in
    place (``done``)."""
    if moment == "simulating":
        return the_server_is_ready(group)
    if moment == "done":
        return (out / "metrics.json").exists()
    return any(out.parent.glob(f".{out.name}.staging-*/{moment}"))


@pytest.mark.parametrize("moment", [
    "simulating",  # the piece simulated: the ensemble rendered by a process, the physical body's waiting
    "metrics.json",  # its outputs begun: the body simulated apart, the pictures drawn by workers
    "physics.csv",  # the physical body's frames all made: the pictures, the BVH, the report
    "done",  # its folder in place: the process ending (the interpreter's clean-up)
])
def test_ctrl_c_during_the_conductor_on_the_physical_body_ends_it_without_a_traceback(tmp_path, moment):
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-m", "agentsim", "run", "conductor", "--physics", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                           start_new_session=True)
    deadline = time.monotonic() + 120
    while not the_moment_came(moment, run.pid, out):
        assert run.poll() is None and time.monotonic() < deadline, run.communicate()[1]
        time.sleep(0.005)
    assert moment == "done" or not (out / "metrics.json").exists()  # (its folder not yet in place)
    os.killpg(run.pid, signal.SIGINT)  # as a terminal does: to every process of the command's group
    _, err = run.communicate(timeout=120)
    # (a shell says 130 of both: 128 + SIGINT); once done, the command may have ended before the Ctrl-C came
    assert run.returncode in (130, -signal.SIGINT) or moment == "done" and run.returncode == 0, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    # its children see their pipes close and end (the picture workers' server once it has imported them)
    while subprocess.run(["pgrep", "-g", str(run.pid)], capture_output=True).returncode == 0:
        assert time.monotonic() < deadline, "a process of the command is left running"
        time.sleep(0.1)
