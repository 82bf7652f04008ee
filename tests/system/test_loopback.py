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


def audio_start_in(capture: np.ndarray, audio: np.ndarray, sr: int) -> int:
    """Where (sample of ``capture``) ``audio`` begins in it: the peak of their cross-correlation over the
    first seconds of the audio (the reference taken from the captured signal itself)."""
    from scipy.signal import correlate

    template = audio[: int(4 * sr)].astype(np.float64)
    score = correlate(capture.astype(np.float64), template, mode="valid", method="fft")
    return int(np.argmax(score))


def test_live_input_through_a_null_sink_loopback(pulse_null_sink, ensemble):
    import sounddevice

    _, audio, sr, beats = ensemble
    seconds = 14.0
    env = make_environment(realtime=True)
    # (opening the player's output stream can take seconds on a loaded machine: the input may stay silent
    # that long without being taken for a dead device)
    anticipator = AudioBeatAnticipator("live", source=DeviceSource("pulse", sr, 0.02, dead_after=8.0))
    realizer = Realizer(env=env, anticipators=[anticipator])
    captured = []
    hear = anticipator.push

    def push(block):  # keep what the device delivered, as the anticipator heard it
        captured.append(np.array(block, dtype=np.float32, copy=True))
        hear(block)

    anticipator.push = push

    def play():
        time.sleep(0.3)
        sounddevice.play(audio[: int(seconds * sr)], sr, device="pulse")
        sounddevice.wait()

    player = threading.Thread(target=play)
    player.start()
    realizer.env.run(until=seconds + 0.5)
    player.join()
    assert anticipator.confidence >= 0.4
    # The time base: where the capture's sample 0 lies on the simulated clock, fitted by the anticipator
    # through the capture stamps (the least delayed of the latest blocks). The reference: where the
    # ensemble begins in the captured signal, by cross-correlation. True beat k was heard at
    # start + (lag + beats[k] * sr) / sr on that clock; the predictions must line up with it up to a small
    # spread, whatever the loopback's latency and however late the player thread got going.
    capture = np.concatenate(captured)
    lag = audio_start_in(capture, audio, sr)
    heard_from = anticipator.start + lag / sr  # simulated time at which the ensemble's sample 0 was heard
    offsets = []
    for t, predicted in anticipator.updates:
        if t > heard_from + 8:
            for b in predicted[:2]:
                k = int(np.argmin(np.abs(beats + heard_from - b)))
                offsets.append(b - (beats[k] + heard_from))
    offsets = np.asarray(offsets)
    assert offsets.size > 10
    # a constant remains: what the capture stamps do not say of the device's input latency (some 70 ms on a
    # PulseAudio monitor); the spread around it is the tracker's alone
    assert abs(np.median(offsets)) < 0.4
    spread = np.percentile(np.abs(offsets - np.median(offsets)), 95)
    print(f"loopback: constant {np.median(offsets) * 1e3:.1f} ms, 95th-percentile spread {spread * 1e3:.2f} ms")
    assert spread < 0.015


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
