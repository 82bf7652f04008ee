"""The audio beat anticipator: a causal beat tracker listening to audio moves the pegs of upcoming beats.

Audio comes from a file (heard at its own pace on the simulated clock), from blocks a scenario pushes as
its simulation advances, or from a live input device (real-time mode). Pegs: ``beat1``, ``beat2``, ...
numbered from ``origin`` (beat 1 is the first beat at or after it), and a rolling window ``next1``,
``next2``, ... of the upcoming beats.
"""

from __future__ import annotations

import queue
import re
import time
from pathlib import Path

import numpy as np

from agentsim.errors import AgentsimError, Unavailable, UsageError
from agentsim.core.anticipator import Anticipator

_BEAT = re.compile(r"^beat(\d{1,9})$")
_NEXT = re.compile(r"^next(\d+)$")


class AudioBeatAnticipator(Anticipator):
    """Predicts beats from audio with a causal tracker (see :mod:`anticipators.beats.tracking`).

    Parameters
    ----------
    anticipator_id : str
        The id BML uses: ``anticipators:<id>:beat3``.
    source : str or Path or DeviceSource, optional
        An audio file, a live device, or None when a scenario pushes blocks with :meth:`push`.
    sample_rate : int, optional
        Sample rate of pushed blocks (files and devices know theirs).
    tracker : str
        Tracker name for :func:`anticipators.beats.tracking.make_tracker`.
    block_seconds : float
        Length of the blocks a file is heard in.
    horizon_beats : int
        How many upcoming beats are predicted.
    origin : float
        Time of beat 1's neighbourhood: beats are numbered from here at the tracked tempo.
    start : float
        Simulated time at which a file starts to sound.
    input : str
        A live input device to listen to instead of ``source`` (a name, a number, or ``default``; the
        command line's ``--anticipator audio:beats,input=DEVICE``), at ``sample_rate`` (44100 if not given).
    """

    def __init__(self, anticipator_id: str = "beats", source=None, sample_rate: int | None = None,
                 tracker: str = "causal", block_seconds: float = 0.02, horizon_beats: int = 8,
                 origin: float = 0.0, start: float = 0.0, input: str = "", **tracker_options):
        super().__init__(anticipator_id)
        from anticipators.beats.tracking import make_tracker

        if input:
            if source is not None:
                raise UsageError("an audio anticipator listens to a source or to an input, not both")
            source = DeviceSource(device_named(input), int(sample_rate or 44100), block_seconds)
            source.check()  # no such device: said now, before anything runs
        self.audio = None
        if isinstance(source, (str, Path)):
            self.audio, sample_rate = read_audio(source)
        elif isinstance(source, DeviceSource):
            sample_rate = source.sample_rate
        elif source is not None:
            raise AgentsimError(f"audio source {source!r}: expected a file path or a DeviceSource")
        if sample_rate is None:
            raise AgentsimError("pushed audio needs a sample_rate")
        self.source = source
        self.sample_rate = int(sample_rate)
        self.tracker = make_tracker(tracker, self.sample_rate, **tracker_options)
        self.block = max(1, int(round(block_seconds * self.sample_rate)))
        self.horizon = int(horizon_beats)
        self.origin = float(origin)
        self.start = float(start)
        self.beats: dict[int, float] = {}  # beat number -> time (final once passed)
        self.last_passed = 0
        self.upcoming: list[float] = []
        self.confidence = 0.0
        self.updates: list[tuple[float, list[float]]] = []

    # ------------------------------------------------------------------ pegs
    def make_peg(self, sync_id: str):
        beat = _BEAT.match(sync_id)
        if beat and int(beat.group(1)) >= 1:
            return self.beat_time(int(beat.group(1)))
        upcoming = _NEXT.match(sync_id)
        if upcoming and 1 <= int(upcoming.group(1)) <= self.horizon:
            k = int(upcoming.group(1)) - 1
            return self.upcoming[k] if k < len(self.upcoming) else None
        return False

    def beat_time(self, n: int) -> float | None:
        """Time of beat ``n``: as heard if passed, else as predicted (None before the first prediction)."""
        if n in self.beats:
            return self.beats[n]
        known = [k for k in self.beats if k < n]
        if not known or len(self.beats) < 2:
            return None
        last = max(known)
        numbers = sorted(self.beats)
        period = (self.beats[numbers[-1]] - self.beats[numbers[0]]) / max(1, numbers[-1] - numbers[0])
        return self.beats[last] + (n - last) * period

    # ------------------------------------------------------------------ hearing
    @property
    def now(self) -> float:
        """Audio time heard so far, on the simulated clock."""
        return self.start + self.tracker.time

    def push(self, block: np.ndarray) -> None:
        """Hear the next block of audio and move the pegs if the predictions changed."""
        self.tracker.process(block)
        self.update()

    def update(self) -> None:
        """Move the pegs to the tracker's latest predictions.

        The first upcoming beat is numbered by how many periods it lies after the last beat passed: when
        an observation moves the next beat's prediction into the past, the tracker no longer predicts it,
        and that beat is passed at its re-estimated time rather than letting the numbering slip by one.
        """
        now = self.now
        predicted = [self.start + float(t) for t in self.tracker.predict(self.horizon)]
        self.confidence = float(getattr(self.tracker, "confidence", 0.0))
        if not predicted:
            return
        period = (predicted[-1] - predicted[0]) / max(1, len(predicted) - 1) if len(predicted) > 1 else None
        for n in sorted(k for k in self.beats if k > self.last_passed):
            if self.beats[n] <= now:
                self.last_passed = n
        last_time = self.beats.get(self.last_passed)
        if self.last_passed == 0 or last_time is None or not period:
            if self.last_passed == 0 and period:
                next_number = max(1, int(round((predicted[0] - self.origin) / period)) + 1)
            else:
                next_number = self.last_passed + 1
        else:
            steps = int(round((predicted[0] - last_time) / period))
            if steps <= 0:
                predicted = predicted[1:]  # the beat just passed, re-estimated: not a new one
                steps = 1
            for k in range(1, steps):  # beats whose prediction moved into the past: passed now
                self.beats[self.last_passed + 1] = min(now, predicted[0] - (steps - k) * period)
                self.last_passed += 1
            next_number = self.last_passed + 1
        if not predicted:
            return
        changed = predicted != self.upcoming
        for stale in [k for k in self.beats if k >= next_number]:
            del self.beats[stale]
        for i, t in enumerate(predicted):
            self.beats[next_number + i] = t
        self.upcoming = predicted
        if changed:
            self.updates.append((now, list(predicted)))
            for sync_id, peg in self.pegs.items():
                time = self.make_peg(sync_id)
                if time is not None and time is not False:
                    if _BEAT.match(sync_id) and int(sync_id[4:]) <= self.last_passed:
                        if int(sync_id[4:]) in self.beats and peg.time is not None and peg.time > now:
                            peg.set(self.beats[int(sync_id[4:])])
                        continue
                    peg.set(time)

    def run(self):
        if self.audio is not None:
            return self._hear_file()
        if isinstance(self.source, DeviceSource):
            return self._hear_device()
        return None

    def _hear_file(self):
        env = self.env
        if self.start > env.now:
            yield env.timeout(self.start - env.now)
        for i in range(0, len(self.audio), self.block):
            block = self.audio[i:i + self.block]
            heard_at = self.start + (i + len(block)) / self.sample_rate
            if heard_at > env.now:
                yield env.timeout(heard_at - env.now)
            self.push(block)

    def _hear_device(self):
        env = self.env
        wall_start = getattr(env, "real_start", None)
        factor = getattr(env, "factor", 1.0)
        if wall_start is None:
            raise AgentsimError("live audio input needs real-time mode (--realtime)")
        # Where sample 0 lies on the simulated clock, from each block's capture stamp: a device may drop or
        # hold samples, so the latest second of blocks decides, and the earliest stamp (the least delayed
        # callback) is the best evidence.
        recent: list[float] = []
        heard = 0
        opened = env.now
        last_block = env.now
        sounded = False
        with self.source.open() as blocks:
            while True:
                yield env.timeout(self.block / self.sample_rate)
                while True:
                    try:
                        stamp, block = blocks.get_nowait()
                    except queue.Empty:
                        break
                    heard += len(block)
                    last_block = env.now
                    sounded = sounded or bool(len(block)) and float(np.max(np.abs(block))) > SILENCE
                    recent = (recent + [(stamp - wall_start) / factor - heard / self.sample_rate])[-50:]
                    self.start = min(recent)
                    self.push(block)
                self.source.watch(env.now - last_block, env.now - opened, sounded)


