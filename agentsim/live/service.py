"""The live service: a :class:`~agentsim.live.runtime.LiveRealizer`, the :class:`~agentsim.live.intake.Intake`
that reads for it, its WebSocket :class:`~agentsim.live.server.Server`, its loudspeaker
(:mod:`agentsim.live.sound`) and its viewer (:mod:`agentsim.live.poses`), put together as ``agentsim serve``
runs them."""

from __future__ import annotations

import asyncio

from agentsim.live.intake import QUEUE, Intake
from agentsim.live.runtime import LiveRealizer
from agentsim.live.server import Server


class Loudspeaker:
    """Plays what the realizer's speech and audio engines start, where the plan says, on a
    :class:`~agentsim.live.sound.LiveSound` (:attr:`sound`, None until it is open: nothing plays); an
    interruption cuts it where it was cut. The engines call it in the realizer's thread."""

    def __init__(self, sound=None):
        self.sound = sound

    def sound_started(self, heard) -> None:
        audio = getattr(heard.utterance, "audio", None)
        if self.sound is not None and audio is not None and len(audio):
            self.sound.add(audio, int(heard.utterance.sample_rate), heard.t0, 1.0 + heard.drift_ppm * 1e-6,
                           label=f"{heard.block}:{heard.behaviour}")

    def file_started(self, played) -> None:
        if self.sound is None:
            return
        import soundfile

        data, rate = soundfile.read(played.path, dtype="float32", always_2d=True)
        self.sound.add(data.mean(axis=1), int(rate), played.start, label=f"{played.block}:{played.behaviour}")

    def sound_stopped(self, block: str, behaviour: str, at: float) -> None:
        if self.sound is not None:
            self.sound.stop(f"{block}:{behaviour}", at)


class Service:
    """``agentsim serve``: the live realizer, its reader, its endpoint, its sound (``audio``: a device, or
    ``"none"``) and its viewer (poses at ``fps``). ``limits`` and ``queue_size``: what the reader takes
    (:class:`~agentsim.live.intake.Intake`); ``media`` and realizer options (``tts``, ``strict``,
    ``speech``, ``anticipators``, ``lexicon``) go to the :class:`~agentsim.live.runtime.LiveRealizer`.
    ``physics``: the pushes of the physical body the viewer shows (``--physics``), or None."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, audio: str = "none", fps: float = 30.0,
                 calibrate: str | None = None, token: str | None = None, allow_origins=(), limits=None,
                 queue_size: int = QUEUE, physics=None, **realizer_options):
        device = None
        if audio != "none":
            from agentsim.live.devices import open_device

            device = open_device(audio)  # says before anything starts if there is no such device
            if calibrate is not None:
                calibrate = open_device(calibrate, "input")
        self.speaker = Loudspeaker() if audio != "none" else None
        self.live = LiveRealizer(hearers=[self.speaker] if self.speaker is not None else [], **realizer_options)
        live = self.live
        self.intake = Intake(live.take, live.backend, name_block=live.names, now=live.now, strict=live.strict,
                             limits=limits, queue_size=queue_size, lexicon=live.realizer.lexicon,
                             gc_pause=live.realizer.gc_pause)
        self.audio = audio
        self.sound = None
        self.poses = None
        self.loop_delay: float | None = None
        files = {}
        if fps > 0:
            from agentsim.live.poses import LivePoses

            self.poses = LivePoses(self.live, fps, physics=physics)
            self.poses.start_process()  # poses are evaluated on another core, never in the realizer's way
            files = self.poses.files()
        try:
            self.server = Server(self.live, self.intake, host, port, files=files, token=token,
                                 allow_origins=allow_origins)
        except BaseException:
            self.close()
            raise
        if self.poses is not None:
            self.poses.publish(self.server)
        self.live.start()
        self.intake.start()
        if audio != "none":
            from agentsim.live.sound import LiveSound

            try:
                self.sound = LiveSound(device, real_start=self.live.env.real_start, factor=self.live.env.factor)
                if calibrate is not None:
                    self.loop_delay = self.sound.calibrate(calibrate)
            except BaseException:
                self.close()
                raise
            self.server.delay = self.sound.delay
            self.server.status_sources.append(lambda: {"sound_errors": self.sound.errors,
                                                       "sound_last_error": self.sound.last_error})
            self.speaker.sound = self.sound  # (before any client can connect: the server listens later)

    def describe(self) -> str:
        if self.sound is None:
            sound = "no sound"
        else:
            sound = f"sound on {self.audio} (feedback {1000 * self.server.delay:.0f} ms after its time, when it is heard"
            if self.loop_delay is not None:
                sound += f"; the loop to the input measured {1000 * self.loop_delay:.1f} ms and made up for"
            sound += ")"
        server, access = self.server, self.server.access
        if access.token_made:
            said = (f"; {access.host} is not loopback: clients need the token made up for this run, "
                      "in the URLs above (choose one with --token)")
        elif access.token is not None:
            said = "; clients need the token, in the URLs above"
        else:
            said = ""
        return f"agentsim serve: {server.url('ws')} for BML, {server.url('http')} to watch; {sound}{said}"

    async def serve(self, ready=None, stop: asyncio.Event | None = None) -> None:
        await self.server.serve(ready, stop)

    def close(self) -> None:
        """Stop the reader, the realizer, the viewer's worker and the sound."""
        self.intake.close()
        self.live.close()
        if self.poses is not None:
            self.poses.close()
        if self.sound is not None:
            self.sound.close()


class Background:
    """A :class:`Service` serving from a thread of its own (for tests, benchmarks and programs that embed
    it): ``with Background(Service(...)) as service: ...``; ``url`` is its WebSocket address."""

    def __init__(self, service: Service, timeout: float = 10.0):
        import threading

        self.service = service
        self.loop = asyncio.new_event_loop()
        self.ready = threading.Event()
        self.stop_event: asyncio.Event | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self.run, name="agentsim-serve", daemon=True)
        self.thread.start()
        if not self.ready.wait(timeout):
            raise RuntimeError(f"the service did not start: {self.error}")

    def run(self) -> None:
        asyncio.set_event_loop(self.loop)

        async def main():
            self.stop_event = asyncio.Event()
            await self.service.serve(ready=self.ready.set, stop=self.stop_event)

        try:
            self.loop.run_until_complete(main())
        except BaseException as exc:
            self.error = exc
            self.ready.set()

    @property
    def url(self) -> str:
        return self.service.server.url("ws")

    def close(self) -> None:
        if self.stop_event is not None:
            self.loop.call_soon_threadsafe(self.stop_event.set)
        self.thread.join(10.0)
        self.service.close()

    def __enter__(self) -> "Background":
        if self.error is not None:
            raise self.error
        return self

    def __exit__(self, *exc) -> None:
        self.close()
