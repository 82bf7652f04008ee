"""One default speech backend: ``Realizer()`` in Python, ``agentsim realize``, ``agentsim plot timeline`` and the
other commands all speak with espeak-ng when it is installed, and give the same times for the same file;
without espeak-ng they all fall back to the built-in timing model and say what to install."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from agentsim.cli import main
from agentsim.examples import HOME

WELCOME = HOME / "welcome.xml"

#: Prints the syncPointProgress times of a run, as JSON: {"id": time}.
TIMES = "; ".join([
    "import json",
    "times = lambda items: json.dumps({f['id']: round(f['globalTime'], 9) for f in items if f['type'] == 'syncPointProgress'})",
])

IN_PYTHON = TIMES + f"""
from anticipators.metronome import Metronome
from agentsim.realizer import Realizer
realizer = Realizer(anticipators=[Metronome('metronome', bpm=100)])
print(realizer.speech.planner.backend.name)
realizer.submit(open({str(WELCOME)!r}).read())
realizer.run()
print(times(realizer.feedback.items))
"""

#: ``agentsim plot timeline`` as typed, with the drawing replaced by printing the run it would draw.
PLOTTED = TIMES + """
import sys
import agentsim.animation as animation
def plot_timelines(recording, out, **kwargs):
    print(times(recording.feedback))
    return [out]
animation.plot_timelines = plot_timelines
from agentsim.cli import main
sys.exit(main(sys.argv[1:]))
"""


def run(*args, cwd) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc


def sync_times(stdout: str) -> dict[str, float]:
    return {f["id"]: f["globalTime"] for f in map(json.loads, stdout.splitlines())
            if f["type"] == "syncPointProgress"}


def test_realizer_realize_and_plot_timeline_share_the_default_backend_and_its_times(tmp_path):
    python = run("-c", IN_PYTHON, cwd=tmp_path).stdout.splitlines()
    realized = run("-m", "agentsim", "realize", str(WELCOME), "--metronome", "100", cwd=tmp_path)
    plotted = run("-c", PLOTTED, "plot", "timeline", str(WELCOME), "--metronome", "100", "--out",
                  str(tmp_path / "t.png"), cwd=tmp_path)
    assert python[0] == "espeak"
    assert "speech: espeak-ng (voice en" in realized.stderr and "speech: espeak-ng (voice en" in plotted.stderr
    times = sync_times(realized.stdout)
    assert len(times) > 20 and times["welcome:beat1:stroke"] > 0.3  # espeak-ng's "Welcome" is not instant
    assert json.loads(python[1]) == times
    assert json.loads(plotted.stdout) == times
    builtin = run("-c", PLOTTED, "plot", "timeline", str(WELCOME), "--metronome", "100", "--tts", "builtin",
                  "--out", str(tmp_path / "b.png"), cwd=tmp_path)
    assert "speech: the built-in timing model" in builtin.stderr
    other = json.loads(builtin.stdout)
    assert other.keys() == times.keys() and other["welcome:beat1:stroke"] != times["welcome:beat1:stroke"]


@pytest.fixture
def without_espeak(monkeypatch):
    """espeak-ng's library as if it were not installed."""
    from speech_timing.espeak import backend, engine

    def missing():  # the process-wide engine as the library's absence leaves it
        return engine._Engine("libespeak-ng-not-installed.so.1")

    monkeypatch.setattr(backend, "shared_engine", missing)


def test_without_espeak_every_default_falls_back_to_the_builtin_model_and_says_what_to_install(
        without_espeak, tmp_path, capsys):
    from agentsim.realizer import Realizer
    from speech_timing.espeak import INSTALL_HINT

    with pytest.warns(UserWarning, match="built-in model, without sound.*" + INSTALL_HINT):
        assert Realizer().speech.planner.backend.name == "builtin"
    assert main(["realize", str(WELCOME), "--metronome", "100"]) == 0
    err = capsys.readouterr().err
    assert INSTALL_HINT in err and "speech: the built-in timing model" in err
    assert main(["realize", str(WELCOME), "--tts", "espeak"]) == 1  # asked for by name: not replaced
    assert INSTALL_HINT in capsys.readouterr().err
    assert main(["realize", str(WELCOME), "--wav", str(tmp_path / "w.wav")]) == 2  # sound is asked for
    assert "--wav needs a backend that makes sound" in capsys.readouterr().err
