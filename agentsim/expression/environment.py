"""The environment over a run's time: which emotion is the strongest at each moment, what the camera, the
key light and the music make of it, one row at time 0 and one at each change (``environment.csv``).

The emotions are the ``emotion`` behaviours of a :class:`~agentsim.core.recording.Recording`, each active from
its start to its end as the run's clock passed them (or to where it was stopped). The strongest active one
(the highest intensity; of equals, the one started last) drives every channel. A change of valence to
positive, neutral or negative chooses a piece of that valence from the library at random (a numpy Generator
seeded with the run's seed); the piece plays on while the valence stays.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agentsim.expression.emotions import DEFAULT_INTENSITY, NO_EMOTION, VALENCE, Channels, channels_of

#: The columns of ``environment.csv``.
COLUMNS = ("time", "emotion", "intensity", "shot", "angle", "key_r", "key_g", "key_b", "attenuation", "valence",
           "music")


@dataclass(frozen=True)
class Felt:
    """One emotion of the run: its type and potential, active on [start, end) (s)."""

    emotion: str
    intensity: float
    start: float
    end: float
    order: int


@dataclass(frozen=True)
class EnvironmentRow:
    """The channels from ``time`` (s) on, and the music piece playing (its name, '' for none)."""

    time: float
    channels: Channels
    music: str = ""

    def cells(self) -> list[str]:
        c = self.channels
        return [f"{self.time:.6f}", c.emotion, f"{c.intensity:g}", c.shot, c.angle, *map(str, c.key),
                f"{c.attenuation:g}", c.valence, self.music]


def felt_emotions(recording) -> list[Felt]:
    """The emotions a recording's clock passed: each ``emotion`` behaviour that started, with its end (its
    last known time, or where it was stopped)."""
    felt = []
    for k, rec in enumerate(recording.behaviours):
        if rec.behaviour.type != "emotion" or not rec.times or rec.times[0] is None or not rec.passed[0]:
            continue
        start = float(rec.times[0])
        end = rec.stopped if rec.stopped is not None else rec.times[-1]
        end = math.inf if end is None else float(end)
        attrs = rec.behaviour.attributes
        kind = attrs.get("type", "").strip()
        if kind not in VALENCE:
            continue
        felt.append(Felt(kind, float(attrs.get("intensity", DEFAULT_INTENSITY)), start, max(start, end), k))
    return felt


def has_emotions(recording) -> bool:
    """Whether a run has any emotion behaviour at all (without one, nothing of this module runs)."""
    return any(rec.behaviour.type == "emotion" for rec in recording.behaviours)


def strongest(felt: list[Felt], t: float) -> Felt | None:
    """The strongest emotion active at ``t``: the highest intensity, of equals the one started last."""
    active = [f for f in felt if f.start <= t < f.end]
    return max(active, key=lambda f: (f.intensity, f.start, f.order)) if active else None


def environment_rows(recording, seed: int = 0, library: dict[str, list[str]] | None = None) -> list[EnvironmentRow]:
    """The environment of a run: one row at time 0 and one at each change of the channels or the music.

    ``library``: the pieces' names of each valence (by default :func:`~agentsim.expression.library.piece_names`);
    the music is chosen from it with ``numpy.random.default_rng(seed)``.
    """
    if library is None:
        from agentsim.expression.library import piece_names

        library = piece_names()
    rng = np.random.default_rng(seed)
    felt = felt_emotions(recording)
    times = sorted({0.0, *(f.start for f in felt), *(f.end for f in felt if math.isfinite(f.end))})
    rows: list[EnvironmentRow] = []
    music, valence = "", "none"
    for t in times:
        top = strongest(felt, t)
        channels = NO_EMOTION if top is None else channels_of(top.emotion, top.intensity)
        if channels.valence != valence:
            valence = channels.valence
            music = "" if valence == "none" else str(library[valence][int(rng.integers(len(library[valence])))])
        row = EnvironmentRow(t, channels, music)
        if not rows or (rows[-1].channels, rows[-1].music) != (channels, music):
            rows.append(row)
    return rows


def write_environment_csv(path: str | Path, rows: list[EnvironmentRow]) -> Path:
    """Write ``environment.csv``: a header of :data:`COLUMNS` and one line per row."""
    from agentsim.written import written

    path = Path(path)
    with written(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        for row in rows:
            writer.writerow(row.cells())
    return path


def valence_spans(rows: list[EnvironmentRow], end: float) -> list[tuple[float, float, str, str]]:
    """The stretches of music: ``(start, stop, valence, piece)`` for each run of rows with one piece, the
    last one stopping at ``end`` (s)."""
    spans: list[tuple[float, float, str, str]] = []
    for k, row in enumerate(rows):
        if spans and spans[-1][3] == row.music and spans[-1][2] == row.channels.valence:
            continue
        if spans:
            spans[-1] = (spans[-1][0], row.time, spans[-1][2], spans[-1][3])
        spans.append((row.time, end, row.channels.valence, row.music))
    return [s for s in spans if s[3] and s[1] > s[0]]
