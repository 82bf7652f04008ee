"""``agentsim serve --anticipator reps,input=ws``: a client's ``{"motion": ...}`` messages move the repetition
anticipator's pegs, a nod pegged to the fourth repetition plays there, and bad motion is one warning to its
sender; the viewer page carries the phone's sender."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from scenarios.trainer.signal import acceleration
from speech_timing.builtin import BuiltinBackend

pytestmark = pytest.mark.system

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def test_motion_from_a_client_pegs_a_nod_to_the_fourth_repetition():
    from anticipators.reps import RepetitionAnticipator

    reps = RepetitionAnticipator("reps", input="ws")
    service = Service(port=0, audio="none", fps=0, tts=BuiltinBackend(), anticipators=[reps])
    with Background(service) as running, connect(running.url) as ws:
        ws.send(json.dumps({"motion": [[0, 1, 1, 1], [0.001, 1, 1, 1], [0.002, 1, 2, 1]]}))
        warning = json.loads(ws.recv(timeout=5))
        assert warning["type"] == "warningFeedback" and "sampled at 1e+03 Hz" in warning["description"]
        ws.send(json.dumps({"subscribe": "feedback"}))
        keys = [1.0 + 1.0 * k for k in range(5)]
        t = np.arange(0, 5.6, 0.02)
        a = acceleration(t, keys, "squat", np.random.default_rng(1))
        started = time.monotonic()
        for i in range(0, len(t), 5):  # as a phone sends them: 100 ms at a time, in real time
            time.sleep(max(0.0, started + t[min(i + 4, len(t) - 1)] - time.monotonic()))
            ws.send(json.dumps({"motion": np.column_stack([t[i:i + 5] + 100.0, a[i:i + 5]]).round(5).tolist()}))
            if i == 140:  # 2.8 s: the second repetition has been found, the fourth is predicted
                ws.send(f'<bml {NS} id="b"><head id="n" lexeme="NOD" stroke="anticipators:reps:rep4"/></bml>')
        stroke = None
        deadline = time.monotonic() + 5
        while stroke is None and time.monotonic() < deadline:
            try:
                item = json.loads(ws.recv(timeout=0.5))
            except TimeoutError:
                continue
            if item.get("id") == "b:n:stroke":
                stroke = item["globalTime"]
        found = reps.tracker.repetitions  # on the service's clock
        assert len(found) == 5 and np.abs(np.diff(found) - 1.0).max() < 0.1
        assert stroke is not None and abs(stroke - found[3]) < 0.15


def test_the_viewer_page_sends_a_phones_motion():
    from importlib.resources import files

    page = files("agentsim.live").joinpath("viewer/index.html").read_text()
    assert "accelerationIncludingGravity" in page and "JSON.stringify({motion: samples})" in page
