"""The storyteller's cost against the length of the story: the bundled story told whole, 1, 4 and 16 times
over (its text concatenated), with its speech synthesised anew (an empty cache) and from the cache.

Each run is a process of its own (so that its peak memory is its own): it reads the story, synthesises
or loads the speech, compiles the BML, realizes it, and writes every output but the plots (poses, BVH,
the motion check, the WAV, the TextGrid and the run report). Prints JSON: per run the wall seconds of
every stage, the whole, the fraction of the story's duration it took and the peak RSS; then the growth
exponent of each (time ~ N^k, fitted over 1x, 4x, 16x) and the targets: every exponent at most 1.05, the
16x run at most 1 % of the story's duration, memory under 1 GB at 16x.

Then the default story's whole run as a user runs it (``agentsim run storytelling --out DIR``: the process
from launch to exit, imports, the pictures and every other output included, the speech cache warm;
minimum of ``--whole-runs``) against the story's duration (target: at most 3 %), and its simulation alone
(``stages_seconds.simulation`` of its ``metrics.json``; target: at most 0.6 %). Every target is listed under
``targets`` with its value and whether it ``holds``.

``python benchmarks/bench_story_scaling.py [--sizes 1,4,16] [--tts espeak|builtin] [--whole-runs 2]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import child_env, whole_command

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

EXPONENT_TARGET = 1.05
FRACTION_TARGET = 0.01
MEMORY_TARGET_MB = 1024.0
WHOLE_TARGET = 0.03
SIMULATION_TARGET = 0.006


def story_source(times: int) -> str:
    """The bundled story's file with its text (everything but comments and directives) ``times`` over."""
    from scenarios.storytelling.run import resolve_story

    lines = resolve_story(None).read_text(encoding="utf-8").splitlines()
    head = [line for line in lines if line.startswith(("#", "@"))]
    body = "\n".join(line for line in lines if not line.startswith(("#", "@")))
    return "\n".join(head) + "\n" + "\n\n".join([body] * times) + "\n"




def child(times: int, cache_dir: str, out: str, tts: str) -> dict:
    """One run, in this process."""
    started = time.perf_counter()
    from scenarios.storytelling.markup import parse_story
    from scenarios.storytelling.run import write_outputs
    from scenarios.storytelling.telling import make_voice, tell
    from speech_timing.backend import SpeechText

    stages: dict[str, float] = {"imports": time.perf_counter() - started}
    t = time.perf_counter()
    story = parse_story(story_source(times), name=f"{times}x")
    stages["read story"] = time.perf_counter() - t
    voice = make_voice(tts, cache_dir=cache_dir)
    cache = voice.backend
    t = time.perf_counter()
    voice.synthesize(SpeechText(story.text))  # synthesised (or loaded) here, not inside tell()
    stages["synthesis" if cache.misses else "cache load"] = time.perf_counter() - t
    telling = tell(story, voice=voice)
    stages["simulation"] = telling.wall_seconds
    stages.update(write_outputs(telling, Path(out), plots=False))
    whole = time.perf_counter() - started
    duration = float(telling.utterance.duration)
    return {"times": times, "cached": not cache.misses, "words": len(story.words), "gestures": len(story.gestures),
            "duration_s": round(duration, 1), "wall_s": round(whole, 2),
            "fraction_of_story": round(whole / duration, 5),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
            "stages_s": {k: round(v, 3) for k, v in stages.items()},
            "p95_ms": round(float(telling.metrics()["sync_error_ms"]["p95"]), 3)}


