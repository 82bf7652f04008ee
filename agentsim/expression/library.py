"""The music library: pieces written here as MIDI, rendered with FluidSynth and the General MIDI soundfont,
and kept on disk, so that nothing of unknown licence is shipped and a run renders nothing twice.

Each valence has three pieces (thesis, section 3.5.4.3: positive fast, neutral medium, negative slow):
positive ones in a major key at 128-144 BPM, neutral ones at 96-104 BPM, negative ones in a minor key at
60-68 BPM. Every beat has a kick (a snare on the back beats of the faster pieces) and the harmony moves only on
beats, so that a tempo estimate (librosa's) reads the piece's own tempo, not half or double it. A piece is
:data:`BEATS` beats long and loops: what rings past its last beat is added to the start of the next turn.

Rendered pieces are cached in ``~/.cache/agentsim/music/`` (``$XDG_CACHE_HOME``), one ``.npy`` file (float32
samples) per piece and sample rate, named after the piece and a digest of the piece and of this module.
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Beats in a piece (eight bars of 4/4).
BEATS = 32
#: Seconds rendered after the last beat (the release of the last notes), added to the next turn.
TAIL = 2.0


@dataclass(frozen=True)
class Piece:
    """A piece of the library: its name, valence, tempo (BPM), key (MIDI note of the tonic), mode and the
    General MIDI programs of its melody and its harmony."""

    name: str
    valence: str
    bpm: float
    tonic: int
    minor: bool
    melody: int
    harmony: int

    @property
    def period(self) -> float:
        """Its length (s) when looped: :data:`BEATS` beats."""
        return BEATS * 60.0 / self.bpm


#: The pieces, three for each valence.
PIECES = (
    Piece("bright-morning", "positive", 132.0, 60, False, 0, 48),    # piano over strings, C major
    Piece("market-day", "positive", 140.0, 67, False, 73, 0),        # flute over piano, G major
    Piece("kite-in-the-wind", "positive", 126.0, 62, False, 11, 24),  # vibraphone over guitar, D major
    Piece("walking-home", "neutral", 100.0, 65, False, 0, 32),       # piano over bass, F major
    Piece("river-road", "neutral", 96.0, 57, True, 24, 48),          # guitar over strings, A minor
    Piece("quiet-hours", "neutral", 104.0, 64, False, 11, 0),        # vibraphone over piano, E major
    Piece("long-night", "negative", 60.0, 57, True, 46, 48),         # harp over strings, A minor
    Piece("grey-shore", "negative", 64.0, 62, True, 0, 89),          # piano over a pad, D minor
    Piece("the-empty-house", "negative", 68.0, 55, True, 71, 48),    # clarinet over strings, G minor
)
BY_NAME = {p.name: p for p in PIECES}


def piece_names() -> dict[str, list[str]]:
    """The pieces' names by valence, in library order."""
    out: dict[str, list[str]] = {}
    for p in PIECES:
        out.setdefault(p.valence, []).append(p.name)
    return out


_MAJOR = (0, 2, 4, 5, 7, 9, 11)
_MINOR = (0, 2, 3, 5, 7, 8, 10)
#: The chord degrees of the eight bars (I vi IV V I IV V I; i VI iv v in minor).
_PROGRESSION = (0, 5, 3, 4, 0, 3, 4, 0)
#: The melody's scale steps, a bar of four beats at a time (a simple tune that ends on the tonic).
_TUNE = ((2, 4, 2, 0), (0, 2, 5, 4), (3, 5, 3, 1), (4, 2, 1, 4), (4, 2, 4, 7), (5, 3, 5, 2), (6, 4, 1, 2), (0, 2, 0, 0))
KICK, SNARE, HIHAT, DRUMS = 36, 38, 42, 9


def _step(piece: Piece, degree: int) -> int:
    scale = _MINOR if piece.minor else _MAJOR
    octave, k = divmod(degree, 7)
    return piece.tonic + 12 * octave + scale[k]


