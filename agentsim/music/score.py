"""Scores: notes placed in beats on a tempo map, the generated band piece, and the levels of dynamics markings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from agentsim.music.instruments import DRUM_CHANNEL, HIHAT, KICK, PART_PROGRAMS, PARTS, SNARE
from agentsim.music.tempo import TempoMap

__all__ = ["DYNAMICS_DB", "Note", "Score", "build_score", "velocity_scale"]

#: Dynamics markings and their level in dB relative to the score's nominal (forte) velocities. A level
#: of L dB scales MIDI velocities by ``10 ** (L / 40)`` (:func:`velocity_scale`): FluidSynth's default
#: velocity curve makes the amplitude grow with the square of the velocity.
DYNAMICS_DB = {"pp": -18.0, "p": -12.0, "mp": -7.0, "mf": -3.5, "f": 0.0, "ff": 3.0}


def velocity_scale(level_db: float) -> float:
    """Factor on MIDI velocities that makes a note ``level_db`` dB louder (negative: softer) in FluidSynth."""
    return 10.0 ** (level_db / 40.0)


@dataclass(frozen=True)
class Note:
    """A note of a score, placed in beats.

    Parameters
    ----------
    start : float
        Position of the note-on in beats from beat 0.
    duration : float
        Length in beats.
    channel : int
        MIDI channel (0-based; 9 is percussion).
    key : int
        MIDI key number.
    velocity : int
        MIDI velocity 1..127.
    part : str
        Name of the part the note belongs to.
    """

    start: float
    duration: float
    channel: int
    key: int
    velocity: int
    part: str


@dataclass(frozen=True)
class Score:
    """Notes of an ensemble on a tempo map.

    Parameters
    ----------
    tempo_map : TempoMap
        Tempo and meter.
    bars : int
        Number of bars.
    notes : tuple of Note
        All notes, sorted by start.
    programs : dict
        General MIDI program of each melodic channel used.
    """

    tempo_map: TempoMap
    bars: int
    notes: tuple[Note, ...]
    programs: dict

    @property
    def n_beats(self) -> int:
        """Number of beats in the score."""
        return self.bars * self.tempo_map.meter.beats_per_bar

    def beat_times(self) -> np.ndarray:
        """Note-on times (seconds, beat 0 at 0 s) of the score's beats."""
        return self.tempo_map.beat_times(self.n_beats)


#: Chord progressions as scale degrees (0-based) of a major key, one chord per bar.
_PROGRESSIONS = (
    (0, 5, 3, 4),  # I vi IV V
    (0, 3, 4, 3),  # I IV V IV
    (0, 4, 5, 3),  # I V vi IV
    (5, 3, 0, 4),  # vi IV I V
    (1, 4, 0, 0),  # ii V I I
)
_MAJOR = np.array([0, 2, 4, 5, 7, 9, 11])


