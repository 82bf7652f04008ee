"""Rendering through FluidSynth: MIDI events block by block as a simulation advances (pyfluidsynth), and
MIDI files with the ``fluidsynth`` program."""

from __future__ import annotations

import ctypes
import heapq
import itertools
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from typing import Iterable, Sequence

import numpy as np

from agentsim.errors import AgentsimError, Unavailable
from agentsim.music.events import EVENT_ORDER, SynthEvent
from agentsim.music.instruments import DRUM_CHANNEL

__all__ = [
    "DEFAULT_SOUNDFONT",
    "INSTALL_HINT",
    "FLUID_BLOCK",
    "AHEAD_SECONDS",
    "PUBLISHED",
    "check_soundfont",
    "import_fluidsynth",
    "FluidSynthRenderer",
    "SampleClock",
    "render_events",
    "render_midi_file",
]

DEFAULT_SOUNDFONT = "/usr/share/sounds/sf2/FluidR3_GM.sf2"
"""Path of the General MIDI soundfont installed by Debian's ``fluid-soundfont-gm``."""

INSTALL_HINT = "apt-get install fluidsynth fluid-soundfont-gm"
"""The command that installs FluidSynth and the General MIDI soundfont on Debian."""

FLUID_BLOCK = 64
"""FluidSynth's internal block length in samples; MIDI events take effect on its boundaries."""


AHEAD_SECONDS = 1.0
"""How far beyond what it handed out :meth:`FluidSynthRenderer.render_ahead` renders at most (seconds)."""

PUBLISHED = 1024
"""The rendering thread (or process) hands out what it rendered every this many samples (a multiple of
FLUID_BLOCK)."""


def check_soundfont(soundfont: "str | os.PathLike") -> str:
    """The path of a soundfont file that exists.

    Parameters
    ----------
    soundfont : str or path-like
        The SoundFont file.

    Returns
    -------
    str
        Its path.

    Raises
    ------
    Unavailable
        When there is no such file, saying how to install the General MIDI soundfont.
    """
    path = os.fspath(soundfont)
    if not os.path.isfile(path):
        raise Unavailable(
            f"General MIDI soundfont not found at {path!r}; install it with `{INSTALL_HINT}`"
        )
    return path


_IMPORT_LOCK = threading.Lock()


def import_fluidsynth():
    try:
        with _IMPORT_LOCK:
            # pyfluidsynth prints where it found the library onto stdout, which carries our JSON, when $CI is
            # set as it is first imported (a process-wide setting, like stdout: hence the lock)
            ci = os.environ.pop("CI", None) if "fluidsynth" not in sys.modules else None
            try:
                import fluidsynth  # pyfluidsynth; raises ImportError when libfluidsynth is missing
            finally:
                if ci is not None:
                    os.environ["CI"] = ci
    except (ImportError, OSError) as exc:
        raise Unavailable(
            f"the FluidSynth library could not be loaded ({exc}); install it with `{INSTALL_HINT}` "
            "and the Python binding with `pip install pyfluidsynth`"
        ) from exc
    return fluidsynth


class SampleClock:
    """What :class:`FluidSynthRenderer` and :class:`~agentsim.music.process.RenderingProcess` share: where a
    renderer of ``sample_rate`` is in its audio (the samples it handed out, ``_handed``), on which sample an
    event takes effect, how far a promise reaches, and a note as its two events (through ``schedule``)."""

    sample_rate: int
    _handed: int

    @property
    def time(self) -> float:
        """Seconds of audio handed out so far."""
        return self._handed / self.sample_rate

    @property
    def samples_rendered(self) -> int:
        """Number of samples handed out so far (by :meth:`render_until`)."""
        return self._handed

    def event_sample(self, time: float) -> int:
        """Sample index at which an event at ``time`` seconds takes effect (nearest 64-sample boundary)."""
        return int(np.round(time * self.sample_rate / FLUID_BLOCK)) * FLUID_BLOCK

    def note(self, time: float, channel: int, key: int, velocity: int, duration: float) -> None:
        """Queue a note: a note-on at ``time`` and a note-off ``duration`` seconds later."""
        self.schedule(
            [SynthEvent(time, "note_on", channel, key, velocity), SynthEvent(time + duration, "note_off", channel, key, 0)]
        )

    def promised_sample(self, until: float) -> int:
        """The sample a promise of quiet until ``until`` seconds reaches: a FLUID_BLOCK boundary, at most
        :data:`AHEAD_SECONDS` beyond what was handed out."""
        until = min(until, self.time + AHEAD_SECONDS)
        return int(until * self.sample_rate) // FLUID_BLOCK * FLUID_BLOCK

    def hand_out(self, ahead: list[np.ndarray], end: int) -> tuple[np.ndarray, list[np.ndarray]]:
        """The samples up to ``end`` from ``ahead`` (the stretches rendered beyond what was handed out), and
        what is left of ``ahead``; they are handed out."""
        have = np.concatenate(ahead) if len(ahead) > 1 else ahead[0]
        n = end - self._handed
        self._handed = end
        return have[:n], ([have[n:]] if have.size > n else [])


