"""Fixtures of the system tests: real devices and real installs, each started only by its own fixture.

Every test module in this folder marks its tests ``system``; the default run leaves them out and
``python -m pytest -m system`` runs them in a process of their own.
"""

from __future__ import annotations

from pathlib import Path

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


@pytest.fixture(scope="session")
def user_environment(tmp_path_factory):
    """A new virtual environment with agentsim installed from a copy of the checkout's tracked files (as a
    package, its data included), seeing this environment's site-packages for the dependencies only: the
    checkout's editable install is not processed there. Yields the environment's folder."""
    import os
    import site
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    home = tmp_path_factory.mktemp("user")
    source = home / "source"
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True).stdout
    for name in filter(None, tracked.decode().split("\0")):
        target = source / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if (root / name).is_symlink():
            target.symlink_to(os.readlink(root / name))
        elif (root / name).is_file():
            target.write_bytes((root / name).read_bytes())
    env = home / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(env)], check=True, timeout=300)
    own = subprocess.run([str(env / "bin" / "python"), "-c", "import site; print(site.getsitepackages()[0])"],
                         check=True, capture_output=True, text=True).stdout.strip()
    ours = [p for p in site.getsitepackages() if Path(p).is_dir() and p != own]
    (Path(own) / "agentsim-dependencies.pth").write_text("".join(f"{p}\n" for p in ours))
    subprocess.run([str(env / "bin" / "python"), "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                    str(source)], check=True, timeout=600)
    yield env


@pytest.fixture(scope="session")
def user_env(user_environment) -> dict:
    """The environment variables of a reader whose shell has :func:`user_environment` first on its PATH."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.update(PATH=f"{user_environment / 'bin'}:/usr/bin:/bin", VIRTUAL_ENV=str(user_environment))
    return env


@pytest.fixture(scope="session")
def piper_stories(tmp_path_factory) -> dict[str, Path | float]:
    """Both shipped stories told with ``--tts piper`` (best strategy, seed 0, no pictures), once per session:
    ``{story: output folder, "cache": the cache of synthesised speech they share, "STORY cpu_s": the CPU seconds
    of its command}``. The cache is the fresh install's too, so that each story is synthesised once in a run of
    the system tests."""
    import os
    import resource
    import subprocess
    import sys

    def cpu() -> float:
        used = resource.getrusage(resource.RUSAGE_CHILDREN)
        return used.ru_utime + used.ru_stime

    root = Path(__file__).resolve().parents[2]
    where = tmp_path_factory.mktemp("piper-stories")
    told: dict[str, Path | float] = {"cache": where / "cache"}
    for story in ("the_lamp_on_heron_hill", "the_north_wind_and_the_sun"):
        before = cpu()
        done = subprocess.run([sys.executable, "-m", "agentsim", "run", "storytelling", "--story", story, "--tts",
                               "piper", "--cache", str(told["cache"]), "--out", str(where / story), "--no-pictures"],
                              cwd=where, env={**os.environ, "PYTHONPATH": str(root)}, capture_output=True, text=True,
                              timeout=1200)
        assert done.returncode == 0, done.stderr
        told[f"{story} cpu_s"] = cpu() - before
        told[story] = where / story
    return told
