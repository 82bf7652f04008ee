"""Tests of the espeak-ng backend against the real library and against its own audio.

Word onsets are checked against energy onsets found in the synthesised audio, so a timing error
(such as taking espeak's WORD event, which comes up to 50 ms before the sound) makes them fail.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from speech_timing.backend import SpeechText, TTSBackend, Utterance
from agentsim.errors import SpeechBackendUnavailable
from speech_timing.espeak import INSTALL_HINT, EspeakBackend
from speech_timing.espeak.engine import _load_library

# Capitalised words after full stops: espeak makes a pause of about 300 ms before each.
ISOLATED_WORDS = ("Apple Banana Cherry Dog Egg Fish Garden Hello Island Jump Kite Lemon Mango Nose Orange "
                  "Pepper Queen River Snake Table Umbrella Violin Water Yellow Zebra Thumb Chair Shoe").split()

PARAGRAPH = (
    "The museum opens at nine in the morning, and the first visitors usually arrive a few minutes later. "
    "Most of them walk straight to the great hall, where the skeleton of a whale hangs from the ceiling. "
    "Our guide, who has worked here for almost twenty years, likes to begin the tour in a quieter room. "
    "She points at a small wooden box on a shelf and asks the children what they think is inside it. "
    "Some guess gold, others guess a snake, and one boy insists that it must hold a tiny dragon."
)

ONSET_TOLERANCE = 0.005  # seconds
SILENCE_DB = -40.0  # relative to the loudest 2 ms of the utterance


@pytest.fixture(scope="module")
def backend() -> EspeakBackend:
    return EspeakBackend()


def run_with_timeout(function, seconds: float = 60.0):
    """Run ``function`` in a thread and fail, rather than hang, if it does not return in time."""
    result: dict = {}

    def target() -> None:
        try:
            result["value"] = function()
        except BaseException as exc:  # re-raised in the calling thread
            result["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"synthesis did not finish within {seconds} s"
    if "error" in result:
        raise result["error"]
    return result["value"]


def loud_mask(utterance: Utterance, db: float = SILENCE_DB) -> np.ndarray:
    """Per sample: whether the RMS over the surrounding 2 ms is above ``db`` relative to its maximum."""
    x = utterance.audio.astype(np.float64)
    half = utterance.sample_rate // 1000
    energy = np.concatenate([[0.0], np.cumsum(x * x)])
    n = np.arange(len(x))
    lo, hi = np.clip(n - half, 0, len(x)), np.clip(n + half, 0, len(x))
    rms = np.sqrt((energy[hi] - energy[lo]) / np.maximum(hi - lo, 1))
    return rms > rms.max() * 10 ** (db / 20)


def energy_onsets(utterance: Utterance) -> list[float]:
    """For each word, the first loud sample between the middle of the preceding gap and 100 ms after
    the word's reported start (the search starts at 0 for the first word)."""
    loud = loud_mask(utterance)
    rate = utterance.sample_rate
    onsets = []
    for i, word in enumerate(utterance.words):
        begin = 0 if i == 0 else int(rate * (utterance.words[i - 1].end + word.start) / 2)
        stop = int(rate * (word.start + 0.1))
        window = loud[begin:stop]
        assert window.any(), f"no sound near {word.text!r}"
        onsets.append((begin + int(np.argmax(window))) / rate)
    return onsets


# ---------------------------------------------------------------------------------------------------


def test_missing_library_raises_with_install_instructions():
    with pytest.raises(SpeechBackendUnavailable) as info:
        _load_library("libespeak-ng-not-installed.so.1")
    assert "apt-get install libespeak-ng1 espeak-ng-data" in str(info.value)
    assert INSTALL_HINT == "apt-get install libespeak-ng1 espeak-ng-data"


def test_backend_satisfies_interface(backend):
    assert isinstance(backend, TTSBackend)
    assert backend.name == "espeak"
    utterance = backend.synthesize(SpeechText("Hello there."))
    assert utterance.backend == "espeak"
    assert utterance.text == "Hello there."
    assert [w.text for w in utterance.words] == ["Hello", "there"]


