"""The hands in the live viewer, in headless Chromium: ``agentsim serve``'s page draws the fingers of a MURML
gesture as the live poses send them (a fist's tips near its wrist, an open hand's far from it), where the whole
run's poses put them; a screenshot is taken."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import whole_run_points
from test_hands_browser import BML, TIPS
from test_live_viewer import clean, feedback_until, free_port, serve

pytestmark = pytest.mark.system

WATCHED = ("l_wrist", "r_wrist", *(f"{s}_{t}" for s in "lr" for t in TIPS))


def test_the_live_viewer_draws_the_hands(browser, tmp_path):
    port = free_port()
    server = serve(port)
    try:
        browser.navigate(f"http://127.0.0.1:{port}/")
        browser.wait_for("window.report && report.ready && report.live.connected && report.live.skeleton",
                         timeout=10)
        browser.wait_for("report.time() !== null", timeout=10)
        for name in WATCHED:
            browser.evaluate(f"report.watch({name!r})")
        times = feedback_until(server.url, BML.replace('start="0.3"', 'start="0.5"'), "b1:end")
        stroke = times["b1:g1:stroke"]
        browser.wait_for(f"report.time() > {times['b1:end'] + 0.3}", timeout=15)
        drawn = {n: np.array(browser.evaluate(f"report.watched({n!r})")) for n in WATCHED}
        shot = browser.screenshot(tmp_path / "live-hands.png")
        clean(browser)
        recording = server.service.live.realizer.recording()
        poses = server.service.poses
    finally:
        server.close()
    # each point as drawn nearest the stroke (each one's watch has rows of its own), and the whole run's there
    rows = {n: drawn[n][int(np.argmin(np.abs(drawn[n][:, 0] - stroke)))] for n in WATCHED}
    at = {n: row[1:4] for n, row in rows.items()}
    reach = {s: np.mean([np.linalg.norm(at[f"{s}_{tip}"] - at[f"{s}_wrist"]) for tip in TIPS]) for s in "lr"}
    error = max(float(np.abs(at[n] - whole_run_points(poses, recording, np.array([row[0]]))[0][poses.names.index(n)])
                      .max()) for n, row in rows.items())
    t, k = drawn["r_wrist"][:, 0], int(np.argmin(np.abs(drawn["r_wrist"][:, 0] - stroke)))
    print(f"at the stroke ({t[k]:.3f} s, {stroke:.3f} s fed back) the fist's tips {reach['r'] * 1000:.0f} mm from "
          f"its wrist, the open hand's {reach['l'] * 1000:.0f} mm; drawn {error * 1000:.2f} mm from the whole "
          f"run's poses; screenshot {shot}")
    assert abs(t[k] - stroke) < 0.05
    assert reach["r"] < 0.6 * reach["l"] and reach["l"] > 0.15
    assert error <= 0.0015  # frames are sent rounded to the millimetre
    assert shot.stat().st_size > 10_000
