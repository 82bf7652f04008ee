"""Drivers, the Arbitrator over degrees of freedom, background drivers and the Driver Manager (Pantomime).

A :class:`Driver` is one motor skill: it *requests* a set of DOFs at a priority and, on every tick,
writes values for the DOFs it holds. The :class:`Arbitrator` grants each DOF to the highest-priority
driver that wants it (ties: the latest request); a driver that loses a DOF is told (``on_dof_loss``) and
keeps its claim, so it gets the DOF back (``on_dof_regain``) when the usurper releases it. Every write
goes through the Arbitrator, which asserts that the writer holds the DOF and that no DOF is written twice
in a frame.

Drivers are ticked over *segments*: runs of frames between two arbitration events (a request, a
release). Inside a segment nobody gains or loses anything, so a driver computes all its frames at once
with numpy. Within a segment drivers are ticked by *stage* (torso, then neck and arms, then eyes, then
eyelids; see :class:`~agentsim.animation.body.Joint`), so a driver may read the pose of the joints above
the ones it drives: arms reach in the torso's frame, eyes fixate from the head, eyelids follow the eyes.

Background drivers run at the lowest priorities all the time and keep the body alive when nothing else
is going on: :class:`IdleSway` (stance, weight shift, arms and head at rest), :class:`Breathing`,
:class:`EyeFixation` (the eyes rest on a point and make small saccades) with its slave
:class:`EyeBlinkReflex` (eyelids follow the eye pitch; blinks arrive from an exponential distribution).

The :class:`DriverManager` holds the drivers and the Arbitrator, runs the event sweep that evaluates a
pose array for a list of frame times, and exposes *motor functions* by name with default parameters
(``manager.execute("nod", at=2.0, amt=0.5)``).
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from agentsim.animation.body import Body, wrap180

#: Two times closer than this (seconds) are the same time.
EPSILON = 1e-9

#: Priorities of the kinds of drivers (higher wins a DOF).
PRIORITY = {
    "idle": 0,         # stance, sway, arms and head at rest
    "reflex": 1,       # breathing, eye fixation and blinks
    "shift": 10,       # gazeShift, headDirectionShift, postureShift, faceShift, locomotion
    "speech": 15,      # the jaw while speaking
    "behaviour": 20,   # gesture, pointing, gaze, face, posture
    "head": 25,        # nod, shake, tilt: they ride on top of a gaze or a head turn
    "command": 30,     # motor functions invoked directly (hand shapes, eyelids, key frames)
}


class ArbitrationError(AssertionError):
    """A driver wrote a DOF it does not hold, or a DOF got two writers in one frame."""


def smoothstep(s):
    """The default blending curve: 3s^2 - 2s^3 on [0, 1] (zero velocity at both ends), clipped."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


