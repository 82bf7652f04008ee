"""A live run's sound, played on an audio device at the time the plan says.

A live realizer runs on ``simpy.rt.RealtimeEnvironment``: simulated time ``s`` happens at
``real_start + (s - initial_time) * factor`` on ``time.monotonic()``. Its feedback reaches clients ``delay``
seconds after its simulated time, and the sound of simulated time ``s`` must reach the DAC at that same
moment, ``real_start + (s - initial_time) * factor + delay``: what people hear and what programs are told
then agree. ``delay`` must be long enough for a sound added at its own simulated time to be written before
the device needs it (the stream's output latency, one block and a margin).

Three clocks meet here:

* simulated time, that of the plan and of every :class:`~agentsim.media.audio.Source`;
* ``time.monotonic()``, that of the realtime environment;
* the stream's clock, in which PortAudio stamps every callback (``currentTime``) and says when the block's
  first frame will reach the DAC (``outputBufferDacTime``) or left the ADC (``inputBufferAdcTime``). On Linux
  (ALSA, and PulseAudio through it) it is the wall clock (``CLOCK_REALTIME``), not the monotonic one.

:class:`StreamClock` maps the stream's clock onto ``time.monotonic()`` from the pairs each callback gives
(its ``currentTime`` and the monotonic time it started at): the offset is their lower envelope over the last
two seconds, the pair whose callback ran soonest after its stamp. :class:`DacTracker` turns PortAudio's
per-block DAC estimates, which jitter, into the sample clock they estimate: the frames written are played
one after the other, so each block starts where the previous one ended, steered slowly towards the reports
and re-anchored when they jump (an underrun). :func:`render_block` is the mixing itself, a pure function of
the block's DAC time, the rate, the sources and the :class:`ClockMap`; :class:`LiveSound` is the output
stream whose callback calls it, and :class:`Recorder` an input stream that keeps what it heard with the
monotonic time of each frame (to measure the loop back, :meth:`LiveSound.measure_latency`).

Sound is played at the plan's times even when that cuts it: a sound added after part of it should already
have been heard starts part-way through (and is counted in :attr:`LiveSound.late`), so that later sounds and
the feedback stay in step with it.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from agentsim.errors import Unavailable
from agentsim.media.audio import FADE, Source

#: What ``delay=None`` adds to the measured output lead and one block (s): a simulation step can call
#: :meth:`LiveSound.add` late by the time it waits for the GIL (Python's switch interval, 5 ms) plus the
#: realtime environment's oversleeping (well under 1 ms here), and the callback can run late by the same
#: switch interval. Twice the switch interval covers both.
MARGIN = 0.010

#: Positions closer than this to a whole source sample (in samples) are taken as that sample, so that a
#: source placed on an output frame plays its samples exactly rather than a 1e-12 blend of two.
SNAP = 1e-6


@dataclass(frozen=True)
class ClockMap:
    """From a stream's clock to simulated time and back.

    A frame reaching the DAC at stream time ``t`` is heard at monotonic time ``t + offset`` and carries the
    sound of simulated time ``initial_time + (t + offset - real_start - delay) / factor``.
    """

    real_start: float
    factor: float = 1.0
    delay: float = 0.0
    offset: float = 0.0
    initial_time: float = 0.0

    def simulated(self, stream_time: float) -> float:
        """The simulated time whose sound a frame at ``stream_time`` (DAC time, stream clock) carries."""
        return self.initial_time + (stream_time + self.offset - self.real_start - self.delay) / self.factor

    def stream_time(self, simulated: float) -> float:
        """The DAC time (stream clock) at which the sound of simulated time ``simulated`` is heard."""
        return self.real_start + (simulated - self.initial_time) * self.factor + self.delay - self.offset


def _interpolate(samples: np.ndarray, position: np.ndarray) -> np.ndarray:
    """``np.interp(position, arange(n), samples, left=0, right=0)`` without an arange of the whole source."""
    n = len(samples)
    valid = (position >= 0.0) & (position <= n - 1)
    i0 = np.floor(position).astype(np.int64)
    np.clip(i0, 0, max(n - 2, 0), out=i0)
    frac = position - i0
    i1 = np.minimum(i0 + 1, n - 1)
    values = samples[i0] * (1.0 - frac) + samples[i1] * frac
    values[~valid] = 0.0
    return values


def render_block(frames: int, dac_time: float, rate: float, sources: Sequence[Source], clock: ClockMap,
                 out: np.ndarray | None = None) -> np.ndarray:
    """The mono samples of one output block whose first frame reaches the DAC at ``dac_time`` (stream clock).

    Frame ``k`` reaches the DAC at ``dac_time + k / rate`` and carries simulated time
    ``clock.simulated(dac_time) + k / (rate * clock.factor)``. Each source is read there as
    :func:`agentsim.media.audio.mix` reads it: its sample ``i`` at simulated time ``start + i / rate * speed``,
    linearly interpolated between samples and silent outside them; its ``gain`` (a function of simulated
    time) evaluated at the block's first and last frames it covers and interpolated between; cut at ``stop``
    with a :data:`~agentsim.media.audio.FADE` ramp that ends there. The sum is clipped to [-1, 1].

    Work and temporaries are O(frames) per source that sounds in the block; ``out`` (float32, at least
    ``frames`` long) is filled instead of a new array when given.
    """
    if out is None:
        out = np.zeros(frames, np.float32)
    else:
        out = out[:frames]
        out.fill(0.0)
    if frames <= 0:
        return out
    first = clock.simulated(dac_time)
    step = 1.0 / (rate * clock.factor)  # simulated seconds per output frame
    last = first + (frames - 1) * step
    for source in sources:
        n = len(source.samples)
        end = source.end
        if n == 0 or source.start > last + step * SNAP or end <= first:
            continue
        k0 = max(0, math.ceil((source.start - first) / step - SNAP))
        k1 = min(frames, math.floor((end - first) / step + SNAP) + 1)
        if k1 <= k0:
            continue
        k = np.arange(k0, k1)
        t = first + k * step
        position = (t - source.start) * (source.rate / source.speed)
        whole = np.rint(position)
        snap = np.abs(position - whole) < SNAP
        position[snap] = whole[snap]
        values = _interpolate(source.samples, position)
        if source.gain is not None:
            g0, g1 = float(source.gain(t[0])), float(source.gain(t[-1]))
            values *= g0 if k1 - k0 == 1 else g0 + (g1 - g0) * (k - k0) / (k1 - 1 - k0)
        if source.stop is not None:
            values *= np.clip((source.stop - t) / FADE, 0.0, 1.0)
        out[k0:k1] += values
    np.clip(out, -1.0, 1.0, out=out)
    return out


class StreamClock:
    """Maps a stream's clock onto ``time.monotonic()``: monotonic = stream time + :attr:`offset`.

    Each callback gives one pair, the monotonic time at which it started and PortAudio's ``currentTime``
    stamped just before; the monotonic one is late by however long the callback waited (for the GIL, for
    the scheduler), never early. The offset is therefore the smallest ``monotonic - currentTime`` over the
    last ``window`` seconds (between half of it and all of it: two buckets of ``window / 2``), which follows
    a step of either clock within ``window``. Each bucket's smallest and largest difference are logged
    (:meth:`history`) to show how stable the mapping is and how late callbacks run.
    """

    def __init__(self, window: float = 2.0, log: int = 600):
        self.window = float(window)
        self.offset: float | None = None
        self._current = math.inf
        self._current_max = -math.inf
        self._previous = math.inf
        self._bucket_start: float | None = None
        self._log = np.full((int(log), 2), np.nan)
        self._logged = 0

    def note(self, monotonic: float, stream_time: float) -> float:
        """Take one (monotonic, stream clock) pair sampled together; return the offset now in force."""
        sample = monotonic - stream_time
        if self._bucket_start is None or monotonic - self._bucket_start >= self.window / 2:
            if self._bucket_start is not None:
                row = self._logged % len(self._log)
                self._log[row, 0] = self._current
                self._log[row, 1] = self._current_max
                self._logged += 1
            self._previous = self._current
            self._current = self._current_max = sample
            self._bucket_start = monotonic
        else:
            if sample < self._current:
                self._current = sample
            if sample > self._current_max:
                self._current_max = sample
        self.offset = min(self._previous, self._current)
        return self.offset

    def to_monotonic(self, stream_time: float) -> float:
        """A stream-clock time on ``time.monotonic()``."""
        return stream_time + (self.offset or 0.0)

    def history(self) -> np.ndarray:
        """The logged buckets, oldest first: one row (smallest, largest) of ``monotonic - stream time`` each."""
        n = min(self._logged, len(self._log))
        order = (np.arange(n) + self._logged - n) % len(self._log)
        return self._log[order].copy()


class DacTracker:
    """The DAC time of each block's first frame, as the sample clock PortAudio's per-block reports estimate.

    Frames written to a stream are played one after the other, so a block starts ``frames / rate`` after
    the previous one; what PortAudio reports scatters around that (by about 0.1 ms on a PulseAudio device).
    Each report moves the prediction by ``gain`` times its error (a running mean for the first ``1 / gain``
    blocks), so the estimate follows a drifting device clock within ``drift_per_block / gain``; a report
    further than ``jump`` from the prediction ``patience`` times in a row (or :meth:`restart`, after an
    underrun) re-anchors it there and counts in :attr:`jumps`. All times on the stream's clock.
    """

    def __init__(self, rate: float, gain: float = 0.02, jump: float = 0.004, patience: int = 3):
        self.rate = float(rate)
        self.gain = float(gain)
        self.jump = float(jump)
        self.patience = int(patience)
        self.predicted: float | None = None
        self.jumps = 0
        self.max_error = 0.0
        self._outliers = 0
        self._updates = 0
        self._square_sum = 0.0

    def restart(self) -> None:
        """Forget the prediction: the next report anchors the clock (after an underrun, a restart)."""
        self.predicted = None
        self._updates = 0
        self._outliers = 0

    def update(self, reported: float, frames: int) -> float:
        """The DAC time of the block whose first frame PortAudio reports at ``reported``."""
        if self.predicted is None:
            dac = reported
            self._updates = 1
        else:
            error = reported - self.predicted
            if abs(error) > self.jump:
                self._outliers += 1
                if self._outliers >= self.patience:
                    self.jumps += 1
                    self.restart()
                    self._updates = 1
                    dac = reported
                else:
                    dac = self.predicted
            else:
                self._outliers = 0
                self._updates += 1
                self.max_error = max(self.max_error, abs(error))
                self._square_sum += error * error
                dac = self.predicted + max(self.gain, 1.0 / self._updates) * error
        self.predicted = dac + frames / self.rate
        return dac

    @property
    def rms_error(self) -> float:
        """Root mean square of the reports' distance from the prediction (s): how much they jitter."""
        return math.sqrt(self._square_sum / max(1, self._updates - 1))


