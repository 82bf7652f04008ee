"""Fixtures of the system tests: real devices and real installs, each started only by its own fixture.

Every test module in this folder marks its tests ``system``; the default run leaves them out and
``python -m pytest -m system`` runs them in a process of their own.
"""

from __future__ import annotations

import pytest


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


@pytest.fixture(scope="session")
def pulse_null_sink():
    """A PulseAudio null sink as a real loopback device: play to it, record its monitor. Yields its name.

    PortAudio lists its devices once, when sounddevice is first imported: the sink is started before any
    test of this folder imports sounddevice, and these tests run in a pytest process of their own
    (``-m system``), where nothing imported it earlier.
    """
    import os
    import sys

    if "sounddevice" in sys.modules:
        pytest.fail("sounddevice was imported before PulseAudio started: run the system tests on their own "
                    "(python -m pytest -m system)")
    problem = start_null_sink()
    if problem:
        pytest.fail(problem)
    os.environ["PULSE_SINK"] = NULL_SINK
    os.environ["PULSE_SOURCE"] = f"{NULL_SINK}.monitor"
    yield NULL_SINK


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium (Debian's ``chromium``), driven over the DevTools protocol."""
    from agentsim.media.report.browser import Chromium, find_chromium

    try:
        find_chromium()
    except RuntimeError as e:
        pytest.fail(str(e))
    with Chromium(width=1280, height=900) as chromium:
        yield chromium
