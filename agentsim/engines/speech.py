"""The speech engine: speech behaviours timed by a text-to-speech backend, played rigidly.

The planner asks the backend for the utterance's timeline (words, marks, duration); a speech behaviour's
sync points are its start, the ``<sync>`` marks in its text and its end, at the backend's times. Speech is
not stretched: constraints that would stretch it make it invalid. Once speech starts, its timing belongs
to the audio: the pegs of its sync points are detached from whatever they were tied to, so behaviours
tied to the speech follow the speech.
"""

from __future__ import annotations

from agentsim.bml.model import Behaviour
from agentsim.plan import Engine, Planner, ScheduleError, TimedBehaviour
from speech_timing.backend import SpeechText, TTSBackend, Utterance

#: Speech keys may be off their rigid spacing by this much (seconds) before the speech is invalid.
RIGID_TOLERANCE = 1e-6


class SpeechPlanner(Planner):
    """Times speech with a :class:`~speech_timing.backend.TTSBackend`."""

    behaviour_types = ("speech",)
    rigid = True

    def __init__(self, backend: TTSBackend):
        super().__init__()
        self.backend = backend
        self._utterances: dict[int, Utterance] = {}

    def utterance(self, behaviour: Behaviour) -> Utterance:
        key = id(behaviour)
        utt = self._utterances.get(key)
        if utt is None:
            utt = self.backend.synthesize(SpeechText(behaviour.text, tuple(behaviour.marks)))
            self._utterances[key] = utt
        return utt

    def preferred(self, behaviour: Behaviour) -> list[float]:
        utt = self.utterance(behaviour)
        marks = {m.name: m.time for m in utt.marks}
        return [0.0] + [marks[s] for s in behaviour.sync_ids[1:-1]] + [utt.duration]

    def check_times(self, behaviour, preferred, times) -> None:
        super().check_times(behaviour, preferred, times)
        for p, t in zip(preferred, times):
            if abs((t - times[0]) - p) > RIGID_TOLERANCE:
                raise ScheduleError("speech cannot be stretched or skewed to meet its constraints")

    def remove(self, timed: TimedBehaviour) -> None:
        super().remove(timed)
        self._utterances.pop(id(timed.behaviour), None)


class SpeechEngine(Engine):
    name = "speech"

    def __init__(self, env, on_sync, backend: TTSBackend):
        super().__init__(env, SpeechPlanner(backend), on_sync)

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        if index == 0:
            self.take_timing(timed, time)
        super().sync_passed(timed, index, time)

    def take_timing(self, timed: TimedBehaviour, start: float) -> None:
        """From its start on, the speech runs on its own audio timeline: detach its pegs from whatever
        they were tied to (an anticipator, another block), keeping their times. Behaviours sharing those
        pegs now follow the speech."""
        block_peg = timed.run.block_peg
        board = block_peg.board
        if board is not None:
            board.muted += 1
        try:
            for peg in set(timed.own_pegs()):
                peg.freeze(block_peg)
        finally:
            if board is not None:
                board.muted -= 1