@pytest.mark.parametrize("separator", [". ", ", ", "! "])
def test_word_onsets_agree_with_audio_energy(backend, separator):
    utterance = backend.synthesize(SpeechText(separator.join(ISOLATED_WORDS) + "."))
    assert [w.text for w in utterance.words] == ISOLATED_WORDS
    onsets = energy_onsets(utterance)
    errors = [onset - word.start for onset, word in zip(onsets, utterance.words)]
    worst = max(range(len(errors)), key=lambda i: abs(errors[i]))
    assert abs(errors[worst]) <= ONSET_TOLERANCE, (
        f"{utterance.words[worst].text!r}: energy onset {onsets[worst]:.4f} s, "
        f"reported {utterance.words[worst].start:.4f} s"
    )


def test_gaps_between_isolated_words_are_silent(backend):
    """Word ends are not too early: no sound between one word's end and the next word's start."""
    utterance = backend.synthesize(SpeechText(". ".join(ISOLATED_WORDS) + "."))
    loud = loud_mask(utterance)
    rate = utterance.sample_rate
    margin = 0.002
    for before, after in zip(utterance.words, utterance.words[1:]):
        gap = loud[int(rate * (before.end + margin)):int(rate * (after.start - margin))]
        assert after.start - before.end > 0.2
        assert not gap.any(), f"sound between {before.text!r} and {after.text!r}"


def test_marks_at_word_onsets_agree_with_audio_energy(backend):
    text = ". ".join(ISOLATED_WORDS) + "."
    starts = [text.index(word) for word in ISOLATED_WORDS]
    utterance = backend.synthesize(SpeechText(text, tuple((s, f"w{i}") for i, s in enumerate(starts))))
    onsets = energy_onsets(utterance)
    for i, onset in enumerate(onsets):
        assert abs(utterance.mark_time(f"w{i}") - onset) <= ONSET_TOLERANCE


def test_phonemes_are_ordered_non_overlapping_and_inside_their_words(backend):
    utterance = backend.synthesize(SpeechText(PARAGRAPH))
    words, phonemes = utterance.words, utterance.phonemes
    assert len(words) == len(PARAGRAPH.split())
    assert len(phonemes) > 3 * len(words)
    for previous, phoneme in zip(phonemes, phonemes[1:]):
        assert previous.end <= phoneme.start
        assert previous.word_index <= phoneme.word_index
    for phoneme in phonemes:
        assert 0.0 <= phoneme.start <= phoneme.end <= utterance.duration
        assert phoneme.symbol and not phoneme.symbol.isspace()
        word = words[phoneme.word_index]
        assert word.start <= phoneme.start and phoneme.end <= word.end
    for index, word in enumerate(words):
        own = [p for p in phonemes if p.word_index == index]
        assert own, f"{word.text!r} has no phonemes"
        assert word.index == index
        assert word.start == own[0].start and word.end == own[-1].end
        assert word.start < word.end
    for previous, word in zip(words, words[1:]):
        assert previous.end <= word.start


def test_phoneme_names_are_ipa_with_primary_stress(backend):
    utterance = backend.synthesize(SpeechText("The photographer took a photograph of the banana."))
    by_word = {w.text: [p for p in utterance.phonemes if p.word_index == w.index] for w in utterance.words}
    assert [p.symbol for p in by_word["took"]] == ["t", "ʊ", "k"]
    assert [p.symbol for p in by_word["photograph"]] == ["f", "əʊ", "t", "ə", "ɡ", "ɹ", "a", "f"]
    assert [p.symbol for p in by_word["photograph"] if p.stressed] == ["əʊ"]
    stressed_photographer = [i for i, p in enumerate(by_word["photographer"]) if p.stressed]
    assert [by_word["photographer"][i].symbol for i in stressed_photographer] == ["ɒ"]
    assert stressed_photographer == [3]  # f ə t ˈɒ ...
    banana = by_word["banana"]
    assert [p.symbol for p in banana if p.stressed] == ["ɑː"] and not banana[1].stressed
    assert not any(p.stressed for p in by_word["The"])


