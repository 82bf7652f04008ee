"""A live run's sound, played on an audio device at the time the plan says.

A live realizer runs on ``simpy.rt.RealtimeEnvironment``: simulated time ``s`` happens at
``real_start + (s - initial_time) * factor`` on ``time.monotonic()``. Its feedback reaches clients ``delay``
seconds after its simulated time, and the sound of simulated time ``s`` must reach the DAC at that same
moment, ``real_start + (s - initial_time) * factor + delay``: what people hear and what programs are told
then agree. ``delay`` must be long enough for a sound added at its own simulated time to be written before
the device needs it (the stream's output latency, one block and a margin).

The clocks that meet here (simulated, monotonic, the stream's) and the mixing of a block are
:mod:`~agentsim.live.clocks`'; which device plays is :mod:`~agentsim.live.devices`'. :class:`LiveSound` is the
output stream whose callback mixes each block (:func:`~agentsim.live.clocks.render_block`), and
:class:`~agentsim.live.recorder.Recorder` an input stream that keeps what it heard with the monotonic time of
each frame (to measure the loop back, :meth:`LiveSound.measure_latency`).

Sound is played at the plan's times even when that cuts it: a sound added after part of it should already
have been heard starts part-way through (and is counted in :attr:`LiveSound.late`), so that later sounds and
the feedback stay in step with it.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from agentsim.errors import Unavailable
from agentsim.live.clocks import MARGIN, ClockMap, DacTracker, Steadiness, StreamClock, render_block
from agentsim.live.devices import device_info, sounddevice_module
from agentsim.live.recorder import Recorder
from agentsim.media.audio import FADE, Source

class LiveSound:
    """An output stream that plays scheduled sounds when the plan says they are heard.

    Parameters
    ----------
    device : str, int or None
        The output device (sounddevice's name or index; None: the default one).
    real_start, factor, initial_time : float
        The realtime environment's ``real_start``, ``factor`` and initial simulated time: simulated time
        ``s`` happens at ``real_start + (s - initial_time) * factor`` on ``time.monotonic()``. Each can be
        set later (``real_start`` after ``env.sync()``, or once the environment exists: opening a stream
        on PulseAudio takes one or two seconds).
    delay : float or None
        Seconds between a simulated time happening and its sound reaching the DAC (the same delay the
        feedback is sent with). None: the measured output lead (:attr:`lead`) plus one block plus
        :data:`MARGIN`, which is what a sound added at its own simulated time needs to be heard whole.
    samplerate : int or None
        The stream's rate (None: the device's default). Sources at other rates are resampled linearly.
    blocksize : int
        Frames per callback; the callback's work is proportional to it.
    channels : int or None
        None: mono if the device takes it, else stereo; every channel gets the same signal.
    start_timeout : float
        Seconds to wait for the stream's callbacks to settle before giving up (Unavailable).

    Notes
    -----
    Counters, none of which the callback ever raises instead of: :attr:`underruns` (PortAudio's output
    underflow flag), :attr:`errors` and :attr:`last_error` (exceptions caught in the callback, whose block
    is then silent), :attr:`late` (``(label, seconds)`` of sounds added or stopped after the time they
    should have begun or ended had already been played), :attr:`blocks` (blocks played).
    """

    def __init__(self, device=None, *, real_start: float, factor: float = 1.0, delay: float | None = None,
                 samplerate: int | None = None, blocksize: int = 256, initial_time: float = 0.0,
                 channels: int | None = None, start_timeout: float = 10.0):
        sounddevice = sounddevice_module()
        info = device_info(sounddevice, device, "output")
        self.device = device
        self.samplerate = int(samplerate or info["default_samplerate"])
        self.blocksize = int(blocksize)
        if channels is None:
            channels = self._channels(sounddevice, device)
        self.channels = int(channels)
        self.underruns = 0
        self.errors = 0
        self.last_error = ""
        self.blocks = 0
        self.late: list[tuple[str, float]] = []
        self.steady = False
        #: The largest lead measured (s): ``outputBufferDacTime - currentTime``, how long after its callback
        #: a block's first frame reaches the DAC by PortAudio's account (the output buffer it sits behind,
        #: including PulseAudio's own). Updated by every callback.
        self.lead = 0.0
        #: The simulated time up to which the sound has been written (the end of the last block).
        self.rendered_until = -math.inf
        #: What the last :meth:`measure_latency` measured, one number per click (s).
        self.loopback_delays: list[float] = []
        self.stream_clock = StreamClock()
        self.tracker = DacTracker(self.samplerate)
        self._steadiness = Steadiness()
        self._sources: tuple[Source, ...] = ()
        self._lock = threading.Lock()
        self._buffer = np.zeros(max(self.blocksize, 4096), np.float32)
        self._real_start = float(real_start)
        self._factor = float(factor)
        self._initial_time = float(initial_time)
        self._delay = None if delay is None else float(delay)
        self._compensation = 0.0
        self._map: ClockMap | None = None
        self._remap()
        try:
            self.stream = sounddevice.OutputStream(device=device, channels=self.channels,
                                                   samplerate=self.samplerate, blocksize=self.blocksize,
                                                   dtype="float32", callback=self._callback)
            self.stream.start()
        except sounddevice.PortAudioError as exc:
            raise Unavailable(f"cannot open audio output {device!r} at {self.samplerate} Hz: {exc}") from None
        deadline = time.monotonic() + start_timeout
        while not self.steady and time.monotonic() < deadline:
            time.sleep(0.005)
        if not self.steady:
            self.close()
            raise Unavailable(f"audio output {device!r} did not settle within {start_timeout:g} s (no steady "
                              f"DAC times from PortAudio; errors in the callback: {self.last_error or 'none'})")
        if self._delay is None:
            self.delay = self.lead + self.blocksize / self.samplerate + MARGIN

    @staticmethod
    def _channels(sounddevice, device) -> int:
        for channels in (1, 2):
            try:
                sounddevice.check_output_settings(device=device, channels=channels, dtype="float32")
                return channels
            except (ValueError, sounddevice.PortAudioError):
                continue
        raise Unavailable(f"audio output {device!r} takes neither mono nor stereo float32 audio")

    # -- the clock -------------------------------------------------------------------------------------

    def _remap(self) -> None:
        if self._delay is None:
            self._map = None
            return
        self._map = ClockMap(self._real_start, self._factor, self._delay - self._compensation,
                             self.stream_clock.offset or 0.0, self._initial_time)

    @property
    def compensation(self) -> float:
        """Seconds by which every sound is written earlier than its DAC time, to make up for the part of the
        loop to the listener that PortAudio's stamps leave out (:meth:`calibrate` measures it)."""
        return self._compensation

    @compensation.setter
    def compensation(self, value: float) -> None:
        self._compensation = float(value)
        self._remap()

    def calibrate(self, input_device=None, clicks: int = 10) -> float:
        """Measure the loop to ``input_device`` (:meth:`measure_latency`, uncompensated) and compensate it
        from now on; returns the delay measured (s). A sound is then heard on that input when the plan says."""
        self.compensation = 0.0
        measured = self.measure_latency(input_device, clicks=clicks)
        self.compensation = measured
        return measured

    @property
    def real_start(self) -> float:
        """Monotonic time of simulated time ``initial_time`` (the realtime environment's ``real_start``)."""
        return self._real_start

    @real_start.setter
    def real_start(self, value: float) -> None:
        self._real_start = float(value)
        self._remap()

    @property
    def factor(self) -> float:
        """Wall-clock seconds per simulated second."""
        return self._factor

    @factor.setter
    def factor(self, value: float) -> None:
        self._factor = float(value)
        self._remap()

    @property
    def initial_time(self) -> float:
        """The simulated time that happens at ``real_start``."""
        return self._initial_time

    @initial_time.setter
    def initial_time(self, value: float) -> None:
        self._initial_time = float(value)
        self._remap()

    @property
    def delay(self) -> float | None:
        """Seconds from a simulated time happening (on the realtime clock) to its sound reaching the DAC."""
        return self._delay

    @delay.setter
    def delay(self, value: float) -> None:
        self._delay = float(value)
        self._remap()

    @property
    def latency(self) -> float:
        """The output latency PortAudio reports for the stream (s): its estimate of the time from a frame
        being written to its reaching the DAC, buffers of the host API (PulseAudio's included) counted."""
        return float(self.stream.latency)

    def heard_at(self, simulated: float) -> float:
        """The monotonic time at which the sound of simulated time ``simulated`` reaches the DAC."""
        return self._real_start + (simulated - self._initial_time) * self._factor + (self._delay or 0.0)

    def simulated_time(self, monotonic: float) -> float:
        """The simulated time whose sound reaches the DAC at monotonic time ``monotonic``."""
        return self._initial_time + (monotonic - self._real_start - (self._delay or 0.0)) / self._factor

    # -- what is played --------------------------------------------------------------------------------

    def add(self, samples: np.ndarray, rate: int, start: float, speed: float = 1.0, label: str = "",
            gain: float | Callable[[float], float] | None = None) -> Source:
        """Play ``samples`` (mono, or channels averaged) at ``rate`` with sample 0 at simulated time ``start``.

        ``speed`` is how fast the sound's own clock runs against the simulated one (its sample ``i`` is at
        ``start + i / rate * speed``); ``gain`` a factor or a function of simulated time. With ``factor``
        other than 1 the sound is played slower or faster, as simulated time is. A sound whose start has
        already been played begins part-way through and is noted in :attr:`late`. Returns its source.
        """
        data = np.asarray(samples, np.float32)
        if data.ndim == 2:
            data = data.mean(axis=1)
        data = np.ascontiguousarray(data, np.float32)
        if gain is not None and not callable(gain):
            gain = _Constant(float(gain))
        source = Source(data, int(rate), float(start), float(speed), None, gain, label)
        with self._lock:
            horizon = self.rendered_until - 1.0
            self._sources = tuple(s for s in self._sources if s.end > horizon) + (source,)
        missed = self.rendered_until - source.start
        if missed > 0:
            self.late.append((label, missed))
        return source

    def stop(self, label: str, at: float) -> int:
        """Cut the sounds labelled ``label`` at simulated time ``at``, with a FADE-long ramp that ends there.

        If the sound up to ``at`` has already been played, the cut comes as soon as it can (after the block
        being written and the fade) and is noted in :attr:`late`. Returns how many sounds were cut.
        """
        cut = 0
        with self._lock:
            soonest = self.rendered_until + self.blocksize / (self.samplerate * self._factor) + FADE
            when = max(float(at), soonest)
            sources = []
            for source in self._sources:
                if source.label == label and source.end > when:
                    source = replace(source, stop=when)
                    cut += 1
                sources.append(source)
            self._sources = tuple(sources)
        if cut and when > at:
            self.late.append((label, when - at))
        return cut

    @property
    def sources(self) -> tuple[Source, ...]:
        """The sources being played or still to play (those long finished are dropped as sounds are added)."""
        return self._sources

    def _callback(self, outdata, frames, time_info, status) -> None:
        try:
            now = time.monotonic()
            if status.output_underflow:
                self.underruns += 1
                self.tracker.restart()
            current = time_info.currentTime
            reported = time_info.outputBufferDacTime
            offset = self.stream_clock.note(now, current)
            if not self.steady:
                self.steady = self._steadiness.note(now, current, reported, frames, self.samplerate)
                if self.steady:
                    self.lead = self._steadiness.lead_max
                outdata.fill(0)
                return
            self.lead = max(self.lead, reported - current)
            dac = self.tracker.update(reported, frames)
            clock = self._map
            if clock is None:
                outdata.fill(0)
                return
            if clock.offset != offset:
                clock = self._map = replace(clock, offset=offset)
            out = self._buffer if frames <= len(self._buffer) else np.zeros(frames, np.float32)
            block = render_block(frames, dac, self.samplerate, self._sources, clock, out=out)
            outdata[:] = block[:, None]
            self.rendered_until = clock.simulated(dac + frames / self.samplerate)
            self.blocks += 1
        except Exception as exc:  # never let PortAudio stop the stream: count, and play silence
            self.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            try:
                outdata.fill(0)
            except Exception:  # not even silence: counted as well
                self.errors += 1

    # -- measuring the loop -----------------------------------------------------------------------------

    def measure_latency(self, input_device=None, clicks: int = 10, spacing: float = 0.3,
                        amplitude: float = 0.5) -> float:
        """Play ``clicks`` clicks and record them from ``input_device``; the median delay (s) of their onsets.

        Each click is a step to ``amplitude`` scheduled at a monotonic DAC time ``M`` (it begins at the first
        output frame whose DAC time is ``M`` or later, so up to one frame after). It is found in a
        :class:`Recorder` of the input as the first sample past half the amplitude, at the monotonic time
        :meth:`Recorder.frame_time` gives it (from ``inputBufferAdcTime``, mapped to monotonic as the output
        is). The number returned is that time minus ``M``: everything between the output's DAC time and the
        input's ADC time that PortAudio does not account for on either side (a cable, a converter's own
        delay, a monitor's copy: about zero on a PulseAudio null sink, where both stamps are the sink's),
        plus both sides' errors in the times they report and half a frame of the threshold. It is not the
        output latency (:attr:`latency`, :attr:`lead`): those are inside the stamps. Nothing else should be
        playing meanwhile. Each click's delay is kept in :attr:`loopback_delays`.
        """
        click = np.full(max(1, int(round(0.002 * self.samplerate))), amplitude, np.float32)
        with Recorder(input_device, samplerate=self.samplerate, seconds=clicks * spacing + 20.0) as recorder:
            recorder.wait_steady()
            first = time.monotonic() + self.lead + 0.2
            times = [first + j * spacing for j in range(clicks)]
            for j, heard in enumerate(times):
                self.add(click, self.samplerate, self.simulated_time(heard), speed=1.0 / self._factor,
                         label=f"latency click {j}")
            time.sleep(max(0.0, times[-1] + spacing - time.monotonic()) + 0.1)
            delays = []
            for heard in times:
                onset = recorder.onset(amplitude / 2, heard - 0.05, heard + spacing - 0.05)
                if onset is not None:
                    delays.append(onset - heard)
        if not delays:
            raise Unavailable(f"none of {clicks} clicks played on {self.device!r} was heard on input "
                              f"{input_device!r}: record the output's loop back (a null sink's monitor, a cable)")
        self.loopback_delays = delays
        return float(np.median(delays))

    def close(self) -> None:
        """Stop and close the stream (the sources are kept)."""
        stream = getattr(self, "stream", None)
        if stream is not None:
            try:
                stream.stop()
            finally:
                stream.close()
            self.stream = None

    def __enter__(self) -> "LiveSound":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Constant:
    """A constant gain, as a function of simulated time."""

    def __init__(self, value: float):
        self.value = value

    def __call__(self, _time: float) -> float:
        return self.value
