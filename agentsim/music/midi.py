"""MIDI files: a score written as a type-1 file with a tempo event per beat, its events read back, and the times of its ticks."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from agentsim.music.events import EVENT_ORDER, SynthEvent
from agentsim.music.score import Note, Score

__all__ = ["score_to_midi", "midi_to_events", "midi_tick_times"]


def score_to_midi(score: Score, path: "str | os.PathLike | None" = None, ticks_per_beat: int = 960):
    """Write a score as a type-1 MIDI file whose tempo events follow the tempo map beat by beat.

    Every beat carries a ``set_tempo`` event with the beat's duration rounded to the microsecond, so
    the file's beat times equal :meth:`~agentsim.music.tempo.TempoMap.beat_times` to within a
    microsecond per beat. Beat 0 is at 0 s.

    Parameters
    ----------
    score : Score
        The piece.
    path : str or path-like, optional
        Where to save the ``.mid`` file; not saved when None.
    ticks_per_beat : int
        MIDI resolution.

    Returns
    -------
    mido.MidiFile
    """
    import mido

    tm = score.tempo_map
    n = score.n_beats
    times = tm.beat_times(n + 1)
    meta = mido.MidiTrack()
    meta.append(mido.MetaMessage("track_name", name="tempo", time=0))
    meta.append(
        mido.MetaMessage(
            "time_signature", numerator=tm.meter.beats_per_bar, denominator=tm.meter.beat_unit, time=0
        )
    )
    us = np.round(np.diff(times) * 1e6).astype(int)
    for k, tempo in enumerate(us):
        meta.append(mido.MetaMessage("set_tempo", tempo=int(tempo), time=0 if k == 0 else ticks_per_beat))
    meta.append(mido.MetaMessage("end_of_track", time=ticks_per_beat))
    mid = mido.MidiFile(type=1, ticks_per_beat=ticks_per_beat)
    mid.tracks.append(meta)
    by_part: dict[str, list[Note]] = {}
    for note in score.notes:
        by_part.setdefault(note.part, []).append(note)
    for part, notes in by_part.items():
        track = mido.MidiTrack()
        track.append(mido.MetaMessage("track_name", name=part, time=0))
        msgs: list[tuple[int, int, mido.Message]] = []
        ch = notes[0].channel
        if ch in score.programs:
            msgs.append((0, 0, mido.Message("program_change", channel=ch, program=score.programs[ch])))
        for note in notes:
            on = int(round(note.start * ticks_per_beat))
            off = int(round((note.start + note.duration) * ticks_per_beat))
            msgs.append((on, 2, mido.Message("note_on", channel=note.channel, note=note.key, velocity=note.velocity)))
            msgs.append((off, 1, mido.Message("note_off", channel=note.channel, note=note.key, velocity=0)))
        msgs.sort(key=lambda m: (m[0], m[1]))
        last = 0
        for tick, _, msg in msgs:
            track.append(msg.copy(time=tick - last))
            last = tick
        track.append(mido.MetaMessage("end_of_track", time=0))
        mid.tracks.append(track)
    if path is not None:
        mid.save(os.fspath(path))
    return mid


def midi_to_events(midi, offset: float = 0.0) -> list[SynthEvent]:
    """Timed synthesizer events of a MIDI file (tempo changes applied by mido).

    Parameters
    ----------
    midi : mido.MidiFile or str or path-like
        A MIDI file or its path.
    offset : float
        Seconds added to every event time.

    Returns
    -------
    list of SynthEvent
        Note-ons, note-offs (including note-ons of velocity 0), program and control changes.
    """
    import mido

    if not isinstance(midi, mido.MidiFile):
        midi = mido.MidiFile(os.fspath(midi))
    events = []
    now = offset
    for msg in midi:  # iterating a MidiFile yields messages with delta times in seconds
        now += msg.time
        if msg.type == "note_on" and msg.velocity > 0:
            events.append(SynthEvent(now, "note_on", msg.channel, msg.note, msg.velocity))
        elif msg.type in ("note_on", "note_off"):
            events.append(SynthEvent(now, "note_off", msg.channel, msg.note, 0))
        elif msg.type == "program_change":
            events.append(SynthEvent(now, "program", msg.channel, msg.program))
        elif msg.type == "control_change":
            events.append(SynthEvent(now, "cc", msg.channel, msg.control, msg.value))
    events.sort(key=lambda e: (e.time, EVENT_ORDER[e.kind]))
    return events


def midi_tick_times(midi, ticks: Sequence[int]) -> np.ndarray:
    """Times in seconds of absolute MIDI ticks, following the file's ``set_tempo`` events.

    Parameters
    ----------
    midi : mido.MidiFile or str or path-like
        A MIDI file or its path.
    ticks : sequence of int
        Absolute tick positions.

    Returns
    -------
    numpy.ndarray
        Seconds from the start of the file (120 BPM until the first tempo event, as in MIDI).
    """
    import mido

    if not isinstance(midi, mido.MidiFile):
        midi = mido.MidiFile(os.fspath(midi))
    changes = {0: 500000}
    for track in midi.tracks:
        tick = 0
        for msg in track:
            tick += msg.time
            if msg.type == "set_tempo":
                changes[tick] = msg.tempo
    at = np.array(sorted(changes), dtype=np.int64)
    tempo = np.array([changes[t] for t in at], dtype=np.float64) * 1e-6 / midi.ticks_per_beat  # s per tick
    start = np.concatenate([[0.0], np.cumsum(np.diff(at) * tempo[:-1])])
    ticks = np.asarray(ticks, dtype=np.int64)
    i = np.searchsorted(at, ticks, side="right") - 1
    return start[i] + (ticks - at[i]) * tempo[i]
