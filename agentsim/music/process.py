"""A FluidSynth renderer in a process of its own, for a simulation that renders as it goes.

:class:`~agentsim.music.rendering.FluidSynthRenderer` renders ahead on a thread: FluidSynth itself runs
without Python's lock, but each of the thread's calls into it (a note, a stretch of samples) has to take the
lock back from the simulation's thread, which holds it while it works, so the two mostly take turns.
:class:`RenderingProcess` keeps the synthesizer in a child process instead: the simulation sends it the
events and the times promised quiet, and it sends back the samples a stretch at a time, rendering while the
simulation works. It makes the same calls into FluidSynth in the same order, so the samples are the same.

:func:`renderer` gives one where a child process can be started (forked: the child inherits the modules
imported, so it starts at once) and a :class:`~agentsim.music.rendering.FluidSynthRenderer` elsewhere.
"""

from __future__ import annotations

import multiprocessing
import os
from typing import Iterable

import numpy as np

from agentsim.core.children import leave_interrupts_to_the_parent, may_fork
from agentsim.errors import Unavailable
from agentsim.music.events import SynthEvent
from agentsim.music.rendering import (DEFAULT_SOUNDFONT, PUBLISHED, FluidSynthRenderer, SampleClock,
                                      check_soundfont, import_fluidsynth)

__all__ = ["RenderingProcess", "renderer"]

#: The tags of the child's messages: samples, a failure.
_SAMPLES, _FAILED = b"s", b"f"


def renderer(sample_rate: int = 44100, soundfont=DEFAULT_SOUNDFONT, gain: float = 0.3, reverb: bool = True,
             chorus: bool = False, programs: dict[int, int] | None = None):
    """A :class:`RenderingProcess` where this process may start a child by forking
    (:func:`~agentsim.core.children.may_fork`), else a :class:`~agentsim.music.rendering.FluidSynthRenderer`.
    The arguments are theirs."""
    if may_fork():
        return RenderingProcess(sample_rate, soundfont, gain, reverb, chorus, programs)
    return FluidSynthRenderer(sample_rate, soundfont, gain, reverb, chorus, programs)


def _serve(connection, parents, arguments: tuple) -> None:
    """The child: render what the parent asks for, a stretch of :data:`PUBLISHED` samples at a time, reading
    its messages between two stretches (``("events", [...])``, ``("until", sample)``, ``("close",)``), until
    the parent says so or has gone. ``parents``: the parent's end of the pipe, which the fork copied, closed
    here first (held open, it would keep the child from seeing the parent go)."""
    parents.close()
    leave_interrupts_to_the_parent()  # (a terminal's Ctrl-C: the parent ends, and with it this child)
    try:
        synth = FluidSynthRenderer(*arguments)
    except Exception as exc:  # (said to the parent, which raises it where it asks for samples)
        connection.send_bytes(_FAILED + f"{type(exc).__name__}: {exc}".encode())
        return
    target = 0
    try:
        while True:
            while synth.position >= target or connection.poll():
                message = connection.recv()
                if message[0] == "events":
                    synth.schedule(message[1])  # (in the order they were scheduled: the same order of ties)
                elif message[0] == "until":
                    target = max(target, message[1])
                else:
                    return
            mono = synth.render_stretch(min(target, synth.position + PUBLISHED))
            connection.send_bytes(_SAMPLES + mono.tobytes())
    except (EOFError, BrokenPipeError):  # the parent has gone
        return
    except Exception as exc:
        connection.send_bytes(_FAILED + f"{type(exc).__name__}: {exc}".encode())
    finally:
        synth.close()


