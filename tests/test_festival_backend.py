"""Tests of the Festival backend against the real festival program, its two voices and its own audio.

Festival is installed by ``scripts/install.sh`` (Debian's festival, festvox-us-slt-hts and
festvox-kallpc16k), so these tests fail, saying what to install, where it is missing: they do not skip.

Word onsets are checked against energy onsets in the audio: the onset of a word after a pause is the
first of three 2 ms frames running whose energy is 20 dB above the median energy of the pause before it
(100 ms of it, ending 40 ms before the time looked at). A word whose reported onset were Festival's
segment boundary, 5-90 ms before the sound after a pause, fails them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile

from agentsim.errors import SpeechBackendUnavailable
from speech_timing.backend import Prosody, SpeechText, TTSBackend
from speech_timing.festival import INSTALL_HINT, PHONES, FestivalBackend, _process, voice_name

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
# Capitalised words of four letters or more after full stops: Festival ends an utterance at each one, and
# the pause between two utterances is about 300 ms. Vowels, nasals, liquids, fricatives and stops.
PAUSED = "Listen. Island. Pepper. Mountains. Orange. Table. Morning. Butter. Animals. Kitten. Rivers. Garden.".split()
ONSET_TOLERANCE = 0.015  # seconds
FRAME = 0.002


@pytest.fixture(scope="module")
def slt() -> FestivalBackend:
    return FestivalBackend("us-slt-hts")


@pytest.fixture(scope="module")
def kal() -> FestivalBackend:
    return FestivalBackend("kal")


def frame_energy(samples: np.ndarray, rate: int) -> tuple[np.ndarray, int]:
    hop = int(rate * FRAME)
    n = len(samples) // hop
    return np.mean(samples[:n * hop].astype(np.float64).reshape(n, hop) ** 2, axis=1) + 1e-15, hop


def onset_after_pause(samples: np.ndarray, rate: int, t: float) -> float:
    """The energy onset after silence nearest after ``t - 40 ms`` (see the module's docstring)."""
    energy, hop = frame_energy(samples, rate)
    k = int(t * rate) // hop
    quiet = energy[k - int(0.14 / FRAME):k - int(0.04 / FRAME)]
    threshold = 100.0 * float(np.median(quiet))  # 20 dB
    for j in range(k - int(0.04 / FRAME), k + int(0.12 / FRAME)):
        if energy[j:j + 3].min() > threshold:
            return j * hop / rate
    raise AssertionError(f"no sound rises out of silence near {t:.3f} s")


def paused_bml(words: list[str]) -> str:
    """A speech of ``words`` with a mark before each, ``w0`` before the first."""
    text = " ".join(f'<sync id="w{i}"/>{w}' for i, w in enumerate(words))
    return f'<bml {NS} id="b1"><speech id="s1"><text>{text}</text></speech></bml>'


def cli(*args, env=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim", *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


# ---------------------------------------------------------------------------------------------------


def test_realize_with_festival_sounds_each_word_where_it_was_fed_back(tmp_path):
    """``agentsim realize --tts festival --wav``: every word, the first after the speech's own silence at its
    start, sounds in the WAV within 15 ms of its mark's feedback, and every mark's feedback is the onset of the
    word it precedes (the TextGrid's)."""
    from praatio import textgrid

    bml = tmp_path / "paused.xml"
    bml.write_text(paused_bml(PAUSED))
    wav, grid_path = tmp_path / "run.wav", tmp_path / "run.TextGrid"
    proc = cli("realize", str(bml), "--tts", "festival", "--wav", str(wav), "--textgrid", str(grid_path))
    assert proc.returncode == 0, proc.stderr
    assert "speech: Festival (voice us-slt-hts" in proc.stderr
    syncs = {f["id"]: f["globalTime"] for f in map(json.loads, proc.stdout.splitlines())
             if f["type"] == "syncPointProgress"}
    samples, rate = soundfile.read(str(wav), dtype="float32")
    assert rate == 32000
    marks = [syncs[f"b1:s1:w{i}"] for i in range(len(PAUSED))]
    assert syncs["b1:s1:start"] == 0.0 < marks[0]  # the first word after the silence Festival starts with
    errors = {w: onset_after_pause(samples, rate, t) - t for w, t in zip(PAUSED, marks)}
    assert max(abs(e) for e in errors.values()) <= ONSET_TOLERANCE, errors
    grid = textgrid.openTextgrid(str(grid_path), includeEmptyIntervals=False)
    words = [(e.label, e.start) for e in grid.getTier("words").entries]
    assert [label for label, _ in words] == [w.rstrip(".") for w in PAUSED]
    for (label, start), t in zip(words, marks):
        assert t == pytest.approx(start, abs=1e-6), label


def test_a_story_sentence_realized_with_festival_has_every_mark_at_its_word(tmp_path):
    """Running speech through ``realize --tts festival --wav``: a mark before a word in mid-phrase, after a comma
    or after a full stop is fed back at that word's onset (the TextGrid's, to the microsecond), and those of
    the words after a pause (200 ms or more) sound in the WAV within 15 ms of it (measured 0 to 4 ms)."""
    from praatio import textgrid

    text = ('The north wind and the sun were arguing. <sync id="m1"/>Which of them was <sync id="m2"/>stronger? '
            '<sync id="m3"/>Then a traveller came along, <sync id="m4"/>wrapped in a <sync id="m5"/>warm cloak. '
            '<sync id="m6"/>Maybe, <sync id="m7"/>said the <sync id="m8"/>sun.')
    before = {"m1": "Which", "m2": "stronger", "m3": "Then", "m4": "wrapped", "m5": "warm", "m6": "Maybe",
              "m7": "said", "m8": "sun"}
    bml = tmp_path / "sentence.xml"
    bml.write_text(f'<bml {NS} id="b1"><speech id="s1"><text>{text}</text></speech></bml>')
    wav, grid_path = tmp_path / "run.wav", tmp_path / "run.TextGrid"
    proc = cli("realize", str(bml), "--tts", "festival", "--wav", str(wav), "--textgrid", str(grid_path))
    assert proc.returncode == 0, proc.stderr
    syncs = {f["id"]: f["globalTime"] for f in map(json.loads, proc.stdout.splitlines())
             if f["type"] == "syncPointProgress"}
    grid = textgrid.openTextgrid(str(grid_path), includeEmptyIntervals=False)
    words = [(e.label, e.start, e.end) for e in grid.getTier("words").entries]
    samples, rate = soundfile.read(str(wav), dtype="float32")
    after_pause = []
    for name, word in before.items():
        t = syncs[f"b1:s1:{name}"]
        k = next(i for i, (label, start, _) in enumerate(words) if abs(start - t) < 1e-6)
        assert words[k][0] == word, (name, words[k])
        if words[k][1] - words[k - 1][2] >= 0.2:
            after_pause.append(name)
            assert abs(onset_after_pause(samples, rate, t) - t) <= ONSET_TOLERANCE, name
    assert after_pause == ["m1", "m3", "m6"]


def test_a_mark_inside_running_speech_is_fed_back_at_the_word_it_precedes(slt):
    text = "The wind and the sun were arguing which was the stronger, when a traveller came along."
    offsets = {name: text.index(word) for name, word in (("m1", "sun"), ("m2", "arguing"), ("m3", "traveller"))}
    utterance = slt.synthesize(SpeechText(text, tuple((o, n) for n, o in offsets.items()) + ((len(text), "end"),)))
    by_start = {w.char_start: w for w in utterance.words}
    for name, offset in offsets.items():
        assert utterance.mark_time(name) == by_start[offset].start
    assert utterance.mark_time("end") == utterance.duration
    # the word before a mark ends by the time it is passed
    assert by_start[offsets["m2"]].start >= by_start[text.index("were")].end


@pytest.mark.parametrize("voice", ["us-slt-hts", "kal"])
def test_word_onsets_after_pauses_agree_with_audio_energy(voice):
    backend = FestivalBackend(voice)
    # kal's diphones voice a pause before a voiced stop for about 100 ms: "Garden" is left out for it
    words = PAUSED if voice == "us-slt-hts" else [w for w in PAUSED if w != "Garden."]
    utterance = backend.synthesize(SpeechText(" ".join(words)))
    assert [w.text for w in utterance.words] == [w.rstrip(".") for w in words]
    errors = {w.text: onset_after_pause(utterance.audio, utterance.sample_rate, w.start) - w.start
              for w in utterance.words[1:]}
    assert max(abs(e) for e in errors.values()) <= ONSET_TOLERANCE, errors


def test_backend_satisfies_interface_and_maps_phones_to_ipa(slt):
    assert isinstance(slt, TTSBackend) and slt.name == "festival"
    utterance = slt.synthesize(SpeechText("The cat thinks, she judges."))
    assert utterance.backend == "festival" and utterance.text == "The cat thinks, she judges."
    assert [w.text for w in utterance.words] == ["The", "cat", "thinks", "she", "judges"]
    spelled = [" ".join(p.symbol for p in utterance.phonemes_of(k)) for k in range(len(utterance.words))]
    assert spelled == ["ð ə", "k a t", "θ ɪ ŋ k s", "ʃ iː", "dʒ ʌ dʒ ɪ z"]
    stressed = [p.symbol for p in utterance.phonemes if p.stressed]
    assert stressed == ["a", "ɪ", "iː", "ʌ"]  # the vowels of the stressed syllables ("the" is not)


def test_every_radio_phone_of_both_voices_is_mapped_vowels_to_vowels():
    """Each phone of the voices' phone sets has an IPA symbol, and it is a vowel to the phoneme-duration model
    (its first character) exactly where the phone set says the phone is a vowel."""
    from speech_timing.duration_model import _is_vowel

    process = _process()
    for voice in ("us-slt-hts", "kal"):
        FestivalBackend(voice)
        process.select(voice)
        lines = process.ask('(format t "%l\\n" (car (PhoneSet.description (quote (name)))))'
                            '(mapcar (lambda (ph) (format t "%s %s\\n" (car ph) (cadr ph)))'
                            ' (cadr (car (PhoneSet.description (quote (phones))))))')
        assert lines[0] == "(name radio)", lines[0]
        phones = dict(line.split() for line in lines[1:] if line.strip())
        assert len(phones) > 45
        for name, vowel in phones.items():
            if name in ("pau", "h#", "brth"):
                continue
            assert name in PHONES, name
            assert _is_vowel(PHONES[name]) == (vowel == "+"), (name, PHONES[name])


def test_phonemes_are_ordered_non_overlapping_and_inside_their_words(slt):
    utterance = slt.synthesize(SpeechText("Our guide, who has worked here for almost twenty years, likes to "
                                          "begin the tour in a quieter room. She points at a small box."))
    for previous, phoneme in zip(utterance.phonemes, utterance.phonemes[1:]):
        assert previous.end <= phoneme.start + 1e-9 and previous.word_index <= phoneme.word_index
    for k, word in enumerate(utterance.words):
        phonemes = utterance.phonemes_of(k)
        assert phonemes and phonemes[0].start == word.start and phonemes[-1].end == word.end
    assert utterance.sentences == [utterance.words[0].start, utterance.words[19].start]
    assert len(utterance.audio) == round(utterance.duration * utterance.sample_rate)


def test_numbers_and_hyphens_stay_one_written_word(kal):
    text = "It cost $1234 in 1999, well-known and/or so."
    utterance = kal.synthesize(SpeechText(text))
    assert [w.text for w in utterance.words] == ["It", "cost", "$1234", "in", "1999", "well-known", "and/or", "so"]
    for w in utterance.words:
        assert text[w.char_start:w.char_end] == w.text
    assert len(utterance.phonemes_of(2)) > 20  # "one thousand two hundred and thirty four dollars"


def test_a_break_puts_its_silence_between_the_two_words(slt):
    text = "Wait for it and then run."
    at = text.index("and")
    plain = slt.synthesize(SpeechText(text))
    broken = slt.synthesize(SpeechText(text, prosody=(Prosody("break", at, at, (("time", "400ms"),)),)))
    strong = slt.synthesize(SpeechText(text, prosody=(Prosody("break", at, at, (("strength", "strong"),)),)))
    k = next(w.index for w in plain.words if w.char_start == at)
    for utterance, seconds in ((broken, 0.4), (strong, 0.3)):
        assert utterance.duration == pytest.approx(plain.duration + seconds, abs=1.0 / plain.sample_rate)
        for a, b in zip(plain.words, utterance.words):
            assert b.start - a.start == pytest.approx(seconds if a.index >= k else 0.0, abs=1e-4)
        gap = utterance.audio[int((plain.words[k - 1].end + 0.005) * 32000):int((utterance.words[k].start - 0.005) * 32000)]
        assert len(gap) > 0.3 * 32000 * seconds and np.abs(gap).max() < 0.01


def test_rate_slows_the_whole_text_and_rate_spans_only_their_words_on_the_diphone_voice(slt, kal):
    text = "We walked along the river until the light began to fade."
    for backend in (slt, kal):
        normal = backend.synthesize(SpeechText(text))
        slow = backend.synthesize(SpeechText(text, rate=0.5))
        ratio = (slow.words[-1].end - slow.words[0].start) / (normal.words[-1].end - normal.words[0].start)
        assert 1.7 < ratio < 2.3, (backend.voice, ratio)
    start, end = text.index("river"), text.index("until") - 1
    span = (Prosody("prosody", start, end, (("rate", "x-slow"),)),)
    plain, spanned = kal.synthesize(SpeechText(text)), kal.synthesize(SpeechText(text, prosody=span))
    k = next(w.index for w in plain.words if w.char_start == start)
    for a, b in zip(plain.words, spanned.words):
        length = (b.end - b.start) / (a.end - a.start)
        if a.index == k:
            assert length > 1.3
        elif a.index < k:
            assert (b.start, b.end) == (a.start, a.end)
    # the HTS engine takes one speed per utterance: the span is left out, nothing moves
    assert [(w.start, w.end) for w in slt.synthesize(SpeechText(text, prosody=span)).words] == \
        [(w.start, w.end) for w in slt.synthesize(SpeechText(text)).words]


def test_the_same_text_gives_the_same_audio_and_times(slt, kal):
    speech = SpeechText("Some guess gold, others guess a snake.")
    first = slt.synthesize(speech)
    assert slt.synthesize(speech) is first  # remembered
    slt.forget(speech)
    kal.synthesize(SpeechText("Something else in between."))  # the process changes voice and back
    again = slt.synthesize(speech)
    assert again is not first  # said again
    assert first.words == again.words and first.phonemes == again.phonemes
    assert np.array_equal(first.audio, again.audio)


def test_the_speech_cache_keeps_festival_utterances_per_voice(tmp_path, slt, kal):
    from scenarios.storytelling.voice import CachedBackend

    text = "The north wind and the sun were disputing."
    cached = CachedBackend(slt, cache_dir=tmp_path)
    made = cached.utterance(text)
    loaded = CachedBackend(FestivalBackend("us-slt-hts"), cache_dir=tmp_path).utterance(text)
    assert loaded.words == made.words and loaded.phonemes == made.phonemes
    assert np.array_equal(np.asarray(loaded.audio), np.asarray(made.audio))
    other = CachedBackend(kal, cache_dir=tmp_path)
    assert other.key(text) != cached.key(text) and other.utterance(text).sample_rate == 16000


def test_speech_calibrate_fits_the_linear_model_on_festival(tmp_path, slt):
    from speech_timing.linear_model import LinearModel, calibrate

    texts = tmp_path / "texts.txt"
    lines = ["The museum opens at nine in the morning.", "Most of them walk straight to the great hall.",
             "She points at a small wooden box on a shelf."]
    texts.write_text("\n".join(lines) + "\n")
    proc = cli("speech", "calibrate", "--tts", "festival", "--texts", str(texts), "--out", str(tmp_path / "m.json"))
    assert proc.returncode == 0, proc.stderr
    saved = LinearModel.load(tmp_path / "m.json")
    fitted = calibrate(slt, lines)
    assert saved.multiplier == pytest.approx(fitted.multiplier) and saved.offset == pytest.approx(fitted.offset)
    proc = cli("speech", "calibrate", "--tts", "festival", "--voice", "kal", "--texts", str(texts), "--out",
               str(tmp_path / "k.json"))
    assert proc.returncode == 0, proc.stderr
    assert LinearModel.load(tmp_path / "k.json").multiplier != pytest.approx(saved.multiplier, rel=0.02)


def test_missing_festival_is_one_line_naming_the_packages(tmp_path):
    env = {**os.environ, "PATH": str(tmp_path)}  # no festival program there
    bml = tmp_path / "s.xml"
    bml.write_text(paused_bml(PAUSED[:3]))
    proc = cli("realize", str(bml), "--tts", "festival", env=env)
    assert proc.returncode != 0 and not proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and INSTALL_HINT in lines[0] and "Traceback" not in proc.stderr, proc.stderr
    assert INSTALL_HINT == "apt-get install festival festvox-us-slt-hts festvox-kallpc16k"


def test_unknown_and_missing_voices(monkeypatch, tmp_path):
    with pytest.raises(ValueError, match="us-slt-hts or kal"):
        voice_name("nosuch")
    assert voice_name(None) == "us-slt-hts" and voice_name("slt") == "us-slt-hts" and voice_name("KAL") == "kal"
    process = _process()
    monkeypatch.setattr(process, "voices", frozenset({"cmu_us_slt_arctic_hts"}))
    with pytest.raises(SpeechBackendUnavailable, match="apt-get install festvox-kallpc16k"):
        FestivalBackend("kal")
    monkeypatch.setattr(process, "voices", frozenset({"kal_diphone"}))
    assert FestivalBackend().voice == "kal"  # the default is the HTS voice only where it is installed
    proc = cli("speech", "export", str(Path(__file__).parent.parent / "examples" / "story.txt"), "--tts", "festival",
               "--voice", "nosuch", "--textgrid", str(tmp_path / "story.TextGrid"))
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "us-slt-hts or kal" in proc.stderr
    assert not (tmp_path / "story.TextGrid").exists()


def test_a_run_with_festival_plays_its_audio_on_the_feedback_axis():
    """What the run track plays is Festival's audio at its own sample rate, from where the speech started."""
    from agentsim.media.audio import run_track
    from agentsim.realizer import Realizer

    realizer = Realizer(tts=FestivalBackend("kal"))
    realizer.submit(paused_bml(PAUSED[:4]))
    realizer.run()
    recording = realizer.recording()
    (heard,) = recording.speech
    assert heard.utterance.backend == "festival" and heard.utterance.sample_rate == 16000
    track = run_track(recording)
    assert track.duration == pytest.approx(heard.t0 + heard.utterance.duration, abs=0.01)


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_the_storyteller_speaks_with_festival_and_its_report_plays_that_audio(tmp_path):
    """``run storytelling --tts festival``: metrics.json names the voice, the narration's words after pauses
    sound where the TextGrid has them, the report's audio is the narration, and the strokes meet their
    syllables (the short story: p95 2.6 ms measured; the bound leaves room, not a target)."""
    from praatio import textgrid

    out = tmp_path / "story"
    proc = cli("run", "storytelling", "--story", "the_north_wind_and_the_sun", "--tts", "festival", "--no-cache",
               "--fps", "30", "--window", "60", "--out", str(out), timeout=600)
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["speech_backend"] == {"tts": "festival", "voice": "us-slt-hts", "sample_rate": 32000}
    assert metrics["missed"] == 0 and metrics["snaps"] == 0 and metrics["sync_error_ms"]["p95"] < 5.0
    narration, rate = soundfile.read(str(out / "narration.wav"), dtype="float32")
    played, played_rate = soundfile.read(str(out / "report_files" / "audio.ogg"), dtype="float32")
    assert played_rate == rate == 32000 and len(played) == len(narration)
    assert np.corrcoef(played, narration)[0, 1] > 0.99  # the same sound, through a lossy codec
    grid = textgrid.openTextgrid(str(out / "story.TextGrid"), includeEmptyIntervals=False)
    words = [(e.start, e.end) for e in grid.getTier("words").entries]
    after_pause = [a for (a, _), (_, b) in zip(words[1:], words[:-1]) if a - b > 0.2]
    assert len(after_pause) >= 5
    errors = [onset_after_pause(narration, rate, a) - a for a in after_pause]
    assert max(abs(e) for e in errors) <= ONSET_TOLERANCE, errors


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_eval_speech_sync_runs_on_festival(slt):
    """``eval speech-sync --tts festival``: the strategy is scored on Festival's speech of the text (its length,
    its words), with the event delivery of condition A, and best stays on the words."""
    from agentsim.cli.speech import read_text

    proc = cli("eval", "speech-sync", "--tts", "festival", "--strategy", "best", "--json")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    utterance = slt.synthesize(SpeechText(read_text(None)))
    assert report["speech_seconds"] == pytest.approx(utterance.duration, abs=1e-6)
    assert report["words"] == len(utterance.words)
    assert report["error_ms"]["p95"] < 15.0 and report["snaps"] == 0 and report["missed"] == 0


@pytest.mark.system  # the longest shipped story with Festival: about two minutes
def test_the_storyteller_with_festival_strikes_its_syllables_within_2_ms_at_p95(tmp_path):
    """``run storytelling --tts festival`` with its defaults (the longest shipped story, strategy best, condition
    A, seed 0): every stroke comes, none snaps, and the sync error's p95 is under 2 ms (0.87 ms measured, as
    ``docs/howto/voices.md`` says; espeak-ng 0.65 ms)."""
    out = tmp_path / "story"
    proc = cli("run", "storytelling", "--tts", "festival", "--no-cache", "--out", str(out), timeout=1200)
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["speech_backend"]["tts"] == "festival" and metrics["strategy"] == "best"
    assert metrics["missed"] == 0 and metrics["snaps"] == 0 and metrics["gestures"] > 400
    assert metrics["sync_error_ms"]["p95"] < 2.0, metrics["sync_error_ms"]
