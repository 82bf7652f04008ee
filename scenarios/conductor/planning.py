"""How the conductor thinks the ensemble responds, and the ictus times it plans from that.

The ensemble as the conductor models it (one aggregate player; averaging the musicians' linear
phase and period correction gives exactly this form, the corrections toward each other cancelling)::

    E[n+1] = E[n] + T[n] - a * m[n] * (E[n] - C[n])
    T[n+1] = T[n] + D[n] - g * m[n] * (E[n] - C[n])
    D[n+1] = D[n]                                       (a slowly wandering push: drag, bias)

``E`` is the ensemble's beat as heard, ``T`` its period, ``C`` the ictus, ``m`` 1 for conducted beats.
The response gains ``a`` (phase) and ``g`` (period) are unknown: :class:`ResponseEstimator` runs one Kalman
filter per point of a grid of (a, g) and weighs the points by the likelihood of the heard beats (with a
prior from the synchronisation literature and a forgetting factor, so that the estimate can follow
change). ``D`` absorbs what the conductor cannot separate: the drag back to a comfortable tempo and
any constant offset between heard and played beats (offset-free model-predictive control).

:func:`plan_ictus` chooses the next ictus times by least squares over the posterior's most likely
models: the ensemble's predicted beat intervals should match the score's, its asynchrony to the ictus
should stay small, and the conductor's own tempo should change smoothly; after the planned beats the
conductor is assumed to beat the score's tempo, so that plans that leave the ensemble still drifting
cost more. :class:`BudgetPlanner` picks the boldest asynchrony weight whose planned asynchrony keeps the
projected standard deviation of the whole piece within a budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Spread (s) of single musicians' onsets around the ensemble's beat, added to the planned asynchrony when
#: projecting the asynchrony's standard deviation (the conductor hears only the ensemble's beat).
MUSICIAN_SPREAD = 0.020


@dataclass(frozen=True)
class Prior:
    """Gaussian prior (truncated to the grid) on the ensemble's response gains.

    Centred below the usual phase correction toward a partner (0.1-0.3, Wing et al. 2014) and on a weak
    period correction (Repp 2005), and wide: the conductor does not know this ensemble.
    """

    a_mean: float = 0.2
    a_sd: float = 0.15
    g_mean: float = 0.05
    g_sd: float = 0.08


class ResponseEstimator:
    """A bank of Kalman filters over a grid of response gains (a, g), advanced beat by beat.

    Parameters
    ----------
    a_grid, g_grid : sequence of float
        Candidate phase and period correction gains.
    prior : Prior
        Prior on the gains.
    observation_sd : float
        Standard deviation (s) of a heard beat around the ensemble's beat.
    beat_sd, period_sd, push_sd : float
        Per-beat process noise (s) of the beat, the period and the push ``D``.
    forgetting : float
        Per-beat factor on the accumulated log-likelihood (1: never forget).
    """

    def __init__(self, a_grid=None, g_grid=None, prior: Prior = Prior(), observation_sd: float = 0.008,
                 beat_sd: float = 0.007, period_sd: float = 0.003, push_sd: float = 0.0008,
                 forgetting: float = 0.97):
        a_grid = np.linspace(0.0, 0.6, 13) if a_grid is None else np.asarray(a_grid, float)
        g_grid = np.linspace(0.0, 0.3, 13) if g_grid is None else np.asarray(g_grid, float)
        aa, gg = np.meshgrid(a_grid, g_grid, indexing="ij")
        self.a = aa.ravel()
        self.g = gg.ravel()
        self.log_prior = -0.5 * (((self.a - prior.a_mean) / prior.a_sd) ** 2
                                 + ((self.g - prior.g_mean) / prior.g_sd) ** 2)
        self.loglik = np.zeros(self.a.size)
        self.R = observation_sd ** 2
        self.Q = np.diag([beat_sd ** 2, period_sd ** 2, push_sd ** 2])
        self.forgetting = float(forgetting)
        self.x: np.ndarray | None = None  # (K, 3): beat time, period, push
        self.P: np.ndarray | None = None  # (K, 3, 3)
        self.beat: int | None = None  # beat number the state stands for
        self.observed: set[int] = set()

    @property
    def ready(self) -> bool:
        return self.x is not None

    def start(self, beat: int, time: float, period: float) -> None:
        """Start all filters at a heard beat ``beat`` at ``time`` with period ``period``."""
        k = self.a.size
        self.x = np.tile(np.array([time, period, 0.0]), (k, 1))
        self.P = np.tile(np.diag([0.01 ** 2, (0.03 * period) ** 2, 0.002 ** 2]), (k, 1, 1))
        self.beat = beat
        self.observed = {beat}

    def advance(self, ictus: float | None) -> None:
        """Predict the next beat; ``ictus`` is the ictus of the current beat (None: not conducted)."""
        m = 0.0 if ictus is None else 1.0
        c = 0.0 if ictus is None else float(ictus)
        k = self.a.size
        F = np.zeros((k, 3, 3))
        F[:, 0, 0] = 1.0 - self.a * m
        F[:, 0, 1] = 1.0
        F[:, 1, 0] = -self.g * m
        F[:, 1, 1] = 1.0
        F[:, 1, 2] = 1.0
        F[:, 2, 2] = 1.0
        u = np.stack([self.a * m * c, self.g * m * c, np.zeros(k)], axis=1)
        self.x = np.einsum("kij,kj->ki", F, self.x) + u
        self.P = np.einsum("kij,kjl,kml->kim", F, self.P, F) + self.Q
        self.beat += 1
        self.loglik *= self.forgetting

    def update(self, z: float) -> None:
        """Correct the current beat with a heard onset at ``z``."""
        S = self.P[:, 0, 0] + self.R
        innovation = z - self.x[:, 0]
        gain = self.P[:, :, 0] / S[:, None]
        self.x = self.x + gain * innovation[:, None]
        self.P = self.P - gain[:, :, None] * self.P[:, None, 0, :]
        self.loglik += -0.5 * (np.log(2 * math.pi * S) + innovation ** 2 / S)
        self.observed.add(self.beat)

    def weights(self) -> np.ndarray:
        """Posterior probability of each grid point."""
        lp = self.log_prior + self.loglik
        w = np.exp(lp - lp.max())
        return w / w.sum()

    def estimate(self) -> dict:
        """Posterior means of a, g, the period and the push."""
        w = self.weights()
        return {"a": float(w @ self.a), "g": float(w @ self.g), "period": float(w @ self.x[:, 1]),
                "push": float(w @ self.x[:, 2]), "beat": self.beat, "time": float(w @ self.x[:, 0])}

    def top(self, count: int = 8, mass: float = 0.95) -> np.ndarray:
        """Indices of the most probable grid points (at most ``count``, enough for ``mass``)."""
        w = self.weights()
        order = np.argsort(-w)
        cum = np.cumsum(w[order])
        n = int(min(count, np.searchsorted(cum, mass) + 1))
        return order[:max(n, 1)]


def rollout(x0: np.ndarray, a: np.ndarray, g: np.ndarray, ictus: np.ndarray, conducted: np.ndarray) -> np.ndarray:
    """Predicted ensemble beats for models (rows of ``x0``, gains ``a``, ``g``) and ictus sequences.

    Parameters
    ----------
    x0 : (K, 3) array
        State (beat, period, push) of each model at the first beat.
    a, g : (K,) arrays
        Gains of each model.
    ictus : (B, L) array
        B ictus sequences for the L beats from the first (entries of unconducted beats are ignored).
    conducted : (L,) bool array
        Which of those beats are conducted.

    Returns
    -------
    (K, B, L + 1) array
        Beat times from the first beat on, for each model and sequence.
    """
    K, B, L = x0.shape[0], ictus.shape[0], ictus.shape[1]
    E = np.empty((K, B, L + 1))
    e = np.repeat(x0[:, 0:1], B, axis=1)
    t = np.repeat(x0[:, 1:2], B, axis=1)
    d = x0[:, 2:3]
    E[:, :, 0] = e
    for k in range(L):
        if conducted[k]:
            asy = e - ictus[None, :, k]
            e, t = e + t - a[:, None] * asy, t + d - g[:, None] * asy
        else:
            e, t = e + t, t + d
        E[:, :, k + 1] = e
    return E


@dataclass
class Plan:
    """The ictus planned for beats ``first`` .. ``first + len(ictus) - 1`` and what it should do."""

    first: int
    ictus: np.ndarray
    asynchrony: np.ndarray  # predicted (ensemble beat minus ictus), expected over the models used
    intervals: np.ndarray  # predicted beat intervals of the ensemble
    weight: float  # the asynchrony weight used


def plan_ictus(x0: np.ndarray, a: np.ndarray, g: np.ndarray, weights: np.ndarray, beat0: int,
               fixed: dict[int, float], free: list[int], conducted_from: int, target_period,
               asynchrony_weight: float, tail_beats: int = 8, tempo_unit: float = 0.01,
               asynchrony_unit: float = 0.04, smooth_unit: float = 0.02,
               previous_ictus: float | None = None) -> Plan:
    """Least-squares ictus times for the beats ``free`` (consecutive, after any ``fixed`` ones).

    Parameters
    ----------
    x0, a, g, weights : arrays
        States at beat ``beat0``, gains and probabilities of the models planned for.
    beat0 : int
        Beat number of the states.
    fixed : dict
        Ictus times already decided (passed, or too close to move) for beats from ``beat0`` on.
    free : list of int
        Beats whose ictus is planned here (consecutive, after ``beat0`` and the fixed ones).
    conducted_from : int
        First conducted beat.
    target_period : callable
        Beat number -> the score's period (s) from that beat to the next.
    asynchrony_weight : float
        How much asynchrony counts against tempo error (1: 40 ms of asynchrony weigh as much as 1 % of
        tempo error).
    tail_beats : int
        Beats after the plan over which the ensemble is followed while the conductor beats the score's
        tempo.
    tempo_unit, asynchrony_unit, smooth_unit : float
        Scales of the three terms: relative interval error, asynchrony (s), change of the conductor's own
        interval (s).
    previous_ictus : float, optional
        The ictus before ``beat0``, for the smoothness of the conductor's first planned interval.
    """
    last = free[-1] + tail_beats
    beats = np.arange(beat0, last + 1)
    L = beats.size - 1  # transitions beat0 -> last
    nf = len(free)
    conducted = beats[:-1] >= conducted_from
    idx = {int(b): i for i, b in enumerate(beats)}
    # ictus = base + M @ c  over all beats (unconducted: anything)
    base = np.zeros(L + 1)
    M = np.zeros((L + 1, nf))
    for b, t in fixed.items():
        if b in idx:
            base[idx[b]] = t
    for j, b in enumerate(free):
        M[idx[b], j] = 1.0
    # the tail: the score's tempo from the last free beat
    for b in range(free[-1] + 1, last + 1):
        i = idx[b]
        base[i] = base[i - 1] + target_period(b - 1)
        M[i] = M[i - 1]
    seqs = np.vstack([base[None, :L], (base[:L, None] + M[:L]).T])  # (1 + nf, L)
    E = rollout(x0, a, g, seqs, conducted)  # (K, 1 + nf, L + 1)
    E0 = E[:, 0, :]
    G = E[:, 1:, :] - E0[:, None, :]  # (K, nf, L + 1): response to a unit of each free ictus
    sq = np.sqrt(weights / weights.sum())
    periods = np.array([target_period(int(b)) for b in beats[:-1]])
    first_free = idx[free[0]]
    # for each model k: the interval errors from the first free beat on (earlier ones cannot be changed),
    # then the asynchrony of the planned (and tail) beats
    i0 = max(first_free - 1, 0)
    scale = sq[:, None] / (tempo_unit * periods[None, i0:L])  # (K, n)
    interval_rows = scale[:, :, None] * (G[:, :, i0 + 1:L + 1] - G[:, :, i0:L]).transpose(0, 2, 1)
    interval_rhs = -scale * (E0[:, i0 + 1:L + 1] - E0[:, i0:L] - periods[None, i0:L])
    sel = np.arange(first_free, L + 1)
    sel = sel[beats[sel] >= conducted_from]
    w_tail = np.where(beats[sel] <= free[-1], 1.0, 0.5)
    scale = sq * asynchrony_weight / asynchrony_unit  # (K,)
    coef = w_tail[None, :] * scale[:, None]
    asynchrony_rows = coef[:, :, None] * (G[:, :, sel].transpose(0, 2, 1) - M[sel][None])
    asynchrony_rhs = (-w_tail)[None, :] * scale[:, None] * (E0[:, sel] - base[sel][None])
    rows = list(np.concatenate([interval_rows, asynchrony_rows], axis=1).reshape(-1, nf))
    rhs = list(np.concatenate([interval_rhs, asynchrony_rhs], axis=1).reshape(-1))
    # smoothness of the conductor's own intervals: second differences of the ictus over the planned part
    ext_base = np.concatenate([[previous_ictus if previous_ictus is not None else 0.0], base])
    ext_M = np.vstack([np.zeros((1, nf)), M])
    ext_beats = np.concatenate([[beat0 - 1], beats])
    known = np.concatenate([[previous_ictus is not None], np.ones(L + 1, bool)])
    for i in range(1, idx[free[-1]] + 2):  # extended index of the middle beat
        lo, hi = i - 1, i + 1
        if hi > L + 1 or not (known[lo] and ext_beats[lo] >= conducted_from):
            continue
        row = (ext_M[hi] - 2 * ext_M[i] + ext_M[lo]) / smooth_unit
        if not row.any():
            continue
        rows.append(row)
        rhs.append(-(ext_base[hi] - 2 * ext_base[i] + ext_base[lo]) / smooth_unit)
    A = np.asarray(rows)
    y = np.asarray(rhs)
    c, *_ = np.linalg.lstsq(A, y, rcond=None)
    ictus_all = base + M @ c
    E_all = E0 + np.einsum("kjl,j->kl", G, c)
    wn = weights / weights.sum()
    E_mean = wn @ E_all
    plan_idx = [idx[b] for b in free]
    return Plan(first=free[0], ictus=ictus_all[plan_idx], asynchrony=E_mean[plan_idx] - ictus_all[plan_idx],
                intervals=np.diff(E_mean), weight=asynchrony_weight)


class BudgetPlanner:
    """Plans with the boldest asynchrony weight that keeps the piece's asynchrony within a budget.

    The projected standard deviation combines the asynchronies heard so far, the planned ones, no
    asynchrony for the rest of the piece, and :data:`MUSICIAN_SPREAD`; it must stay within ``budget``
    times ``margin``. Weights are tried from bold to cautious, within one step of the last plan's weight.
    """

    WEIGHTS = (0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0, 16.0)

    def __init__(self, budget: float = 0.040, margin: float = 0.85, max_asynchrony: float = 0.12):
        self.budget = float(budget)
        self.margin = float(margin)
        self.max_asynchrony = float(max_asynchrony)
        self.index: int | None = None  # the weight of the last plan

    def projected_sd(self, past: list[float], planned: np.ndarray, remaining: int) -> float:
        """Projected standard deviation (s) of the piece's asynchrony.

        ``past`` are heard asynchronies (single onsets: they already scatter), ``planned`` and the
        ``remaining`` beats (no asynchrony) are expectations, to which the musicians' spread is added.
        """
        past = np.asarray(past, float)
        future = np.concatenate([np.asarray(planned, float), np.zeros(max(remaining, 0))])
        values = np.concatenate([past, future])
        if values.size == 0:
            return MUSICIAN_SPREAD
        var = values.var() + MUSICIAN_SPREAD ** 2 * future.size / values.size
        return float(math.sqrt(var))

    def plan(self, past: list[float], remaining: int, **kwargs) -> Plan:
        """The plan with the boldest weight within the budget, moving at most one weight step from the last
        plan's, so that the conductor's beat does not lurch when the budget tightens or loosens."""
        last = len(self.WEIGHTS) // 2 if self.index is None else self.index
        lo, hi = max(last - 1, 0), min(last + 1, len(self.WEIGHTS) - 1)
        chosen = None
        for i in range(lo, hi + 1):
            plan = plan_ictus(asynchrony_weight=self.WEIGHTS[i], **kwargs)
            chosen = (i, plan)
            if (self.projected_sd(past, plan.asynchrony, remaining) <= self.margin * self.budget
                    and np.max(np.abs(plan.asynchrony), initial=0.0) <= self.max_asynchrony):
                break
        self.index = chosen[0]
        return chosen[1]
