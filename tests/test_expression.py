"""Emotions through the environment (``ex:emotion``, :mod:`agentsim.expression`): the behaviour read and
pegged to words, the channels as the thesis's section 3.5.4 specifies them, ``environment.csv`` row by row,
bad input, and nothing of it in a run without emotions."""

from __future__ import annotations

import csv
import json

import pytest

from agentsim.cli import main
from agentsim.expression.emotions import (KEY_COLOUR, VALENCE, angle_of, attenuation_of, emotion_problem,
                                          shot_of)
from agentsim.expression.environment import COLUMNS, Felt, strongest
from agentsim.media.environment import run_environment
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

EX = 'xmlns:ex="urn:agentsim:expression"'
BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" ' + EX + ' id="b1" characterId="teller">'
       '<speech id="s1"><text>Once <sync id="w1"/>upon a time there <sync id="w2"/>was a girl who <sync id="w3"/>'
       'feared the dark but <sync id="w4"/>loved the stars.</text></speech>{}</bml>')
THREE = ('<ex:emotion id="e1" type="joy" intensity="3.2" start="s1:w1" end="s1:w2"/>'
         '<ex:emotion id="e2" type="fear" intensity="6.5" start="s1:w2" end="s1:w3"/>'
         '<ex:emotion id="e3" type="anger" intensity="1" start="s1:w3" end="s1:w4"/>')


def realize(tmp_path, monkeypatch, capsys, body: str, *extra) -> tuple[list[dict], list[dict]]:
    """Realize the speech with ``body`` beside it (the built-in backend) and write ``environment.csv``: the
    feedback and the CSV's rows."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "e.xml").write_text(BML.format(body))
    assert main(["realize", "e.xml", "--tts", "builtin", "--environment-csv", "environment.csv", *extra]) == 0
    feedback = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    with open(tmp_path / "environment.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == COLUMNS
        return feedback, list(reader)


def test_three_emotions_pegged_to_words_drive_the_channels(tmp_path, monkeypatch, capsys):
    feedback, rows = realize(tmp_path, monkeypatch, capsys, THREE)
    assert [f for f in feedback if f["type"] == "warningFeedback"] == []
    word = {f["id"].split(":")[-1]: f["globalTime"] for f in feedback
            if f["type"] == "syncPointProgress" and f["id"].startswith("b1:s1:w")}
    expected = [  # time, emotion, intensity, shot, angle, key, attenuation, valence
        (0.0, "none", "0", "full", "eye", (255, 255, 255), "0.5", "none"),
        (word["w1"], "joy", "3.2", "close-up", "eye", (255, 255, 0), "0.5", "positive"),  # min(0.5, 0.68)
        (word["w2"], "fear", "6.5", "extreme-close-up", "high", (255, 255, 255), "0.65", "negative"),
        (word["w3"], "anger", "1", "full", "low", (255, 0, 0), "0.25", "negative"),  # max(0.25, 0.1)
        (word["w4"], "none", "0", "full", "eye", (255, 255, 255), "0.5", "none"),
    ]
    assert len(rows) == len(expected)
    for row, (t, emotion, intensity, shot, angle, key, attenuation, valence) in zip(rows, expected):
        assert float(row["time"]) == pytest.approx(t, abs=1e-6)
        assert (row["emotion"], row["intensity"], row["shot"], row["angle"]) == (emotion, intensity, shot, angle)
        assert (int(row["key_r"]), int(row["key_g"]), int(row["key_b"])) == key
        assert (row["attenuation"], row["valence"]) == (attenuation, valence)
    # a piece of the valence's, chosen at its change and kept while the valence stays
    assert rows[0]["music"] == rows[4]["music"] == ""
    assert rows[1]["music"] in ("bright-morning", "market-day", "kite-in-the-wind")
    assert rows[2]["music"] == rows[3]["music"] in ("long-night", "grey-shore", "the-empty-house")


def test_the_music_chosen_follows_the_seed(tmp_path, monkeypatch, capsys):
    chosen = set()
    for seed in range(8):
        _, rows = realize(tmp_path, monkeypatch, capsys, THREE, "--seed", str(seed))
        chosen.add((rows[1]["music"], rows[2]["music"]))
        _, again = realize(tmp_path, monkeypatch, capsys, THREE, "--seed", str(seed))
        assert again == rows
    assert len(chosen) > 1


def test_the_tables_of_the_thesis():
    assert [shot_of(x) for x in (0, 1.5, 1.51, 2.5, 2.51, 4.5, 4.51, 10)] == [
        "full", "full", "medium", "medium", "close-up", "close-up", "extreme-close-up", "extreme-close-up"]
    assert [angle_of(e) for e in ("anger", "pride", "fear", "joy", "reproach")] == ["low", "low", "high", "eye", "eye"]
    assert attenuation_of("joy", 8) == pytest.approx(0.2) and attenuation_of("hope", 1) == 0.5
    assert attenuation_of("distress", 9) == pytest.approx(0.9) and attenuation_of("fear", 1) == 0.25
    assert attenuation_of("neutral", 7) == 0.5
    assert KEY_COLOUR["pride"] == KEY_COLOUR["joy"] == (255, 255, 0)
    assert KEY_COLOUR["disliking"] == (220, 255, 0) and KEY_COLOUR["distress"] == (153, 153, 153)
    assert len(VALENCE) == 14 and sorted(set(VALENCE.values())) == ["negative", "neutral", "positive"]
    # the strongest active emotion; of equals, the one started last
    felt = [Felt("joy", 3, 0, 5, 0), Felt("fear", 6, 1, 2, 1), Felt("hope", 3, 2.5, 4, 2)]
    assert [strongest(felt, t).emotion for t in (0.5, 1.5, 2.2, 3.0, 4.5)] == ["joy", "fear", "joy", "hope", "joy"]
    assert strongest(felt, 5.0) is None


def test_bad_emotions_are_one_warning_each_and_the_rest_is_realized(tmp_path, monkeypatch, capsys):
    body = THREE + ('<ex:emotion id="e4" type="glee" start="s1:w1" end="s1:w2"/>'
                    '<ex:emotion id="e5" type="joy" intensity="11" start="s1:w1" end="s1:w2"/>')
    feedback, rows = realize(tmp_path, monkeypatch, capsys, body)
    warnings = [f for f in feedback if f["type"] == "warningFeedback"]
    assert len(warnings) == 2
    assert "e4" in warnings[0]["description"] and "'glee'" in warnings[0]["description"]
    assert "e5" in warnings[1]["description"] and "outside 0-10" in warnings[1]["description"]
    assert [r["emotion"] for r in rows] == ["none", "joy", "fear", "anger", "none"]
    assert emotion_problem("joy", "nan") is not None and emotion_problem("joy", "x") is not None
    assert emotion_problem("fears-confirmed", "0") is None and emotion_problem("joy", None) is None


def test_a_run_without_emotions_has_no_environment():
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(BML.format('<gesture id="g1" lexeme="BEAT" stroke="s1:w1"/>'))
    realizer.run()
    assert run_environment(realizer.recording()) is None
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(BML.format(THREE))
    realizer.run()
    assert run_environment(realizer.recording(), enabled=False) is None
    assert len(run_environment(realizer.recording())) == 5
