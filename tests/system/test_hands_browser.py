"""The hands in the run report, in headless Chromium: the page draws every finger joint and tip where the
run's poses put them, a fist's tips near its wrist and a flat hand's far from it; a screenshot is taken."""

from __future__ import annotations

import numpy as np
import pytest

from agentsim.media.report.data import body_points, point_names
from helpers import open_run_report, seek_drawn

pytestmark = pytest.mark.system

MURML = "http://www.techfak.uni-bielefeld.de/ags/soa/murml"
BML = (f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1">'
       f'<murmlgesture xmlns="{MURML}" id="g1" start="0.3"><murml-description><parallel>'
       '<static slot="HandLocation" value="LocChest LocCenterRight LocNorm" scope="right_arm"/>'
       '<static slot="HandShape" value="BSfist" scope="right_arm"/>'
       '<static slot="HandLocation" value="LocChest LocCenterLeft LocNorm" scope="left_arm"/>'
       '<static slot="HandShape" value="ASL5" scope="left_arm"/>'
       '</parallel></murml-description></murmlgesture></bml>')
TIPS = ("index3.end", "middle3.end", "ring3.end", "pinky3.end")


def test_the_report_draws_the_hands(browser, tmp_path):
    _, recording, stream = open_run_report(BML, browser, tmp_path / "hands.html")
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
    stroke = next(f["globalTime"] for f in recording.feedback if f["id"] == "b1:g1:stroke")
    seek_drawn(browser, stroke)
    names, _ = point_names(stream.body)
    k = int(np.argmin(np.abs(stream.times - stroke)))
    want = body_points(stream.body, stream.values[k:k + 1])[0]
    hand = [n for n in names if n.split(".")[0].split("_", 1)[-1].rstrip("123") in
            ("thumb", "index", "middle", "ring", "pinky")]
    assert len(hand) == 2 * (15 + 5)  # fifteen joints and five tips a hand
    drawn = {n: np.array(browser.evaluate(f"report.joint({n!r})")) for n in hand + ["l_wrist", "r_wrist"]}
    for n in hand:
        assert np.abs(drawn[n] - want[names.index(n)]).max() <= 0.0015, n  # the page's 1 mm quantization
    reach = {s: np.mean([np.linalg.norm(drawn[f"{s}_{t}"] - drawn[f"{s}_wrist"]) for t in TIPS]) for s in "lr"}
    assert reach["r"] < 0.6 * reach["l"] and reach["l"] > 0.15
    shot = browser.screenshot(tmp_path / "hands.png")
    print(f"screenshot {shot}")
    assert shot.stat().st_size > 10_000
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
