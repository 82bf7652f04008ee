"""Live audio through a real loopback device: a PulseAudio null sink played to and recorded from its monitor."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from agentsim.anticipators.audio import AudioBeatAnticipator, DeviceSource
from agentsim.cli import main
from agentsim.core.clock import make_environment
from agentsim.realizer import Realizer

pytestmark = pytest.mark.system


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


def test_live_conducting_through_a_null_sink_loopback(pulse_null_sink, tmp_path):
    """Conduct a rendered ensemble played into a PulseAudio null sink and heard from its monitor."""
    import sounddevice

    from agentsim.music.ensemble import render_ensemble

    audio, sr, _ = render_ensemble(bpm=112, meter="4/4", bars=6, seed=2, sample_rate=22050)
    config = tmp_path / "live.toml"
    config.write_text("[conductor]\njoin_confidence = 0.3\nstrategy = \"follow\"\n")

    def play():
        time.sleep(0.3)
        sounddevice.play(audio[: int(9.5 * sr)], sr, device="pulse")
        sounddevice.wait()

    player = threading.Thread(target=play)
    player.start()
    out = tmp_path / "live"
    try:
        assert main(["run", "conductor", "--config", str(config), "--out", str(out), "--live", "--device", "pulse",
                     "--seconds", "10"]) == 0
    finally:
        player.join()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["live"] and metrics["beats_conducted"] >= 2
    assert metrics["ensemble_asynchrony_ms"]["n"] >= 2 and abs(metrics["ensemble_asynchrony_ms"]["mean"]) < 80
    for name in ("tempo.png", "timeline.png", "ensemble.wav", "conductor.bvh", "feedback.jsonl"):
        assert (out / name).stat().st_size > 0