class FluidSynthRenderer(SampleClock):
    """Render MIDI events to mono audio block by block with FluidSynth, as a simulation advances.

    Events are queued with :meth:`schedule` (or :meth:`note`) and sound when :meth:`render_until`
    passes their time. FluidSynth applies MIDI events at the start of its next internal block of
    :data:`FLUID_BLOCK` (64) samples, so each event is placed on the 64-sample boundary nearest to its
    time and it is known exactly on which sample each note starts (:meth:`event_sample`). A note's
    sound then begins a constant, instrument-specific time after that sample, because the soundfont's
    samples and envelopes start quietly (see :func:`~agentsim.music.onsets.measure_onset_offsets`).
    Events scheduled in the past are applied at once (on the next boundary).

    A caller that knows no event will be scheduled before some time says so with :meth:`render_ahead`:
    a thread of the renderer's own then renders up to there while the caller goes on (FluidSynth does not
    hold Python's lock), and :meth:`render_until` hands out what it rendered. The samples are the same as
    rendering when asked, as long as the promise is kept (:attr:`broken_promises` counts events scheduled
    before a time promised: they sound at once, later than they would have).

    Parameters
    ----------
    sample_rate : int
        Output sample rate in Hz.
    soundfont : str or path-like
        SoundFont file; the General MIDI soundfont by default.
    gain : float
        FluidSynth master gain (``synth.gain``).
    reverb, chorus : bool
        Whether FluidSynth's reverb and chorus are on.
    programs : dict, optional
        Initial General MIDI program per channel; channel 9 always plays the standard drum kit.

    Raises
    ------
    Unavailable
        When the FluidSynth library or the soundfont is missing.
    """

    def __init__(
        self,
        sample_rate: int = 44100,
        soundfont: "str | os.PathLike" = DEFAULT_SOUNDFONT,
        gain: float = 0.3,
        reverb: bool = True,
        chorus: bool = False,
        programs: "dict[int, int] | None" = None,
    ) -> None:
        if sample_rate < 8000 or sample_rate > 192000:
            raise ValueError("sample_rate must be within 8000..192000 Hz")
        path = check_soundfont(soundfont)
        fluidsynth = import_fluidsynth()
        self.sample_rate = int(sample_rate)
        with _IMPORT_LOCK:  # FluidSynth sets up its default modulators, shared by all synthesizers, unguarded
            self._synth = fluidsynth.Synth(gain=float(gain), samplerate=float(sample_rate))
        self._write_s16 = fluidsynth.fluid_synth_write_s16
        self._synth.setting("synth.reverb.active", int(bool(reverb)))
        self._synth.setting("synth.chorus.active", int(bool(chorus)))
        # a sample is read from the soundfont when a preset that plays it is chosen, not all 140 MB up front
        self._synth.setting("synth.dynamic-sample-loading", 1)
        self._queue: list[tuple[int, int, int, SynthEvent]] = []
        self._counter = itertools.count()
        self._pos = 0  # samples synthesised so far, always a multiple of FLUID_BLOCK at event boundaries
        self._handed = 0  # samples handed out by render_until
        # rendering ahead: one thread synthesises up to the time promised, into _ahead (mono float32
        # beyond what was handed out); the queue and _ahead are shared with it under _lock; the synthesizer
        # and _pos belong to whichever thread renders, the caller's only while no job is pending
        self._lock = threading.Lock()
        self._published = threading.Condition(self._lock)  # a stretch was added to _ahead
        self._ahead: list[np.ndarray] = []
        self._ready = 0  # samples synthesised by finished jobs (or by the caller)
        self._promised = 0  # sample before which no new event will be scheduled
        self._jobs: list = []
        self._submitted = self._finished = 0  # jobs handed to the thread, and those over
        self._worker = None
        self.broken_promises = 0
        self._sfid = self._synth.sfload(path)
        if self._sfid < 0:
            raise Unavailable(f"FluidSynth could not load the soundfont {path!r}; reinstall it with `{INSTALL_HINT}`")
        self._synth.program_select(DRUM_CHANNEL, self._sfid, 128, 0)
        for ch, prog in (programs or {}).items():
            self.set_program(ch, prog)

    def set_program(self, channel: int, program: int) -> None:
        """Select a General MIDI program on a melodic channel now."""
        self._drain()  # the synthesizer is the rendering thread's until its jobs are done
        self._select(channel, program)

    def _select(self, channel: int, program: int) -> None:
        """Select a program (by the thread that renders)."""
        if channel == DRUM_CHANNEL:
            self._synth.program_select(DRUM_CHANNEL, self._sfid, 128, int(program))
        else:
            self._synth.program_select(int(channel), self._sfid, 0, int(program))

    def schedule(self, events: "SynthEvent | Iterable[SynthEvent]") -> None:
        """Queue one event or several; they sound when rendering passes their time."""
        if isinstance(events, SynthEvent):
            events = (events,)
        with self._lock:
            for ev in events:
                at = self.event_sample(ev.time)
                if at < self._promised:
                    self.broken_promises += 1
                heapq.heappush(self._queue, (at, EVENT_ORDER[ev.kind], next(self._counter), ev))

    def _apply(self, ev: SynthEvent) -> None:
        s = self._synth
        if ev.kind == "note_on":
            s.noteon(ev.channel, ev.data1, ev.data2)
        elif ev.kind == "note_off":
            s.noteoff(ev.channel, ev.data1)
        elif ev.kind == "program":
            self._select(ev.channel, ev.data1)
        else:
            s.cc(ev.channel, ev.data1, ev.data2)

    def _render(self, n: int, out: list) -> None:
        if n > 0:
            # FluidSynth's 16-bit interleaved stereo written straight into an array (what the binding's
            # get_samples does through a fresh ctypes buffer and a copy)
            samples = np.empty(2 * n, np.int16)
            pointer = samples.ctypes.data_as(ctypes.c_void_p)
            self._write_s16(self._synth.synth, n, pointer, 0, 2, pointer, 1, 2)
            out.append(samples)
            self._pos += n

    def _synthesise(self, end: int) -> None:
        """Synthesise from ``_pos`` to sample ``end``, applying the events due on the way, into ``_ahead``, a
        stretch of at most :data:`PUBLISHED` samples at a time, so that a caller waiting for the start of a long
        stretch waits for that start alone."""
        while self._pos < end:
            mono = self.render_stretch(min(end, self._pos + PUBLISHED))
            with self._published:
                self._ahead.append(mono)
                self._ready = self._pos
                self._published.notify_all()

    @property
    def position(self) -> int:
        """Number of samples synthesised so far (handed out or not)."""
        return self._pos

    def render_stretch(self, stop: int) -> np.ndarray:
        """Synthesise from :attr:`position` to sample ``stop`` (past it), applying the events due on the way,
        and return the mono samples, by the thread that renders (for a renderer not rendering ahead: the
        process of :class:`~agentsim.music.process.RenderingProcess` renders with it)."""
        chunks: list[np.ndarray] = []
        queue = self._queue
        while True:
            with self._lock:
                if not queue or queue[0][0] > stop:
                    break
                at, _, _, event = heapq.heappop(queue)
            # Render up to the event's boundary (event samples are multiples of FLUID_BLOCK, so
            # FluidSynth's block position is aligned there). A late event is applied at once and
            # takes effect on FluidSynth's next block boundary.
            self._render(at - self._pos, chunks)
            self._apply(event)
        self._render(stop - self._pos, chunks)
        stereo = np.concatenate(chunks).astype(np.float32).reshape(-1, 2)
        return (stereo.sum(axis=1) * (0.5 / 32768.0)).astype(np.float32)

    def _drain(self) -> None:
        """Wait for the rendering thread's jobs (raising what one raised)."""
        jobs, self._jobs = self._jobs, []
        for job in jobs:
            job.result()

    def _job(self, end: int) -> None:
        """A job of the rendering thread: synthesise up to ``end``, then say that it is over (its future is
        done only after this returns, too late for a caller waiting on :attr:`_published`)."""
        try:
            self._synthesise(end)
        finally:
            with self._published:
                self._finished += 1
                self._published.notify_all()

    def _wait_for(self, end: int) -> None:
        """Wait until the rendering thread has published sample ``end``, or has no job left (raising what
        a job raised); the jobs finished are let go."""
        with self._published:
            self._published.wait_for(lambda: self._ready >= end or self._finished == self._submitted)
            over = self._finished == self._submitted
        while self._jobs and (over or self._jobs[0].done()):
            self._jobs.pop(0).result()

    def render_ahead(self, until: float) -> None:
        """Promise that no event will be scheduled before ``until`` seconds, and render up to there on a
        thread of the renderer's own (in stretches of at least 2,048 samples, at most :data:`AHEAD_SECONDS`
        beyond what was handed out) while the caller goes on."""
        if self._synth is None:
            return
        target = self.promised_sample(until)
        if target <= self._promised:
            return
        with self._lock:
            self._promised = target
        start = max(self._pos if not self._jobs else self._jobs[-1].target, self._handed)
        if target - start < 2048:
            return
        if self._worker is None:
            from concurrent.futures import ThreadPoolExecutor

            self._worker = ThreadPoolExecutor(1, thread_name_prefix="fluidsynth")
        job = self._worker.submit(self._job, target)
        self._submitted += 1
        job.target = target
        self._jobs.append(job)

    def render_until(self, t: float) -> np.ndarray:
        """Render from the current position up to ``t`` seconds.

        Parameters
        ----------
        t : float
            End time in seconds; nothing is rendered if it is not past :attr:`time`.

        Returns
        -------
        numpy.ndarray
            Float32 mono samples in [-1, 1], ``round(t * sample_rate) - samples_rendered`` of them.
        """
        end = int(round(t * self.sample_rate))
        if end <= self._handed:
            return np.zeros(0, np.float32)
        with self._lock:
            ready = self._ready
        if ready < end:
            self._wait_for(end)
            if not self._jobs and self._pos < end:
                self._synthesise(end)
        with self._lock:
            samples, self._ahead = self.hand_out(self._ahead, end)
        return samples

    def close(self) -> None:
        """Free the synthesizer."""
        if getattr(self, "_synth", None) is not None:
            try:
                self._drain()
            finally:
                if self._worker is not None:
                    self._worker.shutdown()
                    self._worker = None
            self._synth.delete()
            self._synth = None

    def __enter__(self) -> "FluidSynthRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_events(
    events: Sequence[SynthEvent],
    duration: float,
    sample_rate: int = 44100,
    soundfont: "str | os.PathLike" = DEFAULT_SOUNDFONT,
    gain: float = 0.3,
) -> np.ndarray:
    """Render a whole list of events with :class:`FluidSynthRenderer`.

    Parameters
    ----------
    events : sequence of SynthEvent
        Timed events.
    duration : float
        Length of the output in seconds.
    sample_rate : int
        Output sample rate in Hz.
    soundfont : str or path-like
        SoundFont file.
    gain : float
        FluidSynth master gain.

    Returns
    -------
    numpy.ndarray
        Float32 mono audio.
    """
    with FluidSynthRenderer(sample_rate, soundfont, gain) as r:
        r.schedule(events)
        return r.render_until(duration)


