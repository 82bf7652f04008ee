"""Meter and tempo maps: time signatures, tempo changes, ramps, steps and rubato, and the exact beat times they give."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

__all__ = ["Meter", "TempoChange", "TempoRamp", "TempoStep", "TempoMap", "make_tempo_map"]


@dataclass(frozen=True)
class Meter:
    """A time signature.

    Parameters
    ----------
    beats_per_bar : int
        Beats in a bar (the numerator: 4 for 4/4, 3 for 3/4, 2 for 2/4).
    beat_unit : int
        Note value of one beat (the denominator); only used for the MIDI time signature.
    """

    beats_per_bar: int = 4
    beat_unit: int = 4

    def __post_init__(self) -> None:
        if self.beats_per_bar < 1 or self.beat_unit not in (1, 2, 4, 8, 16):
            raise ValueError(f"unsupported meter {self.beats_per_bar}/{self.beat_unit}")

    @classmethod
    def parse(cls, meter: "Meter | str | int") -> "Meter":
        """Make a meter from ``"4/4"``, ``"3/4"``, ``"2/4"``, a number of beats per bar or a meter."""
        if isinstance(meter, Meter):
            return meter
        if isinstance(meter, (int, np.integer)):
            return cls(int(meter), 4)
        num, _, den = str(meter).partition("/")
        return cls(int(num), int(den or 4))

    def __str__(self) -> str:
        return f"{self.beats_per_bar}/{self.beat_unit}"


@dataclass(frozen=True)
class TempoChange:
    """A change to a new tempo: from ``bar`` on the tempo is ``bpm``, reached linearly over ``ramp_bars`` bars.

    During the ramp the tempo moves from the tempo in force before the change (the base tempo and the
    earlier changes) to ``bpm`` in proportion to the bars elapsed since ``bar``; with ``ramp_bars = 0``
    the new tempo starts at once.

    Parameters
    ----------
    bar : float
        Bar (counting from 0) at whose first beat the change begins.
    bpm : float
        Tempo reached, in beats per minute.
    ramp_bars : float
        Length of the ramp in bars; 0 for a change at once.
    """

    bar: float
    bpm: float
    ramp_bars: float = 0.0

    def __post_init__(self) -> None:
        if not self.bpm > 0:
            raise ValueError("bpm must be positive")
        if not self.ramp_bars >= 0:
            raise ValueError("ramp_bars must be >= 0")

    def apply(self, tempo: np.ndarray, bar_position: np.ndarray) -> np.ndarray:
        """The tempo (BPM) after this change, given the tempo ``tempo`` before it at positions in bars."""
        bar_position = np.asarray(bar_position, float)
        tempo = np.asarray(tempo, float)
        if self.ramp_bars > 0:
            frac = np.minimum(1.0, (bar_position - self.bar) / self.ramp_bars)
            changed = tempo + frac * (self.bpm - tempo)
        else:
            changed = np.full(tempo.shape, float(self.bpm))
        return np.where(bar_position >= self.bar, changed, tempo)


@dataclass(frozen=True)
class TempoRamp:
    """A gradual tempo change: the tempo is multiplied by a factor growing linearly over some bars.

    Parameters
    ----------
    start_bar : float
        Bar (counting from 0) at which the ramp begins.
    bars : float
        Length of the ramp in bars; after it the tempo stays at the changed value.
    change : float
        Relative change reached at the end, e.g. ``0.10`` for +10 % or ``-0.05`` for -5 %.
    """

    start_bar: float
    bars: float
    change: float

    def factor(self, bar_position: np.ndarray) -> np.ndarray:
        """Tempo factor (1 before the ramp, ``1 + change`` after it) at positions given in bars."""
        progress = np.clip((np.asarray(bar_position, float) - self.start_bar) / self.bars, 0.0, 1.0)
        return 1.0 + self.change * progress


@dataclass(frozen=True)
class TempoStep:
    """A sudden tempo change: from ``bar`` on, the tempo is multiplied by ``factor``.

    Parameters
    ----------
    bar : float
        Bar (counting from 0) at whose first beat the new tempo starts.
    factor : float
        Tempo multiplier, e.g. ``1.15`` for 15 % faster.
    """

    bar: float
    factor: float

    def factor_at(self, bar_position: np.ndarray) -> np.ndarray:
        """Tempo factor (1 before the step, ``factor`` from it on) at positions given in bars."""
        return np.where(np.asarray(bar_position, float) >= self.bar, self.factor, 1.0)


@dataclass(frozen=True)
class TempoMap:
    """The tempo of a piece as a function of its beat index.

    The interval between beat ``k`` and beat ``k + 1`` lasts ``60 / tempo(k)`` seconds, with
    ``tempo(k) = base(k) * prod(ramp factors) * prod(step factors) * (1 + rubato * r(k))`` evaluated at
    the bar position ``k / beats_per_bar``. ``base`` is ``bpm`` with the tempo changes applied in the
    order of their bars (:meth:`TempoChange.apply`). ``r`` is a smooth random curve in [-1, 1]: values drawn
    uniformly from a numpy Generator seeded with ``seed`` at knots every ``rubato_bars`` bars, joined
    by cosine interpolation (continuous slope, never beyond the knot values).

    Parameters
    ----------
    bpm : float
        Base tempo in beats per minute.
    meter : Meter
        Time signature.
    ramps : tuple of TempoRamp
        Gradual tempo changes.
    steps : tuple of TempoStep
        Sudden tempo changes.
    rubato : float
        Largest relative deviation of the rubato, e.g. ``0.02`` for +-2 %; 0 for none.
    rubato_bars : float
        Distance between the rubato curve's random knots, in bars.
    seed : int
        Seed of the Generator that draws the rubato knots.
    changes : tuple of TempoChange
        Changes to new tempi (at once or ramped), applied before the ramps, steps and rubato.
    """

    bpm: float
    meter: Meter = field(default_factory=Meter)
    ramps: tuple[TempoRamp, ...] = ()
    steps: tuple[TempoStep, ...] = ()
    rubato: float = 0.0
    rubato_bars: float = 2.0
    seed: int = 0
    changes: tuple[TempoChange, ...] = ()

    def __post_init__(self) -> None:
        if not self.bpm > 0:
            raise ValueError("bpm must be positive")
        if not 0.0 <= self.rubato < 0.5:
            raise ValueError("rubato must be in [0, 0.5)")
        if self.rubato_bars <= 0:
            raise ValueError("rubato_bars must be positive")

    def rubato_curve(self, beats: np.ndarray) -> np.ndarray:
        """The smooth random curve ``r`` in [-1, 1] at beat positions ``beats`` (not yet scaled)."""
        beats = np.asarray(beats, float)
        knot_beats = self.rubato_bars * self.meter.beats_per_bar
        top = float(np.max(beats, initial=0.0))
        n_knots = int(np.ceil(max(top, 0.0) / knot_beats)) + 2
        # Draw a fixed-size prefix so that the curve does not depend on how far it is evaluated.
        n_draw = max(n_knots, 4096)
        knots = np.random.default_rng(self.seed).uniform(-1.0, 1.0, size=n_draw)[:n_knots]
        u = np.clip(beats, 0.0, None) / knot_beats
        j = np.minimum(np.floor(u).astype(int), n_knots - 2)
        w = 0.5 - 0.5 * np.cos(np.pi * (u - j))
        return knots[j] * (1.0 - w) + knots[j + 1] * w

    def tempo(self, beats: np.ndarray | float) -> np.ndarray:
        """Tempo in BPM at beat positions ``beats`` (beat 0 is the first beat of bar 0)."""
        beats = np.asarray(beats, float)
        bars = beats / self.meter.beats_per_bar
        out = np.full(beats.shape, float(self.bpm))
        for change in sorted(self.changes, key=lambda c: c.bar):
            out = change.apply(out, bars)
        for ramp in self.ramps:
            out = out * ramp.factor(bars)
        for step in self.steps:
            out = out * step.factor_at(bars)
        if self.rubato > 0:
            out = out * (1.0 + self.rubato * self.rubato_curve(beats))
        return out

    def beat_times(self, n_beats: int) -> np.ndarray:
        """Times in seconds of beats ``0 .. n_beats - 1``, beat 0 at 0 s.

        Parameters
        ----------
        n_beats : int
            Number of beats.

        Returns
        -------
        numpy.ndarray
            Float64 array of shape ``(n_beats,)``: ``t[0] = 0`` and ``t[k + 1] = t[k] + 60 / tempo(k)``.
        """
        if n_beats <= 0:
            return np.zeros(0)
        intervals = 60.0 / self.tempo(np.arange(n_beats - 1))
        return np.concatenate([[0.0], np.cumsum(intervals)])

    def time_at(self, positions: np.ndarray | float) -> np.ndarray:
        """Times in seconds of positions measured in beats (fractions are linear within their beat)."""
        positions = np.asarray(positions, float)
        if positions.size and np.min(positions) < 0:
            raise ValueError("positions must be >= 0")
        top = int(np.floor(np.max(positions, initial=0.0))) + 2
        grid = self.beat_times(top)
        k = np.floor(positions).astype(int)
        return grid[k] + (positions - k) * (grid[k + 1] - grid[k])


def make_tempo_map(
    bpm: float,
    meter: "Meter | str | int" = "4/4",
    *,
    ramp: "TempoRamp | tuple[float, float, float] | None" = None,
    steps: Sequence["TempoStep | tuple[float, float]"] = (),
    rubato: float = 0.0,
    rubato_bars: float = 2.0,
    seed: int = 0,
) -> TempoMap:
    """Build a :class:`TempoMap` from plain values.

    Parameters
    ----------
    bpm : float
        Base tempo in beats per minute.
    meter : Meter or str or int
        ``"4/4"``, ``"3/4"``, ``"2/4"``, a number of beats per bar, or a :class:`Meter`.
    ramp : TempoRamp or (start_bar, bars, change), optional
        One gradual change, e.g. ``(4, 16, 0.10)`` for +10 % over 16 bars from bar 4.
    steps : sequence of TempoStep or (bar, factor)
        Sudden changes.
    rubato : float
        Largest relative smooth random deviation, e.g. ``0.02``.
    rubato_bars : float
        Distance between rubato knots in bars.
    seed : int
        Seed of the rubato Generator.

    Returns
    -------
    TempoMap
    """
    ramps: tuple[TempoRamp, ...] = ()
    if ramp is not None:
        ramps = (ramp if isinstance(ramp, TempoRamp) else TempoRamp(*ramp),)
    step_objs = tuple(s if isinstance(s, TempoStep) else TempoStep(*s) for s in steps)
    return TempoMap(float(bpm), Meter.parse(meter), ramps, step_objs, float(rubato), float(rubato_bars), int(seed))
