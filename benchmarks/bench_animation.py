"""Pose evaluation speed: frames per second of ``evaluate_poses`` with many motion units active.

Prints JSON. The main figure is 20 motion units active all the time (gestures on both hands, pointing,
nod, shake and tilt with repetitions, a gaze, nine face expressions, a posture, a walk) over 30
seconds at 60 frames per second; the target is at least 100 times the frame rate (6,000 frames/s for a
60 Hz character). Beside it: a minute of 240 short behaviours at random times (many arbitration events),
and the stroke error (motion minus feedback) of those whose stroke no later behaviour took over.
"""

from __future__ import annotations

import json
import platform
import statistics
import time

import numpy as np

from agentsim.animation import evaluate_poses
from agentsim.animation.analysis import measure_strokes
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
FPS = 60.0


def twenty_active(t0: float = 0.5, t1: float = 30.5) -> str:
    """A block of 20 behaviours that are all active from ``t0`` to ``t1``."""
    span = f'start="{t0}" end="{t1}"'
    parts = [
        f'<gesture id="g1" lexeme="BEAT" mode="RIGHT_HAND" {span}/>',
        f'<gesture id="g2" lexeme="OFFER" mode="LEFT_HAND" {span}/>',
        f'<gesture id="g3" lexeme="CHOP" mode="RIGHT_HAND" start="{t0 + 0.1}" end="{t1}"/>',
        f'<gesture id="g4" lexeme="CONDUCT_3_4" mode="LEFT_HAND" start="{t0 + 0.1}" end="{t1}"/>',
        f'<pointing id="p1" target="bluebox" mode="LEFT_HAND" start="{t0 + 0.2}" end="{t1}"/>',
        f'<head id="h1" lexeme="NOD" repetition="60" {span}/>',
        f'<head id="h2" lexeme="SHAKE" repetition="40" {span}/>',
        f'<head id="h3" lexeme="TILT" repetition="20" {span}/>',
        f'<gaze id="z1" target="violins" influence="HEAD" {span}/>',
        f'<posture id="s1" lexeme="LEAN_FORWARD" {span}/>',
        f'<locomotion id="w1" target="bluebox" {span}/>',
    ]
    for k, lex in enumerate(("RAISE_BROWS", "FROWN", "WIDEN_EYES", "OPEN_MOUTH", "SMILE")):
        parts.append(f'<faceLexeme id="f{k}" lexeme="{lex}" {span}/>')
    for k, au in enumerate((1, 2, 26, 5)):
        parts.append(f'<faceFacs id="u{k}" au="{au}" {span}/>')
    assert len(parts) == 20
    return f'<bml {NS} id="twenty">{"".join(parts)}</bml>'


def many_short(n: int = 240, seconds: float = 60.0, seed: int = 0) -> str:
    """``n`` short behaviours spread over ``seconds``: beats, nods, shakes, brow raises, glances."""
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n):
        t = round(float(rng.uniform(0.2, seconds - 2.0)), 3)
        kind = i % 5
        if kind == 0:
            parts.append(f'<gesture id="b{i}" lexeme="BEAT" start="{t}"/>')
        elif kind == 1:
            parts.append(f'<head id="b{i}" lexeme="NOD" start="{t}"/>')
        elif kind == 2:
            parts.append(f'<head id="b{i}" lexeme="SHAKE" start="{t}"/>')
        elif kind == 3:
            parts.append(f'<faceLexeme id="b{i}" lexeme="RAISE_BROWS" start="{t}"/>')
        else:
            parts.append(f'<gesture id="b{i}" lexeme="CONDUCT_4_4" mode="LEFT_HAND" start="{t}"/>')
    return f'<bml {NS} id="short">{"".join(parts)}</bml>'


def realize(bml: str) -> Realizer:
    r = Realizer(tts=BuiltinBackend())
    r.submit(bml)
    r.run()
    return r


def measure(r: Realizer, duration: float, repeats: int) -> dict:
    runs = []
    stream = None
    for _ in range(repeats):
        t = time.perf_counter()
        stream = evaluate_poses(r, fps=FPS, duration=duration)
        runs.append(time.perf_counter() - t)
    frames = stream.n_frames
    best, median = min(runs), statistics.median(runs)
    units = [u for u in stream.units if u["keys"]]
    starts = np.array([min(u["keys"].values()) for u in units])
    ends = np.array([max(u["keys"].values()) for u in units])
    active = ((stream.times[:, None] >= starts) & (stream.times[:, None] < ends)).sum(axis=1)
    return {
        "frames": frames, "seconds_of_motion": round(float(stream.times[-1] - stream.times[0]), 3),
        "behaviours": len(units), "active_units_mean": round(float(active.mean()), 2),
        "active_units_max": int(active.max()), "drivers": len(stream.driver_names),
        "dofs": len(stream.channels), "arbitration_events": len(stream.manager.arbitrator.history),
        "best_s": round(best, 4), "median_s": round(median, 4),
        "frames_per_s_best": round(frames / best), "frames_per_s_median": round(frames / median),
        "times_realtime_at_60hz_median": round(frames / median / FPS, 1),
    }, stream


def main() -> None:
    twenty = realize(twenty_active())
    assert not twenty.feedback.warnings(), twenty.feedback.warnings()
    result_20, _ = measure(twenty, 31.0, repeats=7)
    short = realize(many_short())
    result_short, stream = measure(short, 61.0, repeats=3)
    measured = measure_strokes(stream, short.feedback.sync_times())
    errors = np.array([m.error for m in measured if m.intact])
    result_short["stroke_error_ms"] = {
        "strokes": len(measured), "intact": int(len(errors)),
        "taken_over_by_a_later_behaviour": sum(not m.intact for m in measured),
        "max_abs_intact": round(float(np.abs(errors).max() * 1000), 3),
        "mean_abs_intact": round(float(np.abs(errors).mean() * 1000), 3), "frame_ms": round(1000 / FPS, 3)}
    print(json.dumps({
        "benchmark": "animation pose evaluation",
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "cpus": 2},
        "fps_of_character": FPS,
        "target_frames_per_s": 100 * FPS,
        "twenty_active_units": result_20,
        "many_short_units": result_short,
        "meets_target": result_20["frames_per_s_median"] >= 100 * FPS,
    }, indent=2))


if __name__ == "__main__":
    main()