class Steadiness:
    """Whether a stream's callbacks have settled, from the last ``count`` of them.

    Opening a PulseAudio stream, PortAudio first calls back several times at once to fill its buffers with
    DAC times that are not those at which the frames are played, then nothing for one or two seconds.
    Settled means: the last ``count`` blocks are contiguous in DAC time (within ``tolerance``), their
    callbacks took at least half their audio's duration of wall time (no burst), and their lead
    (``outputBufferDacTime - currentTime``) varied by at most two blocks. :attr:`lead_max` is then the
    largest lead among them.
    """

    def __init__(self, count: int = 8, tolerance: float = 0.001):
        self.count = int(count)
        self.tolerance = float(tolerance)
        self.lead_max = 0.0
        self._rows = np.zeros((self.count, 4))
        self._seen = 0

    def note(self, wall: float, current: float, dac: float, frames: int, rate: float) -> bool:
        """Take one callback's wall time, ``currentTime``, DAC time and length; True once settled."""
        self._rows[self._seen % self.count] = (wall, current, dac, frames)
        self._seen += 1
        if self._seen < self.count:
            return False
        order = (np.arange(self.count) + self._seen) % self.count
        w, c, d, f = self._rows[order].T
        if np.max(np.abs(d[1:] - d[:-1] - f[:-1] / rate)) > self.tolerance:
            return False
        if w[-1] - w[0] < 0.5 * f[:-1].sum() / rate:
            return False
        lead = d - c
        if np.ptp(lead) > 2 * f.max() / rate + self.tolerance:
            return False
        self.lead_max = float(lead.max())
        return True


