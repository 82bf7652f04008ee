"""The simulated ensemble: musicians as timekeepers with phase and period correction, playing a score.

:class:`Timekeeper` is the timing model of one musician (see :class:`~scenarios.conductor.config.ModelParams`
for the equations and where the default values come from); it is plain arithmetic, testable on hand-made
numbers. :class:`Ensemble` runs one SimPy process per musician: after each onset the musician waits until
it must commit its next one, takes the asynchronies it has perceived by then (the conductor's ictus of
the beat, seen ``visual_delay`` after the stroke, and the onsets of the other musicians, heard at once)
and decides when to play the next beat; the notes of that beat go to the FluidSynth renderer right away.

Noise comes from a numpy Generator per musician seeded from the run's seed, drawn for all beats before
the piece starts, so that the same seed gives every strategy the same noise beat by beat.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import simpy

from agentsim.music.instruments import DRUM_CHANNEL
from agentsim.music.score import build_score, velocity_scale
from scenarios.conductor.config import ModelParams, MusicianConfig, Piece, ScenarioConfig

#: Conducting gestures are named ``b<beat>``; other gestures the musicians react to by their ids.
BEAT_ID = re.compile(r"^b(\d+)$")

DECISION_LEAD = 0.02
"""A musician's next note sounds at least this long (seconds) after it decides when to play it."""


class Timekeeper:
    """The timing of one musician (Vorberg & Wing's two-level model with linear phase and period correction).

    ``keeper`` is the timekeeper's latest event, ``onsets[k]`` the onset of beat ``k + 1`` (timekeeper event
    plus motor delay), ``periods[k]`` the timekeeper period used after beat ``k + 1``.

    Parameters
    ----------
    params : ModelParams
        Correction gains, noise and drag.
    period : float
        Timekeeper period at the start (s).
    comfortable_period : float
        Period the drag pulls toward (s).
    first_onset : float
        Timekeeper event of beat 1 (s).
    timekeeper_noise, motor_noise : array-like, optional
        Standard normal draws, one per beat (scaled by the sds of ``params``); zeros when not given.
    """

    def __init__(self, params: ModelParams, period: float, comfortable_period: float, first_onset: float,
                 timekeeper_noise=None, motor_noise=None):
        self.p = params
        self.period = float(period)
        self.comfortable = float(comfortable_period)
        self._e = np.zeros(0) if timekeeper_noise is None else np.asarray(timekeeper_noise, float)
        self._m = np.zeros(0) if motor_noise is None else np.asarray(motor_noise, float)
        self.keeper = float(first_onset)
        self.onsets = [self.keeper + self.p.motor_sd * self._draw(self._m, 0)]
        self.periods = [self.period]

    @staticmethod
    def _draw(values: np.ndarray, k: int) -> float:
        return float(values[k]) if k < values.size else 0.0

    def next_onset(self, ictus: float | None = None, partners=(), earliest: float | None = None) -> float:
        """Commit the onset of the next beat from the asynchronies of the latest one.

        Asynchronies of half a period or more are not corrected: such a beat cannot be told apart from the
        next or the previous one, and a musician keeps its own time rather than follow it.

        Parameters
        ----------
        ictus : float, optional
            The conductor's ictus of the latest beat as perceived (None: not seen in time, no correction).
        partners : sequence of float
            Onsets of the latest beat of the other musicians, as heard.
        earliest : float, optional
            The onset cannot come before this (the musician is already past that moment).

        Returns
        -------
        float
            The onset time of the next beat.
        """
        p = self.p
        t = self.onsets[-1]
        phase = period = 0.0
        bound = 0.5 * self.period  # a beat half a period away cannot be told from the next or the last one
        if ictus is not None and abs(t - ictus) < bound:
            a = t - ictus
            phase += p.alpha_conductor * a
            period += p.beta_conductor * a
        for other in partners:
            a = t - other
            if abs(a) < bound:
                phase += p.alpha_partner * a
                period += p.beta_partner * a
        k = len(self.onsets)
        self.keeper = self.keeper + self.period + p.timekeeper_sd * self._draw(self._e, k) - phase
        onset = self.keeper + p.motor_sd * self._draw(self._m, k)
        if earliest is not None and onset < earliest:
            self.keeper += earliest - onset
            onset = earliest
        self.period = self.period - period + p.drag * (self.comfortable - self.period)
        self.onsets.append(onset)
        self.periods.append(self.period)
        return onset


