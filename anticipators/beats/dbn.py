"""A causal joint tempo-phase filter over onset strength: a discretised beat-pointer dynamic Bayesian network.

The hidden state is ``(k, j)``: the beat interval is ``intervals[k]`` frames (one of ``n_tempi`` intervals,
log-spaced between ``60 fps / max_bpm`` and ``60 fps / min_bpm``) and ``j`` (``0 <= j < intervals[k]``)
frames have passed since the last beat. Each frame the position advances by one; at the end of an
interval the pointer wraps to ``j = 0`` (a beat), where the interval may change to ``intervals[m]`` with
probability proportional to ``exp(-transition_lambda * |intervals[m] / intervals[k] - 1|)`` (times an
optional tempo prior). The observation is an activation ``a`` in ``[0, 1]`` per frame: the first
``intervals[k] / observation_lambda`` positions of every interval are beat states, with likelihood ``a``,
the rest ``(1 - a) / (observation_lambda - 1)`` (the model of Krebs, Böck and Widmer's beat-pointer
DBN, as madmom's online beat tracker uses it). Only the forward recursion runs (filtering, causal): the
posterior over states given the frames heard so far, one frame at a time, in numpy over a flat array
holding every interval's positions back to back.

Prediction reads the posterior: :meth:`BeatPointerFilter.best` is the most probable state (or, with
``marginal``, the most probable position within the most probable interval), so the next beat is
``intervals[k] - j`` frames ahead and the following ones an interval apart. The tracker
(:class:`anticipators.beats.tracking.CausalBeatTracker`) adds hysteresis between equally good grids. The filter never
stops committing: it holds a best state from the first frame, and it switches between tempo and phase
hypotheses as soon as the posterior mass moves, without waiting for repeated evidence.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["BeatPointerFilter", "FluxActivation"]


class BeatPointerFilter:
    """Forward filtering of the beat-pointer state space.

    Parameters
    ----------
    fps : float
        Frames per second of the activation.
    min_bpm, max_bpm : float
        Range of beat tempi (the intervals are rounded to whole frames).
    n_tempi : int or None
        Number of log-spaced intervals; None: every whole number of frames in the range.
    transition_lambda : float
        Sharpness of the tempo-change distribution at a beat (higher: fewer tempo changes).
    observation_lambda : float
        The first ``1 / observation_lambda`` of each beat interval counts as beat states.
    prior_bpm, prior_octaves : float or None
        A log-normal preference over the interval taken at each beat (None: no preference), applied as a
        weight at every beat (not renormalised: a tempo far from ``prior_bpm`` pays at each of its beats).
    beat_cost : float
        A further weight ``exp(-beat_cost)`` at every beat (0: none; it favours slower tempi).
    jump_probability : float
        Probability at each beat of a jump to any interval (0: tempo changes only as the transition allows).
    beat_width : int or None
        Beat states per interval; None: ``intervals / observation_lambda`` (at least one).
    """

    def __init__(
        self,
        fps: float,
        min_bpm: float = 55.0,
        max_bpm: float = 215.0,
        *,
        n_tempi: int | None = 60,
        transition_lambda: float = 100.0,
        observation_lambda: float = 16.0,
        prior_bpm: float | None = None,
        prior_octaves: float = 1.0,
        beat_cost: float = 0.0,
        jump_probability: float = 0.0,
        beat_width: int | None = None,
    ) -> None:
        if not 0 < min_bpm < max_bpm:
            raise ValueError("need 0 < min_bpm < max_bpm")
        self.fps = float(fps)
        lo = max(int(math.floor(60.0 * fps / max_bpm)), 2)
        hi = max(int(math.ceil(60.0 * fps / min_bpm)), lo + 1)
        if n_tempi is None or n_tempi >= hi - lo + 1:
            intervals = np.arange(lo, hi + 1)
        else:
            intervals = np.unique(np.round(np.exp(np.linspace(math.log(lo), math.log(hi), int(n_tempi)))).astype(int))
        self.intervals = intervals
        self.n_states = int(intervals.sum())
        self.starts = np.concatenate([[0], np.cumsum(intervals)[:-1]]).astype(np.intp)
        self.ends = (self.starts + intervals - 1).astype(np.intp)
        self.interval_of = np.repeat(intervals, intervals).astype(np.float64)
        self.tempo_of = np.repeat(np.arange(intervals.size), intervals)
        self.position_of = np.arange(self.n_states) - np.repeat(self.starts, intervals)
        if beat_width is None:
            width = np.maximum(np.ceil(intervals / float(observation_lambda)), 1).astype(int)
        else:
            width = np.full(intervals.size, max(int(beat_width), 1))
        #: beat states per interval: the first positions after a beat, where the beat may lie
        self.beat_width = width
        self.beat_states = np.flatnonzero(self.position_of < np.repeat(width, intervals))
        self.observation_lambda = float(observation_lambda)
        ratio = intervals[None, :] / intervals[:, None]
        trans = np.exp(-float(transition_lambda) * np.abs(ratio - 1.0))
        trans /= trans.sum(axis=1, keepdims=True)
        # a sudden change of tempo to any interval, at any beat
        trans = (1.0 - jump_probability) * trans + jump_probability / intervals.size
        # every beat costs: a weight below 1 each time the pointer wraps (not renormalised, so that a
        # faster tempo pays more often), the larger away from the preferred tempo
        weight = np.full(intervals.size, math.exp(-float(beat_cost)))
        if prior_bpm is not None:
            bpm = 60.0 * fps / intervals
            weight *= np.exp(-0.5 * (np.log2(bpm / prior_bpm) / prior_octaves) ** 2)
        trans = trans * weight[None, :]
        self.transition = np.ascontiguousarray(trans)  # [from tempo, to tempo]
        self.reset()

    def reset(self) -> None:
        """Uniform posterior over all states; no frames heard."""
        self.p = np.full(self.n_states, 1.0 / self.n_states)
        self._q = np.empty_like(self.p)
        self.n_frames = 0

    def step(self, activations) -> None:
        """Filter the next frames, given their activations in ``[0, 1]``."""
        acts = np.asarray(activations, np.float64).reshape(-1)
        lam1 = self.observation_lambda - 1.0
        p, q = self.p, self._q
        starts, ends, beats, trans = self.starts, self.ends, self.beat_states, self.transition
        # (the posterior is renormalised every 8 frames and at the end: in between it shrinks by at most
        # a factor 1e-6 * 15 a frame, far from float64's range)
        for i, a in enumerate(acts.tolist()):
            q[1:] = p[:-1]
            q[starts] = p[ends] @ trans
            a = min(max(a, 1e-6), 1.0 - 1e-6)
            q[beats] *= a * lam1 / (1.0 - a)
            if i & 7 == 7:
                q *= 1.0 / q.sum()
            p, q = q, p
        p *= 1.0 / p.sum()
        self.p, self._q = p, q
        self.n_frames += acts.size

    def best(self, marginal: bool = False) -> tuple[float, float]:
        """The most probable state as ``(interval, position)`` in frames (``marginal``: the most probable
        position within the most probable interval)."""
        if marginal:
            k = int(np.argmax(self.tempo_posterior()))
            a = int(self.starts[k])
            j = int(np.argmax(self.p[a : a + int(self.intervals[k])]))
            return float(self.intervals[k]), float(j)
        s = int(np.argmax(self.p))
        return float(self.interval_of[s]), float(self.position_of[s])

    def mass_near(self, interval: float, position: float, width: int = 2) -> float:
        """Posterior probability of ``interval`` (one of :attr:`intervals`) within ``width`` frames of ``position``."""
        k = int(np.searchsorted(self.intervals, int(round(interval))))
        if k >= self.intervals.size or self.intervals[k] != int(round(interval)):
            return 0.0
        n = int(self.intervals[k])
        idx = (int(round(position)) + np.arange(-width, width + 1)) % n
        return float(self.p[self.starts[k] + idx].sum())

    def tempo_posterior(self) -> np.ndarray:
        """Posterior probability of each interval (``intervals``)."""
        return np.bincount(self.tempo_of, weights=self.p, minlength=self.intervals.size)


class FluxActivation:
    """Onset strength turned into a beat activation in ``[0, 1)``: ``z / (z + scale)`` with ``z`` the onset
    strength over its exponential moving mean (time constant ``tau`` seconds), both causal, raised to
    at least ``floor`` (a frame without onset is unlikely, not impossible, to hold a beat)."""

    def __init__(self, fps: float, tau: float = 3.0, scale: float = 20.0, power: float = 1.0,
                 floor: float = 0.01) -> None:
        self.floor = float(floor)
        self.alpha = 1.0 - math.exp(-1.0 / (tau * fps))
        self.scale = float(scale)
        self.power = float(power)
        self.mean = 0.0
        self.n = 0

    def __call__(self, values) -> np.ndarray:
        v = np.asarray(values, np.float64).reshape(-1)
        out = np.empty_like(v)
        mean, alpha, n = self.mean, self.alpha, self.n
        for i, x in enumerate(v.tolist()):
            n += 1
            mean += max(alpha, 1.0 / n) * (x - mean)
            z = x / mean if mean > 1e-9 else 0.0
            out[i] = z
        self.mean, self.n = mean, n
        if self.power != 1.0:
            out = out ** self.power
        return self.floor + (1.0 - self.floor) * out / (out + self.scale)