# --------------------------------------------------------------------------------------------- time
class TimeSource:
    """The time a driver is advanced by, as a function of clock time (vectorised).

    By default it is the clock itself. Given matching ``clock`` and ``driver`` times it maps clock time
    piecewise linearly onto driver time (slope 1 outside the given points). This is Chang's *animator
    time* t_A: a gesture pegged to speech is advanced by the time the speech is known to have reached
    (from phoneme or word events) instead of by the clock, so it stays on the syllable when the speech
    runs early or late.
    """

    def __init__(self, clock: Sequence[float] | None = None, driver: Sequence[float] | None = None):
        self._function: Callable[[float], float] | None = None
        if (clock is None) != (driver is None):
            raise ValueError("give both clock and driver times, or neither")
        if clock is None:
            self.clock = self.driver = None
        else:
            c = np.asarray(clock, dtype=float)
            d = np.asarray(driver, dtype=float)
            if c.shape != d.shape or c.ndim != 1 or len(c) == 0:
                raise ValueError("clock and driver times must be 1-d arrays of one length")
            if np.any(np.diff(c) < 0) or np.any(np.diff(d) < 0):
                raise ValueError("clock and driver times must not decrease")
            self.clock, self.driver = c, d

    @classmethod
    def from_events(cls, event_times: Sequence[float], estimated_times: Sequence[float],
                    naive: bool = False) -> "TimeSource":
        """Animator time from speech events: the event for unit i (a syllable or word) arrived at clock
        time ``event_times[i]`` and was estimated to happen at ``estimated_times[i]``.

        ``naive=True`` gives Chang's first formula t_A = min(dt + T_i, T_(i+1)): after an event the
        animator time runs with the clock but waits at the next estimated time until the next event
        arrives (it "sticks"). By default it is interpolated linearly between events instead.
        """
        ev = np.asarray(event_times, dtype=float)
        est = np.asarray(estimated_times, dtype=float)
        if not naive:
            return cls(ev, est)
        clock: list[float] = []
        drv: list[float] = []
        for i in range(len(ev)):
            clock.append(ev[i])
            drv.append(est[i])
            if i + 1 < len(ev):
                reach = est[i + 1] - est[i]
                stop = min(ev[i] + reach, ev[i + 1])
                clock.append(stop)
                drv.append(est[i] + (stop - ev[i]))
        return cls(clock, drv)

    @classmethod
    def from_function(cls, function: Callable[[float], float]) -> "TimeSource":
        """Driver time from any non-decreasing function of clock time, such as the ``position`` method of
        an animator time strategy in :mod:`agentsim.speech.animator_time` after its events are in."""
        source = cls()
        source._function = function
        source.clock = np.zeros(0)  # not the clock
        return source

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        if self._function is not None:
            return np.vectorize(self._function, otypes=[float])(t) if t.size else t
        if self.clock is None:
            return t
        c, d = self.clock, self.driver
        out = np.interp(t, c, d)
        out = np.where(t < c[0], d[0] + (t - c[0]), out)
        return np.where(t > c[-1], d[-1] + (t - c[-1]), out)

    def inverse(self, tau: float) -> float:
        """The first clock time at which the driver time reaches ``tau``."""
        if self.clock is None or not math.isfinite(tau):
            return tau
        if self._function is not None:  # bisection on a non-decreasing function
            f = self._function
            lo, hi = tau - 1.0, tau + 1.0
            while f(lo) >= tau and lo > tau - 1e6:
                lo -= 2 * (hi - lo)
            while f(hi) < tau and hi < tau + 1e6:
                hi += 2 * (hi - lo)
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if f(mid) < tau else (lo, mid)
            return hi
        c, d = self.clock, self.driver
        if tau <= d[0]:
            return float(c[0] + (tau - d[0]))
        if tau > d[-1]:
            return float(c[-1] + (tau - d[-1]))
        k = int(np.searchsorted(d, tau, side="left"))
        if d[k] == d[k - 1]:
            return float(c[k - 1])
        return float(c[k - 1] + (tau - d[k - 1]) * (c[k] - c[k - 1]) / (d[k] - d[k - 1]))

    def __repr__(self) -> str:
        if self._function is not None:
            return f"TimeSource({self._function!r})"
        return "TimeSource(clock)" if self.clock is None else f"TimeSource({len(self.clock)} points)"


#: The clock: drivers are advanced by clock time unless given another TimeSource.
CLOCK = TimeSource()


# --------------------------------------------------------------------------------------------- drivers
_uids = itertools.count()