@dataclass
class PartNote:
    """A note of one beat: its offset and length in beats from the beat, key and nominal velocity."""

    offset: float
    duration: float
    key: int
    velocity: int


def part_notes(piece: Piece, parts) -> dict[str, list[list[PartNote]]]:
    """The generated score's notes of each part, grouped by beat (index 0 is beat 1)."""
    score = build_score(piece.tempo_map, piece.bars, parts=sorted(set(parts)), seed=piece.music_seed)
    out = {p: [[] for _ in range(piece.n_beats)] for p in set(parts)}
    for note in score.notes:
        k = int(np.floor(note.start + 1e-9))
        if 0 <= k < piece.n_beats:
            out[note.part][k].append(PartNote(note.start - k, note.duration, note.key, note.velocity))
    return out


class Musician:
    """One simulated player: configuration, timekeeper, loudness and what it has seen."""

    def __init__(self, config: MusicianConfig, timekeeper: Timekeeper, ictus_noise: np.ndarray, notes):
        self.config = config
        self.keeper = timekeeper
        self.ictus_noise = ictus_noise
        self.notes = notes
        self.louder_db = 0.0
        self.done = False

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def onsets(self) -> list[float]:
        return self.keeper.onsets


class Ensemble:
    """The musicians playing the piece into a renderer, reacting to the conductor's gestures as seen.

    Call :meth:`see` with every feedback of the realizer (``realizer.feedback.listen(ensemble.see)``):
    the stroke of a conducting gesture ``b<n>`` is the ictus of beat ``n``; the stroke of a gesture with
    lexeme ``LOUDER`` makes everyone play louder; the stroke of a ``STOP`` gesture stops the piece. Each is
    acted on ``visual_delay`` seconds after it happened.

    Parameters
    ----------
    env : simpy.Environment
        The clock shared with the realizer.
    config : ScenarioConfig
        Piece and ensemble.
    renderer : FluidSynthRenderer
        Where the notes go (``renderer.note``); it must not yet have rendered past the simulated time.
    seed : int
        Seed of the musicians' noise and comfortable tempi.
    """

    def __init__(self, env: simpy.Environment, config: ScenarioConfig, renderer, seed: int = 0):
        self.env = env
        self.config = config
        self.piece = config.piece
        self.renderer = renderer
        ens = config.ensemble
        self.visual_delay = ens.visual_delay
        self.ictus: dict[int, float] = {}
        self.louder_times: list[float] = []
        self.stop_time: float | None = None
        self.stopped_at_beat: int | None = None
        musicians = ens.musicians
        notes = part_notes(self.piece, [m.part for m in musicians])
        root = np.random.SeedSequence([int(seed), 1729])
        n = self.piece.n_beats + 1
        start_period = 60.0 / ens.start_bpm
        comfortable = 60.0 / (ens.comfortable_bpm or ens.start_bpm)
        self.musicians: list[Musician] = []
        for cfg, child in zip(musicians, root.spawn(len(musicians))):
            rng = np.random.default_rng(child)
            e, m, v = rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n)
            spread = float(rng.standard_normal()) * ens.comfortable_spread
            keeper = Timekeeper(cfg.model, start_period, comfortable * (1.0 + spread), ens.start_time, e, m)
            self.musicians.append(Musician(cfg, keeper, v, notes[cfg.part]))
        self.finished = env.event()
        # when each musician decides next (None: not yet known); notes it gives the renderer then sound
        # no earlier than DECISION_LEAD after it
        self._decides: list[float | None] = [None] * len(self.musicians)
        self._processes = [env.process(self._play(i, m)) for i, m in enumerate(self.musicians)]

    def quiet_until(self) -> float:
        """The time before which no note not yet given to the renderer will sound (all that can be
        promised to :meth:`~agentsim.music.rendering.FluidSynthRenderer.render_ahead`): the next decision of
        any musician plus :data:`DECISION_LEAD`, less a millisecond for notes that start on their beat."""
        if any(d is None for d in self._decides):
            return self.env.now
        return max(min(self._decides) + DECISION_LEAD - 1e-3, self.env.now)

    # ------------------------------------------------------------------ what the musicians see
    def see(self, feedback: dict) -> None:
        """Take note of a realizer feedback (strokes of conducting, "louder" and "stop" gestures)."""
        if feedback.get("type") != "syncPointProgress" or not feedback["id"].endswith(":stroke"):
            return
        parts = feedback["id"].split(":")
        behaviour = parts[-2]
        t = float(feedback["globalTime"])
        beat = BEAT_ID.match(behaviour)
        if beat:
            self.ictus[int(beat.group(1))] = t
        elif behaviour.startswith("louder"):
            self.louder_times.append(t)
        elif behaviour.startswith("stop") and self.stop_time is None:
            self.stop_time = t

    def seen_ictus(self, beat: int, musician: Musician) -> float | None:
        """The ictus of ``beat`` as ``musician`` perceives it, if seen by now."""
        c = self.ictus.get(beat)
        if c is None or c + self.visual_delay > self.env.now + 1e-12:
            return None
        return c + musician.keeper.p.ictus_sd * float(musician.ictus_noise[beat])

    def stopped(self) -> bool:
        return self.stop_time is not None and self.stop_time + self.visual_delay <= self.env.now + 1e-12

    # ------------------------------------------------------------------ playing
    def _level_db(self, musician: Musician, beat: int) -> float:
        seen = sum(1 for t in self.louder_times if t + self.visual_delay <= self.env.now + 1e-12)
        offset = min(self.config.ensemble.loudness_db + seen * self.config.ensemble.louder_step_db,
                     max(self.config.ensemble.loudness_db, 0.0))
        return self.piece.level_db(beat) + offset

    def _schedule(self, musician: Musician, beat: int, onset: float, period: float) -> None:
        cfg = musician.config
        scale = velocity_scale(self._level_db(musician, beat))
        for note in musician.notes[beat - 1]:
            velocity = int(np.clip(round(note.velocity * scale), 1, 127))
            self.renderer.note(onset + note.offset * period, cfg.channel if cfg.program >= 0 else DRUM_CHANNEL,
                               note.key, velocity, note.duration * period)

    def _play(self, index: int, musician: Musician):
        env = self.env
        keeper = musician.keeper
        p = keeper.p
        n_beats = self.piece.n_beats
        self._schedule(musician, 1, keeper.onsets[0], keeper.period)
        for beat in range(1, n_beats):
            decide = keeper.onsets[beat - 1] + p.decide_fraction * keeper.period
            self._decides[index] = max(decide, env.now)
            if decide > env.now:
                yield env.timeout(decide - env.now)
            if self.stopped():
                self.stopped_at_beat = beat if self.stopped_at_beat is None else min(self.stopped_at_beat, beat)
                break
            ictus = self.seen_ictus(beat, musician)
            partners = [m.onsets[beat - 1] for m in self.musicians
                        if m is not musician and len(m.onsets) >= beat and m.onsets[beat - 1] <= env.now]
            onset = keeper.next_onset(ictus, partners, earliest=env.now + DECISION_LEAD)
            self._schedule(musician, beat + 1, onset, keeper.period)
        self._decides[index] = math.inf  # no more notes
        last = keeper.onsets[-1] + keeper.period
        if last > env.now:
            yield env.timeout(last - env.now)
        musician.done = True
        if all(m.done for m in self.musicians) and not self.finished.triggered:
            self.finished.succeed()

    # ------------------------------------------------------------------ ground truth
    def onset_matrix(self) -> np.ndarray:
        """Onsets (s) of every musician (rows) for every beat (columns, index 0 is beat 1); NaN if not played."""
        out = np.full((len(self.musicians), self.piece.n_beats), np.nan)
        for i, m in enumerate(self.musicians):
            k = min(len(m.onsets), self.piece.n_beats)
            out[i, :k] = m.onsets[:k]
        return out

    def beat_times(self) -> np.ndarray:
        """The ensemble's true beats: the mean onset of the musicians for each beat played by all."""
        onsets = self.onset_matrix()
        with np.errstate(invalid="ignore"):
            mean = onsets.mean(axis=0)
        return mean
