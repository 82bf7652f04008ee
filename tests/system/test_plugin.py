"""A third-party anticipator plugin, installed with pip into a throw-away environment that sees agentsim,
found through its entry point and used from BML on the command line."""

from __future__ import annotations

import json
import shutil
import site
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
PLUGIN = Path(__file__).resolve().parents[2] / "agentsim" / "examples" / "plugins" / "agentsim-countin"


def new_environment(tmp_path) -> Path:
    """The Python of a new virtual environment that sees agentsim and its dependencies (through a .pth
    file naming this environment's site-packages), and its site-packages."""
    env = tmp_path / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True, timeout=120)
    python = env / "bin" / "python"
    own = subprocess.run([str(python), "-c", "import site; print(site.getsitepackages()[0])"], check=True,
                         capture_output=True, text=True).stdout.strip()
    ours = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (Path(own) / "agentsim-project.pth").write_text("".join(f"import site; site.addsitedir({p!r})\n" for p in ours))
    return python, own


@pytest.fixture
def plugin_python(tmp_path) -> str:
    """A new environment with the count-in plugin installed by pip."""
    python, own = new_environment(tmp_path)
    source = tmp_path / "agentsim-countin"  # build from a copy: no build artifacts in the checkout
    shutil.copytree(PLUGIN, source)
    subprocess.run([str(python), "-m", "pip", "--disable-pip-version-check", "-q", "install", "--no-deps",
                    "--no-build-isolation", "--target", own, str(source)], check=True, timeout=300)
    return str(python)


def test_third_party_plugin_installs_and_is_used_from_bml(plugin_python, tmp_path):
    listed = subprocess.run([plugin_python, "-m", "agentsim.cli", "anticipators", "list"], capture_output=True,
                            text=True, timeout=60)
    assert "countin\tagentsim_countin:CountIn" in listed.stdout, listed.stderr
    assert "metronome\tanticipators.metronome:Metronome" in listed.stdout
    # ... and the project's own environment never saw it
    ours = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipators", "list"], capture_output=True,
                          text=True, timeout=60)
    assert "metronome" in ours.stdout and "countin" not in ours.stdout
    doc = tmp_path / "cue.xml"
    doc.write_text(f'<bml {NS} id="b"><gesture id="g" lexeme="BEAT" stroke="anticipators:ci:cue"/>'
                   f'<head id="n" lexeme="NOD" stroke="anticipators:ci:count2"/></bml>')
    proc = subprocess.run([plugin_python, "-m", "agentsim.cli", "realize", str(doc), "--anticipator",
                           "countin:ci,beats=4,period=0.5,start=1,delay=1.5,shift=0.25"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    feedback = [json.loads(line) for line in proc.stdout.splitlines()]
    times = {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
    assert times["b:n:stroke"] == 1.5
    assert times["b:g:stroke"] == 3.25  # the cue at 3.0 moved by 0.25 s at t = 1.5
    assert [f["globalTime"] for f in feedback if f["type"] == "predictionFeedback"] == [0.0, 1.5]


def test_a_new_plugin_from_the_template_installs_and_works_at_once(tmp_path):
    python, _ = new_environment(tmp_path)
    made = subprocess.run([str(python), "-m", "agentsim.cli", "anticipators", "new", "pulse", "--dir", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    folder = tmp_path / "agentsim-pulse"
    assert f"wrote {folder}/" in made.stderr
    subprocess.run([str(python), "-m", "pip", "--disable-pip-version-check", "-q", "install", "--no-deps",
                    "--no-build-isolation", "-e", str(folder)], check=True, timeout=300, cwd=tmp_path)
    listed = subprocess.run([str(python), "-m", "agentsim.cli", "anticipators", "list"], capture_output=True,
                            text=True, timeout=60)
    assert ("pulse\tagentsim_pulse:Pulse\tperiod: float = 0.5, start: float = 0.0, drift: float = 0.0"
            in listed.stdout), listed.stdout + listed.stderr
    # its own tests pass as written
    tested = subprocess.run([str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"], cwd=folder,
                            capture_output=True, text=True, timeout=300)
    assert tested.returncode == 0 and "3 passed" in tested.stdout, tested.stdout + tested.stderr
    # and BML uses it from the command line, its parameters read with their declared types
    doc = tmp_path / "nod.xml"
    doc.write_text(f'<bml {NS} id="b"><head id="n" lexeme="NOD" stroke="anticipators:p:pulse3"/></bml>')
    proc = subprocess.run([str(python), "-m", "agentsim.cli", "realize", str(doc), "--anticipator",
                           "pulse:p,period=0.5,start=1"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    times = {f["id"]: f["globalTime"] for f in map(json.loads, proc.stdout.splitlines())
             if f["type"] == "syncPointProgress"}
    assert times["b:n:stroke"] == 2.0
    bad = subprocess.run([str(python), "-m", "agentsim.cli", "realize", str(doc), "--anticipator",
                          "pulse:p,period=fast"], capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0
    assert bad.stderr.strip().splitlines()[-1] == ("agentsim: anticipator 'pulse': parameter 'period' expects a number (float), "
                                  "got 'fast'")