def test_marks_equal_onset_of_following_word(backend):
    text = "Look at the door, then walk in the hall of a king and open it."
    names = ["look", "the1", "door", "walk", "the2", "a", "king", "it"]
    targets = ["Look", "the door", "door", "walk", "the hall", "a king", "king", "it."]
    offsets = [text.index(target) for target in targets]
    marks = tuple(zip(offsets, names)) + ((len(text), "end"), (offsets[2], "door again"),
                                          (offsets[3] - 1, 'odd <"&> name'))
    utterance = backend.synthesize(SpeechText(text, marks))
    assert [m.name for m in utterance.marks] == [name for _, name in marks]
    for offset, name in zip(offsets, names):
        word = next(w for w in utterance.words if w.char_start == offset)
        assert utterance.mark_time(name) == word.start, name
    assert utterance.mark_time("door again") == utterance.mark_time("door")
    # A mark in the space before a word stands before that word.
    assert utterance.mark_time('odd <"&> name') == utterance.mark_time("walk")
    # A mark after the text comes where the speech ends.
    assert abs(utterance.mark_time("end") - utterance.words[-1].end) <= 0.01


def test_many_marks_after_the_last_word_keep_their_order(backend):
    # espeak-ng's MARK events after the last word come a few samples out of order when many follow one
    # another; a mark never comes before one written before it, and none before the last word ends
    text = " ".join(["word"] * 50)
    marks = tuple((len(text), f"m{i}") for i in range(300))
    utterance = backend.synthesize(SpeechText(text, marks))
    times = [utterance.mark_time(f"m{i}") for i in range(300)]
    assert times == sorted(times)
    assert times[0] >= utterance.words[-1].start and times[-1] <= utterance.duration


def test_words_inside_dictionary_pairs_get_their_own_timing(backend):
    # espeak reads "in the" and "of a" as single words; they are split back into written words.
    text = "Sing it in the hall of a king."
    utterance = backend.synthesize(SpeechText(text))
    assert [w.text for w in utterance.words] == ["Sing", "it", "in", "the", "hall", "of", "a", "king"]
    the = next(w for w in utterance.words if w.text == "the")
    assert [p.symbol for p in utterance.phonemes if p.word_index == the.index] == ["ð", "ə"]


@pytest.mark.parametrize("text, expected", [
    ("café naïve", ["café", "naïve"]),
    ("Le café est naïve, très naïve & déjà-vu!", ["Le", "café", "est", "naïve", "très", "naïve", "&", "déjà-vu"]),
    ("Ünïcödé wörds: façade, coöperate; Straße.", ["Ünïcödé", "wörds", "façade", "coöperate", "Straße"]),
    ("“Quoted” (words) — and 1234 dogs. Dr. Smith said \"hi\"!", ["Quoted", "words", "and", "1234", "dogs",
                                                                  "Dr", "Smith", "said", "hi"]),
    ("a < b & c > d", ["a", "b", "&", "c", "d"]),
    ("Hello\n\nworld 😀 naïve—really, well-known - ok", ["Hello", "world", "😀", "naïve", "really", "well-known",
                                                          "ok"]),
])
def test_char_offsets_map_back_to_the_text(backend, text, expected):
    plain = backend.synthesize(SpeechText(text))
    assert [w.text for w in plain.words] == expected
    for word in plain.words:
        assert text[word.char_start:word.char_end] == word.text
    # Marks before every character shift espeak's positions in the SSML; offsets must not move.
    marked = backend.synthesize(SpeechText(text, tuple((i, f"c{i}") for i in range(len(text) + 1))))
    assert [(w.text, w.char_start, w.char_end) for w in marked.words] == \
        [(w.text, w.char_start, w.char_end) for w in plain.words]


def test_audio_and_duration(backend):
    utterance = backend.synthesize(SpeechText("One sentence. And another one!"))
    audio = utterance.audio
    assert audio is not None and audio.dtype == np.float32 and audio.ndim == 1
    assert utterance.sample_rate == backend.sample_rate == 22050
    assert utterance.duration == len(audio) / utterance.sample_rate
    assert np.abs(audio).max() <= 1.0 and np.abs(audio).max() > 0.1
    assert utterance.words[-1].end <= utterance.duration
    assert len(utterance.sentences) == 2
    assert utterance.sentences[0] == utterance.words[0].start
    assert utterance.sentences[1] == next(w.start for w in utterance.words if w.text == "And")


def timeline(utterance: Utterance) -> tuple:
    """Everything in an utterance but its times and audio."""
    return ([(w.index, w.text, w.char_start, w.char_end) for w in utterance.words],
            [(p.symbol, p.word_index, p.stressed) for p in utterance.phonemes],
            [m.name for m in utterance.marks], len(utterance.sentences))


