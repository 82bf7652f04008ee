"""Procedural motion units: what each BML behaviour does with the body, driven by its actual key times.

Every timed behaviour becomes one or more :class:`MotionDriver`\\ s. A motion driver knows its behaviour's
keys (the global times of its sync points, :class:`KeyTimes`) and places its motion between them by
linear time warping, as the engine's ``motion_state`` does: whatever stretch or squeeze the scheduler
gave a phase, the motion's landmarks land exactly on the keys.

Gestures follow Kendon's phases as Kallmann & Marsella schedule them: *preparation* (start to ready) is
a transition from whatever pose the arm is in; the *pre-stroke hold* (ready to strokeStart) and the
*post-stroke hold* (strokeEnd to relax) are filled by an :class:`Interpolator` with a blending curve,
so slow speech gives long holds; the *stroke* runs strokeStart to strokeEnd; the *retraction* (relax to
end) hands the arm back to the driver below, which blends from the current pose to its own (a
transition unit). When speech is fast and keys are squeezed the preparation and retraction shrink; when
the next gesture of the same hand starts before this one has retracted, this one's retraction and that
one's preparation are dropped (coarticulation): the hand goes straight from one stroke to the next.

**The stroke.** For beats, conducting beats and the other gesture lexemes the ``stroke`` key is the
*ictus*: the moment the wrist reaches the bottom of the stroke, where its vertical velocity changes sign
from down to up. The wrist accelerates into the ictus and rebounds out of it (a bounce, not a rounded
turn), so the lowest point is exactly at the key even with breathing and sway moving the shoulders.
For a head nod the stroke is the lowest head pitch (the first one, with repetitions); for a shake or a
tilt the first extreme; for pointing the moment the arm reaches the target (two-link inverse
kinematics puts the wrist on the target, or on the line to it at arm's length); for gaze the eyes (and
neck) reach the target at ``ready``.

Replacement groups (Elckerlyc): of the gazes (and gaze shifts) only the latest started is active; an
earlier one is stopped for good when a later one starts.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable, Mapping, Sequence

import numpy as np

from agentsim.animation.body import wrap180
from agentsim.animation.drivers import (
    EPSILON, PRIORITY, Driver, MotorFunctionExporter, TimeSource, eye_angles,
)

if TYPE_CHECKING:  # pragma: no cover
    from agentsim.animation.drivers import DriverManager

#: Shortest preparation (s): a squeezed preparation borrows this much from the pre-stroke hold.
MIN_PREP = 0.1
#: Shortest retraction (s) handed to the driver that gets a DOF back.
MIN_HANDOVER = 0.1
#: Handover (s) when a behaviour is stopped early (dropped, interrupted, replaced).
STOP_HANDOVER = 0.3


# --------------------------------------------------------------------------------------------- scene
DEFAULT_SCENE: dict[str, tuple[float, float, float]] = {
    # metres, H-Anim frame: +Y up, the character faces +Z, +X is its left
    "bluebox": (0.55, 1.05, 0.9),
    "redbox": (-0.55, 1.05, 0.9),
    "greenbox": (0.0, 0.9, 0.6),
    "table": (0.0, 0.75, 0.7),
    "user": (0.0, 1.65, 1.2),
    "camera": (0.0, 1.6, 2.5),
    "audience": (0.0, 1.6, 3.0),
    "orchestra": (0.0, 1.2, 3.5),
    "violins": (1.6, 1.1, 2.6),
    "violas": (0.6, 1.1, 3.0),
    "cellos": (-0.6, 1.0, 3.0),
    "basses": (-1.6, 1.2, 2.6),
    "left": (2.0, 1.6, 1.0),
    "right": (-2.0, 1.6, 1.0),
    "up": (0.0, 3.0, 1.5),
    "down": (0.0, 0.3, 1.0),
}
#: Where an unknown target is taken to be: a point ahead, a little below eye height.
DEFAULT_POINT = (0.0, 1.3, 2.0)
#: Where the eyes rest.
DEFAULT_GAZE = (0.0, 1.62, 2.0)


class Scene:
    """Named points of the world (metres). Unknown names fall back to :data:`DEFAULT_POINT`; a target may
    also be written as three numbers, ``"0.5 1.2 2"`` or ``"0.5,1.2,2"``."""

    def __init__(self, points: Mapping[str, Sequence[float]] | None = None,
                 default_point=DEFAULT_POINT, default_gaze=DEFAULT_GAZE):
        self.points = {k.lower(): np.asarray(v, dtype=float) for k, v in DEFAULT_SCENE.items()}
        for k, v in (points or {}).items():
            self.points[k.lower()] = np.asarray(v, dtype=float)
        self.default_point = np.asarray(default_point, dtype=float)
        self.default_gaze = np.asarray(default_gaze, dtype=float)

    def known(self, name: str) -> bool:
        return self._parse(name) is not None

    def _parse(self, name: str) -> np.ndarray | None:
        if not name:
            return None
        key = name.strip().lower()
        if key in self.points:
            return self.points[key]
        parts = re.split(r"[\s,;]+", key)
        if len(parts) == 3:
            try:
                return np.array([float(p) for p in parts])
            except ValueError:
                return None
        return None

    def point(self, name: str | None) -> np.ndarray:
        """The point named ``name``, or the default point ahead."""
        p = self._parse(name or "")
        return (p if p is not None else self.default_point).copy()


def offset_target(point: np.ndarray, origin: np.ndarray, angle: float, direction: str) -> np.ndarray:
    """``point`` turned about ``origin`` by ``angle`` degrees (BML offsetAngle / offsetDirection)."""
    if not angle:
        return point
    d = point - origin
    a = math.radians(angle)
    direction = (direction or "RIGHT").upper()
    if direction in ("LEFT", "RIGHT"):
        a = a if direction == "LEFT" else -a
        c, s = math.cos(a), math.sin(a)
        d = np.array([c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]])
    else:
        horizontal = math.hypot(d[0], d[2])
        elev = math.atan2(d[1], horizontal) + (a if direction in ("UP", "UPLEFT", "UPRIGHT") else -a)
        r = float(np.linalg.norm(d))
        az = math.atan2(d[0], d[2])
        d = r * np.array([math.cos(elev) * math.sin(az), math.sin(elev), math.cos(elev) * math.cos(az)])
    return origin + d


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
    def from_timed(cls, timed, fill: float | None = None) -> "KeyTimes":
        """Keys of a TimedBehaviour (its actual times once passed); unknown times become ``fill``."""
        from agentsim.engines.animation import motion_unit, repetition

        times = list(timed.times())
        known = [t for t in times if t is not None]
        if not known:
            raise ValueError(f"{timed.id} has no known time")
        last = fill if fill is not None else known[-1]
        times = [last if t is None else t for t in times]
        try:
            pref = motion_unit(timed.behaviour).preferred(repetition(timed.behaviour))
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
        self.manager.at(acquire, self._begin)
        self.manager.at(t_rel, lambda t: self._end(t, handover))

    def _begin(self, t: float) -> None:
        if self.stopped or (self.master is not None and self.master.stopped):
            return
        if self.group is not None and not self.group.activate(self, t):
            return
        self.arbitrator.request(self, self.dofs)

    def _end(self, t: float, handover: float) -> None:
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


# --------------------------------------------------------------------------------------------- arms
def arm_dofs(side: str) -> list[str]:
    return [f"{side}_shoulder.roll", f"{side}_shoulder.pitch", f"{side}_shoulder.yaw", f"{side}_elbow.pitch",
            f"{side}_elbow.yaw", f"{side}_wrist.roll", f"{side}_wrist.pitch", f"{side}_fingers.roll"]


def side_sign(side: str) -> float:
    return 1.0 if side == "l" else -1.0


def outward(side: str, v) -> np.ndarray:
    """A point given as (outward, up, forward) relative to a shoulder, in the clavicle frame (+X left)."""
    v = np.asarray(v, dtype=float)
    return v * np.array([side_sign(side), 1.0, 1.0])


@dataclass(frozen=True)
class StrokePath:
    """The wrist's path through a stroke, relative to the shoulder as (outward, up, forward) metres:
    from ``top`` down into the ictus at ``bottom`` and up to ``rebound``; the hand's wrist pitch, the
    flick of the wrist at the ictus, the finger curl and the forearm twist (degrees)."""

    top: tuple[float, float, float]
    bottom: tuple[float, float, float]
    rebound: tuple[float, float, float]
    wrist: float = -8.0
    flick: float = 12.0
    curl: float = 30.0
    twist: float = 0.0

    def scaled(self, amount: float) -> "StrokePath":
        """The same stroke with its drop and rebound scaled by ``amount`` (about the ictus)."""
        if amount == 1.0:
            return self
        b = np.asarray(self.bottom)
        top = b + (np.asarray(self.top) - b) * amount
        reb = b + (np.asarray(self.rebound) - b) * amount
        return StrokePath(tuple(top), self.bottom, tuple(reb), self.wrist, self.flick * amount, self.curl,
                          self.twist)


#: Gesture lexemes and their strokes (unknown lexemes use DEFAULT).
GESTURE_FORMS: dict[str, StrokePath] = {
    "BEAT": StrokePath((-0.04, -0.27, 0.33), (-0.03, -0.37, 0.35), (-0.03, -0.335, 0.35), -8.0, 14.0, 35.0),
    "CHOP": StrokePath((0.0, -0.08, 0.30), (0.0, -0.30, 0.38), (0.0, -0.25, 0.38), 0.0, 6.0, 8.0),
    "OFFER": StrokePath((0.04, -0.24, 0.28), (0.12, -0.33, 0.40), (0.12, -0.31, 0.40), 10.0, -8.0, 10.0, 50.0),
    "POINT_DOWN": StrokePath((0.02, -0.20, 0.30), (0.04, -0.34, 0.38), (0.04, -0.31, 0.38), -15.0, 8.0, 70.0),
    "DEFAULT": StrokePath((0.0, -0.18, 0.34), (0.0, -0.32, 0.37), (0.0, -0.28, 0.37), -5.0, 10.0, 15.0),
}

#: Where conducting happens: the centre of the beat pattern relative to the shoulder (outward, up, forward).
CONDUCT_CENTER = (0.0, -0.20, 0.38)
#: Conducting patterns by beats per bar: each beat's ictus offset from the centre (outward, up, forward),
#: the height the hand falls from into it, and how high it rebounds.
CONDUCT_PATTERNS: dict[int, list[tuple[tuple[float, float, float], float, float]]] = {
    2: [((0.0, 0.0, 0.0), 0.20, 0.12), ((0.06, 0.05, 0.0), 0.12, 0.12)],
    3: [((0.0, 0.0, 0.0), 0.20, 0.10), ((0.17, 0.03, 0.0), 0.12, 0.08), ((0.06, 0.08, 0.0), 0.10, 0.12)],
    4: [((0.0, 0.0, 0.0), 0.20, 0.10), ((-0.14, 0.03, 0.0), 0.12, 0.07), ((0.16, 0.03, 0.0), 0.12, 0.08),
        ((0.04, 0.09, 0.0), 0.10, 0.12)],
}

_CONDUCT = re.compile(r"^CONDUCT(?:ING)?_(\d+)_(\d+)(?:_(\d+))?$")


def conducting_meter(lexeme: str) -> tuple[int, int | None] | None:
    """(beats per bar, beat in the bar or None) for a lexeme like ``CONDUCT_4_4`` or ``CONDUCT_3_4_2``."""
    m = _CONDUCT.match((lexeme or "").upper())
    if not m:
        return None
    return int(m.group(1)), (int(m.group(3)) if m.group(3) else None)


def conducting_path(beats_per_bar: int, beat: int, amount: float = 1.0) -> StrokePath:
    """The stroke of beat ``beat`` (1-based) of a conducting pattern: down into the beat's ictus from
    above (arriving from the side of the previous beat) and rebounding towards the next."""
    pattern = CONDUCT_PATTERNS.get(beats_per_bar)
    if pattern is None:  # other meters: one down-beat, then alternating inside and outside
        pattern = [((0.0, 0.0, 0.0), 0.20, 0.10)] + [
            (((-0.12 if k % 2 else 0.14), 0.03, 0.0), 0.12, 0.08) for k in range(1, max(beats_per_bar, 1))]
    n = len(pattern)
    k = (beat - 1) % n
    ictus, fall, rise = pattern[k]
    prev = pattern[(k - 1) % n][0]
    nxt = pattern[(k + 1) % n][0]
    center = np.asarray(CONDUCT_CENTER)
    bottom = center + np.asarray(ictus)
    top = bottom + np.array([0.35 * (prev[0] - ictus[0]), fall * amount, 0.0])
    rebound = bottom + np.array([0.25 * (nxt[0] - ictus[0]), rise * amount, 0.0])
    return StrokePath(tuple(top), tuple(bottom), tuple(rebound), wrist=-5.0, flick=18.0 * amount, curl=20.0)


class GestureDriver(MotionDriver):
    """A gesture on one arm: preparation from the current pose, holds, a stroke whose ictus (the
    wrist's lowest point) is exactly at the ``stroke`` key, post-stroke hold, retraction by handover.

    The wrist follows a Cartesian path (:class:`StrokePath`) in the clavicle frame, turned into shoulder
    and elbow angles by analytic inverse kinematics every frame: down into the ictus accelerating
    (height ~ 1 - s^2), out of it decelerating (~ 2s - s^2).
    """

    def __init__(self, name: str, keys: KeyTimes, side: str, path: StrokePath, **kw):
        kw.setdefault("info", {})
        super().__init__(name, keys, PRIORITY["behaviour"], arm_dofs(side), **kw)
        self.side = side
        self.path = path
        self.top = outward(side, path.top)
        self.bottom = outward(side, path.bottom)
        self.rebound = outward(side, path.rebound)
        self._from_wrist: np.ndarray | None = None

    def on_dof_grant(self, dofs, t, current, blend) -> None:
        super().on_dof_grant(dofs, t, current, blend)
        angles = {self.body.dof_names[d]: self.start_value(d) for d in self.dofs}
        self._from_wrist = self.body.arm_fk(self.side, angles)[0]

    def on_dof_loss(self, dofs, t) -> None:
        # Losing the arm after the stroke leaves nothing worth coming back for (losing only the fingers,
        # say to a hand shape, is no reason to stop).
        if t >= self.keys.time("stroke") - EPSILON and any(
                self.body.dof_names[d].startswith(f"{self.side}_shoulder") for d in dofs):
            self.stop()

    def phases(self) -> tuple[float, float, float, np.ndarray]:
        """(end of preparation, start of the down stroke, the ictus, the top the stroke falls from)."""
        k = self.keys
        t_acq = self.begun
        s_start, stroke = k.time("strokeStart"), k.time("stroke")
        prep_end = min(max(k.time("ready"), t_acq + MIN_PREP), s_start)
        down = max(s_start, t_acq)
        top = self.top
        if prep_end <= t_acq + EPSILON:  # no time left to prepare
            here = self._from_wrist if self._from_wrist is not None else self.top
            if here[1] >= self.bottom[1] + 0.5 * (self.top[1] - self.bottom[1]):
                # the hand is up (coarticulation): the stroke falls from where it is
                prep_end = t_acq
                top = here.copy()
            else:
                # the hand is down: half of the way into the ictus goes to getting the hand up
                prep_end = down = t_acq + 0.5 * max(stroke - t_acq, 0.0)
        return prep_end, min(down, stroke), stroke, top

    def wrist_path(self, t: np.ndarray) -> np.ndarray:
        """Target wrist positions (n, 3) relative to the shoulder in the clavicle frame."""
        k = self.keys
        prep_end, down, stroke, top = self.phases()
        s_end, relax = k.time("strokeEnd"), k.time("relax")
        settle = self.rebound + (self.bottom - self.rebound) * 0.3 * min(1.0, (relax - s_end) / 0.5)
        f_down = frac(t, down, stroke)[:, None]
        f_up = frac(t, stroke, s_end)[:, None]
        p = np.where((t < down)[:, None], top, top + (self.bottom - top) * f_down ** 2)
        p = np.where((t >= stroke)[:, None], self.bottom + (self.rebound - self.bottom) * (2 * f_up - f_up ** 2), p)
        if relax > s_end:
            hold = HOLD(t, s_end, relax, self.rebound, settle)
            p = np.where((t >= s_end)[:, None], hold, p)
        elif s_end <= stroke:  # no rebound phase: stay in the ictus
            p = np.where((t >= stroke)[:, None], self.bottom, p)
        return p

    def on_tick(self, t: np.ndarray) -> None:
        side, path = self.side, self.path
        prep_end, down, stroke, _ = self.phases()
        p = self.wrist_path(t)
        values = self.body.arm_ik(side, p)
        f_down = frac(t, down, stroke)
        f_up = frac(t, stroke, self.keys.time("strokeEnd"))
        flick = np.where(t < stroke, path.flick * f_down ** 2, path.flick * (1 - (2 * f_up - f_up ** 2)))
        values[f"{side}_wrist.pitch"] = path.wrist + flick
        values[f"{side}_wrist.roll"] = np.zeros(len(t))
        values[f"{side}_elbow.yaw"] = np.full(len(t), path.twist * side_sign(side))
        values[f"{side}_fingers.roll"] = np.full(len(t), -side_sign(side) * path.curl)
        self.write_held(blend_in(self, values, t, self.begun, prep_end))


class PointingDriver(MotionDriver):
    """Pointing with one arm: the wrist reaches the target at the ``stroke`` key (two-link IK in the
    world: on the target when it is within reach, otherwise on the line from the shoulder to it at
    :attr:`REACH` metres) and stays on it until relax."""

    REACH = 0.5
    HOME = (0.05, -0.28, 0.28)

    def __init__(self, name: str, keys: KeyTimes, side: str, target: np.ndarray, **kw):
        super().__init__(name, keys, PRIORITY["behaviour"], arm_dofs(side), **kw)
        self.side = side
        self.target = np.asarray(target, dtype=float)

    def on_dof_loss(self, dofs, t) -> None:
        if t >= self.keys.time("stroke") - EPSILON and any(
                self.body.dof_names[d].startswith(f"{self.side}_shoulder") for d in dofs):
            self.stop()

    def aim(self) -> tuple[np.ndarray, np.ndarray]:
        """Aim point relative to the shoulder in the clavicle frame for the frames being ticked, and the
        world aim point."""
        rot, shoulder = self.parent_frame(f"{self.side}_shoulder")
        d = self.target - shoulder
        dist = np.linalg.norm(d, axis=1)
        aim_world = shoulder + d / np.maximum(dist, 1e-9)[:, None] * np.minimum(dist, self.REACH)[:, None]
        return np.einsum("nji,nj->ni", rot, aim_world - shoulder), aim_world

    def on_tick(self, t: np.ndarray) -> None:
        k = self.keys
        side = self.side
        s_start, stroke = k.time("strokeStart"), k.time("stroke")
        t_acq = self.begun
        prep_end = min(max(k.time("ready"), t_acq + MIN_PREP), s_start)
        aim, _ = self.aim()
        home = outward(side, self.HOME)
        ready = home + 0.5 * (aim - home)
        if prep_end <= t_acq + EPSILON:
            prep_end = t_acq
        go = max(s_start, t_acq)
        f = EASE(frac(t, go, stroke))[:, None]
        p = np.where((t < go)[:, None], ready, ready + (aim - ready) * f)
        p = np.where((t >= stroke)[:, None], aim, p)
        values = self.body.arm_ik(side, p)
        n = len(t)
        values[f"{side}_wrist.pitch"] = np.zeros(n)
        values[f"{side}_wrist.roll"] = np.zeros(n)
        values[f"{side}_elbow.yaw"] = np.zeros(n)
        values[f"{side}_fingers.roll"] = np.full(n, -side_sign(side) * 12.0)
        self.write_held(blend_in(self, values, t, t_acq, prep_end))


# --------------------------------------------------------------------------------------------- head
NECK_SHARE = (("vc4", 0.4), ("skullbase", 0.6))


class HeadDriver(MotionDriver):
    """A head movement on top of the current head pose: NOD (pitch), SHAKE (yaw) or TILT (roll),
    ``repeats`` times. The stroke key is the lowest point of the first nod (the head bounces there) or
    the first extreme of a shake or tilt. The neck (vc4) takes 40 % of the angle, the skull base 60 %."""

    AXES = {"NOD": "pitch", "SHAKE": "yaw", "TILT": "roll"}

    def __init__(self, name: str, keys: KeyTimes, lexeme: str = "NOD", amplitude: float = 14.0,
                 repeats: int = 1, **kw):
        lexeme = lexeme.upper() if lexeme.upper() in self.AXES else "NOD"
        self.axis = self.AXES[lexeme]
        super().__init__(name, keys, PRIORITY["head"], [f"{j}.{self.axis}" for j, _ in NECK_SHARE], **kw)
        self.lexeme = lexeme
        self.amplitude = float(amplitude)
        self.repeats = max(1, int(repeats))

    def curve(self, u: np.ndarray) -> np.ndarray:
        """The head angle (degrees, relative to where it started) on the preferred-time axis ``u``."""
        k, a = self.keys, self.amplitude
        ready = k.pref("ready")
        s0, s1 = k.pref("strokeStart"), k.pref("strokeEnd")
        n = self.repeats
        period = (s1 - s0) / n if s1 > s0 else 1.0
        x = (u - s0) / period
        cyc = np.clip(np.floor(x), 0, n - 1)
        phi = np.clip(x - cyc, 0.0, 1.0)
        first = cyc == 0
        if self.lexeme == "NOD":
            lift = -0.15 * a
            pre = lift * EASE(u / ready) if ready > 0 else np.full(u.shape, lift)
            level = np.where(first, lift, 0.0)
            d = np.clip(2 * phi, 0, 1)
            r = np.clip(2 * phi - 1, 0, 1)
            during = np.where(phi < 0.5, level + (a - level) * d * d, a * (1 - (2 * r - r * r)))
            after = np.zeros(u.shape)
        elif self.lexeme == "SHAKE":
            pre = np.zeros(u.shape)
            level = np.where(first, 0.0, -a)
            during = np.where(phi < 0.5, level + (a - level) * EASE(2 * phi), a - 2 * a * EASE(2 * phi - 1))
            after = np.full(u.shape, -a)
        else:  # TILT
            pre = np.zeros(u.shape)
            during = np.where(phi < 0.5, a * EASE(2 * phi), a * (1 - EASE(2 * phi - 1)))
            after = np.zeros(u.shape)
        return np.where(u < s0, pre, np.where(u >= s1, after, during))

    def on_tick(self, t: np.ndarray) -> None:
        c = self.curve(self.keys.warp(t))
        for joint, share in NECK_SHARE:
            dof = f"{joint}.{self.axis}"
            if self.holds(dof):
                self.write(dof, self.start_value(dof) + share * c)


def head_angles_to(driver: Driver, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pitch, yaw) degrees that would face the head towards ``target`` from the torso as it is in the
    frames being ticked (pitch positive downwards)."""
    rot, neck = driver.parent_frame("vc4")
    eyes = neck + np.einsum("nij,j->ni", rot, np.array([0.0, 0.155, 0.095]))
    d = np.einsum("nji,nj->ni", rot, target - eyes)
    yaw = np.degrees(np.arctan2(d[:, 0], d[:, 2]))
    pitch = np.degrees(np.arctan2(-d[:, 1], np.hypot(d[:, 0], d[:, 2])))
    return pitch, yaw


class HeadTurnDriver(MotionDriver):
    """Turns the head (neck and skull base, pitch and yaw) towards a point, arriving at ``arrive``.

    ``shift=True`` (headDirectionShift) makes the new direction the head's rest direction when the unit
    ends; otherwise it holds until its release and hands the neck back.
    """

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, arrive: str = "end",
                 share: float = 1.0, shift: bool = False, priority: int | None = None, **kw):
        dofs = [f"{j}.{a}" for j, _ in NECK_SHARE for a in ("pitch", "yaw")]
        super().__init__(name, keys, PRIORITY["shift" if shift else "behaviour"] if priority is None else priority,
                         dofs, **kw)
        self.target = np.asarray(target, dtype=float)
        self.arrive = arrive
        self.share = share
        self.shift = shift
        if shift:
            self.release_key = "end"

    def handover(self) -> float:
        return STOP_HANDOVER if self.shift else super().handover()

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if self.shift and idle is not None:
            for d in self.dofs:
                idle.set_base(self.body.dof_names[d], float(self.arbitrator.current[d]), t)

    def on_tick(self, t: np.ndarray) -> None:
        pitch, yaw = head_angles_to(self, self.target)
        values = {}
        for joint, share in NECK_SHARE:
            values[f"{joint}.pitch"] = share * self.share * pitch
            values[f"{joint}.yaw"] = share * self.share * yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(self.arrive)))


# --------------------------------------------------------------------------------------------- gaze
#: Share of the gaze angle taken by the head, by BML ``influence``; the torso joints that join in.
GAZE_INFLUENCE = {
    "EYES": (0.0, ()), "NECK": (0.5, ()), "HEAD": (0.6, ()), "SHOULDER": (0.65, ("vt10",)),
    "WAIST": (0.7, ("vt10", "vl5")), "WHOLE": (0.7, ("vt10", "vl5")),
}


class GazeDriver(MotionDriver):
    """Gaze at a target: the neck (and torso, by ``influence``) turn part of the way, the eyes (a slave,
    :class:`GazeEyes`) the rest, both arriving at ``arrive`` (``ready`` for gaze) and tracking the target
    until the release. A gaze shift (``shift=True``) arrives at its end and leaves the eyes and head
    resting on the target."""

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, influence: str = "HEAD",
                 arrive: str = "ready", shift: bool = False, tolerance: float | None = None, **kw):
        share, torso = GAZE_INFLUENCE.get((influence or "HEAD").upper(), GAZE_INFLUENCE["HEAD"])
        if tolerance is not None:
            share = 1.0
        dofs = []
        if share > 0:
            dofs = [f"{j}.{a}" for j, _ in NECK_SHARE for a in ("pitch", "yaw")] + [f"{j}.yaw" for j in torso]
        super().__init__(name, keys, PRIORITY["shift" if shift else "behaviour"], dofs, **kw)
        self.target = np.asarray(target, dtype=float)
        self.share = share
        self.torso = torso
        self.arrive = arrive
        self.shift = shift
        self.tolerance = tolerance  # degrees the eyes may take before the head follows (eye tracking)
        if shift:
            self.release_key = "end"
        self.eyes = GazeEyes(self)

    def attach(self, manager) -> None:
        super().attach(manager)
        manager.add(self.eyes)

    def handover(self) -> float:
        return STOP_HANDOVER if self.shift else super().handover()

    def finish_unit(self, t: float) -> None:
        if not self.shift:
            return
        mgr = self.manager
        if mgr.eyes is not None:
            mgr.eyes.set_target(t, self.target)
        if mgr.idle is not None:
            for d in self.dofs:
                name = self.body.dof_names[d]
                if name in mgr.idle.base:
                    mgr.idle.set_base(name, float(self.arbitrator.current[d]), t)

    def on_tick(self, t: np.ndarray) -> None:
        if not self.owned:
            return
        pitch, yaw = head_angles_to(self, self.target)
        if self.tolerance is not None:
            pitch = pitch - np.clip(pitch, -self.tolerance, self.tolerance)
            yaw = yaw - np.clip(yaw, -self.tolerance, self.tolerance)
        torso_yaw = {"vt10": 0.15, "vl5": 0.1}
        head_yaw_share = 1.0 - sum(torso_yaw[j] for j in self.torso)
        values = {}
        for joint, share in NECK_SHARE:
            values[f"{joint}.pitch"] = share * self.share * pitch
            values[f"{joint}.yaw"] = share * self.share * head_yaw_share * yaw
        for j in self.torso:
            values[f"{j}.yaw"] = torso_yaw[j] * self.share * yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(self.arrive)))


class GazeEyes(MotionDriver):
    """The eyes of a gaze (a slave of :class:`GazeDriver`, with its priority and keys): each eye turns
    onto the target from where the head really is, arriving at the master's arrival key."""

    def __init__(self, master: GazeDriver):
        dofs = ["l_eyeball.pitch", "l_eyeball.yaw", "r_eyeball.pitch", "r_eyeball.yaw"]
        super().__init__(f"{master.name} (eyes)", master.keys, None, dofs, acquire=master.acquire,
                         stop=master.stop_time, time_source=master.time_source)
        master.add_slave(self)
        self.release_key = master.release_key

    def handover(self) -> float:
        return self.master.handover()

    def on_tick(self, t: np.ndarray) -> None:
        m = self.master
        values = {}
        for side in "lr":
            rot, pos = self.parent_frame(f"{side}_eyeball")
            local = np.einsum("nji,nj->ni", rot, m.target - pos)
            pitch, yaw = eye_angles(local)
            values[f"{side}_eyeball.pitch"] = pitch
            values[f"{side}_eyeball.yaw"] = yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time(m.arrive)))


class SaccadeDriver(MotionDriver):
    """Eyes thrown onto a point (Pantomime's saccade): a fast ballistic move, then a hold."""

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray | None = None,
                 offset: tuple[float, float] = (0.0, 0.0), **kw):
        dofs = ["l_eyeball.pitch", "l_eyeball.yaw", "r_eyeball.pitch", "r_eyeball.yaw"]
        super().__init__(name, keys, PRIORITY["behaviour"], dofs, **kw)
        self.release_key = "end"
        self.target = None if target is None else np.asarray(target, dtype=float)
        self.offset = offset  # (pitch, yaw) degrees from the current direction when no target

    def handover(self) -> float:
        return 0.06

    def on_tick(self, t: np.ndarray) -> None:
        values = {}
        for side in "lr":
            if self.target is not None:
                rot, pos = self.parent_frame(f"{side}_eyeball")
                pitch, yaw = eye_angles(np.einsum("nji,nj->ni", rot, self.target - pos))
            else:
                pitch = np.full(len(t), self.start_value(f"{side}_eyeball.pitch") + self.offset[0])
                yaw = np.full(len(t), self.start_value(f"{side}_eyeball.yaw") + self.offset[1])
            values[f"{side}_eyeball.pitch"] = pitch
            values[f"{side}_eyeball.yaw"] = yaw
        self.write_held(blend_in(self, values, t, self.begun, self.keys.time("ready")))


# --------------------------------------------------------------------------------------------- face, posture
FACE_LEXEMES: dict[str, dict[str, float]] = {
    "RAISE_BROWS": {"l_eyebrow.pitch": -12.0, "r_eyebrow.pitch": -12.0},
    "BROW_RAISE": {"l_eyebrow.pitch": -12.0, "r_eyebrow.pitch": -12.0},
    "FROWN": {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0, "l_eyebrow.roll": -6.0, "r_eyebrow.roll": 6.0},
    "LOWER_BROWS": {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0},
    "CLOSE_EYES": {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
    "BLINK": {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
    "WIDEN_EYES": {"l_eyelid.pitch": -18.0, "r_eyelid.pitch": -18.0, "l_eyebrow.pitch": -6.0,
                   "r_eyebrow.pitch": -6.0},
    "OPEN_MOUTH": {"temporomandibular.pitch": 16.0},
    "SMILE": {"temporomandibular.pitch": 3.0, "l_eyebrow.pitch": -3.0, "r_eyebrow.pitch": -3.0},
    "SURPRISE": {"l_eyebrow.pitch": -14.0, "r_eyebrow.pitch": -14.0, "temporomandibular.pitch": 12.0,
                 "l_eyelid.pitch": -15.0, "r_eyelid.pitch": -15.0},
}
#: FACS action units that this skeleton can show.
FACS_UNITS: dict[int, dict[str, float]] = {
    1: {"l_eyebrow.pitch": -7.0, "r_eyebrow.pitch": -7.0, "l_eyebrow.roll": 3.0, "r_eyebrow.roll": -3.0},
    2: {"l_eyebrow.pitch": -7.0, "r_eyebrow.pitch": -7.0, "l_eyebrow.roll": -3.0, "r_eyebrow.roll": 3.0},
    4: {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0},
    5: {"l_eyelid.pitch": -18.0, "r_eyelid.pitch": -18.0},
    7: {"l_eyelid.pitch": 25.0, "r_eyelid.pitch": 25.0},
    26: {"temporomandibular.pitch": 12.0},
    27: {"temporomandibular.pitch": 22.0},
    41: {"l_eyelid.pitch": 35.0, "r_eyelid.pitch": 35.0},
    43: {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
    45: {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
}

POSTURES: dict[str, dict[str, float]] = {
    "LEAN_FORWARD": {"vl5.pitch": 8.0, "HumanoidRoot.tz": 0.02},
    "LEAN_BACK": {"vl5.pitch": -6.0, "HumanoidRoot.tz": -0.02},
    "LEAN_LEFT": {"vl5.roll": -5.0, "HumanoidRoot.tx": 0.02},
    "LEAN_RIGHT": {"vl5.roll": 5.0, "HumanoidRoot.tx": -0.02},
    "WEIGHT_SHIFT": {"HumanoidRoot.tx": 0.025, "vl5.roll": 2.0, "r_knee.pitch": 8.0, "r_hip.pitch": -4.0},
}


def face_values(behaviour_type: str, attrs: Mapping[str, str]) -> dict[str, float]:
    """DOF values of a face behaviour at full attack (scaled by ``amount``, one side if ``side`` says so)."""
    try:
        amount = float(attrs.get("amount", "1"))
    except ValueError:
        amount = 1.0
    values: dict[str, float] = {}
    if behaviour_type == "faceFacs":
        try:
            au = int(float(attrs.get("au", "0")))
        except ValueError:
            au = 0
        values = dict(FACS_UNITS.get(au, {}))
    else:
        values = dict(FACE_LEXEMES.get(attrs.get("lexeme", "").upper(), {}))
    side = attrs.get("side", "BOTH").upper()
    if side in ("LEFT", "RIGHT"):
        keep = "l_" if side == "LEFT" else "r_"
        values = {k: v for k, v in values.items() if not (k[:2] in ("l_", "r_") and not k.startswith(keep))}
    return {k: v * amount for k, v in values.items()}


class PoseDriver(MotionDriver):
    """Blends DOFs to fixed values and holds them: face expressions (attack to ``attackPeak``), postures
    (to ``ready``), and their shift variants (to ``end``; a shift holds its values afterwards: a face
    shift keeps its DOFs, a posture shift makes the values the rest pose)."""

    def __init__(self, name: str, keys: KeyTimes, values: Mapping[str, float], priority: int,
                 arrive: str, release: str | None = "relax", rest_after: bool = False, **kw):
        super().__init__(name, keys, priority, list(values), **kw)
        self.values = dict(values)
        self.arrive = arrive
        self.rest_after = rest_after
        self.hold_forever = release is None
        self.release_key = release or "end"

    def occupies_until(self) -> float:
        return math.inf if self.hold_forever else self.keys.end

    def setup(self) -> None:
        if not self.hold_forever:
            return super().setup()
        acquire = self.time_source.inverse(self.acquire)
        if self.stop_time is not None and self.stop_time < acquire:
            self.stopped = True
            return
        self.manager.at(acquire, self._begin)
        if self.stop_time is not None:
            self.manager.at(self.stop_time, lambda t: self.stop(STOP_HANDOVER))

    def handover(self) -> float:
        return STOP_HANDOVER if self.rest_after else super().handover()

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if self.rest_after and idle is not None:
            for name, v in self.values.items():
                if name in idle.base:
                    idle.set_base(name, float(self.arbitrator.current[self.body.dof(name)]), t)

    def on_tick(self, t: np.ndarray) -> None:
        n = len(t)
        rest = self.body.rest_pose()
        target = {}
        for k, v in self.values.items():  # root translations are offsets from the rest position
            target[k] = np.full(n, v + (rest[self.body.dof(k)] if k.startswith("HumanoidRoot.t") else 0.0))
        self.write_held(blend_in(self, target, t, self.begun, self.keys.time(self.arrive)))


class LocomotionDriver(MotionDriver):
    """Walks the root to a goal (a point short of the target) between start and end, legs swinging;
    the goal becomes the rest position of the root."""

    STEP_RATE = 1.8  # steps per second

    def __init__(self, name: str, keys: KeyTimes, target: np.ndarray, **kw):
        dofs = ["HumanoidRoot.tx", "HumanoidRoot.tz", "HumanoidRoot.yaw", "l_hip.pitch", "r_hip.pitch",
                "l_knee.pitch", "r_knee.pitch"]
        super().__init__(name, keys, PRIORITY["shift"], dofs, **kw)
        self.release_key = "end"
        self.target = np.asarray(target, dtype=float)
        self.goal: np.ndarray | None = None

    def handover(self) -> float:
        return STOP_HANDOVER

    def on_dof_grant(self, dofs, t, current, blend) -> None:
        super().on_dof_grant(dofs, t, current, blend)
        if self.goal is None:
            here = np.array([self.start_value("HumanoidRoot.tx"), self.start_value("HumanoidRoot.tz")])
            there = self.target[[0, 2]]
            d = there - here
            dist = float(np.linalg.norm(d))
            self.goal = here if dist < 0.7 else here + d * (dist - 0.6) / dist

    def finish_unit(self, t: float) -> None:
        idle = self.manager.idle
        if idle is not None:
            for name in ("HumanoidRoot.tx", "HumanoidRoot.tz"):
                idle.set_base(name, float(self.arbitrator.current[self.body.dof(name)]), t)

    def on_tick(self, t: np.ndarray) -> None:
        t0, t1 = self.begun, self.keys.end
        here = np.array([self.start_value("HumanoidRoot.tx"), self.start_value("HumanoidRoot.tz")])
        f = EASE(frac(t, t0, t1))
        pos = here + np.multiply.outer(f, self.goal - here)
        d = self.goal - here
        heading = math.degrees(math.atan2(d[0], d[1])) if np.linalg.norm(d) > 1e-6 else 0.0
        turn = np.sin(np.pi * frac(t, t0, t1)) ** 0.5
        walking = np.sin(np.pi * frac(t, t0, t1))
        phase = 2 * np.pi * self.STEP_RATE / 2 * (t - t0)
        values = {"HumanoidRoot.tx": pos[:, 0], "HumanoidRoot.tz": pos[:, 1],
                  "HumanoidRoot.yaw": heading * turn,
                  "l_hip.pitch": -20 * walking * np.sin(phase), "r_hip.pitch": 20 * walking * np.sin(phase),
                  "l_knee.pitch": 30 * walking * np.maximum(0, np.sin(phase + np.pi / 2)),
                  "r_knee.pitch": 30 * walking * np.maximum(0, -np.sin(phase + np.pi / 2))}
        self.write_held(values)


class SpeechJawDriver(MotionDriver):
    """The jaw opening and closing at syllable rate while speech plays (start to end)."""

    SYLLABLE_RATE = 4.3

    def __init__(self, name: str, keys: KeyTimes, **kw):
        super().__init__(name, keys, PRIORITY["speech"], ["temporomandibular.pitch"], **kw)
        self.release_key = keys.sync_ids[-1]

    def release_time(self) -> float:
        return self.keys.end

    def on_tick(self, t: np.ndarray) -> None:
        t0, t1 = self.keys.start, self.keys.end
        env = np.clip(np.minimum(t - t0, t1 - t) / 0.1, 0, 1)
        jaw = 9.0 * (0.5 - 0.5 * np.cos(2 * np.pi * self.SYLLABLE_RATE * (t - t0)))
        self.write_held({"temporomandibular.pitch": self.start_value("temporomandibular.pitch") * (1 - env) + jaw * env})


# --------------------------------------------------------------------------------------------- hands, key frames
HAND_SHAPES = {"relaxed": 25.0, "flat": 0.0, "open": 0.0, "fist": 95.0, "point": 70.0, "cup": 40.0, "claw": 60.0}


class HandShapeDriver(MotionDriver):
    """Forms a named hand shape (the fingers' curl), holds it, and hands the fingers back."""

    def __init__(self, name: str, keys: KeyTimes, side: str, shape: str, **kw):
        super().__init__(name, keys, PRIORITY["command"], [f"{side}_fingers.roll"], **kw)
        self.release_key = "end"
        self.side = side
        self.curl = HAND_SHAPES.get(shape.lower(), HAND_SHAPES["relaxed"])

    def handover(self) -> float:
        return 0.3

    def on_tick(self, t: np.ndarray) -> None:
        v = {f"{self.side}_fingers.roll": np.full(len(t), -side_sign(self.side) * self.curl)}
        self.write_held(blend_in(self, v, t, self.begun, self.keys.time("ready")))


#: Key frame sequences for the right arm: (approach seconds, hold seconds, DOF values). For the left arm
#: the DOF names swap side and the roll and yaw values change sign.
KEYFRAMES: dict[str, list[tuple[float, float, dict[str, float]]]] = {
    "wave": [
        (0.5, 0.1, {"shoulder.roll": -70.0, "shoulder.pitch": -30.0, "shoulder.yaw": -80.0, "elbow.pitch": -110.0,
                    "wrist.roll": 0.0, "fingers.roll": 5.0}),
        (0.25, 0.0, {"wrist.roll": 25.0}),
        (0.25, 0.0, {"wrist.roll": -25.0}),
        (0.25, 0.0, {"wrist.roll": 25.0}),
        (0.25, 0.1, {"wrist.roll": 0.0}),
    ],
    "shrug": [
        (0.3, 0.3, {"shoulder.roll": -25.0, "shoulder.pitch": -20.0, "elbow.pitch": -90.0, "elbow.yaw": -60.0,
                    "fingers.roll": 0.0}),
    ],
}


class KeyframeDriver(MotionDriver):
    """Plays a named key frame sequence on one arm (Pantomime's ArmKFMotionDriver): each key frame is
    approached from the previous one and held, the whole sequence ``repeat`` times; then hands back."""

    def __init__(self, name: str, start: float, side: str, sequence: str, repeat: int = 1, **kw):
        frames = KEYFRAMES[sequence]
        s = side_sign(side)
        flip = -s  # the library is written for the right arm (s = -1)
        poses: list[dict[str, float]] = []
        current: dict[str, float] = {}
        times = [0.0]
        for _ in range(max(1, repeat)):
            for approach, hold, vals in frames:
                for k, v in vals.items():
                    current[f"{side}_{k}"] = v * (flip if k.endswith(("roll", "yaw")) else 1.0)
                poses.append(dict(current))
                times.append(times[-1] + approach)
                times.append(times[-1] + hold)
        dofs = sorted(poses[-1])
        keys = KeyTimes(("start", "end"), np.array([start, start + times[-1]]), np.array([0.0, times[-1]]))
        super().__init__(name, keys, PRIORITY["command"], dofs, **kw)
        self.release_key = "end"
        self.poses = poses
        self.frame_times = start + np.asarray(times)

    def handover(self) -> float:
        return 0.4

    def on_tick(self, t: np.ndarray) -> None:
        n = len(t)
        out = {}
        for name in self.dof_names:
            a = np.full(n, self.start_value(name))
            prev = self.start_value(name)
            for k, pose in enumerate(self.poses):
                t0, t1 = self.frame_times[2 * k], self.frame_times[2 * k + 1]
                v = pose.get(name, prev)
                a = np.where(t >= t0, HOLD(t, t0, t1, prev, v, angular=True), a)
                prev = v
            out[name] = a
        self.write_held(out)


class EyelidDriver(MotionDriver):
    """Holds the eyelids (0 open, 1 closed, negative wide open): a staring contest suppresses blinks."""

    def __init__(self, name: str, keys: KeyTimes, amount: float, **kw):
        super().__init__(name, keys, PRIORITY["command"], ["l_eyelid.pitch", "r_eyelid.pitch"], **kw)
        self.release_key = "end"
        self.value = 72.0 * amount if amount >= 0 else 18.0 * amount

    def handover(self) -> float:
        return 0.1

    def on_tick(self, t: np.ndarray) -> None:
        v = np.full(len(t), self.value)
        self.write_held(blend_in(self, {"l_eyelid.pitch": v, "r_eyelid.pitch": v}, t, self.begun,
                                 self.keys.time("ready")))


# --------------------------------------------------------------------------------------------- motor functions
GESTURE_SYNCS = ("start", "ready", "strokeStart", "stroke", "strokeEnd", "relax", "end")


def _unit_keys(unit_name: str):
    from agentsim.engines import animation as engine

    return {"beat": engine.BEAT, "gesture": engine.GESTURE, "pointing": engine.POINTING, "nod": engine.NOD,
            "shake": engine.SHAKE, "gaze": engine.GAZE}[unit_name]


def _side(hand: str, default: str = "r") -> str:
    h = (hand or "").lower()
    if h.startswith("l"):
        return "l"
    if h.startswith("r"):
        return "r"
    return default


class MotionFunctions(MotorFunctionExporter):
    """The motor functions of the motion units (names and defaults after Pantomime's table 4; times in
    seconds, angles in degrees unless noted)."""

    def list_interface(self):
        return {
            "beat": {"hand": "right", "approach": 0.3, "retract": 0.3, "amount": 1.0, "lexeme": "BEAT"},
            "conduct": {"hand": "right", "meter": 4, "beat": 1, "approach": 0.3, "retract": 0.3, "amount": 1.0},
            "point": {"target": "", "x": 0.0, "y": 1.3, "z": 2.0, "hand": "", "approach": 0.5, "hold": 1.0,
                      "retract": 0.4},
            "nod": {"amt": 0.3, "duration": 1.0, "repeat": 1},
            "shake": {"amt": 0.3, "duration": 1.0, "repeat": 1},
            "tilt": {"amt": 0.3, "duration": 1.0},
            "headtowards": {"object": "", "x": 0.0, "y": 1.6, "z": 2.0, "approach": 0.5, "hold": 2.0,
                            "retract": 0.5},
            "saccade": {"target": "", "coord": "eyespace", "x": 0.0, "y": 0.0, "z": 0.5, "hold": 0.5,
                        "dYRot": 0.0, "dXRot": 0.0},
            "eyetrack": {"target": "", "tol": 0.1, "approach": 0.3, "duration": 2.0},
            "gaze track": {"target": "", "tol": 0.1, "approach": 0.3, "duration": 2.0},
            "handshape": {"shape": "relaxed", "hand": "right", "approach": 0.3, "duration": 1.0},
            "keyframe": {"name": "wave", "hand": "right", "repeat": 1},
            "eyelids": {"amount": 0.0, "approach": 0.1, "duration": 1.0},
        }

    def execute(self, name, at, a, manager):
        scene = manager.scene
        label = f"{name}@{at:g}"
        if name in ("beat", "conduct"):
            side = _side(str(a["hand"]))
            unit = _unit_keys("beat")
            keys = KeyTimes.scaled(GESTURE_SYNCS, unit.preferred(), at, "stroke", float(a["approach"]),
                                   float(a["retract"]) + 0.2)
            if name == "beat":
                path = GESTURE_FORMS.get(str(a["lexeme"]).upper(), GESTURE_FORMS["DEFAULT"])
                path = path.scaled(float(a["amount"]))
            else:
                path = conducting_path(int(a["meter"]), int(a["beat"]), float(a["amount"]))
            return manager.add(GestureDriver(label, keys, side, path))
        if name == "point":
            target = scene.point(str(a["target"])) if a["target"] else np.array([a["x"], a["y"], a["z"]], float)
            side = _side(str(a["hand"]), "l" if target[0] > 0 else "r")
            ap, hold, rt = float(a["approach"]), float(a["hold"]), float(a["retract"])
            times = at + np.array([0.0, 0.6 * ap, 0.65 * ap, ap, ap + 0.15, ap + hold, ap + hold + rt])
            keys = KeyTimes(GESTURE_SYNCS, times, times - at)
            return manager.add(PointingDriver(label, keys, side, target))
        if name in ("nod", "shake", "tilt"):
            unit = _unit_keys("shake" if name == "shake" else "nod")
            rep = int(a.get("repeat", 1))
            keys = KeyTimes.scaled(GESTURE_SYNCS, unit.preferred(rep), at, duration=float(a["duration"]))
            return manager.add(HeadDriver(label, keys, name.upper(), 40.0 * float(a["amt"]), rep))
        if name == "headtowards":
            target = scene.point(str(a["object"])) if a["object"] else np.array([a["x"], a["y"], a["z"]], float)
            ap, hold, rt = float(a["approach"]), float(a["hold"]), float(a["retract"])
            times = at + np.array([0.0, ap, ap + hold, ap + hold + rt])
            keys = KeyTimes(("start", "ready", "relax", "end"), times, times - at)
            return manager.add(HeadTurnDriver(label, keys, target, arrive="ready"))
        if name == "saccade":
            hold = float(a["hold"])
            times = at + np.array([0.0, 0.05, 0.05 + hold])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            if a["target"]:
                return manager.add(SaccadeDriver(label, keys, scene.point(str(a["target"]))))
            if a["dXRot"] or a["dYRot"]:
                return manager.add(SaccadeDriver(label, keys, offset=(float(a["dXRot"]), float(a["dYRot"]))))
            p = np.array([a["x"], a["y"], a["z"]], dtype=float)
            if str(a["coord"]).lower() == "eyespace":  # origin between the eyes, z along the nose, at rest
                p = p + np.array([0.0, 1.665, 0.085])
            return manager.add(SaccadeDriver(label, keys, p))
        if name in ("eyetrack", "gaze track"):
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur, ap + dur + 0.3])
            keys = KeyTimes(("start", "ready", "relax", "end"), times, times - at)
            return manager.add(GazeDriver(label, keys, scene.point(str(a["target"])),
                                          tolerance=math.degrees(float(a["tol"]))))
        if name == "handshape":
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            return manager.add(HandShapeDriver(label, keys, _side(str(a["hand"])), str(a["shape"])))
        if name == "keyframe":
            if str(a["name"]) not in KEYFRAMES:
                raise KeyError(f"no key frame sequence {a['name']!r} (known: {', '.join(sorted(KEYFRAMES))})")
            return manager.add(KeyframeDriver(label, at, _side(str(a["hand"])), str(a["name"]), int(a["repeat"])))
        if name == "eyelids":
            ap, dur = float(a["approach"]), float(a["duration"])
            times = at + np.array([0.0, ap, ap + dur])
            keys = KeyTimes(("start", "ready", "end"), times, times - at)
            return manager.add(EyelidDriver(label, keys, float(a["amount"])))
        raise KeyError(name)


def register_motor_functions(manager: "DriverManager") -> None:
    manager.add_exporter(MotionFunctions())


# --------------------------------------------------------------------------------------------- from BML
@dataclass
class UnitInfo:
    """What became of one timed behaviour: its keys, the drivers playing it, hands, and when it stopped."""

    block: str
    id: str
    type: str
    lexeme: str
    keys: dict[str, float]
    drivers: list[str] = field(default_factory=list)
    sides: list[str] = field(default_factory=list)
    stop: float | None = None
    target: list[float] | None = None
    note: str = ""

    def as_dict(self) -> dict:
        return {"block": self.block, "id": self.id, "type": self.type, "lexeme": self.lexeme,
                "keys": dict(self.keys), "drivers": list(self.drivers), "sides": list(self.sides),
                "stop": self.stop, "target": self.target, "note": self.note}


def _stop_times(feedback_items: Sequence[dict] | None) -> tuple[dict[str, float], dict[str, float]]:
    """Drop times by ``block:behaviour`` (from warnings) and end times of blocks (from block progress)."""
    drops: dict[str, float] = {}
    ends: dict[str, float] = {}
    for f in feedback_items or ():
        if f.get("type") == "warningFeedback":
            target = str(f.get("id", ""))
            block = target.split(":", 1)[0]
            for b in f.get("modifiedBehaviours", []) or []:
                drops.setdefault(f"{block}:{b}", float(f.get("globalTime", 0.0)))
        elif f.get("type") == "blockProgress" and str(f.get("id", "")).endswith(":end"):
            ends[str(f["id"])[:-4]] = float(f.get("globalTime", 0.0))
    return drops, ends


def _speech_pegged(timed, speech_ids: set[tuple[str, str]]) -> bool:
    for ref in timed.behaviour.refs.values():
        if ref.kind == "sync" and ref.behaviour is not None:
            if ((ref.block or timed.block_id), ref.behaviour) in speech_ids:
                return True
    return False


def _beat_index(behaviour) -> int | None:
    meter = conducting_meter(behaviour.attributes.get("lexeme", ""))
    if meter and meter[1]:
        return meter[1]
    for k, v in behaviour.attributes.items():
        if k.lower().split(":")[-1] == "beat":
            try:
                return int(float(v))
            except ValueError:
                return None
    return None


def build_drivers(manager: "DriverManager", timed_list: Sequence, feedback_items: Sequence[dict] | None = None,
                  animator_time: TimeSource | None = None) -> list[UnitInfo]:
    """Create the motion drivers that play ``timed_list`` (TimedBehaviours) and add them to ``manager``.

    A behaviour that never started is left out; one that was dropped or interrupted after it started
    plays until then (the time comes from warning or block feedback, else its last passed sync point).
    Behaviours tied to speech are advanced by ``animator_time`` when given.
    """
    drops, block_ends = _stop_times(feedback_items)
    scene = manager.scene
    speech_ids = {(t.block_id, t.id) for t in timed_list if t.behaviour.type == "speech"}
    groups = {"gaze": ReplacementGroup("gaze")}
    infos: list[UnitInfo] = []
    arm_items: list[tuple] = []

    for timed in sorted(timed_list, key=lambda x: (x.times()[0] if x.times()[0] is not None else math.inf, x.order)):
        b = timed.behaviour
        if b.type == "wait":
            continue
        started = timed.passed[0] is not None
        if timed.state == "dropped" and not started:
            continue
        stop = None
        if timed.state == "dropped":
            key = f"{timed.block_id}:{timed.id}"
            passed = [p for p in timed.passed if p is not None]
            stop = drops.get(key, block_ends.get(timed.block_id, passed[-1] if passed else None))
        try:
            keys = KeyTimes.from_timed(timed, fill=stop)
        except ValueError:
            continue
        lexeme = b.attributes.get("lexeme", "")
        info = UnitInfo(timed.block_id, timed.id, b.type, lexeme, keys.as_dict(), stop=stop)
        infos.append(info)
        ts = animator_time if (animator_time is not None and (b.type == "speech" or _speech_pegged(timed, speech_ids))) \
            else None
        name = f"{timed.block_id}:{timed.id}"
        common = {"stop": stop, "time_source": ts}
        if b.type in ("gesture", "pointing"):
            arm_items.append((timed, keys, info, common))
            continue
        if b.type == "speech":
            drv = manager.add(SpeechJawDriver(name, keys, **common))
        elif b.type == "head":
            try:
                amount = float(b.attributes.get("amount", "0.5"))
            except ValueError:
                amount = 0.5
            from agentsim.engines.animation import repetition
            drv = manager.add(HeadDriver(name, keys, lexeme or "NOD", 28.0 * amount, repetition(b), **common))
        elif b.type in ("gaze", "gazeShift"):
            target = _bml_target(scene, b)
            info.target = [float(x) for x in target]
            drv = manager.add(GazeDriver(name, keys, target, b.attributes.get("influence", "HEAD"),
                                         arrive="ready" if b.type == "gaze" else "end", shift=b.type == "gazeShift",
                                         group=groups["gaze"], **common))
        elif b.type == "headDirectionShift":
            drv = manager.add(HeadTurnDriver(name, keys, _bml_target(scene, b), arrive="end", shift=True, **common))
        elif b.type in ("faceLexeme", "faceFacs", "face", "faceShift"):
            values = face_values("faceFacs" if b.type == "faceFacs" else "faceLexeme", b.attributes)
            if not values:
                info.note = "no DOFs for this expression"
                continue
            if b.type == "faceShift":
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["shift"], "end", release=None, **common))
            else:
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["behaviour"], "attackPeak", **common))
        elif b.type in ("posture", "postureShift"):
            label = (b.attributes.get("lexeme") or b.attributes.get("type") or "WEIGHT_SHIFT").upper()
            values = POSTURES.get(label, POSTURES["WEIGHT_SHIFT"])
            if b.type == "posture":
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["behaviour"], "ready", **common))
            else:
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["shift"], "end", release="end",
                                             rest_after=True, **common))
        elif b.type == "locomotion":
            drv = manager.add(LocomotionDriver(name, keys, _bml_target(scene, b), **common))
        else:
            info.note = "no motion for this behaviour type"
            continue
        info.drivers.append(drv.name)

    _build_arms(manager, arm_items, scene)
    return infos


