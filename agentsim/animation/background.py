"""Background drivers, which keep the body alive when nothing else goes on: sway, breathing, gaze rest, blinks.

They run at the lowest priorities all the time: :class:`IdleSway` (stance, weight shift, arms and head
at rest), :class:`Breathing`, :class:`EyeFixation` (the eyes rest on a point and make small saccades)
with its slave :class:`EyeBlinkReflex` (eyelids follow the eye pitch; blinks arrive from an exponential
distribution).
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from agentsim.animation.body import Body
from agentsim.animation.drivers import PRIORITY, Driver, SlaveDriver, smoothstep


def _sway(rng: np.random.Generator, amplitude: float, n: int = 3, low: float = 0.04, high: float = 0.3):
    """Parameters of a smooth random signal: a sum of sinusoids with random frequencies and phases."""
    freqs = rng.uniform(low, high, n)
    phases = rng.uniform(0.0, 2 * np.pi, n)
    amps = rng.uniform(0.5, 1.0, n)
    amps *= amplitude / amps.sum()
    return freqs, phases, amps


class BaseTrack:
    """A value per DOF that changes at given times (a step function), looked up for arrays of times."""

    def __init__(self, value: float):
        self.times: list[float] = [-math.inf]
        self.values: list[float] = [value]

    def set(self, t: float, value: float) -> None:
        i = int(np.searchsorted(self.times, t, side="right"))
        self.times.insert(i, t)
        self.values.insert(i, value)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        if len(self.times) == 1:
            return np.full(np.shape(t), self.values[0])
        k = np.searchsorted(np.asarray(self.times), t, side="right") - 1
        return np.asarray(self.values)[k]


class IdleSway(Driver):
    """The body at rest, never quite still (idle drift): stance, weight shift, arms, head, jaw and lips.

    Each DOF has a base value (the rest pose; shifts such as postureShift, headDirectionShift and
    locomotion move it with :meth:`set_base`) plus a slow random sway drawn from a seeded Generator.
    """

    #: sway amplitude per DOF (degrees, metres for the root)
    SWAY = {
        "HumanoidRoot.tx": 0.008, "HumanoidRoot.tz": 0.006, "vl5.roll": 0.8, "vl5.pitch": 0.5,
        "vc4.pitch": 0.6, "vc4.yaw": 0.8, "skullbase.pitch": 1.0, "skullbase.yaw": 1.2, "skullbase.roll": 0.6,
        "l_shoulder.roll": 1.2, "l_shoulder.pitch": 1.5, "l_elbow.pitch": 2.0, "l_fingers.roll": 3.0,
        "r_shoulder.roll": 1.2, "r_shoulder.pitch": 1.5, "r_elbow.pitch": 2.0, "r_fingers.roll": 3.0,
    }

    def __init__(self, body: Body, rng: np.random.Generator, name: str = "idle sway"):
        joints = ["HumanoidRoot", "sacroiliac", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle",
                  "vl5", "vc4", "skullbase", "temporomandibular", "lower_lip", "upper_lip", "l_lip_corner",
                  "r_lip_corner", "l_eyebrow", "r_eyebrow"]
        for side in "lr":
            joints += [f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist", f"{side}_fingers"]
        names = [f"{j}.{a}" for j in joints for a in ("roll", "pitch", "yaw")]
        names += ["HumanoidRoot.tx", "HumanoidRoot.ty", "HumanoidRoot.tz"]
        super().__init__(name, PRIORITY["idle"], names)
        rest = body.rest_pose()
        self.base = {n: BaseTrack(float(rest[body.dof(n)])) for n in names}
        self.sway = {n: _sway(rng, a) for n, a in self.SWAY.items()}
        cols = [body.dof(n) for n in self.SWAY]
        self._sway_cols = np.array(cols)
        self._sway_f = np.stack([self.sway[n][0] for n in self.SWAY])
        self._sway_p = np.stack([self.sway[n][1] for n in self.SWAY])
        self._sway_a = np.stack([self.sway[n][2] for n in self.SWAY])
        self._rest = rest

    def set_base(self, dof: str, value: float, at: float) -> None:
        """From time ``at`` on, rest ``dof`` at ``value``."""
        self.base[dof].set(at, value)

    def sway_values(self, t: np.ndarray) -> np.ndarray:
        """The sway of every swaying DOF (frames x DOFs)."""
        phase = 2 * np.pi * t[:, None, None] * self._sway_f[None] + self._sway_p[None]
        return np.einsum("nmk,mk->nm", np.sin(phase), self._sway_a)

    def on_tick(self, t: np.ndarray) -> None:
        body = self.body
        cols = np.array(sorted(self.owned))
        n = len(t)
        values = np.broadcast_to(self._rest[cols], (n, len(cols))).copy()
        where = {int(c): k for k, c in enumerate(cols)}
        for k, c in enumerate(cols):
            track = self.base[body.dof_names[c]]
            if len(track.times) > 1:
                values[:, k] = track(t)
            elif track.values[0] != self._rest[c]:
                values[:, k] = track.values[0]
        sway = self.sway_values(t)
        for j, c in enumerate(self._sway_cols):
            k = where.get(int(c))
            if k is not None:
                values[:, k] += sway[:, j]
        self.write_block(cols, values)


class Breathing(Driver):
    """Breathing: the chest rises (vt10 pitch) and the shoulders lift (sternoclavicular roll).

    ``rate`` is breaths per minute; motor function ``breathing`` changes rate and depth at a time.
    """

    def __init__(self, rng: np.random.Generator, rate: float = 15.0, depth: float = 1.0, name: str = "breathing"):
        super().__init__(name, PRIORITY["reflex"],
                         ["vt10.pitch", "l_sternoclavicular.roll", "r_sternoclavicular.roll"])
        self.phase0 = float(rng.uniform(0, 2 * np.pi))
        self.changes: list[tuple[float, float, float]] = [(-math.inf, rate, depth)]

    def set_rate(self, at: float, rate: float | None = None, depth: float | None = None) -> None:
        last = self.changes[-1]
        self.changes.append((at, last[1] if rate is None else rate, last[2] if depth is None else depth))
        self.changes.sort(key=lambda c: c[0])

    def phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Breathing phase (radians) and depth at times ``t``: the rate integrated piecewise."""
        t = np.asarray(t, dtype=float)
        starts = np.array([c[0] for c in self.changes])
        rates = np.array([c[1] for c in self.changes]) * 2 * np.pi / 60.0
        depths = np.array([c[2] for c in self.changes])
        starts_f = np.where(np.isfinite(starts), starts, 0.0)
        acc = np.zeros(len(starts))  # phase at each change point
        for k in range(1, len(starts)):
            acc[k] = acc[k - 1] + rates[k - 1] * (starts_f[k] - (starts_f[k - 1] if k > 1 else 0.0))
        k = np.searchsorted(starts, t, side="right") - 1
        origin = np.where(k == 0, 0.0, starts_f[k])
        return self.phase0 + acc[k] + rates[k] * (t - origin), depths[k]

    def on_tick(self, t: np.ndarray) -> None:
        ph, depth = self.phase(t)
        inhale = depth * (0.5 - 0.5 * np.cos(ph))
        self.write_held({"vt10.pitch": -0.8 * inhale, "l_sternoclavicular.roll": 1.0 * inhale,
                         "r_sternoclavicular.roll": -1.0 * inhale})


