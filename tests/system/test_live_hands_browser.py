"""The hands in the live viewer, in headless Chromium: ``agentsim serve``'s page draws the fingers of a MURML
gesture as the live poses send them (a fist's tips near its wrist, an open hand's far from it), where the whole
run's poses put them; a screenshot is taken. The hands are read in a frame drawn while the gesture holds its
stroke (ready to relax, 1 to 2 s), between two frames received: a loaded machine may draw no frame within some
tenths of a second of the stroke itself, and may hold the last frame received while the next comes late."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import whole_run_points
from test_hands_browser import BML, TIPS
from test_live_viewer import clean, feedback_until, free_port, open_viewer, serve

pytestmark = pytest.mark.system

WATCHED = ("l_wrist", "r_wrist", *(f"{s}_{t}" for s in "lr" for t in TIPS))


def test_the_live_viewer_draws_the_hands(browser, tmp_path):
    port = free_port()
    server = serve(port)
    try:
        open_viewer(browser, port)
        browser.wait_for("report.time() !== null", timeout=10)
        for name in WATCHED:
            browser.evaluate(f"report.watch({name!r})")
        # held until 3 s after its block began: a starved headless browser on a loaded machine draws a frame only every
        # few tenths of a second, and those drawn between two frames received are the ones compared
        times = feedback_until(server.url, BML.replace('start="0.3"', 'start="0.5" relax="3.0"'), "b1:end")
        stroke, ready, relax = (times[f"b1:g1:{s}"] for s in ("stroke", "ready", "relax"))
        browser.wait_for(f"report.time() > {times['b1:end'] + 0.3}", timeout=15)
        drawn = {n: np.array(browser.evaluate(f"report.watched({n!r})")) for n in WATCHED}
        state = browser.evaluate("report.live")
        shot = browser.screenshot(tmp_path / "live-hands.png")
        clean(browser)
        recording = server.service.live.realizer.recording()
        poses = server.service.poses
    finally:
        server.close()
    # each point as drawn nearest the stroke within the hold (each one's watch has rows of its own), and the
    # whole run's there; of the frames drawn between two frames received: a frame drawn while the page waits
    # for poses that come late (a loaded machine) holds the last one received, which stands for an earlier
    # time (as the live viewer's test reads them)
    def nearest(rows):
        held = rows[(rows[:, 0] >= ready) & (rows[:, 0] <= relax) & (rows[:, 4] == 1)]
        assert len(held), (ready, relax, rows[:, [0, 4]])
        return held[int(np.argmin(np.abs(held[:, 0] - stroke)))]

    rows = {n: nearest(drawn[n]) for n in WATCHED}
    at = {n: row[1:4] for n, row in rows.items()}
    reach = {s: np.mean([np.linalg.norm(at[f"{s}_{tip}"] - at[f"{s}_wrist"]) for tip in TIPS]) for s in "lr"}
    error = max(float(np.abs(at[n] - whole_run_points(poses, recording, np.array([row[0]]))[0][poses.names.index(n)])
                      .max()) for n, row in rows.items())
    t = rows["r_wrist"][0]
    print(f"in the stroke's hold ({t:.3f} s, stroke {stroke:.3f} s fed back) the fist's tips "
          f"{reach['r'] * 1000:.0f} mm from its wrist, the open hand's {reach['l'] * 1000:.0f} mm; drawn "
          f"{error * 1000:.2f} mm from the whole run's poses ({state['gaps']} gaps, {state['stalls']} stalls); "
          f"screenshot {shot}")
    assert reach["r"] < 0.6 * reach["l"] and reach["l"] > 0.15
    assert error <= 0.0015  # frames are sent rounded to the millimetre
    assert shot.stat().st_size > 10_000
