"""The virtual storyteller: annotation format, TextGrid import, phoneme-level marks, and telling a story."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from agentsim.bml.parser import parse_bml
from agentsim.errors import AgentsimError
from agentsim.realizer import Realizer
from agentsim.cli import build_parser
from agentsim.cli import main as cli_main
from scenarios.storytelling import run as story_run
from scenarios.storytelling.markup import StoryError, compile_bml, parse_story, read_story
from scenarios.storytelling.praat import export_textgrid, import_textgrid
from scenarios.storytelling.telling import DEFAULT_DELIVERY, make_voice, stress_offsets, syllable_times, tell
from scenarios.storytelling.voice import CachedBackend, PhonemeMarks, mark_event, place_mark
from speech_timing.backend import Phoneme, SpeechText, Utterance, Word

NS = "http://www.bml-initiative.org/bml/bml-1.0"
SHORT = "the_north_wind_and_the_sun"


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("tts-cache")


@pytest.fixture(scope="module")
def voice(cache_dir):
    """espeak-ng behind a private cache, with phoneme-level marks."""
    return make_voice("espeak", cache_dir=cache_dir)


class _Fixed:
    """A backend that always says the same hand-made utterance."""

    name = "fixed"

    def __init__(self, utterance: Utterance):
        self.utterance = utterance

    def synthesize(self, speech: SpeechText) -> Utterance:
        assert speech.text == self.utterance.text
        return self.utterance


def _timeline() -> Utterance:
    """'Once upon a time, a lamp.' with hand-made times (s); stressed vowels marked."""
    text = "Once upon a time, a lamp."
    spans = [(0, 4), (5, 9), (10, 11), (12, 16), (18, 19), (20, 24)]
    times = [(0.10, 0.40), (0.40, 0.70), (0.70, 0.75), (0.75, 1.10), (1.30, 1.35), (1.35, 1.80)]
    phonemes = [("w", 0.10, 0, False), ("ʌ", 0.15, 0, True), ("n", 0.30, 0, False), ("s", 0.35, 0, False),
                ("ə", 0.40, 1, False), ("p", 0.45, 1, False), ("ɒ", 0.50, 1, True), ("n", 0.62, 1, False),
                ("ə", 0.70, 2, False),
                ("t", 0.75, 3, False), ("aɪ", 0.82, 3, True), ("m", 1.00, 3, False),
                ("ə", 1.30, 4, False),
                ("l", 1.35, 5, False), ("a", 1.42, 5, True), ("m", 1.60, 5, False), ("p", 1.70, 5, False)]
    words = [Word(i, text[a:b], s, e, a, b) for i, ((a, b), (s, e)) in enumerate(zip(spans, times))]
    ends = [p[1] for p in phonemes[1:]] + [1.80]
    return Utterance(text, 2.0, words, [Phoneme(sym, t, end, k, st) for (sym, t, k, st), end in zip(phonemes, ends)])


# ----------------------------------------------------------------------------------------------------
# The annotation format and its compiler.


def test_markup_compiles_to_exactly_this_bml():
    story = parse_story("@title Tiny\n# a comment\n@scene well 0.5 0.8 1.5  # by the road\n"
                        "[gaze:audience]Once upon a [nod][beat]time,\n"
                        "in a [icon:chop:both]small [brows]grey [point:left]village.")
    assert story.title == "Tiny" and story.text == "Once upon a time, in a small grey village."
    assert story.scene == {"well": (0.5, 0.8, 1.5)}
    assert [(g.kind, g.word) for g in story.gestures] == [
        ("gaze", 0), ("nod", 3), ("beat", 3), ("icon", 6), ("brows", 7), ("point", 8)]
    assert story.counts() == {"gaze": 1, "nod": 1, "beat": 1, "icon": 1, "brows": 1, "point": 1}
    assert compile_bml(story) == (
        f'<bml xmlns="{NS}" id="story" characterId="storyteller">\n'
        '  <speech id="speech1" start="1"><text><sync id="w0.stress"/>Once upon a <sync id="w3.stress"/>time, '
        'in a <sync id="w6.stress"/>small <sync id="w7.stress"/>grey <sync id="w8.stress"/>village.</text></speech>\n'
        '  <gazeShift id="gaze1" target="audience" end="speech1:w0.stress"/>\n'
        '  <head id="nod1" lexeme="NOD" stroke="speech1:w3.stress"/>\n'
        '  <gesture id="beat1" lexeme="BEAT" stroke="speech1:w3.stress"/>\n'
        '  <gesture id="icon1" lexeme="CHOP" mode="BOTH_HANDS" stroke="speech1:w6.stress"/>\n'
        '  <faceLexeme id="brows1" lexeme="RAISE_BROWS" attackPeak="speech1:w7.stress"/>\n'
        '  <pointing id="point1" target="left" stroke="speech1:w8.stress"/>\n'
        '</bml>\n')
    # The realizer's parser sees the same text, with each mark right before its word.
    block = parse_bml(compile_bml(story, anchor="word"))
    speech = block.behaviours[0]
    assert speech.text == story.text
    assert [(story.text[o:].split(" ")[0], name) for o, name in speech.marks] == [
        ("Once", "w0"), ("time,", "w3"), ("small", "w6"), ("grey", "w7"), ("village.", "w8")]
    assert len(block.behaviours) == 1 + len(story.gestures) and not block.warnings


def test_release_marks_stand_in_time_order_and_offsets_come_from_the_timeline():
    story = parse_story("[beat]Once upon a [nod]time, a [point:left]lamp.")
    timeline = _timeline()
    assert compile_bml(story, timeline) == (
        f'<bml xmlns="{NS}" id="story" characterId="storyteller">\n'
        '  <speech id="speech1" start="1"><text><sync id="w0.stress"/>Once upon a <sync id="w0.stress.d500"/>'
        '<sync id="w3.stress"/>time, a <sync id="w3.stress.d300"/><sync id="w5.stress"/>lamp.</text></speech>\n'
        '  <gesture id="beat1" lexeme="BEAT" stroke="speech1:w0.stress" end="speech1:w0.stress.d500"/>\n'
        '  <head id="nod1" lexeme="NOD" stroke="speech1:w3.stress" end="speech1:w3.stress.d300"/>\n'
        '  <pointing id="point1" target="left" stroke="speech1:w5.stress"/>\n'  # its end would be after the speech
        '</bml>\n')
    offset_bml = compile_bml(story, timeline, anchor="offset")
    assert 'stroke="speech1:w0+0.050000" end="speech1:w0.d550"' in offset_bml
    assert 'stroke="speech1:w3+0.070000" end="speech1:w3.d370"' in offset_bml
    assert stress_offsets(story, timeline) == pytest.approx({0: 0.05, 3: 0.07, 5: 0.07})
    # Played exactly as planned, every stroke is on its stressed vowel and every end where it was tied.
    realizer = Realizer(tts=PhonemeMarks(_Fixed(timeline)))
    realizer.submit(compile_bml(story, timeline))
    realizer.run()
    times = realizer.feedback.sync_times()
    assert not realizer.feedback.warnings()
    assert times["story:beat1:stroke"] == pytest.approx(1.15, abs=1e-9)
    assert times["story:beat1:end"] == pytest.approx(1.65, abs=1e-9)
    assert times["story:nod1:stroke"] == pytest.approx(1.82, abs=1e-9)
    assert times["story:nod1:end"] == pytest.approx(2.12, abs=1e-9)
    assert times["story:point1:stroke"] == pytest.approx(2.42, abs=1e-9)


def test_markup_round_trips_and_bad_tags_say_where():
    story = read_story(story_run.STORIES_DIR / f"{SHORT}.story")
    again = parse_story(story.to_markup())
    assert again.text == story.text and again.gestures == story.gestures and again.scene == story.scene
    cases = {
        "Once [wave]upon": "1:6: unknown tag [wave]",
        "Once [point:moon]upon": "1:6: unknown target 'moon'",
        "Once [icon:juggle]upon": "1:6: unknown gesture [icon:juggle]",
        "Once\nupon [beat]": "2:6: the tag [beat] stands in front of no word",
        "Once [beat upon": "1:6: unmatched '['",
        "@scene door here\nOnce": "1:1: expected '@scene NAME X Y Z'",
        "Once [beat:sideways]upon": "1:6: malformed tag [beat:sideways]",
    }
    for source, message in cases.items():
        with pytest.raises(StoryError, match=message.replace("[", r"\[").replace("]", r"\]")):
            parse_story(source, name="s.story")
    # [point:left] points to the left; a hand is a further argument.
    g1, g2 = parse_story("[point:left]there [point:left:right]there").gestures
    assert (g1.target, g1.hand, g2.target, g2.hand) == ("left", "", "left", "RIGHT_HAND")


# ----------------------------------------------------------------------------------------------------
# Praat.


def test_textgrid_import_from_a_praatio_grid(tmp_path):
    from praatio import textgrid
    from praatio.utilities.constants import Interval, Point

    words = [("Once", 0.0, 0.3), ("upon", 0.3, 0.6), ("a", 0.6, 0.7), ("time,", 0.7, 1.1),
             ("by", 1.4, 1.6), ("the", 1.6, 1.7), ("door.", 1.7, 2.2)]
    grid = textgrid.Textgrid(0.0, 2.5)
    grid.addTier(textgrid.IntervalTier("words", [Interval(a, b, w) for w, a, b in words], 0.0, 2.5))
    grid.addTier(textgrid.PointTier("gestures", [Point(0.1, "gaze:audience"), Point(0.9, "[nod][beat]"),
                                                 Point(1.3, "brows"), Point(1.9, "point:door, point:left")], 0.0, 2.5))
    path = tmp_path / "tiny.TextGrid"
    grid.save(str(path), format="long_textgrid", includeBlankSpaces=True)
    story = import_textgrid(path, scene={"door": (0.9, 1.2, 1.3)})
    assert story.text == "Once upon a time, by the door."
    assert [g.label for g in story.gestures] == ["gaze:audience", "nod", "beat", "brows", "point:door", "point:left"]
    assert [story.word_text(g.word) for g in story.gestures] == ["Once", "time", "time", "by", "door", "door"]
    assert story.scene == {"door": (0.9, 1.2, 1.3)}
    with pytest.raises(StoryError, match="unknown target 'door'"):
        import_textgrid(path)
    with pytest.raises(StoryError, match="no tier 'gesture'"):
        import_textgrid(path, gestures_tier="gesture")


def test_textgrid_export_then_import_gives_the_story_back(tmp_path):
    story = parse_story("[beat]Once upon a [nod]time, a [point:left]lamp.")
    timeline = _timeline()
    _, planned, _ = syllable_times(story, timeline)
    assert list(planned) == [0.15, 0.82, 1.42]
    path = export_textgrid(tmp_path / "t.TextGrid", story, timeline, planned, planned + 0.001, ["a", "b", "c"])
    again = import_textgrid(path)
    assert again.text == story.text and again.gestures == story.gestures
    from praatio import textgrid

    grid = textgrid.openTextgrid(str(path), includeEmptyIntervals=False)
    assert grid.tierNames == ("words", "phones", "gestures", "strokes")
    assert [e.label for e in grid.getTier("phones").entries][:2] == ["w", "ʌˈ"]
    assert [e.label for e in grid.getTier("strokes").entries] == ["a +1.0ms", "b +1.0ms", "c +1.0ms"]


# ----------------------------------------------------------------------------------------------------
# The voice.


def test_phoneme_marks_and_the_cache(tmp_path):
    timeline = _timeline()
    assert mark_event("w3.stress.d250") == ("w3", "stress", None, 0.25)
    assert place_mark(timeline, 12, "w3") == 0.75
    assert place_mark(timeline, 12, "w3.stress") == 0.82
    assert place_mark(timeline, 12, "w3.end") == 1.10
    assert place_mark(timeline, 12, "w3.ph2") == 1.00
    assert place_mark(timeline, 11, "w3.stress.d250") == pytest.approx(1.07)
    assert place_mark(timeline, 18, "x.stress") == 1.30  # no stressed vowel: the word's onset
    from speech_timing.builtin import BuiltinBackend

    first = CachedBackend(BuiltinBackend(), cache_dir=tmp_path)
    speech = SpeechText("Tell me a story.", ((8, "m1"),))
    a = first.synthesize(speech)
    second = CachedBackend(BuiltinBackend(), cache_dir=tmp_path)
    b = second.synthesize(speech)
    assert (first.misses, second.hits, second.misses) == (1, 1, 0)
    assert a.words == b.words and a.phonemes == b.phonemes and a.marks == b.marks
    assert b.marks[0].time == b.words[2].start


def test_the_cache_keeps_the_timeline_in_columns_in_samples_where_they_are_exact(tmp_path):
    """A cache entry is two lines of JSON: what the speech is, then its timeline, the words and phonemes as
    columns, their times as whole samples when each is one (read back as the same seconds), else as seconds; the
    first line says the second's length and CRC-32. An entry of another layout, or whose timeline is not the one
    written (columns of unequal lengths), is synthesised again."""
    import json
    import zlib
    from dataclasses import replace

    from scenarios.storytelling.voice import CACHE_FORMAT
    from speech_timing.builtin import BuiltinBackend

    class OnSamples(BuiltinBackend):  # every time a whole number of samples, as espeak-ng gives them
        def synthesize(self, speech):
            utterance = super().synthesize(speech)
            rate = utterance.sample_rate
            return replace(utterance, words=[replace(w, start=round(w.start * rate) / rate, end=round(w.end * rate) / rate)
                                             for w in utterance.words],
                           phonemes=[replace(p, start=round(p.start * rate) / rate, end=round(p.end * rate) / rate)
                                     for p in utterance.phonemes])

    text = "Tell me a story."
    for backend, times in ((BuiltinBackend(), "seconds"), (OnSamples(), "samples")):
        folder = tmp_path / times
        said = CachedBackend(backend, cache_dir=folder).utterance(text)
        (entry,) = folder.glob("*.json")
        head, line = entry.read_bytes().split(b"\n")
        meta, timeline = json.loads(head), json.loads(line)
        assert (meta["format"], meta["times"], CACHE_FORMAT) == (3, times, 3)
        assert meta["timeline"] == [len(line), zlib.crc32(line)] and "words" not in meta
        assert list(timeline["words"]) == ["index", "text", "start", "end", "char_start", "char_end"]
        assert list(timeline["phonemes"]) == ["symbol", "start", "end", "word_index", "stressed"]
        assert timeline["words"]["text"] == ["Tell", "me", "a", "story"] and len(timeline["phonemes"]["symbol"]) == len(
            said.phonemes) > 4
        rate = said.sample_rate
        assert timeline["phonemes"]["start"] == [round(p.start * rate) if times == "samples" else p.start
                                                 for p in said.phonemes]
        if times == "seconds":  # (the built-in model's times fall between samples)
            assert any(round(p.start * rate) / rate != p.start for p in said.phonemes)
        again = CachedBackend(backend, cache_dir=folder)
        read = again.utterance(text)
        assert again.hits == 1 and read == said
        assert [type(p.stressed) for p in read.phonemes] == [bool] * len(said.phonemes)
        unequal = json.dumps({**timeline, "phonemes": {**timeline["phonemes"],
                                                       "end": timeline["phonemes"]["end"][:-1]}}).encode()
        for spoilt in (json.dumps({**meta, **timeline, "format": 2}).encode(),  # the layout before
                       head + b"\n" + unequal,
                       json.dumps({**meta, "times": "frames"}).encode() + b"\n" + line,
                       head + b"\n" + line[:-1] + b" ",
                       head):
            entry.write_bytes(spoilt)
            third = CachedBackend(backend, cache_dir=folder)
            assert third.utterance(text) == said and (third.hits, third.misses) == (0, 1)
        forged = json.dumps({**meta, "timeline": [len(unequal), zlib.crc32(unequal)]}).encode() + b"\n" + unequal
        entry.write_bytes(forged)  # (a timeline written otherwise than by the cache, and its check with it)
        with pytest.raises(AgentsimError, match="speech cache entry .* is damaged"):
            CachedBackend(backend, cache_dir=folder).utterance(text).phonemes


def test_an_utterance_read_from_the_cache_makes_its_timeline_when_asked_and_is_one_like_any(tmp_path):
    """A cached utterance's words and phonemes are made the first time they are read (a block's schedule needs
    its speeches' lengths and marks only); it equals the utterance said, both ways, and is replaced, copied and
    pickled as that one is."""
    import copy
    import pickle
    from dataclasses import asdict, replace

    from scenarios.storytelling.voice import ReadUtterance
    from speech_timing.backend import Utterance, Word
    from speech_timing.builtin import BuiltinBackend

    speech = SpeechText("Tell me a story, slowly.")
    made = CachedBackend(BuiltinBackend(), cache_dir=tmp_path).synthesize(speech)
    said = Utterance(**{name: getattr(made, name) for name in Utterance.__dataclass_fields__})  # (a plain one)
    read = CachedBackend(BuiltinBackend(), cache_dir=tmp_path).utterance(speech.text)
    assert type(read) is ReadUtterance
    assert not {"_words", "_phonemes", "_timeline_rows"} & set(vars(read))  # nothing read yet
    assert read == made == said
    assert read.duration == said.duration and read.sentences == said.sentences
    assert read == said and said == read and not (read != said)
    assert vars(read)["_words"] == said.words and vars(read)["_phonemes"] == said.phonemes
    assert "_timeline_rows" not in vars(read) and "_timeline" not in vars(read)  # (read, then let go)
    assert read.words is read.words  # made once
    for other in (replace(read), copy.deepcopy(read), pickle.loads(pickle.dumps(read))):
        assert other == said and asdict(other) == asdict(said)
    assert read.word_after(5) == said.word_after(5) == 1 and read.phonemes_of(3) == said.phonemes_of(3)
    moved = replace(read, words=[replace(w, start=w.start + 1.0) for w in read.words])
    assert moved != said and moved.words[0].start == said.words[0].start + 1.0 and moved.phonemes == said.phonemes
    fresh = CachedBackend(BuiltinBackend(), cache_dir=tmp_path).utterance(speech.text)
    fresh.words = [Word(0, "Hi", 0.0, 0.1, 0, 2)]  # set before ever read: the timeline is not read for it
    assert [w.text for w in fresh.words] == ["Hi"] and "_timeline_rows" not in vars(fresh) and fresh.phonemes == said.phonemes
    assert read != replace(said, duration=said.duration + 1.0)


def test_the_cached_audio_is_read_back_as_it_was_said(tmp_path, monkeypatch):
    """The 16-bit samples of a cache file come back as the float32 samples that were cached (read a block at
    a time); a file cut short is not used: the text is synthesised again."""
    from dataclasses import replace

    from scenarios.storytelling import voice as voice_module
    from speech_timing.builtin import BuiltinBackend
    from speech_timing.samples import PcmFile

    class Sounding(BuiltinBackend):
        def synthesize(self, speech):
            utterance = super().synthesize(speech)
            n = int(utterance.duration * utterance.sample_rate)
            samples = np.random.default_rng(1).integers(-32768, 32768, n).astype(np.float32) / np.float32(32768.0)
            return replace(utterance, audio=samples)

    monkeypatch.setattr(voice_module, "READ_BLOCK", 1000)  # several blocks
    speech = SpeechText("Tell me a story.")
    a = CachedBackend(Sounding(), cache_dir=tmp_path).synthesize(speech)
    assert len(a.audio) > 5000
    second = CachedBackend(Sounding(), cache_dir=tmp_path)
    b = second.synthesize(speech)
    assert second.hits == 1 and b.audio.dtype == np.float32 and np.array_equal(a.audio, b.audio)
    # once cached, the samples are read from the file as they are needed, a stretch at a time
    said = np.asarray(a.audio)
    assert isinstance(b.audio, PcmFile) and isinstance(a.audio, PcmFile)
    assert np.array_equal(said, Sounding().synthesize(speech).audio)
    assert np.array_equal(b.audio[1234:5678], said[1234:5678]) and b.audio[-1] == said[-1]
    assert np.array_equal(b.audio[np.arange(4000, 4100)], said[4000:4100])
    (audio_file,) = tmp_path.glob("*.npy")
    audio_file.write_bytes(audio_file.read_bytes()[:-100])
    third = CachedBackend(Sounding(), cache_dir=tmp_path)
    assert np.array_equal(third.synthesize(speech).audio, said) and (third.hits, third.misses) == (0, 1)


# ----------------------------------------------------------------------------------------------------
# Telling.


def test_strokes_are_planned_on_the_stressed_vowels_espeak_says(voice):
    story = parse_story("Long [beat]ago an [beat]old [point:left]lighthouse [beat]keeper [nod]remembered a "
                        "[beat]forgotten [brows]tomorrow, [beat]alone.")
    utterance = voice.synthesize(SpeechText(story.text))
    expected = {}
    for g in story.gestures:
        word = next(w for w in utterance.words if w.char_start == story.words[g.word][0])
        phonemes = [p for p in utterance.phonemes if p.word_index == word.index]
        stressed = next(p for p in phonemes if p.stressed)
        expected[g.word] = (word.start, stressed.start)
    # 'remembered', 'forgotten', 'tomorrow' and 'alone' are stressed on their second syllable.
    for g in story.gestures[4:]:
        assert expected[g.word][1] - expected[g.word][0] > 0.08, story.word_text(g.word)
    assert stress_offsets(story, utterance) == {k: s - o for k, (o, s) in expected.items()}
    offset_bml = compile_bml(story, utterance, anchor="offset")
    for k, (o, s) in expected.items():
        assert f'"speech1:w{k}{s - o:+.6f}"' in offset_bml
    # The planner's sync points are the stressed vowels, and played as planned the strokes land on them.
    realizer = Realizer(tts=voice)
    realizer.submit(compile_bml(story, utterance, block_id="story"))
    realizer.run()
    speech = realizer.scheduler.book.all_runs[0].timed[0]
    strokes = realizer.feedback.sync_times()
    for n, g in enumerate(story.gestures):
        planned = speech.preferred[speech.sync_ids.index(f"w{g.word}.stress")]
        assert planned == expected[g.word][1]
        gid = f"{g.kind}{sum(1 for h in story.gestures[:n + 1] if h.kind == g.kind)}"
        sync = "attackPeak" if g.kind == "brows" else "stroke"
        assert strokes[f"story:{gid}:{sync}"] == pytest.approx(1.0 + expected[g.word][1], abs=1e-9)
    assert not realizer.feedback.warnings()


def test_a_short_story_meets_the_sync_target_and_is_deterministic(voice):
    story = read_story(story_run.STORIES_DIR / f"{SHORT}.story")
    telling = tell(story, "best", DEFAULT_DELIVERY, seed=3, voice=voice)
    m = telling.metrics()
    assert m["gestures"] == len(story.gestures) >= 60 and m["missed"] == 0 and m["warnings"] == 0
    assert m["sync_error_ms"]["p95"] <= 15.0 and m["snaps"] == 0
    # Gesture ends follow the speech too: every beat's stroke-to-end is its preferred 0.5 s.
    beats = [b for b in telling.recording.behaviours if b.id.startswith("beat")]
    assert beats and all(b.state == "finished" for b in beats)
    assert all(abs(b.time("end") - b.time("stroke") - 0.5) < 0.01 for b in beats)
    again = tell(story, "best", DEFAULT_DELIVERY, seed=3, voice=voice)
    other = tell(story, "best", DEFAULT_DELIVERY, seed=4, voice=voice)
    assert np.array_equal(again.passed, telling.passed)
    assert again.realizer.feedback.items == telling.realizer.feedback.items
    assert not np.array_equal(other.passed, telling.passed)
    # Tied to the word onset instead, strokes miss the stressed syllable of many-syllable words.
    word = tell(story, "best", DEFAULT_DELIVERY, seed=3, voice=voice, anchor="word").metrics()
    assert word["sync_error_ms"]["p95"] > 5 * m["sync_error_ms"]["p95"]


def _args(tmp_path, cache_dir, **changes) -> argparse.Namespace:
    args = build_parser().parse_args(["run", "storytelling", "--story", SHORT, "--out", str(tmp_path),
                                      "--cache", str(cache_dir), "--fps", "30", "--window", "8"])
    args.delivery = DEFAULT_DELIVERY
    for key, value in changes.items():
        setattr(args, key, value)
    return args


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_the_command_writes_every_output_and_repeats_itself(tmp_path, cache_dir, capsys):
    first, second = tmp_path / "a", tmp_path / "b"
    assert story_run.main(_args(first, cache_dir)) == 0
    assert "The North Wind and the Sun: 152 words" in capsys.readouterr().out
    for name in ("metrics.json", "narration.wav", "story.bvh", "timeline.png", "sync_errors.png",
                 "story.TextGrid", "feedback.jsonl", "story.bml"):
        assert (first / name).stat().st_size > 0, name
    m = json.loads((first / "metrics.json").read_text())
    for key in ("story", "words", "gestures", "duration_s", "strategy", "sync_error_ms", "wall_seconds", "snaps"):
        assert key in m
    assert m["strategy"] == "best" and m["gestures"] == 65 and m["sync_error_ms"]["p95"] <= 15.0
    assert set(m["sync_error_ms"]) >= {"p50", "p95", "max"}
    assert m["motion_strokes"]["intact"] >= 0.9 * m["motion_strokes"]["measured"]
    # timeline.png is the overview; each --window seconds of the story has its own picture
    windows = sorted(p.name for p in first.glob("timeline_*s.png"))
    assert windows[:2] == ["timeline_0000-0008s.png", "timeline_0008-0016s.png"]
    assert len(windows) >= m["duration_s"] / 8
    lines = (first / "feedback.jsonl").read_text().splitlines()
    assert all(json.loads(line)["type"] for line in lines)
    assert import_textgrid(first / "story.TextGrid", scene=read_story(
        story_run.STORIES_DIR / f"{SHORT}.story").scene).gestures == read_story(
        story_run.STORIES_DIR / f"{SHORT}.story").gestures
    assert (first / "story.bvh").read_text().startswith("HIERARCHY")
    # Again with --compare on the same seed: the same figures for best (in its folder, beside every other
    # strategy's), and a table of every strategy; with --json that table goes to stderr and stdout is
    # compare.json alone.
    assert story_run.main(_args(second, cache_dir, compare=True, json=True)) == 0
    printed = capsys.readouterr()
    from speech_timing.animator_time import STRATEGIES

    assert all(f"\n{name} " in printed.err for name in STRATEGIES)
    assert json.loads(printed.out) == json.loads((second / "compare.json").read_text())
    assert sorted(p.name for p in second.iterdir()) == sorted([*STRATEGIES, "compare.json"])
    again = json.loads((second / "best" / "metrics.json").read_text())
    timing = {"wall_seconds", "wall_fraction_of_story", "stages_seconds", "simulation_seconds", "synthesis_seconds",
              "cache_load_seconds", "compare_wall_seconds", "cached"}
    assert again["cached"] is True  # the story's speech came from the cache
    assert {k: v for k, v in again.items() if k not in timing} == {k: v for k, v in m.items() if k not in timing}
    for name in ("feedback.jsonl", "story.bvh", "story.TextGrid", "story.bml"):
        assert (first / name).read_bytes() == (second / "best" / name).read_bytes(), name
    table = json.loads((second / "compare.json").read_text())["strategies"]
    assert table["best"]["p95_ms"] == m["sync_error_ms"]["p95"] < table["open-loop"]["p95_ms"]


def test_a_missing_story_fails_before_anything_runs(tmp_path, cache_dir):
    out = tmp_path / "never"
    with pytest.raises(AgentsimError, match="no story file or shipped story 'no_such_story'; shipped stories: "):
        story_run.main(_args(out, cache_dir, story="no_such_story"))
    with pytest.raises(AgentsimError, match="no story file or shipped story"):
        story_run.main(_args(out, cache_dir, story=str(tmp_path / "gone.story")))
    assert not out.exists()
    assert cli_main(["run", "storytelling", "--story", "no_such_story", "--out", str(out)]) == 2  # a usage error
    assert not out.exists()


def test_the_default_story_is_the_longest_shipped_one_and_long_enough():
    path = story_run.resolve_story(None)
    story = read_story(path)
    assert path.stem == "the_lamp_on_heron_hill"
    assert len(story.words) >= 900 and len(story.gestures) >= 250
    counts = story.counts()
    assert all(counts.get(kind, 0) > 0 for kind in ("beat", "point", "icon", "nod", "shake", "gaze", "brows"))
    assert not any(math.isnan(x) for p in story.scene.values() for x in p)


def test_a_story_without_gestures_runs_quietly(tmp_path):
    import subprocess
    import sys

    story = tmp_path / "plain.story"
    story.write_text("@title Plain\nThe wind and the sun were arguing which was the stronger.\n")
    proc = subprocess.run([sys.executable, "-m", "agentsim", "run", "storytelling", "--story", str(story), "--tts",
                           "builtin", "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr  # no legend warning from an empty plot
    assert (tmp_path / "out" / "sync_errors.png").stat().st_size > 0
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["gestures"] == 0