def max_time_difference(a: Utterance, b: Utterance) -> float:
    times_a = [t for w in a.words for t in (w.start, w.end)] + [p.start for p in a.phonemes] + \
        [m.time for m in a.marks] + a.sentences
    times_b = [t for w in b.words for t in (w.start, w.end)] + [p.start for p in b.phonemes] + \
        [m.time for m in b.marks] + b.sentences
    assert len(times_a) == len(times_b)
    return float(np.max(np.abs(np.subtract(times_a, times_b))))


# espeak-ng keeps its pitch-flutter phase from one synthesis to the next, so the same text spoken
# again in the same process moves by up to about 20 ms (measured over a 376-word text).
REPEAT_TOLERANCE = 0.03


def test_repeated_synthesis_gives_the_same_timeline(backend):
    speech = SpeechText(PARAGRAPH, ((0, "start"), (PARAGRAPH.index("skeleton"), "skeleton")))
    first = backend.synthesize(speech)
    for other in ("Something different in between, at 1234 metres.", "a", "The cat."):
        backend.synthesize(SpeechText(other))
        again = backend.synthesize(speech)
        assert timeline(again) == timeline(first)
        assert max_time_difference(first, again) <= REPEAT_TOLERANCE
        assert abs(again.duration - first.duration) <= REPEAT_TOLERANCE


FRESH_PROCESS_SCRIPT = """
import hashlib, sys
from speech_timing.backend import SpeechText
from speech_timing.espeak import EspeakBackend
u = EspeakBackend().synthesize(SpeechText(sys.argv[1], ((0, "m"),)))
print(hashlib.sha256(u.audio.tobytes()).hexdigest(), repr((u.words, u.phonemes, u.marks, u.sentences)))
"""


def test_first_synthesis_in_a_fresh_process_is_bit_identical():
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])))
    outputs = [subprocess.run([sys.executable, "-c", FRESH_PROCESS_SCRIPT, PARAGRAPH], env=env, cwd=root,
                              capture_output=True, text=True, timeout=120, check=True).stdout
               for _ in range(2)]
    assert outputs[0] and outputs[0] == outputs[1]


def test_many_texts_and_backends_in_one_process(backend):
    """The library is initialised once; further texts, voices and rates must not hang it."""
    slow = run_with_timeout(lambda: EspeakBackend(voice="en-us", rate=120))
    fast = run_with_timeout(lambda: EspeakBackend(rate=300))
    text = "A short text to compare speaking rates."
    results = [run_with_timeout(lambda b=b, t=t: b.synthesize(SpeechText(t)))
               for t in (text, "Another text entirely.") for b in (backend, slow, fast)]
    durations = [r.duration for r in results[:3]]
    assert durations[1] > durations[0] > durations[2]
    assert [w.text for w in results[0].words] == text.rstrip(".").split()
    assert [w.text for w in results[4].words] == ["Another", "text", "entirely"]


def test_concurrent_synthesis_matches_sequential(backend):
    texts = [f"Thread number {n} says hello to the {word}." for n, word in enumerate(["others", "world", "guide",
                                                                                       "children"])]
    sequential = [backend.synthesize(SpeechText(t)) for t in texts]
    results: list[Utterance | None] = [None] * len(texts)

    def work(i: int) -> None:
        for _ in range(3):
            results[i] = backend.synthesize(SpeechText(texts[i]))

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(texts))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert not any(thread.is_alive() for thread in threads)
    for expected, got in zip(sequential, results):
        assert got is not None and got.text == expected.text
        assert timeline(got) == timeline(expected)
        assert max_time_difference(got, expected) <= REPEAT_TOLERANCE
        assert got.duration == len(got.audio) / got.sample_rate


def test_empty_and_silent_texts(backend):
    for text in ("", "   ", "..."):
        utterance = backend.synthesize(SpeechText(text))
        assert utterance.words == [] and utterance.phonemes == []
        assert utterance.duration == len(utterance.audio) / utterance.sample_rate < 0.05


def test_invalid_arguments(backend):
    with pytest.raises(ValueError):
        EspeakBackend(voice="no-such-voice-here")
    with pytest.raises(ValueError):
        EspeakBackend(rate=20)
    with pytest.raises(ValueError):
        backend.synthesize(SpeechText("Hi.", ((4, "outside"),)))


