"""What a listener of the run heard, as one track on the run's time axis.

Each speech is placed where it was heard: its first sample at ``t0`` (the request plus the playback latency
of its strategy), speech time ``s`` at ``t0 + s * (1 + drift_ppm * 1e-6)``, its BMLA volume changes applied,
cut (with a 5 ms fade) where an interruption stopped it. Sound files (``bmlt:audiofile``) start where they
were played and stop where they were stopped; other sources (an ensemble the conductor heard) are given as
:class:`Source`. Sources at other sample rates are resampled by linear interpolation onto the track's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator

import numpy as np

#: The fade (s) where a sound is cut short, so that the cut does not click.
FADE = 0.005


@dataclass(frozen=True)
class Source:
    """A sound to place on the axis: mono ``samples`` at ``rate``, its sample 0 heard at ``start`` (s).

    ``speed`` is how fast its own clock runs against the run's (1 + drift); ``stop`` cuts it (s, or None);
    ``gain`` is a loudness factor as a function of global time, or None for 1.
    """

    samples: np.ndarray
    rate: int
    start: float
    speed: float = 1.0
    stop: float | None = None
    gain: Callable[[float], float] | None = None
    label: str = ""

    @property
    def end(self) -> float:
        end = self.start + len(self.samples) / self.rate * self.speed
        return min(end, self.stop) if self.stop is not None else end


@dataclass
class Track:
    """Mono samples at ``rate`` whose sample 0 is at simulated time 0, and what went into it."""

    samples: np.ndarray
    rate: int
    labels: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return len(self.samples) / self.rate

    def time_of(self, index: int) -> float:
        return index / self.rate

    @property
    def length(self) -> int:
        """Number of samples."""
        return len(self.samples)

    def stretches(self) -> Iterator[np.ndarray]:
        """The samples in one stretch (as :meth:`TrackStream.stretches` gives them in several)."""
        yield self.samples


def speech_sources(recording) -> list[Source]:
    """The speeches of a recording that made sound, as sources."""
    sources = []
    for heard in recording.speech:
        audio = getattr(heard.utterance, "audio", None)
        if audio is None or len(audio) == 0:
            continue
        gain = heard.gain if heard.volume else None
        # float32 samples left as they are: an array, or samples read from a file as they are needed
        # (:class:`~speech_timing.samples.PcmFile`), which np.asarray would read whole
        samples = audio if getattr(audio, "dtype", None) == np.float32 else np.asarray(audio, np.float32)
        sources.append(Source(samples, int(heard.utterance.sample_rate), float(heard.t0),
                              1.0 + heard.drift_ppm * 1e-6, heard.stopped, gain,
                              f"{heard.block}:{heard.behaviour}"))
    return sources


def file_sources(recording) -> list[Source]:
    """The sound files a recording played (``bmlt:audiofile``), as sources."""
    from agentsim.core.inputs import read_audio_limited

    sources = []
    for played in recording.audio:
        data, rate = read_audio_limited(played.path)  # weighed by its header first
        sources.append(Source(data.mean(axis=1), int(rate), float(played.start), 1.0, played.stopped,
                              label=f"{played.block}:{played.behaviour}"))
    return sources


@dataclass
class TrackStream:
    """A track made a stretch at a time (:func:`mix_stream`): what :func:`mix` gives, without holding the
    whole of it. ``length`` samples at ``rate``; :meth:`stretches` makes them anew on every call."""

    placed: list
    length: int
    rate: int
    labels: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.length / self.rate

    def stretches(self) -> Iterator[np.ndarray]:
        """The samples (float32) in order, :data:`MIX_CHUNK` at a time (the last stretch shorter)."""
        n, rate = self.length, self.rate
        for a in range(0, n, MIX_CHUNK):
            b = min(a + MIX_CHUNK, n)
            acc = np.zeros(b - a, np.float64)
            for source, first, last, gain_grid in self.placed:
                lo, hi = max(a, first), min(b, last)
                if hi > lo:
                    acc[lo - a:hi - a] += _placed(source, rate, lo, hi, gain_grid)
            yield np.clip(acc, -1.0, 1.0, out=acc).astype(np.float32)

    def read(self) -> Track:
        """The whole track in memory."""
        out = np.empty(self.length, np.float32)
        a = 0
        for stretch in self.stretches():
            out[a:a + len(stretch)] = stretch
            a += len(stretch)
        return Track(out, int(self.rate), list(self.labels))


def mix_stream(sources: Iterable[Source], rate: int | None = None, duration: float | None = None) -> TrackStream:
    """The track :func:`mix` makes, as a :class:`TrackStream` to be written a stretch at a time."""
    sources = list(sources)
    if rate is None:
        rate = max((s.rate for s in sources), default=22050)
    end = max((s.end for s in sources), default=0.0)
    n = int(np.ceil((duration if duration is not None else end) * rate))
    placed = []
    for source in sources:
        first = max(0, int(np.floor(source.start * rate)))
        last = min(n, int(np.ceil(source.end * rate)))
        if last <= first:
            continue
        gain_grid = None
        if source.gain is not None and last - first >= 200_000:  # the gain sampled every 256 samples
            grid = np.arange(first, last)[::256] / rate
            gain_grid = (grid, [source.gain(x) for x in grid])
        placed.append((source, first, last, gain_grid))
    # Each stretch of the track is the sum of the sources in their order as it was over the whole length,
    # without arrays of the whole length.
    return TrackStream(placed, n, int(rate), [s.label for s in sources if s.label])


def mix(sources: Iterable[Source], rate: int | None = None, duration: float | None = None) -> Track:
    """Mix ``sources`` into one track at ``rate`` (default: the highest of the sources', or 22050 Hz),
    long enough for the last of them (or ``duration`` s). Samples are summed and clipped to [-1, 1]."""
    return mix_stream(sources, rate, duration).read()


#: Samples of a source placed at a time by :func:`mix`.
MIX_CHUNK = 1 << 20


def _placed(source: Source, rate: int, first: int, last: int, gain_grid) -> np.ndarray:
    """Samples ``first .. last - 1`` of the track that ``source`` makes (before mixing)."""
    t = np.arange(first, last) / rate
    if source.speed == 1.0 and source.rate == rate and abs(source.start * rate - round(source.start * rate)) < 1e-6:
        offset = int(round(source.start * rate))
        # the source's samples first - offset .. last - offset - 1, those it has: one stretch (a slice, which
        # samples read from a file give without reading more)
        lo, hi = max(first - offset, 0), min(last - offset, len(source.samples))
        values = np.zeros(last - first)
        if hi > lo:
            values[lo + offset - first:hi + offset - first] = source.samples[lo:hi]
    else:
        # where in the source each output sample falls (in source samples)
        position = (t - source.start) / source.speed * source.rate
        # the source samples around those positions are enough (the same neighbours, so the same numbers)
        lo = min(max(int(np.floor(position.min())) - 1, 0), len(source.samples))
        hi = min(max(int(np.ceil(position.max())) + 2, lo), len(source.samples))
        values = np.interp(position, np.arange(lo, hi), source.samples[lo:hi], left=0.0, right=0.0)
    if source.gain is not None:
        values = values * (np.array([source.gain(x) for x in t]) if gain_grid is None else
                           np.interp(t, gain_grid[0], gain_grid[1]))
    if source.stop is not None:
        values = values * np.clip((source.stop - t) / FADE, 0.0, 1.0)
    return values


def run_track(recording, extra: Iterable[Source] = (), rate: int | None = None,
              duration: float | None = None) -> Track:
    """Everything the run's listener heard: its speech, its sound files and ``extra`` sources."""
    return mix([*speech_sources(recording), *file_sources(recording), *extra], rate, duration)


def run_track_stream(recording, extra: Iterable[Source] = (), rate: int | None = None,
                     duration: float | None = None) -> TrackStream:
    """What :func:`run_track` gives, as a :class:`TrackStream` (a long run written without holding its track)."""
    return mix_stream([*speech_sources(recording), *file_sources(recording), *extra], rate, duration)
