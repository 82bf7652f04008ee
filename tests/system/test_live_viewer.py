"""The live viewer in a real browser: ``agentsim serve`` (the live service, without sound, poses at 30 fps)
serves its page at ``http://127.0.0.1:PORT/``; headless Chromium opens it, the page connects over a
WebSocket and subscribes to the poses, a real client sends BML, and the test reads the page's
``window.report`` over the DevTools protocol: the wrist it draws moves with the gesture, when and as the
whole run's poses say; the server stops and the page says so; a server comes back and the page plays again.
"""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.builtin import BuiltinBackend
from helpers import whole_run_points

pytestmark = pytest.mark.system

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
FPS = 30.0
BLOCK = (f'<bml {NS} id="b1"><speech id="s"><text>Hello there, <sync id="w"/>look at this one.</text></speech>'
         '<gesture id="g" lexeme="BEAT" stroke="s:w"/></bml>')
#: The right wrist's distance from where it rested, in the page (measured: up to 7.7 mm while nothing plays,
#: breathing and sway; about 400 mm during the beat, at least 355 mm within 0.2 s of its stroke).
STILL = 0.03
MOVED = 0.2
#: What the page draws between two frames is the whole run's poses there to this much (measured 0.49 mm: the
#: frames are sent rounded to the millimetre).
DRAWN = 0.001


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(port: int) -> Background:
    return Background(Service(host="127.0.0.1", port=port, audio="none", fps=FPS, tts=BuiltinBackend()))


def feedback_until(url: str, document: str, last: str) -> dict[str, float]:
    """Send ``document`` over a WebSocket of its own; the globalTime of every feedback up to ``last``."""
    times = {}
    with connect(url) as ws:
        ws.send(document)
        deadline = time.monotonic() + 15
        while last not in times:
            assert time.monotonic() < deadline, f"no {last} in time: {sorted(times)}"
            try:
                item = json.loads(ws.recv(timeout=0.2))
            except TimeoutError:
                continue
            times[item["id"]] = item["globalTime"]
    return times


def open_viewer(browser, port: int, query: str = "", timeout: float = 10.0) -> float:
    """Open the live viewer of the service on ``port`` (``query``: what follows its ``/``) and wait until it plays
    the live run (connected, with its skeleton); the seconds the page took to load."""
    seconds = browser.navigate(f"http://127.0.0.1:{port}/{query}")
    browser.wait_for("window.report && report.ready && report.live.connected && report.live.skeleton",
                     timeout=timeout)
    return seconds


def clean(browser) -> None:
    assert browser.evaluate("report.errors") == [] and browser.exceptions == []


