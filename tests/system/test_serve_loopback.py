"""``agentsim serve`` with sound, through a real loopback: the service plays to a PulseAudio null sink, the
test records the sink's monitor, and what was heard is compared with the feedback a WebSocket client got.

The loop is calibrated first (``calibrate=``, as ``agentsim serve --calibrate``): clicks played and recorded
measure what the device adds to the latency PortAudio reports. Every time here is on ``time.monotonic()``:
the arrival of a feedback at the client, and the moment a recorded frame left the monitor's ADC (PortAudio's
capture stamps, mapped as :class:`agentsim.live.recorder.Recorder` does).
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import soundfile
from scipy.signal import correlate, resample_poly
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.espeak import EspeakBackend

pytestmark = pytest.mark.system

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla" ' \
     'xmlns:bmlt="http://hmi.ewi.utwente.nl/bmlt"'
#: The issue's bound: the speech is heard within this long of its start feedback reaching the client.
AGREEMENT = 0.030


@pytest.fixture(scope="module")
def media(tmp_path_factory):
    """The folder the service reads clients' sound files from (--media)."""
    return tmp_path_factory.mktemp("media")


@pytest.fixture(scope="module")
def served(pulse_null_sink, media):
    from agentsim.live.recorder import Recorder

    service = Service(port=0, audio="pulse", fps=0, calibrate="pulse", tts=EspeakBackend(), media=str(media))
    with Background(service) as running:
        with Recorder("pulse", samplerate=service.sound.samplerate, seconds=60.0) as recorder:
            recorder.wait_steady()
            yield running, recorder


def receive_until(ws, done, timeout: float = 15.0) -> dict[str, tuple[float, dict]]:
    """Feedback by id, with its arrival on time.monotonic(), until ``done(feedback)``."""
    got = {}
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            item = json.loads(ws.recv(timeout=0.2))
        except TimeoutError:
            continue
        got[item["id"]] = (time.monotonic(), item)
        if done(item):
            return got
    raise AssertionError(f"timed out; got {sorted(got)}")


def heard_start(recorder, samples: np.ndarray, rate: int, near: float, search: float = 0.5) -> float:
    """When sample 0 of ``samples`` was heard (monotonic): where the recording within ``search`` s of ``near``
    matches them best (cross-correlation at the recorder's rate)."""
    played = resample_poly(samples, recorder.samplerate, rate) if rate != recorder.samplerate else samples
    lo = int(recorder.index_at(near - search))
    hi = int(recorder.index_at(near + search)) + len(played)
    segment = recorder.samples[max(lo, 0):min(hi, recorder.frames)]
    score = correlate(segment, played, mode="valid")
    lag = int(np.argmax(score))
    return recorder.frame_time(max(lo, 0) + lag)


def source(service, label: str):
    (found,) = [s for s in service.sound.sources if s.label == label]
    return found


def test_speech_is_heard_when_its_start_feedback_arrives(served):
    running, recorder = served
    service = running.service
    assert abs(service.loop_delay) < 0.010  # a null sink's monitor adds next to nothing to the stamps
    with connect(running.url) as ws:
        ws.send(f'<bml {NS} id="b1"><speech id="s1"><text>The lighthouse keeper walked slowly up the hill.'
                '</text></speech></bml>')
        got = receive_until(ws, lambda f: f["id"] == "b1:end")
    time.sleep(0.3)
    arrival, start = got["b1:s1:start"]
    spoken = source(service, "b1:s1")
    heard = heard_start(recorder, spoken.samples, spoken.rate, arrival)
    assert abs(heard - arrival) <= AGREEMENT, (heard - arrival)
    # and where the plan put it: its start's global time, heard after the service's delay
    assert abs(heard - service.sound.heard_at(start["globalTime"])) <= 0.005
    assert service.sound.errors == 0  # (underruns come with a loaded machine; the times above hold through them)


def test_an_interrupted_speech_falls_silent_when_its_end_feedback_arrives(served):
    running, recorder = served
    with connect(running.url) as ws:
        ws.send(f'<bml {NS} id="talk"><speech id="s"><text>' + "This goes on and on and on. " * 10
                + "</text></speech></bml>")
        receive_until(ws, lambda f: f["id"] == "talk:s:start")
        time.sleep(1.0)
        ws.send(f'<bml {NS} id="stop"><bmla:interrupt id="i" target="talk"/></bml>')
        got = receive_until(ws, lambda f: f["id"] == "talk:s:end")
    time.sleep(0.5)
    ended, _ = got["talk:s:end"]
    level = np.abs(recorder.samples)
    before = level[int(recorder.index_at(ended - 0.5)):int(recorder.index_at(ended - AGREEMENT))]
    after = level[int(recorder.index_at(ended + AGREEMENT)):int(recorder.index_at(ended + 0.4))]
    assert before.max() > 0.05  # it was speaking up to the end feedback
    assert after.max() < 1e-3, after.max()  # and silent from just after it


def test_a_sound_file_plays_at_its_planned_time(served, media):
    running, recorder = served
    service = running.service
    rate = 16000
    rng = np.random.default_rng(7)
    noise = (0.3 * rng.standard_normal(int(0.25 * rate))).clip(-1, 1).astype(np.float32)
    soundfile.write(media / "burst.wav", noise, rate)  # a client names files in the --media folder
    with connect(running.url) as ws:
        ws.send(f'<bml {NS} id="f"><wait id="w" start="0" end="0.4"/>'
                f'<bmlt:audiofile id="a" fileName="burst.wav" start="w:end"/></bml>')
        got = receive_until(ws, lambda f: f["id"] == "f:end")
    time.sleep(0.3)
    arrival, start = got["f:a:start"]
    heard = heard_start(recorder, noise, rate, arrival)
    assert abs(heard - arrival) <= AGREEMENT, (heard - arrival)
    assert abs(heard - service.sound.heard_at(start["globalTime"])) <= 0.005
