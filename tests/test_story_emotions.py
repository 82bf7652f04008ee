"""Emotion tags in stories (``[emotion:joy]``, ``[emotion:fear,6.5]``): what each lasts, the BML they compile
to (pegged to the speech's own marks when the utterance is known, so the gestures keep their timing), and the
shipped story that has them."""

from __future__ import annotations

import pytest

from agentsim.realizer import Realizer
from scenarios.storytelling import run as story_run
from scenarios.storytelling.markup import Emotion, StoryError, compile_bml, parse_story, read_story
from speech_timing.backend import SpeechText
from speech_timing.builtin import BuiltinBackend

STORY = """@title Two moods
[emotion:joy]Once [beat]upon a time [emotion:fear,6.5]a [beat]wolf came.

The [emotion:glee,3]end [beat]came.

[nod]Then [emotion:anger,11]all was [beat]quiet.
"""


def test_an_emotion_lasts_until_the_next_tag_or_its_paragraphs_end():
    story = parse_story(STORY)
    assert [g.word for g in story.gestures] == [1, 5, 9, 10, 13]
    assert story.emotions == [Emotion("joy", "", 0, 4), Emotion("fear", "6.5", 4, 7), Emotion("glee", "3", 8, 10),
                              Emotion("anger", "11", 11, None)]
    again = parse_story(story.to_markup())
    assert [(e.kind, e.intensity, e.word) for e in again.emotions] == [(e.kind, e.intensity, e.word)
                                                                      for e in story.emotions]
    with pytest.raises(StoryError, match="malformed tag"):
        parse_story("[emotion:]Once upon a time.")


def test_the_emotions_compile_to_ex_emotion_and_bad_ones_are_warnings():
    story = parse_story(STORY)
    bml = compile_bml(story, anchor="word", release=False)
    assert 'xmlns:ex="urn:agentsim:expression"' in bml
    assert '<ex:emotion id="emotion1" type="joy" start="speech1:w0" end="speech1:w4"/>' in bml
    assert '<ex:emotion id="emotion4" type="anger" intensity="11" start="speech1:w11" end="speech1:end"/>' in bml
    assert '<text><sync id="w0"/>Once' in bml and '<sync id="w4"/>a ' in bml  # an emotion's word: a mark
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(bml)
    realizer.run()
    warnings = [f for f in realizer.feedback.items if f["type"] == "warningFeedback"]
    assert len(warnings) == 2 and "'glee'" in warnings[0]["description"] and "11" in warnings[1]["description"]
    times = {r.id: (r.times[0], r.times[-1]) for r in realizer.recording().behaviours if r.behaviour.type == "emotion"}
    assert sorted(times) == ["emotion1", "emotion2"]
    assert times["emotion1"][1] == times["emotion2"][0]
    # without emotions, the same BML as before
    plain = parse_story(STORY.replace("[emotion:joy]", "").replace("[emotion:fear,6.5]", "")
                        .replace("[emotion:glee,3]", "").replace("[emotion:anger,11]", ""))
    assert "ex:" not in compile_bml(plain, anchor="word", release=False)


def test_with_the_utterance_emotions_are_pegged_to_the_speechs_own_marks():
    story = parse_story(STORY)
    backend = BuiltinBackend()
    timeline = backend.synthesize(SpeechText(story.text))
    with_emotions = compile_bml(story, timeline=timeline, anchor="offset")
    plain = parse_story(STORY.replace("[emotion:fear,6.5]", "").replace("[emotion:joy]", "")
                        .replace("[emotion:glee,3]", "").replace("[emotion:anger,11]", ""))
    without = compile_bml(plain, timeline=timeline, anchor="offset")
    text = [line for line in with_emotions.splitlines() if "<speech" in line]
    assert text == [line for line in without.splitlines() if "<speech" in line]  # the same marks
    # 'a', where fear starts: the last mark before it (the beat's release on 'upon') plus the rest
    line = next(x for x in with_emotions.splitlines() if 'id="emotion2"' in x)
    ref = line.split('start="')[1].split('"')[0]
    mark, _, offset = ref.partition("+")
    assert mark.startswith("speech1:w1.d")
    release = int(mark.rpartition(".d")[2]) / 1000  # the mark's time after the word's onset, as its name says
    assert float(offset) == pytest.approx(timeline.words[4].start - timeline.words[1].start - release, abs=2e-6)


def test_the_shipped_story_with_emotions_is_shorter_than_the_default():
    wolf = read_story(story_run.STORIES_DIR / "the_boy_who_cried_wolf.story")
    default = read_story(story_run.resolve_story(None))
    assert default.title == "The Lamp on Heron Hill" and len(wolf.words) < len(default.words)
    kinds = {e.kind for e in wolf.emotions}
    assert {"joy", "fear", "anger", "neutral"} <= kinds and len(wolf.gestures) >= 60


def test_the_storyteller_writes_the_environment_with_any_backend(tmp_path, capsys):
    import csv

    import soundfile

    from agentsim.cli import main

    (tmp_path / "two.story").write_text("@title Two moods\n[emotion:joy,3]The [beat]wind and the [beat]sun were "
                                        "glad.\n\n[emotion:fear,6.5]Then the [beat]storm came [beat]down.\n")
    (tmp_path / "none.story").write_text("@title None\nThe [beat]wind and the [beat]sun were glad.\n")
    for name, extra in (("two", []), ("none", []), ("off", ["--no-environment"])):
        story = "none" if name == "none" else "two"
        assert main(["run", "storytelling", "--story", str(tmp_path / f"{story}.story"), "--tts", "builtin",
                     "--no-pictures", "--out", str(tmp_path / name), *extra]) == 0
    capsys.readouterr()
    with open(tmp_path / "two" / "environment.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["emotion"], r["shot"], r["angle"], r["valence"]) for r in rows] == [
        ("none", "full", "eye", "none"), ("joy", "close-up", "eye", "positive"),
        ("fear", "extreme-close-up", "high", "negative"), ("none", "full", "eye", "none")]
    music, rate = soundfile.read(tmp_path / "two" / "music.wav", dtype="int16")
    narration, _ = soundfile.read(tmp_path / "two" / "narration.wav", dtype="int16")
    assert rate == 22050 and len(music) > rate and (music == narration).all()  # the built-in voice is silent
    for name in ("none", "off"):  # no emotion, or the channels left out: no environment, no music, no narration
        assert not any((tmp_path / name / f).exists() for f in ("environment.csv", "music.wav", "narration.wav"))
    assert "ex:emotion" in (tmp_path / "off" / "story.bml").read_text()
