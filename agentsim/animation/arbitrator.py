"""The Arbitrator: one writer per degree of freedom and frame, granted by priority (Pantomime).

The Arbitrator grants each DOF to the highest-priority driver that wants it (ties: the latest request);
a driver that loses a DOF is told (``on_dof_loss``) and keeps its claim, so it gets the DOF back
(``on_dof_regain``) when the usurper releases it. Every write goes through the Arbitrator, which asserts
that the writer holds the DOF and that no DOF is written twice in a frame.
"""

from __future__ import annotations

import itertools
import math
from typing import Callable, Iterable, Sequence

import numpy as np

from agentsim.animation.body import Body
from agentsim.animation.drivers import Driver


class ArbitrationError(AssertionError):
    """A driver wrote a DOF it does not hold, or a DOF got two writers in one frame."""


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
        self.base = 0
        self._sink = None
        self._window = self._n_frames = 0
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
    def begin(self, n_frames: int, sink: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
              window: int = 16384) -> None:
        """Make room for ``n_frames`` frames. With ``sink``, only a window of them is held: the frames before
        a segment are final once it begins (drivers write and read the frames of their segment only), so when
        ``window`` frames or more are final they go to ``sink(first, values, writers)`` and are dropped;
        :meth:`flush` hands over the rest. :attr:`values` and :attr:`writers` then hold frames from
        :attr:`base` on."""
        n = self.body.n_dofs
        self._sink = sink
        self._window = int(window)
        self._n_frames = int(n_frames)
        self.base = 0
        rows = n_frames if sink is None else min(n_frames, 2 * self._window)
        self.values = np.empty((rows, n))
        self.writers = np.full((rows, n), -1, dtype=np.int32)

    def _make_room(self, lo: int, hi: int) -> None:
        """Hand the final frames before ``lo`` to the sink (when a window of them is ready) and make the
        buffer reach frame ``hi``."""
        if self._sink is None:
            return
        if lo - self.base >= self._window:
            self._hand_over(lo - self.base)
        need = hi - self.base
        if need > len(self.values):
            n = self.body.n_dofs
            rows = max(need, 2 * len(self.values))
            values = np.empty((rows, n))
            writers = np.full((rows, n), -1, dtype=np.int32)
            kept = lo - self.base
            values[:kept] = self.values[:kept]
            writers[:kept] = self.writers[:kept]
            self.values, self.writers = values, writers

    def _hand_over(self, rows: int) -> None:
        self._sink(self.base, self.values[:rows], self.writers[:rows])
        self.base += rows
        self.writers[:rows] = -1  # the buffer is reused: its rows are the next frames

    def flush(self) -> None:
        """With a sink: hand it the frames not yet handed over (at the end of the sweep)."""
        if self._sink is not None and self._n_frames > self.base:
            self._hand_over(self._n_frames - self.base)

    def tick_segment(self, lo: int, hi: int, times: np.ndarray, drivers: Iterable[Driver]) -> None:
        """Tick every driver holding DOFs over frames ``lo:hi`` (one segment), stage by stage."""
        seg = times[lo:hi]
        self._make_room(lo, hi)
        lo, hi = lo - self.base, hi - self.base  # rows of the buffer from here on
        self._lo, self._hi = lo, hi
        self._segment += 1
        self.values[lo:hi] = self.current
        self._fk_cache = {}
        owners = [d for d in {o for o in self.owner if o is not None} if hi > lo or d.wants_intervals]
        stage = self.body.stage
        owners.sort(key=lambda d: (min(stage[i] for i in d.owned), d.uid))
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
        if driver.blends:
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
        if driver.blends:
            for k, d in enumerate(cols):
                if int(d) in driver.blends:
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
