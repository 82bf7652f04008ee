"""The Driver Manager (Pantomime): a body's drivers, Arbitrator and motor functions, and the sweep that evaluates poses.

The manager runs the event sweep that evaluates a pose array for a list of frame times, and exposes
*motor functions* by name with default parameters (``manager.execute("nod", at=2.0, amt=0.5)``): those
of the background drivers and of the motion units (:mod:`agentsim.animation.functions`).
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Callable, Mapping, Sequence

import numpy as np

from agentsim.animation.arbitrator import Arbitrator
from agentsim.animation.background import Breathing, EyeBlinkReflex, EyeFixation, IdleSway
from agentsim.animation.body import Body
from agentsim.animation.drivers import EPSILON, Driver
from agentsim.animation.functions import BackgroundFunctions, MotionFunctions, MotorFunctionExporter
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.scene import Scene


class DriverManager:
    """Holds the drivers, the Arbitrator and the motor functions, and evaluates poses (Pantomime's
    DriverManager).

    ``background=True`` adds the background drivers (:attr:`idle`, :attr:`breathing`, :attr:`eyes`,
    :attr:`blink`), each with its own Generator spawned from ``seed``. Motor functions are registered by
    exporters; the first exporter to register a name keeps it. :meth:`evaluate` runs the event sweep.
    ``lexicon``: what the lexemes of its behaviours and motor functions play (default: the built-in
    :class:`~agentsim.animation.lexicon.Lexicon`).
    """

    def __init__(self, body: Body | None = None, seed: int | np.random.SeedSequence = 0,
                 background: bool = True, scene: Mapping[str, Sequence[float]] | None = None,
                 lexicon: Lexicon | None = None):
        self.body = body or Body()
        self.lexicon = lexicon if lexicon is not None else Lexicon.builtin()
        self.arbitrator = Arbitrator(self.body)
        self.scene = Scene(scene)
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
            self.add_exporter(BackgroundFunctions(self.blink, self.breathing))
        self.add_exporter(MotionFunctions())

    # ------------------------------------------------------------------ drivers and motor functions
    def add(self, driver: Driver) -> Driver:
        """Register a driver: it will be ticked while it holds DOFs; its setup schedules its requests. It is
        numbered (:attr:`~agentsim.animation.drivers.Driver.uid`) in the order drivers join."""
        driver.uid = len(self.drivers)
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
    def evaluate(self, times: Sequence[float], sink: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
                 window: int = 16384) -> tuple[np.ndarray, np.ndarray] | None:
        """Evaluate the pose at each of ``times`` (increasing, seconds).

        Returns the pose array (frames x DOFs) and, for every value, the uid of the driver that wrote it
        (-1 where nobody held the DOF and it kept its last value). With ``sink``, the frames are handed to
        ``sink(first, values, writers)`` in order, about ``window`` frames at a time (the arrays are reused
        afterwards: copy or write them out), none are held and None is returned; a segment longer than
        ``window`` (the frames between two events) is then ticked ``window`` frames at a time.
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
        arb.begin(n, sink, window)
        events = self._events
        i = 0
        t_prev = -math.inf
        while True:
            t_next = events[0][0] if events else math.inf
            j = int(np.searchsorted(times, t_next - EPSILON, side="left")) if t_next < math.inf else n
            self.segment_bounds = (t_prev, t_next)
            if j > i or t_prev > -math.inf:
                # with a sink, a long segment (a long speech, an empty stretch before a late behaviour) is
                # ticked a window at a time: the drivers write functions of time, so the frames are the same
                step = window if sink is not None and window > 0 else max(j - i, 1)
                for a in range(i, j, step) if j > i else (i,):
                    arb.tick_segment(a, min(a + step, j), times, self.drivers)
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
        if sink is not None:
            arb.flush()
            return None
        return arb.values, arb.writers

    def driver_names(self) -> dict[int, str]:
        return {d.uid: d.name for d in self.drivers}