def test_the_viewer_plays_the_live_run_and_says_when_the_server_goes(browser, tmp_path):
    port = free_port()
    server = serve(port)
    try:
        seconds = open_viewer(browser, port)
        print(f"viewer loaded in {seconds:.2f} s")
        clean(browser)
        assert browser.evaluate("report.live.url") == f"ws://127.0.0.1:{port}/"
        # the report's own script, style and three.js, all from the server
        loaded = browser.evaluate("performance.getEntriesByType('resource').map(e => e.name)")
        assert {u.rsplit("/", 1)[1] for u in loaded} >= {"report.js", "report.css", "three.min.js"}
        assert all(u.startswith(f"http://127.0.0.1:{port}/") or u.startswith(f"ws://127.0.0.1:{port}/")
                   for u in loaded), loaded
        assert browser.evaluate("typeof THREE.WebGLRenderer") == "function"

        browser.wait_for("report.time() !== null", timeout=10)
        browser.evaluate("report.watch('r_wrist')")
        time.sleep(1.5)  # nothing plays
        times = feedback_until(server.url, BLOCK, "b1:end")
        start, stroke, end = times["b1:g:start"], times["b1:g:stroke"], times["b1:g:end"]
        browser.wait_for(f"report.time() > {times['b1:end'] + 0.5}", timeout=10)
        # the page plays a steady delay behind the server's clock
        live = server.service.live
        behind = (time.monotonic() - live.env.real_start) / live.env.factor - browser.evaluate("report.time()")
        state = browser.evaluate("report.live")
        shot = browser.screenshot(tmp_path / "live.png")
        drawn = np.array(browser.evaluate("report.watched('r_wrist')"))
        clean(browser)
        assert "b1:g:stroke" in browser.evaluate("document.getElementById('feed').innerText")
        recording = live.realizer.recording()
        poses = server.service.poses
        cost = poses.cost()
    finally:
        server.close()

    t, wrist, between = drawn[:, 0], drawn[:, 1:4], drawn[:, 4] == 1
    print(f"page: {state['frames']} frames in {state['messages']} messages from frame {state['first']} to "
          f"{state['latest']:.3f} s, {state['gaps']} gaps, {state['repeats']} repeats, {state['stalls']} stalls; "
          f"playing {behind:.3f} s behind the server (hold {state['hold']:.2f} s); {len(t)} frames drawn "
          f"from {t[0]:.3f} to {t[-1]:.3f} s (median step {1000 * np.median(np.diff(t)):.1f} ms), "
          f"{100 * between.mean():.1f} % of them between two frames received; server: "
          f"{cost['ms_per_frame']:.2f} ms per frame sent ({cost['evaluated']} evaluated for {cost['frames']}), "
          f"snapshot {cost['snapshot_ms']:.3f} ms; screenshot {shot}")
    # every frame since the page subscribed, once
    assert state["gaps"] == 0 and state["repeats"] == 0
    assert state["frames"] == round(state["latest"] * FPS) - state["first"] + 1
    assert state["frames"] >= (end - t[0]) * FPS
    # played smoothly: time never goes back, and what is drawn lies between frames that came in time
    assert state["hold"] - 0.02 <= behind <= state["hold"] + 0.15
    assert np.all(np.diff(t) >= 0) and np.median(np.diff(t)) < 0.1
    assert between.mean() >= 0.8  # measured 100 %; 90 % with two more test runs on the two cores

    # what the page drew is the whole run's poses at the times it drew them
    expected = whole_run_points(poses, recording, t[between])[:, poses.names.index("r_wrist")]
    off = np.abs(wrist[between] - expected).max()
    # still while nothing plays, moving around the stroke
    quiet = t < start - 0.1
    rest = wrist[quiet].mean(axis=0)
    away = np.linalg.norm(wrist - rest, axis=1)
    near = np.abs(t - stroke) <= 0.2
    during = (t >= start) & (t <= end)
    print(f"right wrist: {1000 * away[quiet].max():.1f} mm from its rest over {t[quiet][-1] - t[0]:.2f} s with "
          f"nothing playing, up to {1000 * away[during].max():.0f} mm during the beat, "
          f"{1000 * away[near].min():.0f}-{1000 * away[near].max():.0f} mm within 0.2 s of the stroke at "
          f"{stroke:.3f} s; off the whole run's by {1000 * off:.2f} mm at most")
    assert t[quiet][-1] - t[0] >= 1.0 and quiet.sum() >= 10 and near.sum() >= 3
    assert away[quiet].max() < STILL
    assert away[near].min() > MOVED
    assert off < DRAWN

    # the server went away: the page says so, keeps the last pose, and throws nothing
    browser.wait_for("report.live.state === 'disconnected'", timeout=10)
    status = browser.evaluate("document.getElementById('status').innerText")
    print(f"status: {status}")
    assert "disconnected" in status and "went away" in status
    assert browser.evaluate("report.live.connected") is False
    assert browser.evaluate("report.joint('r_wrist')") is not None
    browser.screenshot(tmp_path / "live-disconnected.png")
    clean(browser)

    # a server on the same port again: the page connects to it and plays its clock afresh
    again = serve(port)
    try:
        browser.wait_for("report.live.connected && report.live.connections === 2 && report.live.frames > 10",
                         timeout=15)
        state = browser.evaluate("report.live")
        print(f"connected again: {state['frames']} frames from frame {state['first']}, time {state['time']:.3f} s")
        assert state["first"] < 6 * FPS and state["gaps"] == 0
        clean(browser)
    finally:
        again.close()
