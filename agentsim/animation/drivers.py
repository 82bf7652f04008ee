"""Drivers, one motor skill each, with their priorities: the Driver base and the SlaveDriver (Pantomime).

A :class:`Driver` *requests* a set of DOFs at a priority and, on every tick, writes values for the DOFs
it holds; the :class:`~agentsim.animation.arbitrator.Arbitrator` decides who holds what. Drivers are
ticked over *segments*: runs of frames between two arbitration events (a request, a release). Inside a
segment nobody gains or loses anything, so a driver computes all its frames at once with numpy. Within
a segment drivers are ticked by *stage* (torso, then neck and arms, then eyes, then eyelids; see
:class:`~agentsim.animation.body.Joint`), so a driver may read the pose of the joints above the ones it
drives: arms reach in the torso's frame, eyes fixate from the head, eyelids follow the eyes.

A driver learns its :class:`~agentsim.animation.manager.DriverManager` and Arbitrator when it joins a
manager (:meth:`Driver.attach`).
"""

from __future__ import annotations

from typing import Iterable, Mapping, Sequence

import numpy as np

from agentsim.animation.body import Body, wrap180
from agentsim.animation.time_source import CLOCK, TimeSource

#: Two times closer than this (seconds) are the same time.
EPSILON = 1e-9

#: Priorities of the kinds of drivers (higher wins a DOF).
PRIORITY = {
    "idle": 0,         # stance, sway, arms and head at rest
    "reflex": 1,       # breathing, eye fixation and blinks
    "shift": 10,       # gazeShift, headDirectionShift, postureShift, faceShift, locomotion
    "speech": 15,      # the jaw while speaking
    "behaviour": 20,   # gesture, pointing, gaze, face, posture
    "lips": 22,        # visemes and keyframed face curves: the mouth speaks over the speech jaw and expressions
    "head": 25,        # nod, shake, tilt: they ride on top of a gaze or a head turn
    "command": 30,     # motor functions invoked directly (hand shapes, eyelids, key frames)
}


def smoothstep(s):
    """The default blending curve: 3s^2 - 2s^3 on [0, 1] (zero velocity at both ends), clipped."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)



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
        #: its number in its manager, in the order drivers joined it (-1 until it joins one): the pose's
        #: writers are these numbers, and ties between drivers are broken by them
        self.uid = -1
        self.body: Body | None = None
        #: the DriverManager and its Arbitrator, known once the driver joins a manager (:meth:`attach`)
        self.manager = None
        self.arbitrator = None
        self.owned: set[int] = set()
        self.ever_owned: set[int] = set()
        self.master: Driver | None = None
        self.slaves: list[Driver] = []
        self.stopped = False
        #: blends under way: DOF column -> (start time, duration, value blended from)
        self.blends: dict[int, tuple[float, float, float]] = {}
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
    def attach(self, manager) -> None:
        """Join ``manager``, a DriverManager (called by its ``add``); then :meth:`setup` schedules requests."""
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
                self.blends[d] = (t, duration, float(v))
            else:
                self.blends.pop(d, None)

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
        b = self.blends.get(dof)
        if b is None:
            return values
        t0, duration, start = b
        times = self._times
        if len(times) and times[0] >= t0 + duration:
            del self.blends[dof]
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