def _sounddevice():
    """The sounddevice module, or Unavailable saying what to install (or what is wrong with ALSA)."""
    from anticipators.audio import alsa_problem

    problem = alsa_problem()
    if problem:
        raise Unavailable(problem)
    try:
        import sounddevice
    except ImportError:
        raise Unavailable("live sound needs the sounddevice package: pip install sounddevice") from None
    except OSError as exc:
        raise Unavailable(f"live sound needs the PortAudio library ({exc}): apt-get install libportaudio2") from None
    return sounddevice


#: How to get a device to play on, where there is none.
GET_A_DEVICE = "plug in a sound card or start PulseAudio (apt-get install pulseaudio libasound2-plugins)"


class NoAudioDevice(Unavailable):
    """There is no audio device of the ``kind`` (``"output"`` or ``"input"``) asked for: none at all here, no
    such device, or one without channels of that kind. ``problem`` says which and what devices there are;
    the message adds how to get one (:data:`GET_A_DEVICE`) and name it."""

    def __init__(self, problem: str, kind: str):
        super().__init__(f"{problem}; {GET_A_DEVICE} and name its device (e.g. 'pulse')")
        self.problem = problem
        self.kind = kind


def _device_info(sounddevice, device, kind: str) -> dict:
    """The device's info from PortAudio, or :class:`NoAudioDevice` naming the devices there are."""
    try:
        return dict(sounddevice.query_devices(device, kind))
    except (ValueError, sounddevice.PortAudioError) as exc:
        problem = exc
    try:
        devices = [dict(d) for d in sounddevice.query_devices()]
    except Exception:  # PortAudio itself is broken: say so through the original error
        devices = []
    names = ", ".join(d["name"] for d in devices if d[f"max_{kind}_channels"] > 0)
    found = None
    if device is not None:
        try:
            found = dict(sounddevice.query_devices(device))
        except (ValueError, sounddevice.PortAudioError):
            pass
    if found is not None:  # it is there, but it does not play (or record)
        raise NoAudioDevice(f"audio device {device!r} ({found['name']}) has no {kind} channels; {kind} devices "
                            f"here: {names or 'none'}", kind)
    if device is None and not names:
        other = "input" if kind == "output" else "output"
        only = ", ".join(d["name"] for d in devices if d[f"max_{other}_channels"] > 0)
        besides = f"; only {other} devices: {only}" if only else ""
        raise NoAudioDevice(f"there is no audio {kind} device here (PortAudio finds no sound card and no sound "
                            f"server{besides})", kind)
    which = f"no default audio {kind} device" if device is None else f"no audio {kind} device {device!r}"
    raise NoAudioDevice(f"{which} ({problem}); {kind} devices here: {names or 'none'}", kind)


def open_device(name: str | int | None, kind: str = "output"):
    """The sounddevice spec of the audio ``kind`` device ``name`` ("default" or None: the default one), after
    checking that PortAudio has it: Unavailable says which devices there are and what to install or start,
    before a live run begins."""
    sounddevice = _sounddevice()
    device = None if name in (None, "default") else name
    if isinstance(device, str) and device.isdigit():
        device = int(device)
    _device_info(sounddevice, device, kind)
    return device


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

    Counters, none of which the callback ever raises instead of: :attr:`underruns` (PortAudio's output
    underflow flag), :attr:`errors` and :attr:`last_error` (exceptions caught in the callback, whose block
    is then silent), :attr:`late` (``(label, seconds)`` of sounds added or stopped after the time they
    should have begun or ended had already been played), :attr:`blocks` (blocks played).
    """

    def __init__(self, device=None, *, real_start: float, factor: float = 1.0, delay: float | None = None,
                 samplerate: int | None = None, blocksize: int = 256, initial_time: float = 0.0,
                 channels: int | None = None, start_timeout: float = 10.0):
        sounddevice = _sounddevice()
        info = _device_info(sounddevice, device, "output")
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
        sounddevice = _sounddevice()
        info = _device_info(sounddevice, device, "input")
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