def test_stress_marked_clause_by_clause_is_that_of_the_whole_text(backend, monkeypatch):
    """The stressed vowels found by aligning each clause with its transcription are those that aligning the
    whole text at once finds (which costs the square of a long story's length)."""
    from speech_timing.espeak import alignment
    from speech_timing.espeak import backend as espeak_backend

    text = (PARAGRAPH + " “Yes!” said the cat; and then — well. Mr. Smith paid $1,000.50 on 3/4/2021, didn't he? "
            "In the end, of a sort: it's (quite) 'odd'... isn't it?!")
    clauses = backend._engine.transcribe_clauses(text, backend.voice, backend.rate)
    assert len(clauses) > 8 and [end for end, _ in clauses] == sorted(end for end, _ in clauses)
    assert [p for _, c in clauses for p in c] == backend._engine.transcribe(text, backend.voice, backend.rate)
    by_clause = EspeakBackend().synthesize(SpeechText(text))
    EspeakBackend().forget(SpeechText(text))  # said again below, not answered from what was said

    def whole(groups, tokens, clauses):
        alignment._mark_stress([p for g in groups for p in g.phonemes], [p for _, c in clauses for p in c])

    monkeypatch.setattr(espeak_backend, "mark_stress_by_clause", whole)
    at_once = EspeakBackend().synthesize(SpeechText(text))
    assert at_once is not by_clause
    marks = [(p.symbol, p.stressed) for p in by_clause.phonemes]
    assert marks == [(p.symbol, p.stressed) for p in at_once.phonemes]
    assert sum(stressed for _, stressed in marks) > 40


def test_a_speech_forgotten_is_synthesised_again(backend):
    """The backend remembers what it said (the same utterance again) until told to forget it; said again,
    its samples (collected chunk by chunk from the library) last as long, within what espeak-ng varies
    from one synthesis to the next in a process."""
    speech = SpeechText("A lighthouse keeper remembered the storm, long ago, and the ships it sank.")
    first = backend.synthesize(speech)
    assert backend.synthesize(speech) is first
    backend.forget(speech)
    again = backend.synthesize(speech)
    assert again is not first and again.audio.dtype == np.float32 and len(again.audio) > 22050
    assert abs(len(again.audio) - len(first.audio)) < 0.01 * len(first.audio)
    assert again.duration == len(again.audio) / again.sample_rate
    backend.forget(SpeechText("never said"))  # nothing to forget: no error


def test_a_text_is_said_the_same_whatever_was_said_before_and_in_every_process(tmp_path):
    """espeak-ng keeps state from one synthesis to the next; each synthesis runs in a fork of an engine that
    has never spoken, so it is the first synthesis of a fresh process, sample for sample."""
    import subprocess
    import sys

    from speech_timing.linear_model import TEXTS_DIR

    text = " ".join((TEXTS_DIR / "clocks.txt").read_text().split())
    other = " ".join((TEXTS_DIR / "orchard.txt").read_text().split())
    first = EspeakBackend().synthesize(SpeechText(text))
    EspeakBackend().synthesize(SpeechText(other))
    assert EspeakBackend().synthesize(SpeechText(text)) is first  # a new backend answers from what was said
    EspeakBackend().forget(SpeechText(text))
    again = EspeakBackend().synthesize(SpeechText(text))  # forgotten: synthesised anew, after another text
    assert again is not first and np.array_equal(again.audio, first.audio)
    assert again.words == first.words and again.phonemes == first.phonemes
    # ... and as a fresh process says it first, in that process itself (the engine's own synthesis)
    script = ("import sys, numpy as np; from speech_timing.espeak import EspeakBackend; "
              "from speech_timing.espeak.engine import shared_engine; "
              "from speech_timing.backend import SpeechText; e = shared_engine(); e.synth = e.synth_here; "
              "np.save(sys.argv[2], EspeakBackend().synthesize(SpeechText(sys.argv[1])).audio)")
    subprocess.run([sys.executable, "-c", script, text, str(tmp_path / "fresh.npy")], check=True, timeout=120)
    assert np.array_equal(np.load(tmp_path / "fresh.npy"), first.audio)
    # while the engine's own synthesis, spoken after the other text, comes out otherwise
    script = script.replace("np.save(", "EspeakBackend().synthesize(SpeechText(sys.argv[3])); np.save(")
    subprocess.run([sys.executable, "-c", script, text, str(tmp_path / "later.npy"), other], check=True, timeout=120)
    assert not np.array_equal(np.load(tmp_path / "later.npy"), first.audio)