def midi_bytes(piece: Piece) -> bytes:
    """The piece as a standard MIDI file (type 1, 480 ticks a beat)."""
    import mido

    tpb = 480
    mid = mido.MidiFile(type=1, ticks_per_beat=tpb)
    meta = mido.MidiTrack()
    meta.append(mido.MetaMessage("set_tempo", tempo=int(round(60e6 / piece.bpm)), time=0))
    meta.append(mido.MetaMessage("time_signature", numerator=4, denominator=4, time=0))
    mid.tracks.append(meta)
    notes: list[tuple[float, float, int, int, int]] = []  # (beat, length, channel, key, velocity)
    slow = piece.valence == "negative"
    for bar, degree in enumerate(_PROGRESSION):
        first = 4 * bar
        chord = [_step(piece, degree + d) - 12 for d in (0, 2, 4)]
        for beat in range(4):
            b = first + beat
            notes.append((b, 1.0, 0, _step(piece, _TUNE[bar][beat]) + 12, 96 if beat == 0 else 84))
            notes.append((b, 1.0, 2, _step(piece, degree) - 24, 90))  # the bass on every beat
            if not slow or beat % 2 == 0:
                notes += [(b, 2.0 if slow else 1.0, 1, key, 60) for key in chord]
            notes.append((b, 0.25, DRUMS, KICK, 118 if beat % 2 == 0 else 100))
            if not slow and beat % 2 == 1:
                notes.append((b, 0.25, DRUMS, SNARE, 92))
    programs = {0: piece.melody, 1: piece.harmony, 2: 32}
    for channel in (0, 1, 2, DRUMS):
        track = mido.MidiTrack()
        if channel in programs:
            track.append(mido.Message("program_change", channel=channel, program=programs[channel], time=0))
        events = []
        for beat, length, ch, key, velocity in notes:
            if ch == channel:
                events.append((round(beat * tpb), 1, mido.Message("note_on", channel=ch, note=key, velocity=velocity)))
                events.append((round((beat + length) * tpb) - 1, 0, mido.Message("note_off", channel=ch, note=key)))
        events.sort(key=lambda e: (e[0], e[1]))
        last = 0
        for tick, _, msg in events:
            track.append(msg.copy(time=tick - last))
            last = tick
        mid.tracks.append(track)
    buffer = io.BytesIO()
    mid.save(file=buffer)
    return buffer.getvalue()


def cache_dir() -> Path:
    """Where rendered pieces are kept: ``~/.cache/agentsim/music`` (under ``$XDG_CACHE_HOME`` if set)."""
    from agentsim.written import user_cache

    return user_cache("music")


def rendered(piece: Piece, rate: int, folder: Path | None = None) -> np.ndarray:
    """The piece rendered at ``rate`` (float32 mono, its beat 0 at sample 0, :attr:`Piece.period` plus
    :data:`TAIL` seconds), from the cache, or rendered with FluidSynth and cached; read once a process (the
    array is shared: not to be written to)."""
    key = (piece, rate, str(folder or cache_dir()))
    if key not in _READ:
        _READ[key] = _rendered(piece, rate, folder)
        _READ[key].flags.writeable = False
    return _READ[key]


#: The pieces read in this process, by piece, rate and cache folder.
_READ: dict[tuple, np.ndarray] = {}


def _rendered(piece: Piece, rate: int, folder: Path | None) -> np.ndarray:
    from agentsim.music.rendering import render_midi_file
    from agentsim.written import written

    # the key: the piece and this module's source, which writes its MIDI (reading it costs less than writing it)
    digest = hashlib.sha256(repr(piece).encode() + Path(__file__).read_bytes()).hexdigest()[:16]
    folder = folder or cache_dir()
    path = folder / f"{piece.name}-{rate}-{digest}.npy"
    if path.is_file():
        try:
            samples = np.load(path, allow_pickle=False)
            if samples.dtype == np.float32 and samples.ndim == 1:
                return samples
        except (OSError, ValueError):
            pass  # a damaged file: rendered again
    folder.mkdir(parents=True, exist_ok=True)
    with written(folder / f"{piece.name}.mid") as tmp:
        Path(tmp).write_bytes(midi_bytes(piece))
    audio, _ = render_midi_file(folder / f"{piece.name}.mid", sample_rate=rate, gain=0.5)
    n = int(round((piece.period + TAIL) * rate))
    samples = np.zeros(n, np.float32)
    samples[:min(n, len(audio))] = audio[:n]
    with written(path) as tmp, open(tmp, "wb") as f:
        np.save(f, samples, allow_pickle=False)
    return samples


def looped(piece: Piece, rate: int, length: int) -> np.ndarray:
    """``length`` samples of the piece at ``rate`` played over and over from its start, each turn's tail
    ringing on into the next."""
    samples = rendered(piece, rate)
    period = int(round(piece.period * rate))
    out = np.zeros(length + len(samples), np.float32)
    for start in range(0, length, period):
        out[start:start + len(samples)] += samples
    return out[:length]
