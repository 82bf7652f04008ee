"""The clock: one SimPy environment drives everything, simulated or in real time."""

from __future__ import annotations

import simpy
import simpy.rt


def make_environment(realtime: bool = False, factor: float = 1.0, initial_time: float = 0.0) -> simpy.Environment:
    """Create the environment every engine, player and anticipator runs on.

    Parameters
    ----------
    realtime : bool
        False: simulated time, as fast as possible. True: ``simpy.rt.RealtimeEnvironment``, one simulated
        second per ``factor`` wall-clock seconds. Nothing else differs between the two.
    factor : float
        Wall-clock seconds per simulated second in real-time mode.
    initial_time : float
        Simulated time at which the environment starts, in seconds.
    """
    if realtime:
        return simpy.rt.RealtimeEnvironment(initial_time=initial_time, factor=factor, strict=False)
    return simpy.Environment(initial_time=initial_time)