def read_audio(path: str | Path) -> tuple[np.ndarray, int]:
    """Mono float32 samples and the sample rate of an audio file (WAV, FLAC, OGG via soundfile)."""

    path = Path(path)
    if not path.is_file():
        raise UsageError(f"{str(path)!r} is a folder, not an audio file" if path.is_dir()
                         else f"no audio file {str(path)!r}")
    try:
        from agentsim.core.inputs import read_audio_limited

        data, sample_rate = read_audio_limited(path)
    except RuntimeError as exc:
        raise AgentsimError(f"cannot read audio file {str(path)!r}: {exc}") from None
    return data.mean(axis=1), int(sample_rate)


#: Below this peak (about -80 dBFS) an input is silent.
SILENCE = 1e-4
#: How long an input may be dead (no audio arriving at all) or, from the start, silent (s).
DEAD_AFTER = 2.0


#: Where ALSA reads its configuration when ALSA_CONFIG_PATH does not say.
ALSA_CONFIG = "/usr/share/alsa/alsa.conf"


def alsa_problem() -> str | None:
    """Why PortAudio cannot be loaded here without aborting the whole process, or None.

    ALSA aborts (SIGABRT) in PortAudio's start-up when its configuration file is missing or empty; loading
    sounddevice would take the process down with it. So the configuration is looked at first. (Machines
    without ALSA at all are fine: PortAudio then starts without it.)
    """
    import os

    listed = os.environ.get("ALSA_CONFIG_PATH")
    paths = [p for p in listed.split(":") if p] if listed else [ALSA_CONFIG]
    if not listed and not os.path.exists(ALSA_CONFIG):
        return None  # no ALSA here
    usable = [p for p in paths if os.path.isfile(p) and os.path.getsize(p) > 0]
    if not usable:
        where = f"ALSA_CONFIG_PATH={listed}" if listed else ALSA_CONFIG
        return (f"the ALSA configuration ({where}) is missing or empty: PortAudio would abort on it; reinstall "
                "alsa-lib's configuration (apt-get install --reinstall libasound2-data) or unset ALSA_CONFIG_PATH")
    return None