class Driver:
    """One motor skill driving a set of DOFs at a priority (Pantomime's BaseDriver).

    Subclasses implement :meth:`on_tick`, which is given the driver's times for the frames of a
    segment (clock times mapped through :attr:`time_source`) and writes values with :meth:`write`.
    A driver asks for DOFs with :meth:`request` and gives them back with :meth:`release`, either now
    (inside an event) or at a given time. It is told when it gets DOFs (:meth:`on_dof_grant`), loses
    them (:meth:`on_dof_loss`) and gets them back (:meth:`on_dof_regain`). By default it blends from the
    pose it finds when it gets DOFs to its own values over :attr:`grant_blend` / :attr:`regain_blend`
    seconds (a transition from the current pose).

    Master/slave: a driver may have slaves (:meth:`add_slave`). A slave inherits its master's priority
    unless given its own, follows values on its master's DOFs (see :class:`SlaveDriver`), and every
    DOF loss it suffers is also reported to the master, after the slave's own handler.
    """

    stage_hint = 0
    grant_blend = 0.0
    regain_blend = 0.25
    #: tick even for segments without frames (drivers that must know every interval they held DOFs)
    wants_intervals = False

    def __init__(self, name: str, priority: int | None = 0, dofs: Iterable[str] = (),
                 time_source: TimeSource | None = None):
        self.name = name
        self._priority = priority
        self.dof_names: list[str] = list(dofs)
        self.time_source = time_source or CLOCK
        self.uid = next(_uids)
        self.manager: DriverManager | None = None
        self.body: Body | None = None
        self.arbitrator: Arbitrator | None = None
        self.owned: set[int] = set()
        self.ever_owned: set[int] = set()
        self.master: Driver | None = None
        self.slaves: list[Driver] = []
        self.stopped = False
        self._blend: dict[int, tuple[float, float, float]] = {}
        self.log: list[tuple[float, str, tuple[str, ...]]] = []
        self._times: np.ndarray = np.empty(0)

    # ------------------------------------------------------------------ identity
    @property
    def priority(self) -> int:
        if self._priority is None and self.master is not None:
            return self.master.priority
        return self._priority or 0

    @priority.setter
    def priority(self, value: int | None) -> None:
        self._priority = value

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, priority={self.priority})"

    # ------------------------------------------------------------------ life
    def attach(self, manager: "DriverManager") -> None:
        """Join a manager (called by :meth:`DriverManager.add`); then :meth:`setup` schedules requests."""
        self.manager = manager
        self.body = manager.body
        self.arbitrator = manager.arbitrator
        self.dofs = [self.body.dof(n) for n in self.dof_names]
        self.setup()

    def setup(self) -> None:
        """Schedule this driver's requests and releases (by default: hold its DOFs all the time)."""
        self.request()

    def prepare(self, t_begin: float, t_end: float) -> None:
        """Called before an evaluation of frames from ``t_begin`` to ``t_end`` (seconds)."""

    def add_slave(self, slave: "Driver") -> "Driver":
        if slave.master is not None and slave.master is not self:
            raise ValueError(f"{slave.name} already has a master ({slave.master.name})")
        slave.master = self
        self.slaves.append(slave)
        return slave

    def remove_slave(self, slave: "Driver") -> None:
        if slave in self.slaves:
            self.slaves.remove(slave)
            slave.master = None

    # ------------------------------------------------------------------ requests
    def _indices(self, dofs) -> list[int]:
        if dofs is None:
            return list(self.dofs)
        return [d if isinstance(d, (int, np.integer)) else self.body.dof(d) for d in dofs]

    def request(self, dofs: Iterable[str | int] | None = None, at: float | None = None) -> None:
        """Ask for DOFs (default: all of this driver's), now or at time ``at``."""
        idx = self._indices(dofs)
        if at is None:
            self.arbitrator.request(self, idx)
        else:
            self.manager.at(at, lambda t: None if self.stopped else self.arbitrator.request(self, idx))

    def release(self, dofs: Iterable[str | int] | None = None, at: float | None = None,
                handover: float | None = None) -> None:
        """Give DOFs back (default: all), now or at ``at``. The driver that gets them back blends from the
        current pose to its own over ``handover`` seconds (default: its own regain blend)."""
        idx = self._indices(dofs)
        if at is None:
            self.arbitrator.release(self, idx, handover)
        else:
            self.manager.at(at, lambda t: self.arbitrator.release(self, idx, handover))

    def stop(self, handover: float | None = None) -> None:
        """Stop for good: release every claim now; later scheduled requests are ignored."""
        self.stopped = True
        self.arbitrator.release(self, list(self.arbitrator.claimed_by(self)), handover)

    def holds(self, dof: str | int) -> bool:
        i = dof if isinstance(dof, (int, np.integer)) else self.body.dof(dof)
        return i in self.owned

    # ------------------------------------------------------------------ callbacks
    def on_dof_grant(self, dofs: Sequence[int], t: float, current: np.ndarray, blend: float | None) -> None:
        """Got DOFs for the first time at ``t``; ``current`` are their values there."""
        self.blend_from(dofs, t, current, self.grant_blend if blend is None else blend)

    def on_dof_loss(self, dofs: Sequence[int], t: float) -> None:
        """Lost DOFs to a driver of higher priority at ``t`` (the claim stays: they may come back)."""

    def on_dof_regain(self, dofs: Sequence[int], t: float, current: np.ndarray, blend: float | None) -> None:
        """Got DOFs back at ``t`` after losing them; ``current`` are their values there."""
        self.blend_from(dofs, t, current, self.regain_blend if blend is None else blend)

    def blend_from(self, dofs: Sequence[int], t: float, current: np.ndarray, duration: float) -> None:
        """Blend the values written for ``dofs`` from ``current`` to this driver's own over ``duration``."""
        for d, v in zip(dofs, current):
            if duration > EPSILON:
                self._blend[d] = (t, duration, float(v))
            else:
                self._blend.pop(d, None)

    # ------------------------------------------------------------------ ticking
    def tick(self, times: np.ndarray) -> None:
        """Advance over the frames of a segment (clock times): map them through the time source, then
        :meth:`on_tick`."""
        self._times = times
        self.on_tick(self.time_source(times))

    def on_tick(self, t: np.ndarray) -> None:
        """Write values for the held DOFs at driver times ``t`` (one per frame of the segment)."""
        raise NotImplementedError

    @property
    def clock_times(self) -> np.ndarray:
        """Clock times of the frames being ticked."""
        return self._times

    def write(self, dof: str | int, values) -> None:
        """Write values (scalar or one per frame) for a held DOF, through the Arbitrator."""
        i = dof if isinstance(dof, (int, np.integer)) else self.body.dof(dof)
        self.arbitrator.write(self, i, values)

    def write_held(self, values: Mapping[str | int, object]) -> None:
        """Write those of ``values`` (DOF name or column -> values) whose DOFs this driver holds."""
        for dof, v in values.items():
            i = dof if isinstance(dof, (int, np.integer)) else self.body.dof(dof)
            if i in self.owned:
                self.arbitrator.write(self, i, v)

    def write_block(self, columns: Sequence[int], values: np.ndarray) -> None:
        """Write several held DOFs at once (``values``: frames x len(columns))."""
        self.arbitrator.write_block(self, columns, values)

    def read(self, dof: str | int) -> np.ndarray:
        """Values of any DOF in the frames being ticked, as written so far (earlier stages are final)."""
        i = dof if isinstance(dof, (int, np.integer)) else self.body.dof(dof)
        return self.arbitrator.read(i)

    def parent_frame(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """World rotation of ``joint``'s parent and the joint's world position, in the frames being ticked
        (computed from the pose written so far; joints of earlier stages are final)."""
        return self.arbitrator.parent_frame(joint)

    def apply_blend(self, dof: int, values: np.ndarray) -> np.ndarray:
        b = self._blend.get(dof)
        if b is None:
            return values
        t0, duration, start = b
        times = self._times
        if len(times) and times[0] >= t0 + duration:
            del self._blend[dof]
            return values
        w = smoothstep((times - t0) / duration)
        if self.body.channels[dof][1].endswith("rotation"):
            blended = start + wrap180(values - start) * w
        else:
            blended = start + (values - start) * w
        return np.where(w >= 1.0, values, blended)


class SlaveDriver(Driver):
    """A driver that follows values on its master's DOFs: ``follow`` maps a target DOF to
    ``(source DOF, gain, offset)`` and the slave writes ``gain * source + offset``.

    The source is read from the pose of the frames being ticked, which is what the master wrote while
    it holds the source DOF (and what whoever holds it now wrote otherwise). The slave should drive
    joints of a later stage than its sources.
    """

    def __init__(self, name: str, master: Driver, follow: Mapping[str, tuple[str, float, float]],
                 priority: int | None = None, time_source: TimeSource | None = None):
        super().__init__(name, priority, follow.keys(), time_source or master.time_source)
        self.follow = dict(follow)
        master.add_slave(self)

    def followed(self) -> dict[str, np.ndarray]:
        return {dst: gain * self.read(src) + off for dst, (src, gain, off) in self.follow.items()}

    def on_tick(self, t: np.ndarray) -> None:
        self.write_held(self.followed())


# --------------------------------------------------------------------------------------------- arbitration
class Arbitrator:
    """Grants DOFs by priority and is the only way values get into the pose (Pantomime's Arbitrator).

    Per DOF it keeps the claims of the drivers that want it; the owner is the claim of highest
    ``(priority, request order)``. ``request`` may usurp a DOF (the loser's ``on_dof_loss`` is called,
    its claim is kept); ``release`` hands the DOF to the next claimant (``on_dof_regain``). Writes are
    checked: only the owner may write, and only once per frame (:class:`ArbitrationError` otherwise).
    """

    def __init__(self, body: Body):
        self.body = body
        n = body.n_dofs
        self.claims: list[dict[Driver, tuple[int, int]]] = [dict() for _ in range(n)]
        self.owner: list[Driver | None] = [None] * n
        self._serial = itertools.count()
        self.now = -math.inf
        self.current = body.rest_pose()
        self.values = np.empty((0, n))
        self.writers = np.empty((0, n), dtype=np.int32)
        self._lo = self._hi = 0
        self._segment = 0
        self._stamp = np.full(n, -1, dtype=np.int64)
        self.writes = 0
        self._fk_cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.history: list[tuple[float, str, str, tuple[str, ...]]] = []  # (t, event, driver, dofs)

    # ------------------------------------------------------------------ claims
    def claimed_by(self, driver: Driver) -> list[int]:
        return [d for d, c in enumerate(self.claims) if driver in c]

    def _top(self, d: int) -> Driver | None:
        claims = self.claims[d]
        if not claims:
            return None
        return max(claims, key=claims.__getitem__)

    def request(self, driver: Driver, dofs: Sequence[int]) -> None:
        """``driver`` wants ``dofs`` from now on (at its priority)."""
        losses: dict[Driver, list[int]] = {}
        gains: list[int] = []
        for d in dofs:
            self.claims[d][driver] = (driver.priority, next(self._serial))
            top = self._top(d)
            old = self.owner[d]
            if top is not old:
                if old is not None:
                    old.owned.discard(d)
                    losses.setdefault(old, []).append(d)
                self.owner[d] = top
                top.owned.add(d)
                if top is driver:
                    gains.append(d)
        for loser, lost in losses.items():
            self._lost(loser, lost)
        if gains:
            self._gained(driver, gains, None)

    def release(self, driver: Driver, dofs: Sequence[int], handover: float | None = None) -> None:
        """``driver`` no longer wants ``dofs``; the next claimant of each gets it back."""
        gains: dict[Driver, list[int]] = {}
        for d in dofs:
            if self.claims[d].pop(driver, None) is None:
                continue
            if self.owner[d] is driver:
                driver.owned.discard(d)
                top = self._top(d)
                self.owner[d] = top
                if top is not None:
                    top.owned.add(d)
                    gains.setdefault(top, []).append(d)
        if dofs:
            self.history.append((self.now, "release", driver.name, tuple(self.body.dof_names[d] for d in dofs)))
        for gainer, got in gains.items():
            self._gained(gainer, got, handover)

    def _lost(self, driver: Driver, dofs: list[int]) -> None:
        names = tuple(self.body.dof_names[d] for d in dofs)
        self.history.append((self.now, "loss", driver.name, names))
        driver.log.append((self.now, "loss", names))
        driver.on_dof_loss(dofs, self.now)
        if driver.master is not None:
            driver.master.on_dof_loss(dofs, self.now)

    def _gained(self, driver: Driver, dofs: list[int], handover: float | None) -> None:
        again = [d for d in dofs if d in driver.ever_owned]
        first = [d for d in dofs if d not in driver.ever_owned]
        driver.ever_owned.update(dofs)
        if first:
            self.history.append((self.now, "grant", driver.name, tuple(self.body.dof_names[d] for d in first)))
            driver.log.append((self.now, "grant", tuple(self.body.dof_names[d] for d in first)))
            driver.on_dof_grant(first, self.now, self.current[first], handover)
        if again:
            self.history.append((self.now, "regain", driver.name, tuple(self.body.dof_names[d] for d in again)))
            driver.log.append((self.now, "regain", tuple(self.body.dof_names[d] for d in again)))
            driver.on_dof_regain(again, self.now, self.current[again], handover)

    # ------------------------------------------------------------------ the pose
    def begin(self, n_frames: int) -> None:
        n = self.body.n_dofs
        self.values = np.empty((n_frames, n))
        self.writers = np.full((n_frames, n), -1, dtype=np.int32)

    def tick_segment(self, lo: int, hi: int, times: np.ndarray, drivers: Iterable[Driver]) -> None:
        """Tick every driver holding DOFs over frames ``lo:hi`` (one segment), stage by stage."""
        self._lo, self._hi = lo, hi
        self._segment += 1
        self.values[lo:hi] = self.current
        self._fk_cache = {}
        owners = [d for d in {o for o in self.owner if o is not None} if hi > lo or d.wants_intervals]
        stage = self.body.stage
        owners.sort(key=lambda d: (min(stage[i] for i in d.owned), d.uid))
        seg = times[lo:hi]
        for d in owners:
            d.tick(seg)
        if hi > lo:
            self.current = self.values[hi - 1].copy()

    def write(self, driver: Driver, d: int, values) -> None:
        if self.owner[d] is not driver:
            holder = self.owner[d].name if self.owner[d] is not None else "nobody"
            raise ArbitrationError(f"{driver.name} wrote {self.body.dof_names[d]}, which {holder} holds")
        if self._stamp[d] == self._segment:
            raise ArbitrationError(f"{self.body.dof_names[d]} was written twice in one frame "
                                   f"(second writer: {driver.name})")
        self._stamp[d] = self._segment
        lo, hi = self._lo, self._hi
        if hi <= lo:
            return
        v = np.asarray(values, dtype=float)
        if v.shape != (hi - lo,):
            v = np.broadcast_to(v, (hi - lo,))
        if driver._blend:
            v = driver.apply_blend(d, v)
        self.values[lo:hi, d] = np.minimum(np.maximum(v, self.body.lower[d]), self.body.upper[d])
        self.writers[lo:hi, d] = driver.uid
        self.writes += 1
        self._fk_cache.clear()

    def write_block(self, driver: Driver, columns: Sequence[int], values: np.ndarray) -> None:
        """Write several DOFs at once: ``values`` has one column per DOF in ``columns`` (same checks)."""
        cols = np.asarray(columns, dtype=int)
        for d in cols:
            if self.owner[d] is not driver:
                holder = self.owner[d].name if self.owner[d] is not None else "nobody"
                raise ArbitrationError(f"{driver.name} wrote {self.body.dof_names[d]}, which {holder} holds")
        if np.any(self._stamp[cols] == self._segment) or len(set(cols.tolist())) != len(cols):
            raise ArbitrationError(f"a DOF was written twice in one frame (writer: {driver.name})")
        self._stamp[cols] = self._segment
        lo, hi = self._lo, self._hi
        if hi <= lo:
            return
        v = np.broadcast_to(np.asarray(values, dtype=float), (hi - lo, len(cols))).copy()
        if driver._blend:
            for k, d in enumerate(cols):
                if int(d) in driver._blend:
                    v[:, k] = driver.apply_blend(int(d), v[:, k])
        self.values[lo:hi, cols] = np.minimum(np.maximum(v, self.body.lower[cols]), self.body.upper[cols])
        self.writers[lo:hi, cols] = driver.uid
        self.writes += len(cols)
        self._fk_cache.clear()

    def read(self, d: int) -> np.ndarray:
        return self.values[self._lo:self._hi, d]

    def pose(self) -> np.ndarray:
        """The pose rows of the segment being ticked."""
        return self.values[self._lo:self._hi]

    def parent_frame(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """World frame of ``joint``'s parent in the segment's frames (cached until the next write)."""
        body = self.body
        i = body.joint_index[joint]
        parent = body.joints[body.parent_index[i]].name
        hit = self._fk_cache.get(parent)
        if hit is None:
            hit = body.forward_kinematics(self.values[self._lo:self._hi], [parent])[parent]
            self._fk_cache[parent] = hit
        rot, pos = hit
        return rot, pos + rot @ body.offsets[i]


# --------------------------------------------------------------------------------------------- background
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
    """The body at rest, never quite still (idle drift): stance, weight shift, arms, head and jaw.

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
                  "vl5", "vc4", "skullbase", "temporomandibular", "l_eyebrow", "r_eyebrow"]
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
        self.saccade_times = np.empty(0)
        self.saccade_offsets = np.zeros((1, 2))
        self.saccade_duration = 0.04

    def set_target(self, at: float, target) -> None:
        self.targets.append((at, np.asarray(target, dtype=float)))
        self.targets.sort(key=lambda x: x[0])

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
        starts = np.array([x[0] for x in self.targets])
        pts = np.stack([x[1] for x in self.targets])
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


# --------------------------------------------------------------------------------------------- manager
class MotorFunctionExporter:
    """Something that offers motor functions: names with default parameters, and a way to run them."""

    def list_interface(self) -> dict[str, dict[str, object]]:
        """Motor function name -> default parameters."""
        raise NotImplementedError

    def execute(self, name: str, at: float, args: dict[str, object], manager: "DriverManager") -> Driver | None:
        raise NotImplementedError


class _BackgroundFunctions(MotorFunctionExporter):
    """Motor functions of the background drivers: blink reflex on/off, a forced blink, breathing."""

    def __init__(self, blink: EyeBlinkReflex, breathing: Breathing):
        self.blink, self.breathing = blink, breathing

    def list_interface(self):
        return {"blinkreflex": {"msg": "on"}, "eyeblink": {"which": "both"},
                "breathing": {"rate": 15.0, "depth": 1.0}}

    def execute(self, name, at, args, manager):
        if name == "blinkreflex":
            self.blink.turn(str(args["msg"]).lower() != "off", at)
            return self.blink
        if name == "eyeblink":
            self.blink.force(at)
            return self.blink
        self.breathing.set_rate(at, float(args["rate"]), float(args["depth"]))
        return self.breathing


class DriverManager:
    """Holds the drivers, the Arbitrator and the motor functions, and evaluates poses (Pantomime's
    DriverManager).

    ``background=True`` adds the background drivers (:attr:`idle`, :attr:`breathing`, :attr:`eyes`,
    :attr:`blink`), each with its own Generator spawned from ``seed``. Motor functions are registered by
    exporters; the first exporter to register a name keeps it. :meth:`evaluate` runs the event sweep.
    """

    def __init__(self, body: Body | None = None, seed: int | np.random.SeedSequence = 0,
                 background: bool = True, scene: Mapping[str, Sequence[float]] | None = None):
        from agentsim.animation import motion  # motion units build on drivers

        self.body = body or Body()
        self.arbitrator = Arbitrator(self.body)
        self.scene = motion.Scene(scene)
        self.drivers: list[Driver] = []
        self.motor_functions: dict[str, tuple[MotorFunctionExporter, dict[str, object]]] = {}
        self._events: list[tuple[float, int, Callable[[float], None]]] = []
        self._event_order = itertools.count()
        self.segment_bounds = (-math.inf, math.inf)
        self._evaluated = False
        seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        self.seed_sequence = seq
        streams = seq.spawn(5)
        self.rng = np.random.default_rng(streams[4])
        self.idle = self.breathing = self.eyes = self.blink = None
        if background:
            self.idle = self.add(IdleSway(self.body, np.random.default_rng(streams[0])))
            self.breathing = self.add(Breathing(np.random.default_rng(streams[1])))
            self.eyes = self.add(EyeFixation(np.random.default_rng(streams[2]), self.scene.default_gaze))
            self.blink = self.add(EyeBlinkReflex(self.eyes, np.random.default_rng(streams[3])))
            self.add_exporter(_BackgroundFunctions(self.blink, self.breathing))
        motion.register_motor_functions(self)

    # ------------------------------------------------------------------ drivers and motor functions
    def add(self, driver: Driver) -> Driver:
        """Register a driver: it will be ticked while it holds DOFs; its setup schedules its requests."""
        self.drivers.append(driver)
        driver.attach(self)
        return driver

    def add_exporter(self, exporter: MotorFunctionExporter) -> None:
        for name, defaults in exporter.list_interface().items():
            self.motor_functions.setdefault(name, (exporter, dict(defaults)))

    def interface(self) -> dict[str, dict[str, object]]:
        """Every motor function with its default parameters."""
        return {name: dict(defaults) for name, (_, defaults) in sorted(self.motor_functions.items())}

    def execute(self, function: str, /, at: float = 0.0, **args) -> Driver | None:
        """Run motor function ``function`` at time ``at`` with ``args`` (defaults for the rest)."""
        try:
            exporter, defaults = self.motor_functions[function]
        except KeyError:
            known = ", ".join(sorted(self.motor_functions))
            raise KeyError(f"no motor function {function!r} (known: {known})") from None
        unknown = set(args) - set(defaults)
        if unknown:
            raise TypeError(f"motor function {function!r} has no parameter(s) {sorted(unknown)}; "
                            f"parameters: {defaults}")
        full = dict(defaults)
        full.update(args)
        return exporter.execute(function, float(at), full, self)

    # ------------------------------------------------------------------ events
    def at(self, t: float, action: Callable[[float], None]) -> None:
        """Call ``action(t)`` when the sweep reaches time ``t`` (before the frames at or after ``t``)."""
        heapq.heappush(self._events, (float(t), next(self._event_order), action))

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, times: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Evaluate the pose at each of ``times`` (increasing, seconds).

        Returns the pose array (frames x DOFs) and, for every value, the uid of the driver that wrote it
        (-1 where nobody held the DOF and it kept its last value).
        """
        if self._evaluated:
            raise RuntimeError("a DriverManager evaluates one run of frames; make a new one to evaluate again")
        times = np.asarray(times, dtype=float)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) <= 0):
            raise ValueError("frame times must be a non-empty 1-d increasing array")
        self._evaluated = True
        n = len(times)
        t_begin = float(times[0]) if n else 0.0
        t_end = float(times[-1]) + 1.0 if n else 1.0
        for d in self.drivers:
            d.prepare(t_begin, t_end)
        arb = self.arbitrator
        arb.begin(n)
        events = self._events
        i = 0
        t_prev = -math.inf
        while True:
            t_next = events[0][0] if events else math.inf
            j = int(np.searchsorted(times, t_next - EPSILON, side="left")) if t_next < math.inf else n
            self.segment_bounds = (t_prev, t_next)
            if j > i or t_prev > -math.inf:
                arb.tick_segment(i, j, times, self.drivers)
            i = j
            if not events or (i >= n and t_next > t_end):
                break
            while events and events[0][0] <= t_next + EPSILON:
                t, _, action = heapq.heappop(events)
                arb.now = t
                action(t)
            t_prev = t_next
        for d in self.drivers:
            finish = getattr(d, "finish", None)
            if finish is not None:
                finish()
        return arb.values, arb.writers

    def driver_names(self) -> dict[int, str]:
        return {d.uid: d.name for d in self.drivers}
