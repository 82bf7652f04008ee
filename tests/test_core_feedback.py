"""BML feedback values and the feedback log on hand-built cases."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from agentsim.core import feedback as fb


def test_feedback_has_the_bml_names():
    assert fb.block_progress("b", "start", 1.5, "agent") == {
        "type": "blockProgress", "id": "b:start", "globalTime": 1.5, "characterId": "agent"}
    assert fb.sync_point_progress("b", "g", "stroke", 0.5, 2.0, "agent") == {
        "type": "syncPointProgress", "id": "b:g:stroke", "time": 0.5, "globalTime": 2.0, "characterId": "agent"}
    w = fb.warning("b:g", "IMPOSSIBLE_TO_SCHEDULE", "why", 3.0, "agent", ["g"], line=4, column=7)
    assert (w["warningType"], w["modifiedBehaviours"], w["line"], w["column"]) == ("IMPOSSIBLE_TO_SCHEDULE", ["g"], 4, 7)
    assert "line" not in fb.warning("b", "PARSING_FAILURE", "why", 0.0, "agent")
    with pytest.raises(ValueError):
        fb.warning("b", "NOT_A_TYPE", "why", 0.0, "agent")
    p = fb.prediction("b", 1.0, "agent", 0.0, 2.5, [{"id": "g"}])
    assert p["bml"] == {"id": "b", "globalStart": 0.0, "globalEnd": 2.5} and p["behaviours"] == [{"id": "g"}]


def test_json_lines_have_no_nan_or_infinity():
    p = fb.prediction("b", 0.0, "agent", 0.0, math.inf, [{"id": "g", "syncs": {"a": math.nan, "b": 1.0}}])
    line = fb.to_json(p)
    assert "NaN" not in line and "Infinity" not in line
    back = json.loads(line)
    assert back["bml"]["globalEnd"] is None and back["behaviours"][0]["syncs"] == {"a": None, "b": 1.0}


def test_the_log_keeps_order_and_tells_every_listener():
    log = fb.FeedbackLog()
    heard: list[tuple[str, str]] = []
    log.listen(lambda f: heard.append(("one", f["id"])))
    log.listen(lambda f: heard.append(("two", f["id"])))
    log.send(fb.block_progress("b", "start", 0.0, "agent"))
    log.send(fb.sync_point_progress("b", "g", "end", 1.0, 1.0, "agent"))
    log.send(fb.warning("b", "PARSING_FAILURE", "x", 1.0, "agent"))
    assert heard == [("one", "b:start"), ("two", "b:start"), ("one", "b:g:end"), ("two", "b:g:end"),
                     ("one", "b"), ("two", "b")]
    assert log.sync_times() == {"b:g:end": 1.0}
    assert [w["id"] for w in log.warnings()] == ["b"] and len(log.of_type("blockProgress")) == 1


def _written_by_the_encoder(feedback) -> str:
    """What :func:`~agentsim.core.feedback.to_json` writes of any feedback, made the plain way."""
    return fb._ENCODER.encode(fb._clean(feedback))


def _prediction(rng, n: int, time) -> dict:
    entries = []
    for i in range(n):
        syncs = {s: time() for s in ("start", "w0.stress", "strokeStart", "stroke", "strokeEnd", "relax", "end")[
            :int(rng.integers(1, 8))]}
        entry = {"id": f"b{i}" if i % 7 else f"b{i}.", "type": ("gesture", "head", "speech")[i % 3],
                 "globalStart": time(), "globalEnd": time(), "syncs": syncs}
        if i % 4 == 0:
            entry["lexeme"] = "BEAT"
        entries.append(entry)
    return fb.prediction("bench", float(rng.uniform(0, 5)), "agent", time(), time(), entries)


def test_a_large_prediction_is_written_as_the_encoder_writes_it():
    """A prediction of many behaviours is written by a quicker path (two string formattings); it writes what
    the encoder writes of every time rounded to the nanosecond, from times of every size it takes (and at
    the edges of that range: 1e-4, 1e6, zeros, ties at the tenth decimal, the largest that round up), and
    leaves to the encoder what it does not take: the same text either way."""
    rng = np.random.default_rng(7)
    edges = [0.0, -0.0, 1e-4, -1e-4, 0.00010000000049, 0.0001000000005, 9.9999999e-05, 4.9e-10, 5e-10, -5e-10,
             0.0009765625, 1.0009765625, 2.5e-9, 999999.9999999994, -999999.999999999, 3.0, 12.5, 1e-9 * 3,
             0.1 + 0.2, 1200.451496599, 1.421269841 + 0.05]
    kinds = [
        lambda: float(rng.uniform(0, 2000)),
        lambda: float(rng.uniform(-5, 5)),
        lambda: float(10.0 ** rng.uniform(-4, 6)) * float(rng.choice([-1, 1])),
        lambda: round(float(rng.uniform(0, 100)), int(rng.integers(0, 12))) + float(rng.choice([0.0, 5e-10, -5e-10])),
        lambda: float(int(rng.integers(0, 2 ** 20)) / 1024.0),  # (binary fractions: exact ties at the 10th place)
        lambda: float(rng.choice(edges)),
    ]
    taken = 0
    for k in range(300):
        kind = kinds[k % len(kinds)]
        feedback = _prediction(rng, int(rng.integers(16, 60)), kind)
        quick = fb._prediction_json(feedback, feedback["behaviours"])
        assert fb.to_json(feedback) == _written_by_the_encoder(feedback)
        if quick is not None:
            taken += 1
            assert quick == _written_by_the_encoder(feedback)
    assert taken >= 200  # (the quick path wrote most of them: those without a time under 1e-4)


@pytest.mark.parametrize("change", ["nan", "inf", "int", "bool", "numpy", "million", "small", "id %", "id .,",
                                    "lexeme", "removed", "key", "sync name", "not a dict", "order"])
def test_a_prediction_the_quick_path_does_not_take_is_written_by_the_encoder(change):
    rng = np.random.default_rng(3)
    feedback = _prediction(rng, 20, lambda: float(rng.uniform(0, 10)))
    entry = feedback["behaviours"][5]
    if change in ("nan", "inf"):
        entry["syncs"]["start"] = math.nan if change == "nan" else -math.inf
    elif change in ("int", "bool", "numpy"):
        entry["globalEnd"] = {"int": 3, "bool": True, "numpy": np.float64(2.123456789123)}[change]
    elif change in ("million", "small"):
        entry["globalStart"] = 1e6 if change == "million" else 2.5e-5
    elif change in ("id %", "id ."):
        entry["id"] = "b%s5" if change == "id %" else "b.,5"
    elif change == "lexeme":
        entry["lexeme"] = 7
    elif change == "removed":
        feedback["behaviours"].append({"id": "b9", "type": "gesture", "status": "removed"})
    elif change == "key":
        entry["extra"] = "x"
    elif change == "sync name":
        entry["syncs"] = {1: 0.5, "end": 1.0}
    elif change == "not a dict":
        feedback["behaviours"][5] = ["b5"]
    else:
        feedback = {"id": feedback["id"], **feedback}
    assert fb._prediction_json(feedback, feedback["behaviours"]) is None
    assert fb.to_json(feedback) == _written_by_the_encoder(feedback)