def device_named(name: str) -> str | int | None:
    """The sounddevice device a command line names: ``default`` (None), a number, or a name."""
    name = name.strip()
    return None if name == "default" else int(name) if name.isdigit() else name


class DeviceSource:
    """A live audio input device (sounddevice/PortAudio), delivering mono blocks through a queue.

    An input that delivers nothing for :data:`DEAD_AFTER` seconds, or only silence from the start for that
    long, stops the run with an :class:`~agentsim.errors.Unavailable` saying so (a machine without a
    sound card records zeros; listening to them would only give empty results).
    """

    def __init__(self, device: str | int | None = None, sample_rate: int = 44100, block_seconds: float = 0.02,
                 dead_after: float = DEAD_AFTER):
        self.device = device
        self.sample_rate = int(sample_rate)
        self.block = max(1, int(round(block_seconds * self.sample_rate)))
        self.dead_after = dead_after

    def watch(self, since_block: float, since_open: float, sounded: bool) -> None:
        """Raise :class:`Unavailable` if the input is dead or has been silent since it opened."""
        name = "the default input" if self.device is None else f"input device {self.device!r}"
        if since_block > self.dead_after:
            raise Unavailable(f"{name} delivered no audio for {since_block:.1f} s: it is not working (check "
                              "the device, or choose another with --input)")
        if not sounded and since_open > self.dead_after:
            raise Unavailable(f"{name} has been silent for {since_open:.1f} s since it opened (nothing above "
                              f"{20 * np.log10(SILENCE):.0f} dBFS): nothing plays into it, or the machine has no "
                              "sound card; play into it, or choose another with --input")

    def check(self):
        """The sounddevice module and the device's info; AgentsimError saying what to do if missing."""
        problem = alsa_problem()
        if problem:
            raise Unavailable(problem)
        try:
            import sounddevice
        except OSError as exc:
            raise AgentsimError(f"audio input needs PortAudio ({exc}): apt-get install libportaudio2") from None
        try:
            info = sounddevice.query_devices(self.device, "input")
        except (ValueError, sounddevice.PortAudioError) as exc:
            names = [d["name"] for d in sounddevice.query_devices() if d["max_input_channels"] > 0]
            raise AgentsimError(f"no audio input device {self.device!r} ({exc}); input devices: "
                                f"{', '.join(names) or 'none'} (start PulseAudio or set --input)") from None
        return sounddevice, info

    def open(self):
        sounddevice, info = self.check()
        blocks: queue.Queue = queue.Queue()

        def callback(indata, frames, time_info, status):
            blocks.put((time.monotonic(), indata.mean(axis=1).astype(np.float32).copy()))

        stream = sounddevice.InputStream(device=self.device, channels=1, samplerate=self.sample_rate,
                                         blocksize=self.block, dtype="float32", callback=callback)
        return _Stream(stream, blocks)


class _Stream:
    def __init__(self, stream, blocks):
        self.stream, self.blocks = stream, blocks

    def __enter__(self):
        self.stream.start()
        return self.blocks

    def __exit__(self, *exc):
        self.stream.stop()
        self.stream.close()
