"""Synthesizer events: timed MIDI note, program and control messages, and the events of a score."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim.music.score import Score

__all__ = ["EVENT_ORDER", "SynthEvent", "score_events"]

#: Order of events of the same time: program and control changes first, then note-offs, then note-ons (a
#: note ending where the next one starts on the same key is released before it is struck again).
EVENT_ORDER = {"program": 0, "cc": 1, "note_off": 2, "note_on": 3}


@dataclass(frozen=True, order=True)
class SynthEvent:
    """A timed MIDI event for the synthesizer.

    Parameters
    ----------
    time : float
        Time in seconds.
    kind : str
        ``"note_on"``, ``"note_off"``, ``"program"`` or ``"cc"``.
    channel : int
        MIDI channel (0-based).
    data1 : int
        Key, program or controller number.
    data2 : int
        Velocity or controller value (0 for program changes).
    """

    time: float
    kind: str
    channel: int
    data1: int
    data2: int = 0

    def __post_init__(self) -> None:
        if self.kind not in EVENT_ORDER:
            raise ValueError(f"unknown event kind {self.kind!r}")


def score_events(score: Score, offset: float = 0.0) -> list[SynthEvent]:
    """Timed synthesizer events (program changes at ``offset``, then notes) of a score.

    Parameters
    ----------
    score : Score
        The piece.
    offset : float
        Time in seconds at which beat 0 sounds.

    Returns
    -------
    list of SynthEvent
        Sorted by time.
    """
    events = [SynthEvent(offset, "program", ch, prog) for ch, prog in sorted(score.programs.items())]
    if not score.notes:
        return events
    starts = np.array([n.start for n in score.notes])
    ends = starts + np.array([n.duration for n in score.notes])
    t_on = score.tempo_map.time_at(starts) + offset
    t_off = score.tempo_map.time_at(ends) + offset
    for n, a, b in zip(score.notes, t_on, t_off):
        events.append(SynthEvent(float(a), "note_on", n.channel, n.key, n.velocity))
        events.append(SynthEvent(float(b), "note_off", n.channel, n.key, 0))
    events.sort(key=lambda e: (e.time, EVENT_ORDER[e.kind]))
    return events