def _triad(key_root: int, degree: int) -> np.ndarray:
    """Pitch classes (semitones above the key's tonic, may exceed 12) of a diatonic triad."""
    idx = degree + np.array([0, 2, 4])
    return key_root + _MAJOR[idx % 7] + 12 * (idx // 7)


def build_score(
    tempo_map: TempoMap,
    bars: int,
    *,
    parts: Sequence[str] = PARTS,
    hihat: str = "eighths",
    seed: int = 0,
) -> Score:
    """Compose a simple ensemble piece whose beats are marked by the drums.

    Drums (GM channel 10): kick on every bar's first beat, snare on the backbeats (beats 2 and 4 in 4/4,
    2 and 3 in 3/4, 2 in 2/4), closed hi-hat on every beat or every eighth (accented on the beats).
    Bass: one note per beat (root on the downbeat, chord tones and octaves after), sometimes an eighth
    pickup before the next bar. Piano: short chords on a per-bar pattern that is sometimes syncopated.
    Strings: the bar's chord sustained over the bar, soft. Key, progression, patterns and velocities are
    drawn from a numpy Generator seeded with ``seed``.

    Parameters
    ----------
    tempo_map : TempoMap
        Tempo and meter of the piece.
    bars : int
        Number of bars.
    parts : sequence of str
        Any of ``"drums"``, ``"bass"``, ``"piano"``, ``"strings"``.
    hihat : {"eighths", "beats"}
        Hi-hat on every eighth note or only on the beats.
    seed : int
        Seed of the Generator for the musical choices.

    Returns
    -------
    Score
    """
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"unknown parts: {sorted(unknown)}")
    if hihat not in ("eighths", "beats"):
        raise ValueError("hihat must be 'eighths' or 'beats'")
    if bars < 1:
        raise ValueError("bars must be >= 1")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7]))
    bpb = tempo_map.meter.beats_per_bar
    tonic = int(rng.choice([0, 2, 5, 7, 9, 10]))  # C, D, F, G, A, B flat
    progression = _PROGRESSIONS[int(rng.integers(len(_PROGRESSIONS)))]
    notes: list[Note] = []

    def vel(base: int, spread: int = 8) -> int:
        return int(np.clip(base + rng.integers(-spread, spread + 1), 1, 127))

    backbeats = {4: (1, 3), 3: (1, 2), 2: (1,)}.get(bpb, tuple(range(1, bpb)))
    for bar in range(bars):
        b0 = bar * bpb
        chord = _triad(tonic, progression[bar % len(progression)])
        if "drums" in parts:
            notes.append(Note(b0, 0.5, DRUM_CHANNEL, KICK, vel(112, 6), "drums"))
            for bb in backbeats:
                notes.append(Note(b0 + bb, 0.5, DRUM_CHANNEL, SNARE, vel(104, 6), "drums"))
            for beat in range(bpb):
                notes.append(Note(b0 + beat, 0.25, DRUM_CHANNEL, HIHAT, vel(92, 6), "drums"))
                if hihat == "eighths":
                    notes.append(Note(b0 + beat + 0.5, 0.25, DRUM_CHANNEL, HIHAT, vel(62, 6), "drums"))
        if "bass" in parts:
            ch = PART_PROGRAMS["bass"][0]
            root = 36 + (chord[0] % 12)
            root = root - 12 if root > 43 else root
            choices = np.array([root, root + 7, root + 12, root + (chord[1] - chord[0])])
            for beat in range(bpb):
                key = root if beat == 0 else int(rng.choice(choices))
                pickup = beat == bpb - 1 and rng.random() < 0.35
                dur = 0.45 if pickup else 0.9
                notes.append(Note(b0 + beat, dur, ch, key, vel(96), "bass"))
                if pickup:
                    notes.append(Note(b0 + beat + 0.5, 0.45, ch, int(root + 7), vel(80), "bass"))
        if "piano" in parts:
            ch = PART_PROGRAMS["piano"][0]
            if bpb == 4:
                patterns = ((0, 1, 2, 3), (0, 1.5, 2, 3), (0, 2, 2.5, 3), (0, 1, 2, 3.5))
            elif bpb == 3:
                patterns = ((0, 1, 2), (1, 2), (0, 1, 2.5))
            else:
                patterns = tuple([tuple(range(bpb)), tuple(list(range(bpb - 1)) + [bpb - 0.5])])
            pattern = patterns[int(rng.integers(len(patterns)))]
            voicing = 60 + ((chord - 60) % 12)  # close position around middle C
            voicing = np.sort(np.where(voicing > 67, voicing - 12, voicing))
            for pos in pattern:
                v = vel(84 if float(pos).is_integer() else 74)
                for key in voicing:
                    notes.append(Note(b0 + pos, 0.45, ch, int(key), v, "piano"))
        if "strings" in parts:
            ch = PART_PROGRAMS["strings"][0]
            keys = np.concatenate([48 + (chord % 12), 60 + (chord % 12)])
            for key in np.unique(keys):
                notes.append(Note(float(b0), bpb - 0.05, ch, int(key), vel(58, 5), "strings"))
    notes.sort(key=lambda n: (n.start, n.channel, n.key))
    programs = {PART_PROGRAMS[p][0]: PART_PROGRAMS[p][1] for p in parts if p in PART_PROGRAMS}
    return Score(tempo_map, int(bars), tuple(notes), programs)
