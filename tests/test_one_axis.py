"""One time axis: the WAV a run writes is what its listener heard where it heard it, the BVH's frame k is at
k / fps, and both meet the feedback: every word's onset in the audio is where its sync point was fed back,
every beat's lowest wrist is at its stroke."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import soundfile

from helpers import bvh_positions
from agentsim.engines.speech import SpeechConfig
from agentsim.media.audio import run_track
from agentsim.media.files import write_wav
from agentsim.realizer import Realizer
from speech_timing.delivery import CONDITIONS
from speech_timing.espeak import EspeakBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
# words after pauses, so that their onsets stand out of silence in the audio
BML = (f'<bml {NS} id="b1"><speech id="s1"><text>Listen. <sync id="w1"/>Mountains rise slowly. '
       '<sync id="w2"/>Rivers fall, <sync id="w3"/>forests grow. <sync id="w4"/>Nothing stays.</text></speech>'
       + "".join(f'<gesture id="g{i}" lexeme="BEAT" stroke="s1:w{i}"/>' for i in range(1, 5)) + "</bml>")
MARKS = [f"b1:s1:w{i}" for i in range(1, 5)]
ONSET_TOLERANCE = 0.015


def onsets(samples: np.ndarray, rate: int, near: list[float], frame: float = 0.002) -> list[float]:
    """The onset of sound after a pause nearest each time in ``near``: where the energy (2 ms frames) first
    rises above -40 dB of its peak after at least 80 ms below it."""
    hop = int(rate * frame)
    energy = np.array([np.mean(samples[i:i + hop] ** 2) for i in range(0, len(samples) - hop, hop)])
    loud = energy > 1e-4 * energy.max()
    quiet_run = int(0.08 / frame)
    starts = [i for i in range(quiet_run, len(loud)) if loud[i] and not loud[i - quiet_run:i].any()]
    times = np.array(starts) * hop / rate  # a frame is a whole number of samples, not exactly 2 ms
    return [float(times[np.argmin(np.abs(times - t))]) for t in near]


@pytest.mark.parametrize("condition", [None, "A"])
def test_the_wav_sounds_each_word_where_its_sync_point_was_fed_back(tmp_path, condition):
    config = None if condition is None else SpeechConfig(strategy="best", delivery=CONDITIONS[condition], seed=3)
    realizer = Realizer(tts=EspeakBackend(), speech=config)
    realizer.submit(BML)
    realizer.run()
    syncs = realizer.feedback.sync_times()
    recording = realizer.recording()
    (heard,) = recording.speech
    if condition is not None:  # the audio really was late and drifting: the WAV must say so
        assert heard.t0 > 0.05 and heard.drift_ppm == 500.0
    path = write_wav(tmp_path / "run.wav", run_track(recording))
    samples, rate = soundfile.read(str(path), dtype="float32")
    with soundfile.SoundFile(str(path)) as f:
        assert "simulated time" in f.comment
    found = onsets(samples, rate, [syncs[m] for m in MARKS])
    errors = [abs(a - syncs[m]) for a, m in zip(found, MARKS)]
    assert max(errors) <= ONSET_TOLERANCE, errors
    # and the gestures are pegged to those words: each stroke is its word's sync point
    for i, m in enumerate(MARKS, 1):
        assert syncs[f"b1:g{i}:stroke"] == syncs[m]


def test_the_cli_writes_audio_and_motion_on_the_feedback_axis(tmp_path):
    bml = tmp_path / "talk.xml"
    bml.write_text(BML)
    wav, bvh = tmp_path / "talk.wav", tmp_path / "talk.bvh"
    fps = 60
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "realize", str(bml), "--wav", str(wav),
                           "--bvh", str(bvh), "--fps", str(fps)], capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert b"speech: espeak-ng" in proc.stderr
    import json

    feedback = [json.loads(line) for line in proc.stdout.decode().splitlines()]
    syncs = {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
    samples, rate = soundfile.read(str(wav), dtype="float32")
    found = onsets(samples, rate, [syncs[m] for m in MARKS])
    assert max(abs(a - syncs[m]) for a, m in zip(found, MARKS)) <= ONSET_TOLERANCE
    wrists = bvh_positions(bvh, ["l_wrist", "r_wrist"])
    for i in range(1, 5):
        # the beat's ictus: the lowest point of the wrist that beats (a beat takes the free hand), between
        # ready and relax (at rest the arm hangs lower)
        stroke = syncs[f"b1:g{i}:stroke"]
        lo, hi = int(np.ceil(syncs[f"b1:g{i}:ready"] * fps)), int(syncs[f"b1:g{i}:relax"] * fps) + 1
        a, b = int(syncs[f"b1:g{i}:start"] * fps), int(syncs[f"b1:g{i}:end"] * fps)
        wrist = max((w[:, 1] for w in wrists.values()), key=lambda y: np.ptp(y[a:b]))
        lowest = (lo + int(np.argmin(wrist[lo:hi]))) / fps
        assert abs(lowest - stroke) <= 1.0 / fps, (i, lowest, stroke)


def test_an_output_that_cannot_be_written_is_named_before_any_work(tmp_path):
    bml = tmp_path / "talk.xml"
    bml.write_text(BML)
    (tmp_path / "afile").write_text("")
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "realize", str(bml), "--wav",
                           str(tmp_path / "afile" / "x.wav")], capture_output=True, timeout=120)
    assert proc.returncode == 2 and not proc.stdout
    assert proc.stderr.decode().strip().splitlines() == [f"agentsim: cannot write {tmp_path}/afile/x.wav: "
                                                         f"a file is in the way of its folder {tmp_path}/afile"]
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "realize", str(bml), "--tts", "builtin", "--wav",
                           str(tmp_path / "x.wav")], capture_output=True, timeout=120)
    assert proc.returncode == 2 and b"--tts espeak" in proc.stderr and not (tmp_path / "x.wav").exists()


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_the_storyteller_writes_its_files_on_the_feedback_axis(tmp_path):
    """narration.wav, story.TextGrid and feedback.jsonl of a short story meet on one axis: the TextGrid's
    strokes are the stroke feedback, its words are where the WAV sounds them, and each word's mark was fed
    back within the onset tolerance of the word."""
    import json

    from praatio import textgrid

    out = tmp_path / "story"
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "run", "storytelling", "--story",
                           "the_north_wind_and_the_sun", "--anchor", "word", "--no-cache", "--out", str(out)],
                          capture_output=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    feedback = [json.loads(line) for line in (out / "feedback.jsonl").read_text().splitlines()]
    syncs = {f["id"]: f["globalTime"] for f in feedback if f["type"] == "syncPointProgress"}
    grid = textgrid.openTextgrid(str(out / "story.TextGrid"), includeEmptyIntervals=False)
    assert any(name.startswith("axis: simulated time") for name in grid.tierNames)
    words = [(e.label, e.start, e.end) for e in grid.getTier("words").entries]
    strokes = grid.getTier("strokes").entries
    assert strokes
    stroke_feedback = sorted({round(t, 3) for k, t in syncs.items() if k.endswith((":stroke", ":attackPeak", ":end"))})
    for point in strokes:
        assert min(abs(point.time - t) for t in stroke_feedback) <= 0.0005, point
    # gestures.csv says each gesture's word sounded where the TextGrid has that word (with --anchor word a
    # gesture is tied to its word's onset), and its stroke where the feedback has it
    import csv

    rows = list(csv.DictReader(open(out / "gestures.csv")))
    assert len(rows) == len(strokes) or len(rows) >= len(strokes)
    starts = {round(a, 6): label for label, a, _ in words}
    for row in rows:
        assert starts.get(round(float(row["sounded_s"]), 6), "").strip(".,;:!?\"'") == row["word"].strip(".,;:!?\"'")
        assert float(row["happened_s"]) == pytest.approx(syncs[f"{row['block']}:{row['behaviour']}:{row['sync']}"],
                                                         abs=1e-6)
    metrics = json.loads((out / "metrics.json").read_text())
    # and the WAV sounds the words that follow a pause where the TextGrid has them
    samples, rate = soundfile.read(str(out / "narration.wav"), dtype="float32")
    after_pause = [a for (_, a, _), (_, _, b) in zip(words[1:], words[:-1]) if a - b > 0.1]
    assert len(after_pause) >= 5
    found = onsets(samples, rate, after_pause)
    assert max(abs(x - a) for x, a in zip(found, after_pause)) <= ONSET_TOLERANCE
    assert metrics["time_axis"].startswith("simulated time") and metrics["audio_start_s"] > 1.0


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_the_conductor_writes_the_ensemble_and_its_beats_on_the_motion_axis(tmp_path):
    import csv
    import json

    out = tmp_path / "conductor"
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "run", "conductor", "--out", str(out)],
                          capture_output=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    samples, rate = soundfile.read(str(out / "ensemble.wav"), dtype="float32")
    beats = list(csv.DictReader(open(out / "beats.csv")))
    sounded = [float(b["sounded_s"]) for b in beats if b["sounded_s"]]
    # silence until the first beat sounds, then sound within a few milliseconds of it (the audio is placed
    # where the conductor heard it, not from its own sample 0)
    first_sound = np.flatnonzero(np.abs(samples) > 1e-3)[0] / rate
    assert sounded[0] - 0.01 <= first_sound <= sounded[0] + 0.01
    feedback = [json.loads(line) for line in (out / "feedback.jsonl").read_text().splitlines()]
    assert len(samples) / rate >= max(f["globalTime"] for f in feedback) - 1.0
    conducted = [b for b in beats if b["ictus_s"] and b["sounded_s"]]
    assert conducted
    for b in conducted:
        assert float(b["asynchrony_ms"]) == pytest.approx(1000 * (float(b["sounded_s"]) - float(b["ictus_s"])),
                                                          abs=1e-3)
    ictus = {int(b["beat"]): float(b["ictus_s"]) for b in beats if b["ictus_s"]}
    gestures = list(csv.DictReader(open(out / "gestures.csv")))
    strokes = {row["tied_to"].rsplit("beat", 1)[1]: float(row["happened_s"]) for row in gestures if row["happened_s"]}
    common = set(strokes) & {str(k) for k in ictus}
    assert common and all(strokes[k] == pytest.approx(ictus[int(k)], abs=1e-6) for k in common)
    assert json.loads((out / "metrics.json").read_text())["time_axis"].startswith("simulated time")


def test_a_speech_cut_by_replace_is_silent_from_the_cut():
    realizer = Realizer(tts=EspeakBackend())
    realizer.submit(f'<bml {NS} id="long"><speech id="s"><text>This goes on and on for a good while, and then on '
                    'some more.</text></speech></bml>')
    realizer.submit_at(1.0, f'<bml {NS} id="other" composition="REPLACE"><head id="h" lexeme="NOD"/></bml>')
    realizer.run()
    (heard,) = realizer.recording().speech
    assert heard.stopped == 1.0
    track = run_track(realizer.recording())
    cut = int(1.0 * track.rate)
    assert np.abs(track.samples[:cut]).max() > 0.05 and not np.abs(track.samples[cut:]).any()