def run_child(times: int, cache_dir: str, tts: str) -> dict:
    with tempfile.TemporaryDirectory() as out:
        env = child_env()
        done = subprocess.run([sys.executable, __file__, "--child", str(times), "--cache", cache_dir, "--out", out,
                               "--tts", tts], env=env, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def exponent(sizes: list[int], values: list[float]) -> float | None:
    if len(sizes) < 2 or min(values) <= 0:
        return None
    return round(float(np.polyfit(np.log(sizes), np.log(values), 1)[0]), 3)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="1,4,16")
    parser.add_argument("--tts", default="espeak")
    parser.add_argument("--child", type=int)
    parser.add_argument("--cache")
    parser.add_argument("--out")
    parser.add_argument("--whole-runs", type=int, default=2)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.cache, args.out, args.tts)))
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    load = [os.getloadavg()[0]]
    runs = {"uncached": [], "cached": []}
    with tempfile.TemporaryDirectory() as cache_dir:
        for times in sizes:
            runs["uncached"].append(run_child(times, cache_dir, args.tts))  # an empty cache for this text
            runs["cached"].append(run_child(times, cache_dir, args.tts))    # the same text, from the cache
            load.append(os.getloadavg()[0])
    growth = {}
    for kind, rows in runs.items():
        names = [n for n in rows[0]["stages_s"] if all(n in r["stages_s"] for r in rows)]
        growth[kind] = {"whole": exponent(sizes, [r["wall_s"] for r in rows]),
                        "peak_rss": exponent(sizes, [r["peak_rss_mb"] for r in rows]),
                        "stages": {n: exponent(sizes, [r["stages_s"][n] for r in rows]) for n in names
                                   if n != "imports" and min(r["stages_s"][n] for r in rows) >= 0.02}}
    whole = whole_command(["run", "storytelling", "--tts", args.tts], runs=args.whole_runs)
    load.append(os.getloadavg()[0])
    duration = whole[0]["metrics"]["duration_s"]
    whole_fraction = min(r["wall_s"] for r in whole) / duration
    simulation_fraction = min(r["metrics"]["stages_seconds"]["simulation"] for r in whole) / duration
    largest = {kind: rows[-1] for kind, rows in runs.items()}
    exponents = [v for g in growth.values() for v in [g["whole"], *g["stages"].values()] if v is not None]
    print(json.dumps({
        "benchmark": "story_scaling",
        "machine": f"{platform.processor() or platform.machine()}, python {platform.python_version()}",
        "load_average_1min": [round(x, 2) for x in load],
        "tts": args.tts,
        "runs": runs,
        "growth_exponent": growth,
        "whole_run": {"command": f"agentsim run storytelling --tts {args.tts} --out DIR", "duration_s": duration,
                      "wall_s": [round(r["wall_s"], 2) for r in whole],
                      "simulation_s": [round(r["metrics"]["stages_seconds"]["simulation"], 3) for r in whole],
                      "stages_s_of_best": {k: round(v, 3) for k, v in min(whole, key=lambda r: r["wall_s"])[
                          "metrics"]["stages_seconds"].items()},
                      "files": whole[0]["files"]},
        "targets": {"exponent_at_most": EXPONENT_TARGET, "fraction_of_story_at_most": FRACTION_TARGET,
                    "peak_rss_mb_under": MEMORY_TARGET_MB},
        "meets_targets": {
            "exponents": bool(exponents) and max(exponents) <= EXPONENT_TARGET,
            "fraction_of_story": largest["cached"]["fraction_of_story"] <= FRACTION_TARGET,
            "memory": max(r["peak_rss_mb"] for r in largest.values()) < MEMORY_TARGET_MB,
        },
        "targets_held": [
            {"target": "whole run, all outputs, default story (fraction of the story)", "at_most": WHOLE_TARGET,
             "value": round(whole_fraction, 5), "holds": whole_fraction <= WHOLE_TARGET},
            {"target": "simulation alone (fraction of the story)", "at_most": SIMULATION_TARGET,
             "value": round(simulation_fraction, 5), "holds": simulation_fraction <= SIMULATION_TARGET},
            {"target": "growth exponents without plots", "at_most": EXPONENT_TARGET,
             "value": max(exponents) if exponents else None,
             "holds": bool(exponents) and max(exponents) <= EXPONENT_TARGET},
            {"target": f"{sizes[-1]}x story without plots, cached (fraction of the story)", "at_most": FRACTION_TARGET,
             "value": largest["cached"]["fraction_of_story"],
             "holds": largest["cached"]["fraction_of_story"] <= FRACTION_TARGET},
            {"target": f"peak RSS of the {sizes[-1]}x story (MB)", "under": MEMORY_TARGET_MB,
             "value": max(r["peak_rss_mb"] for r in largest.values()),
             "holds": max(r["peak_rss_mb"] for r in largest.values()) < MEMORY_TARGET_MB},
        ],
    }, indent=2))


if __name__ == "__main__":
    main()
