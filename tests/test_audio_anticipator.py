"""The audio beat anticipator: BML pegged to beats heard in rendered ensemble audio, live input through a
PulseAudio null sink, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import soundfile

from agentsim.core.clock import make_environment
from agentsim.core.errors import AgentsimError
from agentsim.realizer import Realizer
from agentsim.anticipators.audio import AudioBeatAnticipator, DeviceSource
from agentsim.music.ensemble import render_ensemble, write_beats

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


@pytest.fixture(scope="module")
def ensemble(tmp_path_factory):
    """20 bars at 120 BPM speeding up 10 % over bars 4-12, with rubato: audio file and true beats."""
    audio, sr, beats = render_ensemble(bpm=120, meter="4/4", bars=20, ramp=(4, 8, 0.10), rubato=0.02, seed=11,
                                       sample_rate=22050)
    folder = tmp_path_factory.mktemp("ensemble")
    soundfile.write(folder / "ensemble.wav", audio, sr)
    write_beats(folder / "beats.txt", beats)
    return folder, audio, sr, np.asarray(beats)


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


def test_live_input_through_a_null_sink_loopback(pulse_null_sink, ensemble):
    import sounddevice

    _, audio, sr, beats = ensemble
    seconds = 14.0
    env = make_environment(realtime=True)
    anticipator = AudioBeatAnticipator("live", source=DeviceSource("pulse", sr, 0.02))
    realizer = Realizer(env=env, anticipators=[anticipator])
    started = {}

    def play():
        time.sleep(0.3)
        started["sim"] = (time.monotonic() - env.real_start) / env.factor  # simulated time of play start
        sounddevice.play(audio[: int(seconds * sr)], sr, device="pulse")
        sounddevice.wait()

    player = threading.Thread(target=play)
    player.start()
    realizer.env.run(until=seconds + 0.5)
    player.join()
    assert anticipator.confidence >= 0.4
    # Predicted upcoming beats line up with the true beats shifted by the playback start, up to a constant
    # of the loopback (opening the output stream alone can take a few hundred ms on a loaded machine) and
    # with a small spread: the predictions are on one clock with the audio.
    # The constant can be near half a beat, where "the nearest true beat" flips between the beats either
    # side; offsets are therefore taken modulo the local beat period, around their circular mean.
    offsets, periods = [], []
    for t, predicted in anticipator.updates:
        if t > started["sim"] + 8:
            for b in predicted[:2]:
                k = min(np.searchsorted(beats + started["sim"], b), len(beats) - 1)
                offsets.append(b - (beats[k] + started["sim"]))
                periods.append(beats[k] - beats[k - 1])
    offsets, periods = np.asarray(offsets), np.asarray(periods)
    assert offsets.size > 10
    centre = np.angle(np.mean(np.exp(2j * np.pi * offsets / periods))) * periods / (2 * np.pi)
    offsets = (offsets - centre + periods / 2) % periods - periods / 2 + centre
    assert abs(np.median(offsets)) < 0.4
    assert np.percentile(np.abs(offsets - np.median(offsets)), 95) < 0.015


def test_anticipate_beats_listens_to_a_live_device(pulse_null_sink, ensemble):
    import os

    import sounddevice

    _, audio, sr, beats = ensemble
    proc = subprocess.Popen([sys.executable, "-m", "agentsim.cli", "anticipate", "beats", "--input", "pulse",
                             "--seconds", "9", "--sample-rate", str(sr), "--json"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    time.sleep(1.5)
    sounddevice.play(audio[: 9 * sr], sr, device="pulse")
    out, err = proc.communicate(timeout=60)
    sounddevice.stop()
    assert proc.returncode == 0, err
    run = json.loads(out)
    locked = [u for u in run["updates"] if u["beats"]]
    assert len(locked) > 5
    period = np.median(np.diff(locked[-1]["beats"]))
    assert period == pytest.approx(0.5, rel=0.05)  # 120 BPM: the ramp starts at bar 5
