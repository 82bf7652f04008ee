"""An input stream that keeps what it recorded with the monotonic time of each frame, to measure a loop back
(:meth:`~agentsim.live.sound.LiveSound.measure_latency`, the loopback tests)."""

from __future__ import annotations

import math
import time

import numpy as np

from agentsim.errors import Unavailable
from agentsim.live.devices import device_info, sounddevice_module

def find_onset(samples: np.ndarray, threshold: float) -> float | None:
    """The fractional index where ``|samples|`` first reaches ``threshold`` (linear between samples), or None."""
    above = np.flatnonzero(np.abs(samples) >= threshold)
    if above.size == 0:
        return None
    i = int(above[0])
    if i == 0:
        return 0.0
    a, b = abs(float(samples[i - 1])), abs(float(samples[i]))
    return i - 1 + (threshold - a) / (b - a)


class Recorder:
    """An input stream that keeps what it records (mono, up to ``seconds``) and when each block was captured.

    The callback copies each block into one buffer allocated beforehand and logs its first frame's index,
    ``inputBufferAdcTime``, ``currentTime`` and the monotonic time it ran at. :meth:`frame_time` turns a
    frame index into the monotonic time it left the ADC: the input's frames are contiguous, so a frame is
    ``index / rate`` after a common origin, taken as the median over the blocks within half a second of it
    (PulseAudio's capture stamps jitter by up to 3 ms, in 4-block chunks), each mapped to monotonic with the
    lower envelope of ``monotonic - currentTime`` as :class:`StreamClock` does. Blocks from before the stream
    settled (:meth:`wait_steady`) are left out.
    """

    def __init__(self, device=None, samplerate: int | None = None, seconds: float = 30.0, blocksize: int = 256):
        sounddevice = sounddevice_module()
        info = device_info(sounddevice, device, "input")
        self.device = device
        self.samplerate = int(samplerate or info["default_samplerate"])
        self.samples = np.zeros(int(seconds * self.samplerate), np.float32)
        self.frames = 0
        self.blocks = 0
        self.overflows = 0
        self.errors = 0
        self.last_error = ""
        self.steady_from: int | None = None
        self._log = np.zeros((len(self.samples) // 32 + 64, 4))
        try:
            self.stream = sounddevice.InputStream(device=device, channels=1, samplerate=self.samplerate,
                                                  blocksize=int(blocksize), dtype="float32",
                                                  callback=self._callback)
        except sounddevice.PortAudioError as exc:
            raise Unavailable(f"cannot open audio input {device!r} at {self.samplerate} Hz: {exc}") from None

    def _callback(self, indata, frames, time_info, status) -> None:
        try:
            now = time.monotonic()
            if status.input_overflow:
                self.overflows += 1
            n = min(frames, len(self.samples) - self.frames)
            if n <= 0 or self.blocks >= len(self._log):
                return
            self.samples[self.frames:self.frames + n] = indata[:n, 0]
            self._log[self.blocks] = (self.frames, time_info.inputBufferAdcTime, time_info.currentTime, now)
            self.blocks += 1
            self.frames += n
        except Exception as exc:  # never let PortAudio stop the stream
            self.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"

    def start(self) -> "Recorder":
        """Start recording."""
        self.stream.start()
        return self

    def close(self) -> None:
        """Stop and close the stream (what was recorded is kept)."""
        if self.stream is not None:
            try:
                self.stream.stop()
            finally:
                self.stream.close()
            self.stream = None

    def __enter__(self) -> "Recorder":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def _rows(self) -> np.ndarray:
        return self._log[: self.blocks]

    def find_steady(self, count: int = 32, tolerance: float = 0.005, early: float = 0.02) -> int | None:
        """The first frame from which ``count`` blocks in a row have steady stamps, or None (yet).

        Steady: their ADC times less their frames' ``index / rate`` agree within ``tolerance`` of their
        median, and each was stamped at most 0.25 s before its callback (opening a PulseAudio input first
        delivers half a second of older, wrongly stamped audio in bursts) and at most ``early`` after it
        (a null sink's monitor stamps its ADC times up to 5.3 ms after the callback's ``currentTime`` while
        an output stream plays to the sink: a sawtooth of its 4-block chunks, not a fault).
        """
        rows = self._rows()
        if len(rows) < count:
            return None
        origin = rows[:, 1] - rows[:, 0] / self.samplerate
        lead = rows[:, 2] - rows[:, 1]
        for b in range(len(rows) - count + 1):
            window = origin[b:b + count]
            if (np.max(np.abs(window - np.median(window))) <= tolerance
                    and np.all((lead[b:b + count] >= -early) & (lead[b:b + count] <= 0.25))):
                return int(rows[b, 0])
        return None

    def wait_steady(self, timeout: float = 10.0) -> int:
        """Wait until the stream's stamps are steady; the first steady frame. Unavailable after ``timeout``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.steady_from = self.find_steady()
            if self.steady_from is not None:
                return self.steady_from
            time.sleep(0.05)
        raise Unavailable(f"audio input {self.device!r} gave no steady capture times within {timeout:g} s")

    def frame_time(self, index: float, window: float = 0.5) -> float:
        """The monotonic time at which frame ``index`` (fractional allowed) left the ADC, by PortAudio."""
        rows = self._rows()
        if self.steady_from is not None:
            rows = rows[rows[:, 0] >= self.steady_from]
        near = rows[np.abs(rows[:, 0] - index) <= window * self.samplerate]
        if len(near) == 0:
            near = rows
        if len(near) == 0:
            raise ValueError("nothing recorded yet")
        offset = np.min(near[:, 3] - near[:, 2])
        origin = np.median(near[:, 1] - near[:, 0] / self.samplerate)
        return float(origin + offset + index / self.samplerate)

    def index_at(self, monotonic: float) -> float:
        """The (fractional) frame index that left the ADC at monotonic time ``monotonic``."""
        guess = (monotonic - self.frame_time(0.0)) * self.samplerate
        return (monotonic - self.frame_time(guess)) * self.samplerate + guess

    def onset(self, threshold: float, after: float, before: float) -> float | None:
        """The monotonic time at which ``|samples|`` first reaches ``threshold`` between two monotonic times."""
        lo = max(0, int(math.floor(self.index_at(after))))
        hi = min(self.frames, int(math.ceil(self.index_at(before))))
        if hi <= lo:
            return None
        found = find_onset(self.samples[lo:hi], threshold)
        return None if found is None else self.frame_time(lo + found)