class RenderingProcess(SampleClock):
    """Render MIDI events to mono audio as a simulation advances, in a child process: the interface of
    :class:`~agentsim.music.rendering.FluidSynthRenderer` that a simulation uses (:meth:`schedule`,
    :meth:`note`, :meth:`render_ahead`, :meth:`render_until`, :meth:`close`), and the same samples.

    The child renders up to the time promised quiet (:meth:`render_ahead`) while the caller goes on, and
    up to the time asked for (:meth:`render_until`), which waits for it. What went wrong in the child (no
    FluidSynth library, a soundfont it cannot load) is raised where samples are first asked for.
    """

    def __init__(self, sample_rate: int = 44100, soundfont=DEFAULT_SOUNDFONT, gain: float = 0.3,
                 reverb: bool = True, chorus: bool = False, programs: dict[int, int] | None = None) -> None:
        if sample_rate < 8000 or sample_rate > 192000:
            raise ValueError("sample_rate must be within 8000..192000 Hz")
        check_soundfont(soundfont)
        import_fluidsynth()  # here, so that the child has it (and says nothing of its library on stdout)
        self.sample_rate = int(sample_rate)
        self.broken_promises = 0
        self._events: list = []  # not yet sent
        self._promised = 0  # sample before which no new event will be scheduled
        self._asked = 0  # sample the child was asked to render up to
        self._received = 0
        self._handed = 0
        self._ahead: list[np.ndarray] = []  # received, not yet handed out
        context = multiprocessing.get_context("fork")
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_serve, name="fluidsynth", daemon=True,
                                        args=(child, self._connection, (sample_rate, os.fspath(soundfont), gain,
                                                                        reverb, chorus, programs)))
        self._process.start()
        child.close()

    def schedule(self, events: SynthEvent | Iterable[SynthEvent]) -> None:
        """Queue one event or several; they sound when rendering passes their time."""
        if isinstance(events, SynthEvent):
            events = (events,)
        for ev in events:
            at = self.event_sample(ev.time)
            if at < self._promised:
                self.broken_promises += 1
            self._events.append(ev)

    def _ask(self, end: int) -> None:
        """Send the events queued, and ask the child to render up to sample ``end``."""
        if self._events:
            self._connection.send(("events", self._events))
            self._events = []
        if end > self._asked:
            self._connection.send(("until", end))
            self._asked = end

    def _receive(self, wait: bool) -> None:
        """Take the stretches the child has sent (``wait``: one at least)."""
        while wait or self._connection.poll():
            wait = False
            try:
                message = self._connection.recv_bytes()
            except EOFError:
                raise RuntimeError("the FluidSynth process ended before the samples asked for") from None
            tag, body = message[:1], message[1:]
            if tag == _SAMPLES:
                samples = np.frombuffer(body, np.float32).copy()  # (an array of its own, as a renderer's)
                self._ahead.append(samples)
                self._received += len(samples)
            else:
                raise Unavailable(f"FluidSynth could not render: {body.decode(errors='replace')}")

    def render_ahead(self, until: float) -> None:
        """Promise that no event will be scheduled before ``until`` seconds; the child renders up to there
        (at most :data:`~agentsim.music.rendering.AHEAD_SECONDS` beyond what was handed out) while the caller
        goes on."""
        target = self.promised_sample(until)
        if target <= self._promised:
            return
        self._promised = target
        self._ask(target)

    def render_until(self, t: float) -> np.ndarray:
        """Render from the current position up to ``t`` seconds; returns float32 mono samples in [-1, 1],
        ``round(t * sample_rate) - samples_rendered`` of them (none if ``t`` is not past :attr:`time`)."""
        end = int(round(t * self.sample_rate))
        if end <= self._handed:
            return np.zeros(0, np.float32)
        self._ask(end)
        self._receive(wait=False)
        while self._received < end:
            self._receive(wait=True)
        samples, self._ahead = self.hand_out(self._ahead, end)
        return samples

    def close(self) -> None:
        """End the child process."""
        if self._process is None:
            return
        try:
            self._connection.send(("close",))
        except (BrokenPipeError, OSError):
            pass
        self._process.join(timeout=5)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._connection.close()
        self._process = None

    def __enter__(self) -> RenderingProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
