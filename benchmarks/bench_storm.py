"""Event storm: 100,000 progress events reaching an animator-time strategy at one instant.

For every strategy, a long utterance's events (words and phonemes, about 100,000) are delivered at one
clock instant, in order and shuffled (a seeded numpy Generator), and, shuffled, over 1,000 instants 1 ms
apart; ``t_A`` is looked at after each instant, as the speech engine does. Prints JSON: seconds per storm
and whether ``t_A`` stayed monotone (sampled before, after each instant, and up to 10 s later). Target:
under 5 s for every strategy, ``t_A`` monotone.

A peg storm follows: an anticipator moves all of its 120 pegs every millisecond while a block of 120
nods, each tied to one of them, plays; it prints the wall seconds per simulated second and whether the
nods' strokes passed where the pegs last were (the largest error).

Usage: python benchmarks/bench_storm.py [--events N] [--pegs N] [--seconds S]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from speech_timing.animator_time import STRATEGIES, make_strategy
from speech_timing.builtin import BuiltinBackend
from speech_timing.backend import SpeechText
from speech_timing.delivery import true_events
from speech_timing.linear_model import default_linear_model, plan_from_utterance

WORDS = ["we", "walk", "along", "the", "river", "slowly", "today", "and", "talk", "about", "nothing"]


def storm_events(n_events: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    backend = BuiltinBackend()
    text, events, utterance = "", [], None
    n_words = max(10, n_events // 5)
    while True:
        text = " ".join(rng.choice(WORDS, n_words)) + "."
        utterance = backend.synthesize(SpeechText(text))
        events = [e for e in true_events(utterance, t0=0.0) if e.kind in ("word", "phoneme", "end")]
        if len(events) >= n_events:
            break
        n_words = int(n_words * n_events / len(events)) + 10
    return backend, utterance, events[:n_events - 1] + [events[-1]]


def run_storm(name: str, backend, utterance, events, order, instant: float, instants: int = 1) -> dict:
    """Feed ``events`` in ``order``, spread over ``instants`` clock instants 1 ms apart from ``instant`` (all
    at one instant by default), looking at ``t_A`` after each instant as the speech engine does."""
    model = default_linear_model(backend) if name == "linear-model" else None
    plan = plan_from_utterance(utterance, delay=0.05, latency=0.0, t_request=0.0, linear_model=model)
    strategy = make_strategy(name)
    strategy.reset(plan, 0.0)
    seen = [strategy.position(instant)]
    start = time.perf_counter()
    for k, chunk in enumerate(np.array_split(np.asarray(order), instants)):
        now = instant + k * 0.001
        for i in chunk:
            event = events[i]
            event.arrival_time = now
            strategy.on_event(event, now)
        seen.append(strategy.position(now))
    seconds = time.perf_counter() - start
    now = instant + instants * 0.001
    seen += [strategy.position(now + d) for d in (0.0, 0.01, 0.1, 1.0, 10.0)]
    monotone = all(b >= a - 1e-12 for a, b in zip(seen, seen[1:]))
    return {"seconds": round(seconds, 3), "monotone": bool(monotone)}


class Swarm:
    """An anticipator of ``n`` pulses that moves every one still to come by 1 us each millisecond."""

    def __new__(cls, n: int):
        from anticipators import Anticipator

        class _Swarm(Anticipator):
            def make_peg(self, sync_id):
                return 0.5 + 0.02 * int(sync_id[1:]) if sync_id.startswith("p") else False

            def run(self):
                return self.move()

            def move(self):
                while True:
                    yield self.env.timeout(0.001)
                    for peg in list(self.pegs.values()):
                        if peg.time > self.env.now:
                            peg.set(peg.time + 1e-6)

        return _Swarm("swarm")


def peg_storm(n_pegs: int, seconds: float) -> dict:
    """Wall seconds per simulated second while ``n_pegs`` pegs move every millisecond under a block of nods."""
    from agentsim.realizer import Realizer

    swarm = Swarm(n_pegs)
    realizer = Realizer(anticipators=[swarm], tts=BuiltinBackend())
    ns = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
    nods = "".join(f'<head id="h{i}" lexeme="NOD" stroke="anticipators:swarm:p{i}"/>' for i in range(n_pegs))
    realizer.submit(f'<bml {ns} id="b">{nods}</bml>')
    start = time.perf_counter()
    realizer.env.run(until=seconds)
    wall = time.perf_counter() - start
    strokes = {f["id"].split(":")[1]: f["globalTime"] for f in realizer.recording().feedback
               if f["type"] == "syncPointProgress" and f["id"].endswith(":stroke")}
    errors = [abs(t - swarm.pegs[f"p{name[1:]}"].time) for name, t in strokes.items()]
    return {"pegs": n_pegs, "simulated_s": seconds, "wall_s": round(wall, 3),
            "wall_per_simulated_s": round(wall / seconds, 3), "strokes_passed": len(strokes),
            "max_stroke_error_s": max(errors) if errors else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=100_000)
    parser.add_argument("--pegs", type=int, default=120)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    backend, utterance, events = storm_events(args.events)
    instant = utterance.duration / 2  # mid-speech: the storm arrives while it plays
    rng = np.random.default_rng(1)
    results = {}
    for name in sorted(STRATEGIES):
        shuffled = rng.permutation(len(events))
        results[name] = {
            "one instant, in order": run_storm(name, backend, utterance, events, range(len(events)), instant),
            "one instant, shuffled": run_storm(name, backend, utterance, events, shuffled, instant),
            "1000 instants, shuffled": run_storm(name, backend, utterance, events, shuffled, instant, 1000),
        }
    print(json.dumps({"events": len(events), "words": len(utterance.words), "machine": platform.machine(),
                      "python": platform.python_version(), "strategies": results,
                      "peg_storm": peg_storm(args.pegs, args.seconds)}, indent=1))


if __name__ == "__main__":
    main()
