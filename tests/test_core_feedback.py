"""BML feedback values and the feedback log on hand-built cases."""

from __future__ import annotations

import json
import math

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