def _bml_target(scene: Scene, behaviour) -> np.ndarray:
    attrs = behaviour.attributes
    point = scene.point(attrs.get("target", ""))
    try:
        angle = float(attrs.get("offsetAngle", "0"))
    except ValueError:
        angle = 0.0
    if angle:
        point = offset_target(point, np.array([0.0, 1.665, 0.085]), angle, attrs.get("offsetDirection", "RIGHT"))
    return point


def _build_arms(manager: "DriverManager", items: list[tuple], scene: Scene) -> None:
    """Gestures and pointing: choose hands, number conducting beats, coarticulate on each hand."""
    # Hands: the mode says, else the right hand (pointing: the hand on the target's side), unless that
    # hand is busy then and the other is free. Behaviours with a mode are placed first.
    busy: dict[str, list[tuple[float, float]]] = {"l": [], "r": []}
    planned: list[tuple[str, tuple]] = []
    explicit_modes = {"LEFT_HAND": ["l"], "LEFT": ["l"], "RIGHT_HAND": ["r"], "RIGHT": ["r"],
                      "BOTH_HANDS": ["l", "r"], "BOTH": ["l", "r"]}
    ordered = sorted(items, key=lambda it: it[0].behaviour.attributes.get("mode", "").upper() not in explicit_modes)
    for item in ordered:
        timed, keys, info, common = item
        b = timed.behaviour
        sides = explicit_modes.get(b.attributes.get("mode", "").upper())
        if sides is None:
            if b.type == "pointing":
                first = "l" if scene.point(b.attributes.get("target", ""))[0] > 0 else "r"
            else:
                first = "r"
            other = "l" if first == "r" else "r"
            clash = lambda s: any(a < keys.end and keys.start < e for a, e in busy[s])  # noqa: E731
            sides = [other] if clash(first) and not clash(other) else [first]
        for s in sides:
            busy[s].append((keys.start, keys.end))
            planned.append((s, item))
    # Conducting: number the beats of each hand in stroke order, unless the lexeme or an attribute says.
    counters: dict[tuple[str, int], int] = {}
    beat_of: dict[tuple[str, int], int] = {}
    for s, item in sorted(planned, key=lambda x: x[1][1].time("stroke")):
        b = item[0].behaviour
        meter = conducting_meter(b.attributes.get("lexeme", "")) if b.type == "gesture" else None
        if meter is None:
            continue
        explicit = _beat_index(b)
        n = counters.get((s, meter[0]), 0)
        beat = explicit if explicit is not None else n % max(meter[0], 1) + 1
        counters[(s, meter[0])] = beat
        beat_of[(s, id(item))] = beat
    # Coarticulation: a gesture taking over a hand whose previous gesture is past its stroke starts at
    # once (dropping that one's retraction); one arriving during the previous stroke waits for its end.
    last: dict[str, tuple] = {}
    for s, item in sorted(planned, key=lambda x: (x[1][1].start, x[1][0].order)):
        timed, keys, info, common = item
        b = timed.behaviour
        acquire = keys.start
        prev = last.get(s)
        if prev is not None and prev[1].end > keys.start:
            prev_end = prev[1].time("strokeEnd")
            if prev_end <= keys.time("strokeStart"):
                acquire = max(keys.start, prev_end)
                info.note = (info.note + " coarticulated").strip()
        last[s] = item
        name = f"{timed.block_id}:{timed.id}" + (f" ({'left' if s == 'l' else 'right'})" if len(
            [p for p in planned if p[1] is item]) > 1 else "")
        if b.type == "pointing":
            target = _bml_target(scene, b)
            info.target = [float(x) for x in target]
            drv = PointingDriver(name, keys, s, target, acquire=acquire, **common)
        else:
            lexeme = b.attributes.get("lexeme", "").upper() or "BEAT"
            meter = conducting_meter(lexeme)
            if meter is not None:
                try:
                    amount = float(b.attributes.get("amount", "1"))
                except ValueError:
                    amount = 1.0
                path = conducting_path(meter[0], beat_of.get((s, id(item)), 1), amount)
                info.note = (info.note + f" beat {beat_of.get((s, id(item)), 1)} of {meter[0]}").strip()
            else:
                path = GESTURE_FORMS.get(lexeme, GESTURE_FORMS["DEFAULT"])
            drv = GestureDriver(name, keys, s, path, acquire=acquire, **common)
        manager.add(drv)
        info.drivers.append(drv.name)
        info.sides.append(s)
