"""The clocks of live sound, and the mixing of a block of it: which sample of which source reaches the DAC when.

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
the block's DAC time, the rate, the sources and the :class:`ClockMap`; :class:`Steadiness` says when the
stream's lead has settled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

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
