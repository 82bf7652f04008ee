"""The environment in the run report, in headless Chromium: three emotions pegged to words (espeak-ng), the
body drawn as solid capsules under three-point lighting. At the joy close-up the character's pixels are
yellow (the key light of Table 3.2) and the head fills more of the frame than at the full shot before it; at
the fear shot (a high angle) the camera is above the eyes; at the anger shot (low) below them."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest

from agentsim.animation import evaluate_poses
from agentsim.media.audio import run_track
from agentsim.media.environment import report_environment, run_environment
from agentsim.media.report import write_report
from agentsim.media.report.browser import open_report
from agentsim.realizer import Realizer
from helpers import seek_drawn

pytestmark = pytest.mark.system

BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:ex="urn:agentsim:expression" id="b1">'
       '<speech id="s1"><text>Once <sync id="w1"/>upon a time there <sync id="w2"/>was a girl who <sync id="w3"/>'
       'feared the dark but <sync id="w4"/>loved the stars.</text></speech>'
       '<ex:emotion id="e1" type="joy" intensity="3.2" start="s1:w1" end="s1:w2"/>'
       '<ex:emotion id="e2" type="fear" intensity="6.5" start="s1:w2" end="s1:w3"/>'
       '<ex:emotion id="e3" type="anger" intensity="1" start="s1:w3" end="s1:w4"/></bml>')
#: The stage's background (stage.js), which no part of the character is.
BACKGROUND = np.array([0x1d, 0x22, 0x2b])


def canvas_pixels(browser) -> np.ndarray:
    """The 3D view's pixels (RGB) as drawn."""
    from PIL import Image

    url = browser.evaluate("document.querySelector('#view canvas').toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"), dtype=float)


def test_the_report_films_and_lights_the_emotions(browser, tmp_path):
    from speech_timing.espeak import EspeakBackend

    realizer = Realizer(tts=EspeakBackend())
    realizer.submit(BML)
    realizer.run()
    recording = realizer.recording()
    assert not realizer.feedback.warnings()
    rows = run_environment(recording)
    stream = evaluate_poses(recording, fps=30)
    path = write_report(tmp_path / "emotions.html", recording=recording, stream=stream, track=run_track(recording),
                        environment=report_environment(rows, stream))
    open_report(path, browser)
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
    shown = {}
    for row, following in zip(rows, rows[1:]):
        t = (row.time + following.time) / 2
        seek_drawn(browser, t)
        state = browser.evaluate("report.environment()")
        assert (state["emotion"], state["shot"], state["angle"]) == (row.channels.emotion, row.channels.shot,
                                                                    row.channels.angle)
        pixels = canvas_pixels(browser)
        body = np.abs(pixels - BACKGROUND).sum(axis=2) > 30
        shown[row.channels.emotion] = state, pixels[body].mean(axis=0), body.mean()
        browser.screenshot(tmp_path / f"{row.channels.emotion}.png")
    none, joy, fear, anger = (shown[e] for e in ("none", "joy", "fear", "anger"))
    print({e: (s["shot"], s["angle"], np.round(colour), round(s["headShare"], 4), round(share, 3))
           for e, (s, colour, share) in shown.items()})
    # joy: a close-up in yellow light, the head larger in the frame than at the full shot
    r, g, b = joy[1]
    assert r > 1.4 * b and g > 1.4 * b and joy[0]["key"] == [1, 1, 0]
    assert joy[0]["headShare"] > 10 * none[0]["headShare"]  # the projected head's share of the frame
    r0, g0, b0 = none[1]
    assert b0 > 0.75 * r0  # under the white key light the character is not yellow
    # fear: high angle, the camera above the eyes; anger: low angle, below them, in red light
    assert fear[0]["camera"][1] > fear[0]["eyes"] + 0.1 and fear[0]["shot"] == "extreme-close-up"
    assert anger[0]["camera"][1] < anger[0]["eyes"] - 0.3 and anger[1][0] > 1.4 * anger[1][2]


LIVE = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:ex="urn:agentsim:expression" id="b1">'
        '<head id="h1" lexeme="NOD" start="0.2"/>'
        '<ex:emotion id="e1" type="joy" intensity="3.2" start="0.3" end="2.5"/>'
        '<ex:emotion id="e2" type="fear" intensity="6.5" start="2.5" end="4.5"/></bml>')


def test_the_live_viewer_films_and_lights_the_emotions(browser):
    from test_live_viewer import clean, feedback_until, free_port, open_viewer, serve

    port = free_port()
    server = serve(port)
    try:
        open_viewer(browser, port)
        assert browser.evaluate("report.environment().emotion") == "none"
        times = feedback_until(server.url, LIVE, "b1:e1:start")
        browser.wait_for("report.environment().emotion === 'joy'", timeout=10)
        joy = browser.evaluate("report.environment()")
        browser.wait_for("report.environment().emotion === 'fear'", timeout=10)
        fear = browser.evaluate("report.environment()")
        browser.wait_for("report.environment().emotion === 'none'", timeout=10)
        clean(browser)
    finally:
        server.close()
    print(f"joy from {joy['t']:.3f} s (fed back {times['b1:e1:start']:.3f} s): {joy['shot']}, {joy['key']}; fear "
          f"camera {fear['camera'][1]:.3f} m, eyes {fear['eyes']:.3f} m")
    assert joy["t"] == times["b1:e1:start"] and (joy["shot"], joy["angle"], joy["key"]) == ("close-up", "eye", [1, 1, 0])
    assert (fear["shot"], fear["angle"]) == ("extreme-close-up", "high") and fear["camera"][1] > fear["eyes"] + 0.1
