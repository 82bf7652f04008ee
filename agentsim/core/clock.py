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


def run_until(env: simpy.Environment, until: simpy.Event, on_time=None, every: float = 1.0):
    """``env.run(until=until)``, calling ``on_time(env.now)`` whenever another ``every`` simulated seconds
    have passed (for a progress bar). The events are processed one by one in the same order as
    ``env.run`` processes them, and nothing is scheduled, so the run is the same with or without it.
    Returns the value of ``until``; raises ``RuntimeError`` as ``env.run`` does when no events are left
    before ``until`` has happened."""
    if on_time is None:
        return env.run(until=until)
    from simpy.core import EmptySchedule, StopSimulation

    if until.callbacks is None:  # it has happened already
        return until.value
    until.callbacks.append(StopSimulation.callback)
    step, due = env.step, env.now + every
    try:
        while True:
            step()
            if env.now >= due:
                on_time(env.now)
                due = env.now + every
    except StopSimulation as exc:
        return exc.args[0]
    except EmptySchedule:
        raise RuntimeError(f'No scheduled events left but "until" event was not triggered: {until}') from None
