"""The HTML run report in a real browser: headless Chromium opens it from file:// (no network) and the test
reads the page's ``window.report`` over the DevTools protocol, on a run realized with espeak-ng.

Nothing here plays sound: time is moved by seeking, and a run without sound plays on the page's own clock,
so no audio device is needed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agentsim.animation import evaluate_poses
from agentsim.media.audio import run_track
from agentsim.media.report import write_report
from agentsim.media.report.browser import open_report
from agentsim.media.tables import gesture_rows
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend
from helpers import seek_drawn

pytestmark = pytest.mark.system

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
BML = (f'<bml {NS} id="b1"><speech id="s1"><text>The <sync id="w1"/>lighthouse keeper walked '
       '<sync id="w2"/>slowly up the hill.</text></speech>'
       '<gesture id="g1" lexeme="BEAT" stroke="s1:w1"/>'
       '<gesture id="g2" lexeme="BEAT" mode="LEFT_HAND" stroke="s1:w2"/></bml>')


@pytest.fixture(scope="module")
def spoken():
    """Two beats pegged to two words of a speech, realized with espeak-ng: recording, track, poses, table."""
    from speech_timing.espeak import EspeakBackend

    realizer = Realizer(tts=EspeakBackend())
    realizer.submit(BML)
    realizer.run()
    recording = realizer.recording()
    return recording, run_track(recording), evaluate_poses(recording, fps=60), gesture_rows(recording)


def moved_wrist(stream, t: float) -> str:
    """The wrist that moves most (vertically) within 0.3 s of ``t``."""
    near = np.abs(stream.times - t) <= 0.3
    return max(("r_wrist", "l_wrist"), key=lambda j: np.ptp(stream.position(j)[near, 1]))


def test_the_report_plays_the_run_in_chromium(spoken, browser, tmp_path):
    recording, track, stream, rows = spoken
    path = write_report(tmp_path / "run.html", recording=recording, stream=stream, track=track, gestures=rows,
                        title="Two beats on two words", notes=["espeak-ng", "poses at 60 fps"])
    seconds = open_report(path, browser)
    print(f"report ready {seconds:.2f} s after navigation")
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
    audio = browser.evaluate("document.getElementById('audio').duration")
    print(f"audio element {audio:.4f} s, track {track.duration:.4f} s")
    assert audio == pytest.approx(track.duration, abs=0.05)
    assert browser.evaluate("report.duration()") == pytest.approx(max(track.duration, stream.times[-1]), abs=1e-3)

    assert len(rows) == 2 and all(r.happened_s is not None for r in rows)
    for row in rows:
        stroke = row.happened_s
        wrist = moved_wrist(stream, stroke)
        heights = {}
        for dt in (-0.1, 0.0, 0.1):
            assert browser.evaluate(f"report.seek({stroke + dt!r})") == pytest.approx(stroke + dt, abs=1e-6)
            assert browser.evaluate("report.time()") == pytest.approx(stroke + dt, abs=1e-6)
            heights[dt] = browser.evaluate(f"report.joint({json.dumps(wrist)})")
        drawn = np.array(heights[0.0])
        # what the stream has there: between the two frames around the stroke, both sent to the page
        expected = np.array([np.interp(stroke, stream.times, stream.position(wrist)[:, k]) for k in range(3)])
        nearest = stream.position(wrist)[int(round(stroke * stream.fps))]
        print(f"{row.behaviour} stroke {stroke:.4f} s on {row.word!r}: {wrist} y = {drawn[1]:.4f} m "
              f"(-0.1 s: {heights[-0.1][1]:.4f}, +0.1 s: {heights[0.1][1]:.4f}); stream {expected[1]:.4f} "
              f"between frames, {nearest[1]:.4f} at the nearest frame; off by "
              f"{np.abs(drawn - expected).max() * 1000:.2f} mm")
        assert drawn[1] < heights[-0.1][1] and drawn[1] < heights[0.1][1]
        assert np.abs(drawn - expected).max() < 0.002
        assert np.abs(drawn - nearest).max() < 0.012

    # the cursor follows time, and sits where the time is
    xs = []
    for t in (0.3, 1.0, 1.6):
        browser.evaluate(f"report.seek({t})")
        xs.append(browser.evaluate("report.cursor()"))
        assert browser.evaluate("report.cursorTime()") == pytest.approx(t, abs=1e-6)
    print(f"cursor at {xs} px for 0.3, 1.0, 1.6 s")
    assert xs[0] < xs[1] < xs[2]
    # seeking the audio element itself moves the skeleton and the cursor too
    before = browser.evaluate("[report.cursor(), report.joint('r_wrist')]")
    browser.evaluate(f"document.getElementById('audio').currentTime = {rows[0].happened_s}")
    browser.wait_for(f"Math.abs(report.cursorTime() - {rows[0].happened_s}) < 1e-6", timeout=10)
    after = browser.evaluate("[report.cursor(), report.joint('r_wrist')]")
    assert after[0] != before[0] and after[1] != before[1]
    # clicking a row of the table goes to its stroke
    browser.evaluate("report.seek(0)")
    browser.evaluate("document.querySelectorAll('#gestures tbody tr')[1].click()")
    assert browser.evaluate("report.time()") == pytest.approx(rows[1].happened_s, abs=1e-6)
    assert browser.evaluate("document.querySelector('#gestures tr.current').dataset.index") == "1"

    shots = []
    for name, t in (("before", 0.2), ("stroke1", rows[0].happened_s), ("stroke2", rows[1].happened_s)):
        seek_drawn(browser, t)
        shots.append(browser.screenshot(tmp_path / f"report-{name}.png"))
    for shot in shots:
        print(f"screenshot {shot}")
        assert shot.stat().st_size > 10_000
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []


def test_a_run_without_sound_plays_on_the_pages_clock(browser, tmp_path):
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(BML)
    realizer.run()
    recording = realizer.recording()
    stream = evaluate_poses(recording, fps=60)
    path = write_report(tmp_path / "silent.html", recording=recording, stream=stream, gestures=gesture_rows(recording))
    open_report(path, browser)
    assert browser.evaluate("document.getElementById('audio')") is None
    assert "no sound in this run" in browser.evaluate("document.body.innerText")
    assert browser.evaluate("report.duration()") == pytest.approx(stream.times[-1], abs=1e-3)
    browser.evaluate("report.seek(0)")
    start = browser.evaluate("[report.cursor(), report.joint('r_wrist')]")
    browser.evaluate("report.play()")
    browser.evaluate("new Promise(r => setTimeout(r, 600))", await_promise=True)
    t = browser.evaluate("report.time()")
    browser.evaluate("report.pause()")
    print(f"the page's clock ran to {t:.3f} s in 0.6 s")
    assert 0.3 < t < 1.5
    later = browser.evaluate("[report.cursor(), report.joint('r_wrist')]")
    assert later[0] > start[0] and later[1] != start[1]
    held = browser.evaluate("report.time()")
    browser.evaluate("new Promise(r => setTimeout(r, 200))", await_promise=True)
    assert browser.evaluate("report.time()") == held
    browser.screenshot(tmp_path / "silent.png")

    bare = write_report(tmp_path / "bare.html", recording=recording)
    open_report(bare, browser)
    text = browser.evaluate("document.body.innerText")
    assert "no sound in this run" in text and "no motion in this run" in text
    assert browser.evaluate("report.joint('r_wrist')") is None
    browser.evaluate("report.seek(1.0)")
    assert browser.evaluate("report.cursorTime()") == pytest.approx(1.0)
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []
