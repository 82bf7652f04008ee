"""Shared helpers for the tests: realise BML and look at the feedback."""

from __future__ import annotations

from pathlib import Path

import pytest

from agentsim.realizer import Realizer

# The BML 1.0 examples of the OpenBMLParser/AsapRealizer test suite (MIT licence, LICENSE-OpenBMLParser.txt),
# with their "Required timing" headers
EXAMPLES = Path(__file__).resolve().parent / "bml-examples"


class Result:
    """Feedback of one run, indexed for assertions."""

    def __init__(self, realizer: Realizer):
        self.realizer = realizer
        self.items = list(realizer.feedback.items)
        self.syncs = [f for f in self.items if f["type"] == "syncPointProgress"]
        self.local = {f["id"].split(":", 1)[1]: f["time"] for f in self.syncs}
        self.glob = {f["id"]: f["globalTime"] for f in self.syncs}
        self.warnings = [f for f in self.items if f["type"] == "warningFeedback"]
        self.blocks = [f for f in self.items if f["type"] == "blockProgress"]

    def t(self, name: str) -> float:
        """Block-relative time of ``behaviour:sync``."""
        return self.local[name]

    def dropped(self) -> set[str]:
        return {b for w in self.warnings for b in w["modifiedBehaviours"]}


def realize(*documents, at=None, until=None, **kwargs) -> Result:
    realizer = Realizer(**kwargs)
    times = at or [0.0] * len(documents)
    for t, doc in zip(times, documents):
        realizer.submit_at(t, doc)
    realizer.run(until=until)
    return Result(realizer)


@pytest.fixture
def examples() -> Path:
    assert EXAMPLES.is_dir(), f"the BML examples are expected in {EXAMPLES}"
    return EXAMPLES


NULL_SINK = "agentsim_null"


def start_null_sink() -> str | None:
    """Start PulseAudio (possibly as root, as in CI) with a null sink if needed; None if it worked, else why."""
    import shutil
    import subprocess
    import time

    if shutil.which("pulseaudio") is None or shutil.which("pactl") is None:
        return "the loopback tests need PulseAudio: apt-get install pulseaudio libportaudio2"
    if subprocess.run(["pulseaudio", "--check"]).returncode != 0:
        started = subprocess.run(["pulseaudio", "--daemonize=yes", "--exit-idle-time=-1", "-n",
                                  f"--load=module-null-sink sink_name={NULL_SINK}",
                                  "--load=module-native-protocol-unix"], capture_output=True, timeout=30)
        if started.returncode != 0:
            return f"PulseAudio did not start: {started.stderr.decode(errors='replace').strip()}"
        for _ in range(50):
            if subprocess.run(["pulseaudio", "--check"]).returncode == 0:
                break
            time.sleep(0.1)
    sinks = subprocess.run(["pactl", "list", "short", "sinks"], capture_output=True, text=True).stdout
    if NULL_SINK not in sinks:
        loaded = subprocess.run(["pactl", "load-module", "module-null-sink", f"sink_name={NULL_SINK}"],
                                capture_output=True, timeout=30)
        if loaded.returncode != 0:
            return f"cannot load the null sink: {loaded.stderr.decode(errors='replace').strip()}"
    return None


_SINK_PROBLEM: list[str | None] = []


def pytest_configure(config):
    # PortAudio lists its devices once, when sounddevice is first imported (at collection): PulseAudio
    # must be running before that for the 'pulse' device to exist.
    _SINK_PROBLEM.append(start_null_sink())


@pytest.fixture(scope="session")
def pulse_null_sink():
    """A PulseAudio null sink as a real loopback device: play to it, record its monitor. Yields its name."""
    import os

    problem = _SINK_PROBLEM[0] if _SINK_PROBLEM else start_null_sink()
    if problem:
        pytest.fail(problem)
    os.environ["PULSE_SINK"] = NULL_SINK
    os.environ["PULSE_SOURCE"] = f"{NULL_SINK}.monitor"
    yield NULL_SINK
