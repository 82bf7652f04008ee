"""The audio beat anticipator: BML pegged to beats heard in rendered ensemble audio, and bad input (live
input through a PulseAudio null sink is in tests/system)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from agentsim.errors import AgentsimError
from agentsim.realizer import Realizer
from anticipators.audio import AudioBeatAnticipator, DeviceSource

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def test_bml_pegged_to_heard_beats_is_retimed_while_playing(ensemble):
    folder, _, _, beats = ensemble
    anticipator = AudioBeatAnticipator("band", source=folder / "ensemble.wav", origin=float(beats[0]) - 0.1)
    realizer = Realizer(anticipators=[anticipator])
    numbers = list(range(16, 60, 3))
    doc = f'<bml {NS} id="conduct">' + "".join(
        f'<gesture id="g{n}" lexeme="BEAT" stroke="anticipators:band:beat{n}"/>' for n in numbers) + "</bml>"
    realizer.submit_at(6.0, doc)
    realizer.run()
    strokes = realizer.feedback.sync_times()
    errors = np.array([strokes[f"conduct:g{n}:stroke"] - beats[n - 1] for n in numbers])
    assert np.max(np.abs(errors)) < 0.010, errors
    # Each stroke is passed exactly when the peg said, as the tracker last predicted it.
    for n in numbers:
        assert strokes[f"conduct:g{n}:stroke"] == anticipator.beats[n]
    predictions = realizer.feedback.of_type("predictionFeedback")
    assert len(predictions) > 5 and all(p["globalTime"] >= 6.0 for p in predictions)
    assert not realizer.feedback.warnings()


def test_anticipate_beats_command_scores_predictions(ensemble):
    folder, *_ = ensemble
    out = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipate", "beats", str(folder / "ensemble.wav"),
                          "--reference", str(folder / "beats.txt"), "--lookahead", "0.2", "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["f_measure"] >= 0.98 and result["mae_ms"] < 15 and result["real_time_factor"] < 0.05
    updates = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipate", "beats",
                              str(folder / "ensemble.wav"), "--json"], capture_output=True, text=True, timeout=120)
    run = json.loads(updates.stdout)
    assert run["tracker"] == "causal" and run["audio_seconds"] == pytest.approx(41.0, abs=2)
    assert all(all(b >= u["t"] for b in u["beats"]) for u in run["updates"])


def test_silence_after_music_keeps_the_last_good_prediction(ensemble):
    _, audio, sr, beats = ensemble
    anticipator = AudioBeatAnticipator("band", sample_rate=sr)
    anticipator.push(audio[: 15 * sr])
    confident, before = anticipator.confidence, list(anticipator.upcoming)
    anticipator.push(np.zeros(3 * sr, dtype=np.float32))
    assert confident >= 0.4 > anticipator.confidence
    period = np.median(np.diff(before))
    phase = (np.asarray(anticipator.upcoming) - before[0]) / period
    assert np.allclose(phase, np.round(phase), atol=0.05)  # the same grid, continued


@pytest.mark.parametrize("kind", ["silence", "noise", "clipped"])
def test_bad_audio_never_crashes_and_is_not_trusted(kind):
    rng = np.random.default_rng(5)
    sr = 16000
    x = {"silence": np.zeros(10 * sr), "noise": rng.normal(0, 0.3, 10 * sr),
         "clipped": np.clip(rng.normal(0, 3, 10 * sr), -1, 1)}[kind].astype(np.float32)
    anticipator = AudioBeatAnticipator("a", sample_rate=sr)
    for i in range(0, len(x), 1024):
        anticipator.push(x[i:i + 1024])
    assert anticipator.confidence < 0.4


def test_missing_device_and_file_give_clear_errors(tmp_path):
    with pytest.raises(AgentsimError, match="no audio input device 'no such device'"):
        DeviceSource("no such device").check()
    with pytest.raises(AgentsimError, match="no audio file"):
        AudioBeatAnticipator("a", source=tmp_path / "missing.wav")
    bad = tmp_path / "bad.wav"
    bad.write_text("not audio")
    with pytest.raises(AgentsimError, match="cannot read audio file"):
        AudioBeatAnticipator("a", source=bad)


