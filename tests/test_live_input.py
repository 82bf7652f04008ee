"""A live input that is dead, or silent from the start, stops the run within two seconds with a message that
says so (a machine without a sound card records zeros; listening to them would only give empty results)."""

from __future__ import annotations

import queue
import time

import numpy as np
import pytest

from anticipators.audio import AudioBeatAnticipator, DeviceSource
from agentsim.core.clock import make_environment
from agentsim.errors import Unavailable
from agentsim.core.pegboard import PegBoard


class FakeInput(DeviceSource):
    """An input device that delivers ``level`` (zeros: silence) every block, or nothing at all (dead)."""

    def __init__(self, level: float | None):
        super().__init__(None, 8000, 0.02)
        self.level = level

    def check(self):
        return None, {}

    def open(self):
        source = self

        class Blocks:
            """What the device has captured by now, a block at a time, stamped with when it was complete
            (the queue a real device's callback fills, without a thread: ``get_nowait`` alone is asked)."""

            def __init__(self):
                self.opened = time.monotonic()
                self.taken = 0
                self.rng = np.random.default_rng(0)

            def get_nowait(self):
                stamp = self.opened + (self.taken + 1) * source.block / source.sample_rate
                if source.level is None or stamp > time.monotonic():
                    raise queue.Empty
                self.taken += 1
                return stamp, (source.level * self.rng.standard_normal(source.block)).astype(np.float32)

        class Stream:
            def __enter__(self):
                return Blocks()

            def __exit__(self, *exc):
                pass

        return Stream()


@pytest.mark.parametrize("level, what", [(0.0, "silent"), (None, "delivered no audio")])
def test_a_silent_or_dead_input_stops_within_two_seconds(level, what):
    env = make_environment(realtime=True)
    anticipator = AudioBeatAnticipator("live", source=FakeInput(level))
    anticipator.attach(env, PegBoard())
    env.sync()  # simulated time 0 is now (attaching may take a while: the tracker's first import)
    with pytest.raises(Unavailable, match=what):
        env.run(until=10.0)
    assert 2.0 <= time.monotonic() - env.real_start < 2.5


def test_an_input_that_sounds_goes_on():
    env = make_environment(realtime=True)
    anticipator = AudioBeatAnticipator("live", source=FakeInput(0.01))
    anticipator.attach(env, PegBoard())
    env.run(until=2.6)
    assert anticipator.tracker.time > 2.0