def render_midi_file(
    midi_path: "str | os.PathLike",
    wav_path: "str | os.PathLike | None" = None,
    sample_rate: int = 44100,
    soundfont: "str | os.PathLike" = DEFAULT_SOUNDFONT,
    gain: float = 0.6,
) -> tuple[np.ndarray, int]:
    """Render a MIDI file with the FluidSynth command line program (``fluidsynth -ni -F``).

    The command line player applies events on FluidSynth's 64-sample blocks as well, but places
    note-ons less exactly than :class:`FluidSynthRenderer`: 0.7 to 4.6 ms (mean 2.7 ms) after the MIDI
    time at 44.1 kHz.

    Parameters
    ----------
    midi_path : str or path-like
        The ``.mid`` file.
    wav_path : str or path-like, optional
        Where to keep the rendered WAV file; a temporary file is used when None.
    sample_rate : int
        Output sample rate in Hz.
    soundfont : str or path-like
        SoundFont file.
    gain : float
        FluidSynth gain (``-g``).

    Returns
    -------
    audio : numpy.ndarray
        Float32 mono audio.
    sample_rate : int
        Its sample rate.

    Raises
    ------
    Unavailable
        When the ``fluidsynth`` program or the soundfont is missing.
    AgentsimError
        When the program fails.
    """
    import soundfile as sf

    sf_path = check_soundfont(soundfont)
    exe = shutil.which("fluidsynth")
    if exe is None:
        raise Unavailable(f"the fluidsynth program is not installed; install it with `{INSTALL_HINT}`")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.fspath(wav_path) if wav_path is not None else os.path.join(tmp, "render.wav")
        cmd = [exe, "-ni", "-g", str(gain), "-r", str(int(sample_rate)), "-F", out, sf_path, os.fspath(midi_path)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0 or not os.path.isfile(out):
            raise AgentsimError(f"fluidsynth failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
        audio, sr = sf.read(out, dtype="float32", always_2d=True)
    return audio.mean(axis=1).astype(np.float32), int(sr)
