"""A fresh virtual environment (no system site packages) takes a copy of the checkout and its declared
dependencies alone, and runs ``agentsim --version``, a ``realize`` and a two-point sweep on a local cluster;
then the ``piper`` extra, and the storyteller speaks with Piper.

The wheels come from a cache outside the checkout (``~/.cache/agentsim/wheels``), filled from the package
index the first time; every install after that is offline (``--no-index``). A package the project imports
but ``pyproject.toml`` does not declare is then missing, as it would be for a user.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.helpers import SWEEP_TEXT

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
WHEELS = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "agentsim" / "wheels"
#: What the copy of the checkout leaves out: the environment, the history, caches and outputs.
LEFT_OUT = shutil.ignore_patterns(".venv", ".git", "__pycache__", "*.egg-info", "build", "out", ".pytest_cache",
                                  ".hypothesis", "_build")


def _pip(venv: Path, *args: str, offline: bool) -> subprocess.CompletedProcess:
    index = ["--no-index", "--find-links", str(WHEELS)] if offline else ["--find-links", str(WHEELS)]
    return subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "--disable-pip-version-check", "-q", *args,
                           *index], capture_output=True, text=True, timeout=1200)


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> Path:
    """A virtual environment without the system's site packages, with a copy of the checkout installed from
    the wheel cache alone."""
    where = tmp_path_factory.mktemp("fresh")
    source = where / "agentsim"
    shutil.copytree(ROOT, source, ignore=LEFT_OUT)
    venv = where / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    config = (venv / "pyvenv.cfg").read_text()
    assert "include-system-site-packages = false" in config
    installed = _pip(venv, "install", str(source), offline=True)
    if installed.returncode != 0:  # the first time: fill the cache from the index, then install offline
        WHEELS.mkdir(parents=True, exist_ok=True)
        filled = _pip(venv, "download", "-d", str(WHEELS), str(source), "setuptools>=68", "wheel", offline=False)
        assert filled.returncode == 0, filled.stderr
        installed = _pip(venv, "install", str(source), offline=True)
    assert installed.returncode == 0, installed.stderr
    return venv


def _agentsim(venv: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run([str(venv / "bin" / "agentsim"), *args], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=600)


def test_a_fresh_environment_imports_nothing_it_did_not_install(fresh, tmp_path):
    found = subprocess.run([str(fresh / "bin" / "python"), "-c", "import agentsim, sys; print(agentsim.__file__); "
                            "print(sys.flags.no_site, [p for p in sys.path if 'site-packages' in p])"],
                           capture_output=True, text=True, cwd=tmp_path, check=True).stdout.splitlines()
    assert found[0].startswith(str(fresh))  # the installed copy, not the checkout
    assert all(p.startswith(str(fresh)) for p in json.loads(found[1].split(" ", 1)[1].replace("'", '"')))


def test_version_realize_and_a_local_sweep_in_a_fresh_environment(fresh, tmp_path):
    version = _agentsim(fresh, "--version", cwd=tmp_path)
    assert version.returncode == 0 and version.stdout.startswith("agentsim "), version.stderr
    realized = _agentsim(fresh, "realize", "--tts", "builtin", "--metronome", "100", "examples/welcome.xml", cwd=tmp_path)
    assert realized.returncode == 0, realized.stderr
    feedback = [json.loads(line) for line in realized.stdout.splitlines()]
    assert [f["id"] for f in feedback if f["type"] == "blockProgress"][-1].endswith(":end")
    assert not [f for f in feedback if f["type"] == "warningFeedback"]
    (tmp_path / "story.txt").write_text(SWEEP_TEXT)
    (tmp_path / "spec.toml").write_text('command = ["eval", "speech-sync"]\n[grid]\nstrategy = ["best", "chang-naive"]\n'
                                        '[fixed]\ntts = "builtin"\ntext = "story.txt"\n')
    swept = _agentsim(fresh, "sweep", "spec.toml", "--out", "swept", cwd=tmp_path)
    assert swept.returncode == 0, swept.stderr
    with open(tmp_path / "swept" / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [row["strategy"] for row in rows] == ["best", "chang-naive"]
    assert all(not row.get("error") for row in rows)


def test_the_piper_extra_installs_and_the_storyteller_speaks_with_it(fresh, piper_stories, tmp_path):
    """Without the extra, ``--tts piper`` is a usage error naming it; with the extra's packages installed from the
    wheel cache alone, the storyteller speaks with Piper: its speech read from the cache the session's
    storyteller runs filled (keyed by the voice's digest, not by where it is installed), its feedback theirs."""
    (tmp_path / "s.xml").write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b"><speech id="s">'
                                    '<text>Hello there.</text></speech></bml>')
    missing = _agentsim(fresh, "realize", "s.xml", "--tts", "piper", cwd=tmp_path)
    assert (missing.returncode, missing.stderr.strip().splitlines(), missing.stdout) == (2, [
        "agentsim: Piper is not installed here (no module piper); install it with: pip install 'agentsim[piper]'"], "")
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["piper"]
    installed = _pip(fresh, "install", *extra, offline=True)
    if installed.returncode != 0:  # the first time: the extra's wheels into the cache, then offline
        filled = _pip(fresh, "download", "-d", str(WHEELS), *extra, offline=False)
        assert filled.returncode == 0, filled.stderr
        installed = _pip(fresh, "install", *extra, offline=True)
    assert installed.returncode == 0, installed.stderr
    story = "the_north_wind_and_the_sun"
    told = _agentsim(fresh, "run", "storytelling", "--story", story, "--tts", "piper", "--cache",
                     str(piper_stories["cache"]), "--out", "told", "--no-pictures", cwd=tmp_path)
    assert told.returncode == 0, told.stderr
    metrics = json.loads((tmp_path / "told" / "metrics.json").read_text())
    assert metrics["speech_backend"]["tts"] == "piper"
    assert (metrics["cached"], metrics["synthesis_seconds"]) == (True, 0.0)
    assert (tmp_path / "told" / "feedback.jsonl").read_bytes() == (piper_stories[story] / "feedback.jsonl").read_bytes()
