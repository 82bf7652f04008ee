"""Shared helpers for the tests: realise BML and look at the feedback."""

from __future__ import annotations

from pathlib import Path

import pytest

from agentsim.realizer import Realizer

# The shared examples live beside the checkout: <checkout>/../shared/bml-examples
EXAMPLES = Path(__file__).resolve().parents[2] / "shared" / "bml-examples"


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


@pytest.fixture(scope="session")
def pulse_null_sink():
    """A PulseAudio null sink as a real loopback device: play to it, record its monitor.

    Starts PulseAudio (as CI does, possibly as root) if it is not running. Yields the sink name.
    """
    import os
    import shutil
    import subprocess
    import time

    name = "agentsim_null"
    if shutil.which("pulseaudio") is None:
        pytest.fail("the loopback tests need PulseAudio: apt-get install pulseaudio libportaudio2")
    if subprocess.run(["pulseaudio", "--check"]).returncode != 0:
        subprocess.run(["pulseaudio", "--daemonize=yes", "--exit-idle-time=-1", "-n",
                        f"--load=module-null-sink sink_name={name}", "--load=module-native-protocol-unix"],
                       check=True, capture_output=True, timeout=30)
        for _ in range(50):
            if subprocess.run(["pulseaudio", "--check"]).returncode == 0:
                break
            time.sleep(0.1)
    sinks = subprocess.run(["pactl", "list", "short", "sinks"], capture_output=True, text=True).stdout
    if name not in sinks:
        subprocess.run(["pactl", "load-module", "module-null-sink", f"sink_name={name}"], check=True,
                       capture_output=True, timeout=30)
    os.environ["PULSE_SINK"] = name
    os.environ["PULSE_SOURCE"] = f"{name}.monitor"
    yield name
