"""The face in the run report, in headless Chromium: a BML 1.0 face lexeme of one side moves that side's
points on the page (the brow's end site, the mouth corner) where the run's poses put them, and the other
side's stay; a screenshot is taken."""

from __future__ import annotations

import numpy as np
import pytest

from agentsim.media.report.data import body_points, point_names
from helpers import open_run_report, seek_drawn

pytestmark = pytest.mark.system

BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1">'
       '<faceLexeme id="f1" lexeme="RAISE_LEFT_BROW" start="0.2" attackPeak="0.6" relax="1.0" end="1.4"/>'
       '<faceLexeme id="f2" lexeme="RAISE_RIGHT_MOUTH_CORNER" start="1.6" attackPeak="2.0" relax="2.4" end="2.8"/>'
       '</bml>')
POINTS = ("l_eyebrow.end", "r_eyebrow.end", "l_lip_corner.end", "r_lip_corner.end")


def test_the_report_draws_a_face_lexeme_on_its_side(browser, tmp_path):
    realizer, recording, stream = open_run_report(BML, browser, tmp_path / "face.html")
    assert recording.feedback and not realizer.feedback.warnings()
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
    names, _ = point_names(stream.body)
    drawn, shots = {}, []
    for t in (0.1, 0.8, 1.5, 2.2):
        seek_drawn(browser, t)
        drawn[t] = {n: np.array(browser.evaluate(f"report.joint({n!r})")) for n in POINTS + ("skullbase",)}
        k = int(np.argmin(np.abs(stream.times - t)))
        want = body_points(stream.body, stream.values[k:k + 1])[0]
        for n in POINTS:
            assert np.abs(drawn[t][n] - want[names.index(n)]).max() <= 0.0015, (t, n)  # the page's 1 mm steps
        if t in (0.8, 2.2):
            shots.append(browser.screenshot(tmp_path / f"face-{t}.png"))

    def up(t, before, n):  # mm, relative to the head, between two times
        return ((drawn[t][n] - drawn[t]["skullbase"]) - (drawn[before][n] - drawn[before]["skullbase"]))[1] * 1000

    moved = {n: (round(float(up(0.8, 0.1, n)), 1), round(float(up(2.2, 1.5, n)), 1)) for n in POINTS}
    print(f"mm up at the brow's peak and at the corner's: {moved}; screenshots {shots}")
    # the named side rises well past the other (each drawn coordinate is rounded to the millimetre, and the
    # head sways a little: the other side's points move by a millimetre or two on the page)
    assert moved["l_eyebrow.end"][0] > 5.0 and moved["l_eyebrow.end"][0] - moved["r_eyebrow.end"][0] > 5.0
    assert moved["r_lip_corner.end"][1] > 3.0 and moved["r_lip_corner.end"][1] - moved["l_lip_corner.end"][1] > 3.0
    assert all(shot.stat().st_size > 10_000 for shot in shots)
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
