"""Exit statuses as a user meets them: 2 for every usage error (a missing input file, a folder where a file
is meant, a bad value), each with one line naming it, the same in every command."""

from __future__ import annotations

import subprocess
import sys

import pytest

AGENTSIM = [sys.executable, "-m", "agentsim"]


@pytest.mark.parametrize("args, message", [
    (["realize", "nosuch.xml"], "agentsim: no such file: nosuch.xml"),
    (["realize", "folder"], "agentsim: folder is a folder, not a BML file (name the files in it: folder/*.xml)"),
    (["plot", "timeline", "nosuch.xml", "--out", "x.png"], "agentsim: no such file: nosuch.xml"),
    (["anticipate", "beats", "nosuch.wav"], "agentsim: no audio file 'nosuch.wav'"),
    (["anticipate", "beats", "folder"], "agentsim: 'folder' is a folder, not an audio file"),
    (["speech", "export", "nosuch.txt", "--wav", "x.wav"], "agentsim: no text file 'nosuch.txt'"),
    (["eval", "speech-sync", "--text", "folder"], "agentsim: 'folder' is a folder, not a text file"),
    (["run", "storytelling", "--story", "nosuch"], "agentsim: no story file or shipped story 'nosuch'; shipped "
                                                   "stories: the_boy_who_cried_wolf, the_lamp_on_heron_hill, "
                                                   "the_north_wind_and_the_sun"),
    (["run", "conductor", "--config", "nosuch"], "agentsim: no configuration file or shipped configuration named "
     "'nosuch' (shipped: default, falls_apart, march_2_4, waltz_3_4; 'agentsim run conductor --list-configs')"),
    (["sweep", "nosuch", "--out", "x"], "agentsim: no sweep spec 'nosuch'"),
    (["serve", "--audio", "none", "--calibrate", "pulse"], "agentsim: --calibrate measures the sound device's "
                                                              "delay: it needs --audio DEVICE, not --audio none"),
    (["speech", "export", "examples/story.txt"], "agentsim: say what to write: --wav FILE.wav and/or --textgrid "
                                                 "FILE.TextGrid"),
    (["speech", "export", "examples/story.txt", "--tts", "builtin", "--wav", "x.wav"],
     "agentsim: --wav needs a backend that makes sound: the built-in one only times speech; use --tts espeak"),
])
def test_a_missing_or_wrong_input_is_a_usage_error_of_one_line(tmp_path, args, message):
    (tmp_path / "folder").mkdir()
    proc = subprocess.run([*AGENTSIM, *args], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert (proc.returncode, proc.stderr.strip().splitlines()[-1:], proc.stdout) == (2, [message], "")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]  # nothing written
