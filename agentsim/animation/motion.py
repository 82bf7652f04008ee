"""Motion drivers: key times with linear time warping, blending curves, replacement groups and the MotionDriver base.

Every timed behaviour becomes one or more :class:`MotionDriver`\\ s. A motion driver knows its
behaviour's keys (the global times of its sync points, :class:`KeyTimes`) and places its motion between
them by linear time warping, as :func:`agentsim.animation.units.motion_state` does: whatever stretch or
squeeze the scheduler gave a phase, the motion's landmarks land exactly on the keys. Holds are filled by
an :class:`Interpolator` with a blending curve.

Replacement groups (Elckerlyc): of the gazes (and gaze shifts) only the latest started is active; an
earlier one is stopped for good when a later one starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from agentsim.animation.body import wrap180
from agentsim.animation.drivers import EPSILON, Driver
from agentsim.animation.time_source import TimeSource
from agentsim.animation.units import motion_unit, repetition

#: Shortest preparation (s): a squeezed preparation borrows this much from the pre-stroke hold.
MIN_PREP = 0.1
#: Shortest retraction (s) handed to the driver that gets a DOF back.
MIN_HANDOVER = 0.1
#: Handover (s) when a behaviour is stopped early (dropped, interrupted, replaced).
STOP_HANDOVER = 0.3


# --------------------------------------------------------------------------------------------- time warping
def frac(t, a: float, b: float) -> np.ndarray:
    """Fraction of the way from time ``a`` to ``b`` (clipped to [0, 1]; a zero-length span is a step)."""
    t = np.asarray(t, dtype=float)
    if b - a > EPSILON:
        return np.clip((t - a) / (b - a), 0.0, 1.0)
    return (t >= b).astype(float)


@dataclass
class KeyTimes:
    """The keys of one timed motion unit: sync ids, their global times and their preferred times.

    :meth:`warp` maps global time to the unit's preferred-time axis by linear time warping between the
    keys (Elckerlyc's f^-1(t), up to the scale of the canonical time alpha).
    """

    sync_ids: tuple[str, ...]
    times: np.ndarray
    preferred: np.ndarray

    def __post_init__(self):
        self.times = np.maximum.accumulate(np.asarray(self.times, dtype=float))
        self.preferred = np.asarray(self.preferred, dtype=float)
        self._index = {s: i for i, s in enumerate(self.sync_ids)}

    @classmethod
    def from_record(cls, timed, fill: float | None = None, lexicon=None) -> "KeyTimes":
        """Keys of what a behaviour did (a :class:`~agentsim.core.recording.BehaviourRecord`: its actual
        times once passed); unknown times become ``fill``. ``lexicon``: the one it was planned with (its
        forms are timed as forms; default: the built-in one)."""
        times = list(timed.times)
        known = [t for t in times if t is not None]
        if not known:
            raise ValueError(f"{timed.id} has no known time")
        # unknown times after the last known one become ``fill``; one between known times (a sync point
        # an interruption skipped) takes the next known time: that phase is left out
        following = fill if fill is not None else known[-1]
        for i in range(len(times) - 1, -1, -1):
            if times[i] is None:
                times[i] = following
            else:
                following = times[i]
        try:
            pref = motion_unit(timed.behaviour, lexicon).preferred(repetition(timed.behaviour))
        except KeyError:
            pref = [t - times[0] for t in times]
        if len(pref) != len(times):
            pref = [t - times[0] for t in times]
        return cls(tuple(timed.sync_ids), np.asarray(times), np.asarray(pref))

    @classmethod
    def scaled(cls, sync_ids: Sequence[str], preferred: Sequence[float], start: float,
               anchor: str | None = None, before: float | None = None, after: float | None = None,
               duration: float | None = None) -> "KeyTimes":
        """Keys from preferred times: starting at ``start``; stretched so that ``anchor`` comes ``before``
        seconds after the start and the end ``after`` seconds after the anchor, or to a total
        ``duration``."""
        pref = np.asarray(preferred, dtype=float) - preferred[0]
        times = pref.copy()
        if anchor is not None and (before is not None or after is not None):
            k = list(sync_ids).index(anchor)
            pa = pref[k]
            b = before if before is not None else pa
            a = after if after is not None else pref[-1] - pa
            times = np.where(pref <= pa, pref * (b / pa if pa > 0 else 1.0),
                             b + (pref - pa) * (a / (pref[-1] - pa) if pref[-1] > pa else 1.0))
        elif duration is not None and pref[-1] > 0:
            times = pref * (duration / pref[-1])
        return cls(tuple(sync_ids), start + times, pref)

    def time(self, sync: str) -> float:
        return float(self.times[self._index[sync]])

    def pref(self, sync: str) -> float:
        return float(self.preferred[self._index[sync]])

    def has(self, sync: str) -> bool:
        return sync in self._index

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def warp(self, t) -> np.ndarray:
        """Preferred time at global time ``t`` (vectorised; zero-length phases are skipped)."""
        t = np.asarray(t, dtype=float)
        times, pref = self.times, self.preferred
        if len(times) < 2:
            return np.full(t.shape, pref[0])
        k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
        t0, t1 = times[k], times[k + 1]
        span = t1 - t0
        f = np.where(span > EPSILON, (t - t0) / np.where(span > EPSILON, span, 1.0), 1.0)
        f = np.clip(f, 0.0, 1.0)
        return pref[k] + f * (pref[k + 1] - pref[k])

    def as_dict(self) -> dict[str, float]:
        return {s: float(t) for s, t in zip(self.sync_ids, self.times)}


# --------------------------------------------------------------------------------------------- interpolation
class BlendCurve:
    """A blending curve w(s) from (0, 0) to (1, 1): a monotone piecewise cubic through control points
    (Fritsch-Carlson slopes), flat at both ends unless told otherwise. The default is smoothstep."""

    def __init__(self, points: Sequence[tuple[float, float]] = ((0.0, 0.0), (1.0, 1.0)),
                 end_slopes: tuple[float, float] = (0.0, 0.0)):
        pts = sorted((float(x), float(y)) for x, y in points)
        self.x = np.array([p[0] for p in pts])
        self.y = np.array([p[1] for p in pts])
        if self.x[0] != 0.0 or self.x[-1] != 1.0 or np.any(np.diff(self.x) <= 0):
            raise ValueError("control points must start at s=0, end at s=1 and increase")
        h = np.diff(self.x)
        delta = np.diff(self.y) / h
        m = np.zeros(len(self.x))
        m[0], m[-1] = end_slopes
        for k in range(1, len(self.x) - 1):
            if delta[k - 1] * delta[k] > 0:
                w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
                m[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k])
        self.m = m

    def __call__(self, s) -> np.ndarray:
        s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
        k = np.clip(np.searchsorted(self.x, s, side="right") - 1, 0, len(self.x) - 2)
        h = self.x[k + 1] - self.x[k]
        u = (s - self.x[k]) / h
        u2, u3 = u * u, u * u * u
        return ((2 * u3 - 3 * u2 + 1) * self.y[k] + (u3 - 2 * u2 + u) * h * self.m[k]
                + (-2 * u3 + 3 * u2) * self.y[k + 1] + (u3 - u2) * h * self.m[k + 1])


#: The default ease-in/ease-out blending curve (equal to smoothstep).
EASE = BlendCurve()


class Interpolator:
    """Fills a span of time between the last pose of one phase and the first pose of the next with a
    blending curve (Kallmann & Marsella's interpolator controller); the curve stretches to any length."""

    def __init__(self, curve: BlendCurve = EASE):
        self.curve = curve

    def __call__(self, t, t0: float, t1: float, a, b, angular: bool = False) -> np.ndarray:
        w = self.curve(frac(t, t0, t1))
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        diff = wrap180(b - a) if angular else b - a
        if diff.ndim == 0:  # one value per frame
            return a + w * diff
        return a + w[:, None] * diff  # one point (or one point per frame) per frame


HOLD = Interpolator()


# --------------------------------------------------------------------------------------------- groups
class ReplacementGroup:
    """Behaviours of which only one may be active (Elckerlyc): the one started last; with equal starts,
    the one that ends first. When a member starts, the others that are active are stopped for good."""

    def __init__(self, name: str):
        self.name = name
        self.members: list[MotionDriver] = []

    def activate(self, member: "MotionDriver", t: float) -> bool:
        if member not in self.members:
            self.members.append(member)
        active = [m for m in self.members if not m.stopped and m.acquire <= t + EPSILON
                  and (m.occupies_until() > t + EPSILON or m is member)]
        winner = max(active, key=lambda m: (m.acquire, -m.occupies_until(), m.uid))
        for m in active:
            if m is not winner:
                m.stop(STOP_HANDOVER)
        return winner is member


# --------------------------------------------------------------------------------------------- base unit
class MotionDriver(Driver):
    """A driver playing one timed motion unit: it requests its DOFs at the unit's start (or at
    ``acquire``), releases them at :attr:`release_key` and hands them over for the rest of the unit
    (the retraction), or earlier at ``stop`` (a dropped or interrupted behaviour).

    :attr:`initial` holds the value of each DOF when it was granted: motions start from the current
    pose (a transition unit) rather than jumping to their own start pose.
    """

    release_key = "relax"
    grant_blend = 0.0

    def __init__(self, name: str, keys: KeyTimes, priority: int | None, dofs: Iterable[str], *,
                 acquire: float | None = None, stop: float | None = None, group: ReplacementGroup | None = None,
                 time_source: TimeSource | None = None, info: dict | None = None):
        super().__init__(name, priority, dofs, time_source)
        self.keys = keys
        self.acquire = keys.start if acquire is None else max(keys.start, acquire)
        self.stop_time = stop
        self.group = group
        self.initial: dict[int, float] = {}
        self.t_grant: float | None = None
        self.info = info or {}

    # ------------------------------------------------------------------ schedule
    def release_time(self) -> float:
        key = self.release_key if self.keys.has(self.release_key) else self.keys.sync_ids[-1]
        return self.keys.time(key)

    def handover(self) -> float:
        return max(self.keys.end - self.release_time(), MIN_HANDOVER)

    def occupies_until(self) -> float:
        return self.keys.end

    def setup(self) -> None:
        # Keys are in driver time: the DOFs are requested and released when the driver's time reaches them.
        clock = self.time_source.inverse
        acquire = clock(self.acquire)
        t_rel, handover = clock(self.release_time()), self.handover()
        if self.stop_time is not None and self.stop_time < t_rel:
            t_rel, handover = self.stop_time, STOP_HANDOVER
        if t_rel < acquire - EPSILON:
            self.stopped = True
            return
        self.manager.at(acquire, self.begin_unit)
        self.manager.at(t_rel, lambda t: self.end_unit(t, handover))

    def begin_unit(self, t: float) -> None:
        """Request the unit's DOFs at ``t``, unless it (or its master) was stopped or its group chose another."""
        if self.stopped or (self.master is not None and self.master.stopped):
            return
        if self.group is not None and not self.group.activate(self, t):
            return
        self.arbitrator.request(self, self.dofs)

    def end_unit(self, t: float, handover: float) -> None:
        """Release the unit's DOFs at ``t`` with a ``handover`` blend; in time, :meth:`finish_unit` first."""
        if not self.stopped:
            self.finish_unit(t)
        self.arbitrator.release(self, self.dofs, handover)

    def finish_unit(self, t: float) -> None:
        """Called when the unit releases its DOFs in time (not when stopped): shifts leave their mark."""

    def stop(self, handover: float | None = None) -> None:
        for slave in self.slaves:
            slave.stop(handover)
        super().stop(handover)

    def on_dof_grant(self, dofs, t, current, blend) -> None:
        for d, v in zip(dofs, current):
            self.initial[int(d)] = float(v)
        if self.t_grant is None:
            self.t_grant = t
        super().on_dof_grant(dofs, t, current, blend)

    def start_value(self, dof: str | int) -> float:
        i = dof if isinstance(dof, (int, np.integer)) else self.body.dof(dof)
        if i in self.initial:
            return self.initial[i]
        return float(self.arbitrator.current[i])

    @property
    def begun(self) -> float:
        """When the unit really got its DOFs (its start, or later if it had to wait), in driver time."""
        if self.t_grant is None:
            return self.acquire
        if self.time_source.clock is None:
            return self.t_grant
        return max(self.acquire, float(self.time_source(np.array([self.t_grant]))[0]))


def blend_in(driver: MotionDriver, values: dict[str, np.ndarray], t, t0: float, t1: float) -> dict[str, np.ndarray]:
    """``values`` blended from the driver's start values over [t0, t1] (a transition from the current pose)."""
    if t1 - t0 <= EPSILON:
        return values
    w = EASE(frac(t, t0, t1))
    out = {}
    for name, v in values.items():
        a = driver.start_value(name)
        if driver.body.channels[driver.body.dof(name)][1].endswith("rotation"):
            blended = a + wrap180(v - a) * w
        else:
            blended = a + (v - a) * w
        out[name] = np.where(w >= 1.0, v, blended)
    return out