def eye_angles(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eye (pitch, yaw) in degrees that turn the eye's forward axis (+Z) onto ``direction`` (n, 3), given
    in the eye's parent frame; positive pitch looks down, positive yaw to the character's left."""
    d = direction / np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-12)
    yaw = np.degrees(np.arcsin(np.clip(d[..., 0], -1, 1)))
    pitch = np.degrees(np.arctan2(-d[..., 1], d[..., 2]))
    return pitch, yaw


class EyeFixation(Driver):
    """The eyes at rest: they fixate a point in the world (compensating head motion) and make small
    saccades to nearby points every few seconds (seeded). ``set_target`` moves the point (gazeShift)."""

    def __init__(self, rng: np.random.Generator, target=(0.0, 1.6, 2.0), name: str = "eye fixation"):
        super().__init__(name, PRIORITY["reflex"],
                         ["l_eyeball.pitch", "l_eyeball.yaw", "r_eyeball.pitch", "r_eyeball.yaw"])
        self.rng = rng
        self.targets: list[tuple[float, np.ndarray]] = [(-math.inf, np.asarray(target, dtype=float))]
        self._target_arrays: tuple[np.ndarray, np.ndarray] | None = None  # starts and points, for target_at
        self.saccade_times = np.empty(0)
        self.saccade_offsets = np.zeros((1, 2))
        self.saccade_duration = 0.04

    def set_target(self, at: float, target) -> None:
        # in time order, after targets set for the same time (as a stable sort would put it)
        bisect.insort_right(self.targets, (at, np.asarray(target, dtype=float)), key=lambda x: x[0])
        self._target_arrays = None

    def prepare(self, t_begin: float, t_end: float) -> None:
        times = []
        t = t_begin
        while True:
            t += float(self.rng.uniform(1.0, 3.5))
            if t >= t_end:
                break
            times.append(t)
        self.saccade_times = np.asarray(times)
        self.saccade_offsets = np.vstack([[0.0, 0.0], self.rng.normal(0.0, 1.2, (len(times), 2))])

    def target_at(self, t: np.ndarray) -> np.ndarray:
        arrays = self._target_arrays
        if arrays is None or len(arrays[0]) != len(self.targets):  # made again once targets change
            arrays = self._target_arrays = (np.array([x[0] for x in self.targets]),
                                            np.stack([x[1] for x in self.targets]))
        starts, pts = arrays
        return pts[np.searchsorted(starts, t, side="right") - 1]

    def micro(self, t: np.ndarray) -> np.ndarray:
        """Offsets (pitch, yaw degrees) of the small saccades, fast transitions between fixations."""
        if len(self.saccade_times) == 0:
            return np.broadcast_to(self.saccade_offsets[0], (len(t), 2))
        k = np.searchsorted(self.saccade_times, t, side="right")
        cur = self.saccade_offsets[k]
        prev = self.saccade_offsets[np.maximum(k - 1, 0)]
        since = t - np.where(k > 0, self.saccade_times[np.maximum(k - 1, 0)], -np.inf)
        w = smoothstep(since / self.saccade_duration)[:, None]
        return prev + (cur - prev) * w

    def on_tick(self, t: np.ndarray) -> None:
        target = self.target_at(t)
        off = self.micro(t)
        for side in "lr":
            if not (self.holds(f"{side}_eyeball.pitch") or self.holds(f"{side}_eyeball.yaw")):
                continue
            rot, pos = self.parent_frame(f"{side}_eyeball")
            local = np.einsum("nji,nj->ni", rot, target - pos)
            pitch, yaw = eye_angles(local)
            self.write_held({f"{side}_eyeball.pitch": pitch + off[:, 0], f"{side}_eyeball.yaw": yaw + off[:, 1]})


class EyeBlinkReflex(SlaveDriver):
    """Reflexive blinking (Pantomime's EyeBlinkReflex), a slave of the eye driver.

    The eyelids follow the eye pitch (they lower as the eyes look down). Blinks arrive at times drawn
    from an exponential distribution (mean :attr:`mean_interval` seconds) from a seeded Generator. A
    blink whose arrival falls while a driver of higher priority holds the eyelids is suppressed (a
    staring contest); so is one while the reflex is turned off (motor function ``blinkreflex``).
    :attr:`executed` and :attr:`suppressed` list the arrival times of both kinds after an evaluation.
    """

    wants_intervals = True
    CLOSED = 72.0

    def __init__(self, master: Driver, rng: np.random.Generator, mean_interval: float = 4.0,
                 close: float = 0.08, reopen: float = 0.17, name: str = "eye-blink reflex"):
        super().__init__(name, master, {"l_eyelid.pitch": ("l_eyeball.pitch", 0.8, 0.0),
                                        "r_eyelid.pitch": ("r_eyeball.pitch", 0.8, 0.0)})
        self.rng = rng
        self.mean_interval = mean_interval
        self.close, self.reopen = close, reopen
        self.arrivals = np.empty(0)
        self._state = np.empty(0, dtype=np.int8)  # 0 pending, 1 executed, 2 suppressed
        self.off: list[tuple[float, float]] = []
        self.forced: list[float] = []

    def prepare(self, t_begin: float, t_end: float) -> None:
        times = []
        t = t_begin
        while True:
            t += float(self.rng.exponential(self.mean_interval))
            if t >= t_end:
                break
            times.append(t)
        self.arrivals = np.asarray(sorted(times + [f for f in self.forced if t_begin <= f < t_end]))
        self._state = np.zeros(len(self.arrivals), dtype=np.int8)

    def turn(self, on: bool, at: float) -> None:
        """Turn the reflex on or off from ``at``."""
        if on:
            if self.off and self.off[-1][1] == math.inf:
                self.off[-1] = (self.off[-1][0], at)
        else:
            self.off.append((at, math.inf))

    def force(self, at: float) -> None:
        """A blink at ``at`` (motor function ``eyeblink``)."""
        self.forced.append(at)

    @property
    def executed(self) -> np.ndarray:
        return self.arrivals[self._state == 1]

    @property
    def suppressed(self) -> np.ndarray:
        return self.arrivals[self._state != 1]

    def _closure(self, t: np.ndarray) -> np.ndarray:
        done = self.arrivals[self._state == 1]
        if len(done) == 0 or len(t) == 0:
            return np.zeros(len(t))
        k = np.searchsorted(done, t, side="right") - 1
        dt = np.where(k >= 0, t - done[np.maximum(k, 0)], np.inf)
        closing = np.clip(dt / self.close, 0, 1)
        opening = 1.0 - np.clip((dt - self.close) / self.reopen, 0, 1)
        c = np.where(dt < self.close, closing, opening)
        return np.where((dt >= 0) & (dt < self.close + self.reopen), smoothstep(c), 0.0)

    def tick(self, times: np.ndarray) -> None:
        # Arrivals inside the interval held now happen; the interval runs to the next arbitration event.
        mgr = self.manager
        t0, t1 = mgr.segment_bounds
        held = self.holds("l_eyelid.pitch") or self.holds("r_eyelid.pitch")
        if held and len(self.arrivals):
            a, b = np.searchsorted(self.arrivals, [t0, t1], side="left")
            for k in range(a, b):
                if self._state[k] == 0:
                    off = any(s <= self.arrivals[k] < e for s, e in self.off)
                    self._state[k] = 2 if off else 1
        super().tick(times)

    def finish(self) -> None:
        """After the sweep: arrivals never reached while holding the eyelids were suppressed."""
        self._state[self._state == 0] = 2

    def on_tick(self, t: np.ndarray) -> None:
        follow = self.followed()
        closure = self._closure(self.clock_times)
        for dof, base in follow.items():
            if self.holds(dof):
                self.write(dof, base + (self.CLOSED - base) * closure)
