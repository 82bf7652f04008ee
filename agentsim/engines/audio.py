"""The audio engine: BMLT ``<bmlt:audiofile fileName>`` behaviours, a sound file played from its start to its
end, lasting as long as the file.

The file name is resolved beside the BML document it came from, then in the working directory. What
was played, from when until when, is kept for the recording of the run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError
from agentsim.core.timed import TimedBehaviour

#: A sound may be off its length by this much (seconds) before the timing asked of it is refused.
RIGID_TOLERANCE = 1e-6


def resolve_audio(behaviour: Behaviour) -> Path:
    """Where a behaviour's ``fileName`` is: beside its BML document, else in the working directory."""
    name = behaviour.attributes.get("fileName", "").strip()
    candidates = []
    if behaviour.source:
        candidates.append(Path(behaviour.source).resolve().parent / name)
    candidates.append(Path.cwd() / name)
    for path in candidates:
        if path.is_file():
            return path
    looked = " or ".join(str(p) for p in candidates)
    raise ScheduleError(f"audio file {name!r} not found (looked for {looked})", "NO_SUCH_TARGET")


@dataclass(frozen=True)
class HeardAudio:
    """A sound file as it was played in the run: from ``start`` (global s), stopped early at ``stopped``."""

    block: str
    behaviour: str
    path: str
    start: float
    duration: float
    stopped: float | None = None


class AudioPlanner(Planner):
    """Times sound files by their length; a file cannot be stretched."""

    behaviour_types = ("audiofile",)
    rigid = True

    def __init__(self, locate: Callable[[Behaviour], Path] = resolve_audio) -> None:
        super().__init__()
        self.durations: dict[int, tuple[Path, float]] = {}
        #: where a behaviour's file is (a service confines it: :class:`agentsim.live.intake.MediaDirectory`)
        self.locate = locate

    def sound(self, behaviour: Behaviour) -> tuple[Path, float]:
        """The file and its length (s); ScheduleError if it is missing or not audio."""
        found = self.durations.get(id(behaviour))
        if found is None:
            import soundfile

            path = self.locate(behaviour)
            try:
                info = soundfile.info(str(path))
            except (RuntimeError, soundfile.LibsndfileError) as exc:
                raise ScheduleError(f"{path} is not a sound file this realizer reads: {exc}") from None
            if not info.frames or not info.samplerate:
                raise ScheduleError(f"{path} holds no sound")
            found = self.durations[id(behaviour)] = (path, info.frames / info.samplerate)
        return found

    def preferred(self, behaviour: Behaviour) -> list[float]:
        return [0.0, self.sound(behaviour)[1]]

    def check_times(self, behaviour, preferred, times) -> None:
        super().check_times(behaviour, preferred, times)
        if abs((times[-1] - times[0]) - preferred[-1]) > RIGID_TOLERANCE:
            raise ScheduleError("a sound file cannot be stretched to meet its constraints")

    def judges(self, timed: TimedBehaviour) -> bool:
        return timed.passed[0] is None and super().judges(timed)  # once playing, it plays to its end


class AudioEngine(Engine):
    """Plays sound files and remembers what it played."""

    name = "audio"

    def __init__(self, context: EngineContext, locate: Callable[[Behaviour], Path] = resolve_audio):
        super().__init__(context, AudioPlanner(locate))
        #: who hears the files as they play: ``file_started(heard)``, ``sound_stopped(block, behaviour, at)``
        self.listeners: list = []
        self.played: list[HeardAudio] = []

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        if index == 0:
            path, duration = self.planner.sound(timed.behaviour)
            self.played.append(HeardAudio(timed.block_id, timed.id, str(path), time, duration))
            for listener in self.listeners:
                listener.file_started(self.played[-1])
        super().sync_passed(timed, index, time)

    def forget(self, block_ids: set[str]) -> None:
        self.played = [heard for heard in self.played if heard.block not in block_ids]

    def stopped(self, timed: TimedBehaviour, now: float) -> None:
        for listener in self.listeners:
            listener.sound_stopped(timed.block_id, timed.id, now)
        for i, heard in enumerate(self.played):
            if (heard.block, heard.behaviour) == (timed.block_id, timed.id) and heard.stopped is None:
                self.played[i] = HeardAudio(heard.block, heard.behaviour, heard.path, heard.start, heard.duration,
                                            now)
