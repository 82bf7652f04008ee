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


def test_anticipate_beats_command_commits_and_scores_beats(ensemble, tmp_path):
    """The committed sequence the command writes is every beat the update in force ``--lookahead`` before it
    predicted; ``--reference`` scores that sequence."""
    from anticipators.beats.evaluation import score_beats

    folder, _, _, beats = ensemble
    wav = str(folder / "ensemble.wav")
    for lookahead in ("0.2", "0"):
        out = tmp_path / f"committed-{lookahead}.txt"
        proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipate", "beats", wav, "--beats-out", str(out),
                               "--lookahead", lookahead, "--json"], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        run = json.loads(proc.stdout)
        assert run["tracker"] == "causal" and run["audio_seconds"] == pytest.approx(41.0, abs=2)
        assert run["lookahead"] == float(lookahead) and 0 < run["cpu_seconds"] < 0.05 * run["audio_seconds"]
        written = np.loadtxt(out, ndmin=1)
        np.testing.assert_allclose(written, run["committed"], atol=1e-6)
        # the rule, beat by beat: predicted by the update at u with u <= b - L < u_next
        updates, lead = run["updates"], float(lookahead)
        expected = []
        for i, update in enumerate(updates):
            following = updates[i + 1]["t"] if i + 1 < len(updates) else float("inf")
            expected += [b for b in update["beats"] if update["t"] <= b - lead < following and b <= run["audio_seconds"]]
        assert run["committed"] == sorted(expected) and len(expected) > 60
        # the music's beats, each once: 200 ms ahead as at lead 0
        music = written[written <= beats[-1] + 0.07]
        assert score_beats(beats, music)["f_measure"] >= 0.99
        assert np.all(np.diff(music) > 0.3)  # no beat doubled (the tempo stays under 140 BPM)
        scored = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipate", "beats", wav,
                                 "--reference", str(folder / "beats.txt"), "--lookahead", lookahead, "--json"],
                                capture_output=True, text=True, timeout=120)
        assert scored.returncode == 0, scored.stderr
        result = json.loads(scored.stdout)
        # the whole committed sequence is scored, the beats committed in the ringing after the music too
        want = score_beats(beats, written, skip=5.0)
        for key in ("f_measure", "cmlt", "amlt", "p_score", "mae_ms", "n_estimated", "n_reference"):
            assert result[key] == pytest.approx(want[key], abs=1e-3), key  # (the file holds microseconds)
        assert result["committed"] == written.size and result["lookahead"] == float(lookahead)
        assert result["mae_ms"] < 15 and result["real_time_factor"] < 0.05 and not result["silent"]
        assert result["time_to_4"] < 6.0


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


