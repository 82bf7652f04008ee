"""The live sound's arithmetic, without a device: the block mixing that the output callback does is the offline
mix of the same sources, block after block; the clocks it steers by follow the stamps PortAudio gives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agentsim.errors import Unavailable
from agentsim.live.clocks import ClockMap, DacTracker, Steadiness, StreamClock, render_block
from agentsim.live.devices import open_device
from agentsim.live.recorder import find_onset
from agentsim.media.audio import FADE, Source, mix

RATE = 48000


def sources(rng) -> list[Source]:
    """Speech-like sources at other rates, one drifting, one cut, one with a gain ramp."""
    a = rng.uniform(-0.3, 0.3, 22050).astype(np.float32)
    b = rng.uniform(-0.3, 0.3, 16000).astype(np.float32)
    c = rng.uniform(-0.3, 0.3, RATE // 2).astype(np.float32)
    return [Source(a, 22050, 0.1037, 1.0 + 80e-6, None, None, "a"),
            Source(b, 16000, 0.25, 1.0, 0.61, None, "b"),
            Source(c, RATE, 0.5, 1.0, None, lambda t: 1.0 - 0.5 * (t - 0.5), "c")]


def blocks(clock: ClockMap, frames: int, n: int, srcs, rate: int = RATE) -> np.ndarray:
    """``n`` blocks rendered one after the other, as the callback renders them (DAC times contiguous)."""
    first = clock.stream_time(0.0)
    out = [render_block(frames, first + k * frames / rate, rate, srcs, clock) for k in range(n)]
    return np.concatenate(out)


def test_blocks_rendered_one_after_the_other_are_the_offline_mix():
    srcs = sources(np.random.default_rng(3))
    offline = mix(srcs, rate=RATE, duration=1.2).samples
    clock = ClockMap(real_start=1000.0, delay=0.056, offset=-3.5)  # feedback delayed 56 ms
    live = blocks(clock, 256, len(offline) // 256, srcs)
    n = len(live)
    # the gain is interpolated linearly within a block: exact for this linear ramp
    assert np.max(np.abs(live - offline[:n])) < 1e-5
    assert np.max(np.abs(live)) > 0.2  # something sounded
    # On Linux the stream's clock is CLOCK_REALTIME, 1.8e9 s: its doubles resolve 0.24 us, so each block
    # starts up to that far from where it should; on these white-noise sources (slope up to 0.6 per
    # 22050 Hz sample) that is at most 0.6 * 22050 * 2.4e-7 = 0.003 off, and nothing near a click.
    far = blocks(ClockMap(real_start=1000.0, delay=0.056, offset=-1.8e9), 256, len(offline) // 256, srcs)
    assert np.max(np.abs(far - offline[:n])) < 0.006


def test_a_slower_clock_plays_the_sound_slower():
    tone = np.sin(2 * np.pi * 440 * np.arange(RATE) / RATE).astype(np.float32)
    src = [Source(tone, RATE, 0.0)]
    live = blocks(ClockMap(real_start=0.0, factor=2.0), 480, 200, src)  # two wall seconds per simulated one
    crossings = np.flatnonzero(np.diff(np.signbit(live[: RATE])))  # the first wall second
    assert len(crossings) == pytest.approx(440, abs=2)  # 220 Hz heard: half speed


def test_a_cut_ends_with_a_fade_that_ends_at_the_cut():
    ones = np.full(RATE, 0.5, np.float32)
    clock = ClockMap(real_start=0.0)
    cut = 0.4
    live = blocks(clock, 256, 200, [Source(ones, RATE, 0.0, stop=cut)])
    t = np.arange(len(live)) / RATE
    assert np.all(live[t >= cut] == 0.0)
    assert np.allclose(live[t <= cut - FADE], 0.5)
    ramp = live[(t > cut - FADE) & (t < cut)]
    assert np.all(np.diff(ramp) < 0)


def test_the_clock_map_goes_both_ways():
    clock = ClockMap(real_start=12.5, factor=1.5, delay=0.04, offset=-3.2, initial_time=2.0)
    for s in (2.0, 3.7, 100.25):
        assert clock.simulated(clock.stream_time(s)) == pytest.approx(s, abs=1e-9)
    # simulated time 2.0 happens at monotonic 12.5 and is heard 40 ms later, at stream time 12.54 + 3.2
    assert clock.stream_time(2.0) == pytest.approx(15.74)


def test_the_dac_tracker_follows_the_sample_clock_through_jitter_and_an_underrun():
    rng = np.random.default_rng(11)
    frames, rate = 256, 48000.0
    tracker = DacTracker(rate)
    true = 100.0 + np.arange(3000) * frames / rate
    true[2000:] += 0.050  # an underrun: the clock jumps 50 ms
    reported = true + rng.normal(0.0, 1e-4, true.size)  # 0.1 ms of jitter, as PulseAudio's
    estimated = np.array([tracker.update(r, frames) for r in reported])
    settled = np.abs(estimated - true)[500:2000]
    assert settled.max() < 5e-5  # a twentieth of the jitter once the running mean has settled
    assert tracker.jumps == 1
    assert np.abs(estimated - true)[2600:].max() < 5e-5  # settled again after the jump
    assert 1e-4 <= tracker.rms_error < 2e-4  # the jitter, and the prediction's own error while it settles


def test_the_stream_clock_takes_the_callbacks_that_ran_soonest():
    rng = np.random.default_rng(5)
    clock = StreamClock(window=2.0)
    offset = 1234.5
    for k in range(2000):
        stream = 10.0 + k * 0.005
        late = rng.exponential(0.002) + (0.03 if k % 97 == 0 else 0.0)  # waits for the GIL, now and then long
        clock.note(stream + offset + late, stream)
    assert 0.0 <= clock.offset - offset < 2e-4
    assert clock.to_monotonic(20.0) == pytest.approx(20.0 + offset, abs=2e-4)
    history = clock.history()
    assert len(history) >= 8 and np.all(history[:, 1] >= history[:, 0])


def test_steadiness_waits_for_contiguous_unhurried_callbacks():
    steady = Steadiness(count=8)
    rate, frames = 48000, 256
    block = frames / rate
    wall = 0.0
    # the opening burst: callbacks at the same instant, DAC times not contiguous
    for k in range(10):
        assert not steady.note(wall, wall, wall + 0.3 + 0.02 * k, frames, rate)
    settled = []
    for k in range(20):
        wall += block
        settled.append(steady.note(wall, wall, wall + 0.035, frames, rate))
    assert not any(settled[:7]) and all(settled[8:])
    assert steady.lead_max == pytest.approx(0.035)


def test_find_onset_is_fractional():
    samples = np.array([0.0, 0.0, 0.1, 0.3, 0.9, 0.2])
    assert find_onset(samples, 0.2) == pytest.approx(2.5)
    assert find_onset(samples, 0.95) is None
    assert math.isclose(find_onset(np.array([0.7]), 0.5), 0.0)


def test_an_unknown_device_says_which_there_are():
    pytest.importorskip("sounddevice", reason="needs sounddevice (it is a dependency of agentsim)")
    with pytest.raises(Unavailable, match=r"no audio output device 'no such card'.*output devices here"):
        open_device("no such card")
