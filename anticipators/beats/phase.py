"""Beat phase by a comb over onset strength: where, at a known period, the latest beat lies.

A comb of teeth one beat period apart, ending at a candidate phase, sums the onset strength under its
teeth (interpolated between frames), the most recent weighted most (:data:`COMB_DECAY` per beat
back). The best of the phases, in half-frame steps over one period before the last frame, is the
latest beat. Inputs are plain arrays of onset strength with the beat period in frames (seconds times
the frame rate); frame indices may be absolute: ``start`` is the index of the first value given.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

__all__ = ["COMB_DECAY", "PHASE_STEP", "CombPhase", "comb_phase", "comb_score"]

COMB_DECAY = 0.85
"""Weight of a comb tooth relative to the one a beat later."""

PHASE_STEP = 0.5
"""Spacing (frames) of the candidate phases."""


class CombPhase(NamedTuple):
    """Result of :func:`comb_phase`.

    Attributes
    ----------
    frame : float
        Absolute (fractional) frame index of the latest beat.
    score : float
        Comb score of that phase (onset strength units).
    mean_score : float
        Mean comb score over all phases tried.
    """

    frame: float
    score: float
    mean_score: float


def _teeth(onset_strength: np.ndarray, lag: float, start: int) -> tuple[int, np.ndarray, np.ndarray]:
    """Index of the last frame, tooth numbers ``0 .. n_beats - 1`` and their weights."""
    end = start + onset_strength.size - 1
    j, w = _tooth_weights(max(int((end - start) / lag), 1))
    return end, j, w


@functools.lru_cache(maxsize=256)
def _tooth_weights(n_beats: int) -> tuple[np.ndarray, np.ndarray]:
    """Tooth numbers ``0 .. n_beats - 1`` and their weights (read-only: they are shared)."""
    j = np.arange(n_beats)
    w = COMB_DECAY**j
    j.flags.writeable = w.flags.writeable = False
    return j, w


@functools.lru_cache(maxsize=256)
def _grid(size: int) -> np.ndarray:
    """``np.arange(size)`` (read-only: it is shared)."""
    found = np.arange(size)
    found.flags.writeable = False
    return found


def comb_phase(onset_strength: np.ndarray, lag: float, start: int = 0) -> CombPhase:
    """The latest beat in onset strength whose beat period is ``lag`` frames.

    Parameters
    ----------
    onset_strength : numpy.ndarray
        Onset strength of frames ``start .. start + size - 1`` (at least one frame).
    lag : float
        Beat period in frames (seconds times the frame rate).
    start : int
        Absolute index of the first frame given.

    Returns
    -------
    CombPhase
        The latest beat's absolute frame index (at most the last frame, less than one period before
        it), its comb score and the mean score over phases.
    """
    o = onset_strength
    end, j, w = _teeth(o, lag, start)
    phases = _grid(math.ceil(lag / PHASE_STEP)) * PHASE_STEP  # np.arange(0.0, lag, PHASE_STEP)
    pos = end - phases[:, None] - j[None, :] * lag - start  # positions in o
    vals = np.interp(pos, _grid(o.size), o, left=0.0)
    score = vals @ w
    k = int(np.argmax(score))
    return CombPhase(float(end - phases[k]), float(score[k]), float(np.add.reduce(score) / score.size))


def comb_score(onset_strength: np.ndarray, lag: float, beat_frame: float, start: int = 0) -> float:
    """Comb score of the beat grid through frame ``beat_frame`` with a period of ``lag`` frames.

    Parameters
    ----------
    onset_strength : numpy.ndarray
        Onset strength of frames ``start .. start + size - 1`` (at least one frame).
    lag : float
        Beat period in frames.
    beat_frame : float
        Absolute (fractional) frame index of any beat of the grid; the comb ends at the grid's latest
        beat not after the last frame.
    start : int
        Absolute index of the first frame given.

    Returns
    -------
    float
        Weighted sum of onset strength under the comb's teeth (the score :func:`comb_phase` maximises).
    """
    o = onset_strength
    end, j, w = _teeth(o, lag, start)
    i_beat = float(beat_frame)
    # move the beat to the latest one not after the end
    i_beat += math.floor((end - i_beat) / lag) * lag
    vals = np.interp(i_beat - j * lag - start, _grid(o.size), o, left=0.0)
    return float(vals @ w)