def test_what_is_remembered_is_weighed_in_bytes(monkeypatch):
    """The utterances remembered hold at most REMEMBERED_BYTES of audio together: the oldest are forgotten first,
    and one larger than that is not kept at all."""
    backend = EspeakBackend()
    texts = [SpeechText(f"The {word} keeper walked up the hill at night.") for word in ("first", "second", "third")]
    first = backend.synthesize(texts[0])
    size = first.audio.held_bytes
    monkeypatch.setattr(backend._spoken, "max_bytes", int(2.5 * size))
    kept = [first] + [backend.synthesize(t) for t in texts[1:]]
    # the three together pass the bound: the first one is forgotten, the other two are what is weighed
    assert backend.remembered_bytes == kept[1].audio.held_bytes + kept[2].audio.held_bytes <= 2.5 * size
    assert backend.synthesize(texts[2]) is kept[2] and backend.synthesize(texts[0]) is not first
    monkeypatch.setattr(backend._spoken, "max_bytes", size // 2)
    big = SpeechText("A sentence a good deal longer than any of the ones before, said only once.")
    said = backend.synthesize(big)
    assert backend.synthesize(big) is not said and backend.remembered_bytes == 0


LONG_SYNTHESIS_SCRIPT = """
import re, sys
from speech_timing.backend import SpeechText
from speech_timing.espeak import EspeakBackend
from speech_timing.linear_model import TEXTS_DIR

def status(name):
    return int(re.search(name + r":\\s+(\\d+)", open("/proc/self/status").read()).group(1)) * 1024

words = " ".join((TEXTS_DIR / name).read_text() for name in ("clocks.txt", "lighthouse.txt", "orchard.txt")).split()
text = " ".join((words * (int(sys.argv[1]) // len(words) + 1))[:int(sys.argv[1])])
backend = EspeakBackend()
backend.synthesize(SpeechText("Warm up."))
before = status("VmRSS")
utterance = backend.synthesize(SpeechText(text))
print(before, status("VmHWM"), status("VmRSS"), utterance.audio.held_bytes, 2 * len(utterance.audio))
"""


def test_a_long_synthesis_holds_its_samples_once():
    """The samples of a long speech come from the synthesising fork straight into the one buffer the utterance
    keeps: the peak of the process is what it holds afterwards, not that and a second copy of the audio (as
    when the reply was read whole and unpickled: 2.2 times the audio, 0.95 of it gone again afterwards)."""
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, "-c", LONG_SYNTHESIS_SCRIPT, "3000"], env=env, cwd=root,
                          capture_output=True, text=True, timeout=300, check=True)
    before, peak, after, held, audio = (int(v) for v in proc.stdout.split())
    assert held == audio > 30e6  # about 40 MB of 16-bit samples, in memory, weighed as such
    assert peak - after < 0.2 * audio, (before, peak, after, audio)  # no second copy on the way
    assert peak - before < 1.5 * audio, (before, peak, after, audio)


def test_a_synthesis_cut_short_is_said_and_the_next_reply_is_read_whole():
    """A fork that dies while it sends its samples: the process between passes on zeros for the rest and says
    so; the reply is an error, and the next reply on the pipe is read from its start."""
    import io

    from speech_timing.espeak.engine import _read_reply, _relay, _send

    samples = np.arange(-300, 300, dtype="<i2")
    pipe = io.BytesIO()
    _send(pipe, (len(samples), []))
    _relay(io.BytesIO(samples.tobytes()[:500]), pipe, samples.nbytes)  # the fork died after 250 samples
    _send(pipe, (len(samples), ["events"]))
    _relay(io.BytesIO(samples.tobytes()), pipe, samples.nbytes)
    pipe.seek(0)
    assert _read_reply(pipe) == "the synthesising process died"
    buffer, events = _read_reply(pipe)
    assert events == ["events"] and np.array_equal(buffer.samples(), samples)
    assert pipe.read() == b""
