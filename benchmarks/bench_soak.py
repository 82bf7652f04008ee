"""Soak: 24 simulated hours of a metronome and a block every few seconds, with memory and speed per hour.

A realizer with ``keep`` (as the live service runs) hears a metronome at 100 BPM whose tempo drifts every
minute, and gets a block every 4 s (seeded numpy Generator): beats on the next metronome beats, a nod, and
now and then a short speech whose gesture strokes on one of its words. Prints one JSON line per simulated
hour: RSS (MB), wall and CPU seconds for that hour, blocks so far, and the worst timing error (s) of the
hour (a stroke against its beat's peg when it passes, a stroke against its word's feedback); then a summary with the RSS growth per hour after
the first and the spread of wall time per hour. Targets: growth at most 1 MB per simulated hour, wall per
hour constant within 20 %, timing error at most 1 microsecond.

Usage: python benchmarks/bench_soak.py [--hours 24] [--every 4] [--keep 64]
"""

from __future__ import annotations

import argparse
import gc
import json
import resource
import time

import numpy as np

from anticipators.metronome import Metronome
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
WORDS = ["we", "walk", "along", "the", "river", "slowly", "today", "and", "talk"]


def rss_mb() -> float:
    """Resident set size now (MB), from /proc (ru_maxrss would be the peak)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
        return pages * resource.getpagesize() / 1e6
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


class Soak:
    def __init__(self, every: float, keep: int, seed: int = 0):
        self.rng = np.random.default_rng(seed)
        self.metronome = Metronome("metronome", bpm=100.0)
        self.realizer = Realizer(anticipators=[self.metronome], keep=keep, tts=BuiltinBackend())
        self.every = every
        self.blocks = 0
        self.worst = 0.0
        self.beat_of: dict[str, str] = {}  # stroke feedback id -> its beat's sync id
        self.pair: dict[str, str] = {}  # stroke <-> word feedback ids, whichever comes first waits for the other
        self.heard: dict[str, float] = {}
        self.realizer.feedback.listen(self.hear)
        env = self.realizer.env
        env.process(self.submitter())
        env.process(self.tempo())

    def hear(self, feedback: dict) -> None:
        """Compare each stroke with what it is tied to: its beat's time, or its word's feedback."""
        if feedback["type"] != "syncPointProgress":
            return
        fid, t = feedback["id"], feedback["globalTime"]
        if fid in self.beat_of:  # the beat's peg where the metronome has it now (tempo changes move it)
            self.worst = max(self.worst, abs(t - self.metronome.peg(self.beat_of.pop(fid)).time))
        elif fid in self.pair:
            other = self.pair.pop(fid)
            if other in self.heard:
                self.worst = max(self.worst, abs(t - self.heard.pop(other)))
            else:
                self.heard[fid] = t
                self.pair[other] = fid

    def tempo(self):
        env = self.realizer.env
        while True:
            yield env.timeout(60.0)
            self.metronome.set_tempo(float(self.rng.uniform(90.0, 110.0)))

    def submitter(self):
        env = self.realizer.env
        while True:
            yield env.timeout(self.every)
            self.blocks += 1
            name = f"b{self.blocks}"
            n = self.metronome.last_beat_before(env.now) + 2
            beat = f"beat{n}"
            self.beat_of[f"{name}:g:stroke"] = beat
            body = (f'<gesture id="g" lexeme="BEAT" mode="RIGHT_HAND" stroke="anticipators:metronome:{beat}"/>'
                    '<head id="h" lexeme="NOD"/>')
            if self.blocks % 5 == 0:
                words = " ".join(self.rng.choice(WORDS, 5))
                body += (f'<speech id="s"><text>{words} <sync id="m"/>{words}.</text></speech>'
                         '<gesture id="g2" lexeme="BEAT" mode="LEFT_HAND" stroke="s:m"/>')
                self.pair[f"{name}:g2:stroke"], self.pair[f"{name}:s:m"] = f"{name}:s:m", f"{name}:g2:stroke"
            self.realizer.submit(f'<bml {NS} id="{name}">{body}</bml>')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=int, default=24)
    parser.add_argument("--every", type=float, default=4.0, help="seconds between blocks (4)")
    parser.add_argument("--keep", type=int, default=64, help="ended blocks the realizer keeps (64: about 4 minutes)")
    args = parser.parse_args()
    soak = Soak(args.every, args.keep)
    rows = []
    for hour in range(1, args.hours + 1):
        soak.worst = 0.0
        start, cpu = time.perf_counter(), time.process_time()
        soak.realizer.env.run(until=hour * 3600.0)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        gc.collect()
        row = {"hour": hour, "rss_mb": round(rss_mb(), 1), "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
               "blocks": soak.blocks,
               "worst_error_s": soak.worst, "feedback_kept": len(soak.realizer.feedback.items),
               "runs_kept": len(soak.realizer.scheduler.book.all_runs),
               "metronome_pegs": len(soak.metronome.pegs)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    later = rows[1:] if len(rows) > 1 else rows
    growth = (later[-1]["rss_mb"] - later[0]["rss_mb"]) / max(1, len(later) - 1)
    walls, cpus = [r["wall_s"] for r in later], [r["cpu_s"] for r in later]
    median = float(np.median(walls))
    print(json.dumps({"summary": True, "hours": args.hours, "rss_growth_mb_per_hour_after_first": round(growth, 3),
                      "wall_per_hour_min_s": min(walls), "wall_per_hour_median_s": median,
                      "wall_per_hour_max_s": max(walls),
                      "wall_spread_from_median": [round(min(walls) / median - 1, 3), round(max(walls) / median - 1, 3)],
                      "cpu_per_hour_min_s": min(cpus), "cpu_per_hour_max_s": max(cpus),
                      "first_vs_last_4h_wall": [round(float(np.mean(walls[:4])), 3), round(float(np.mean(walls[-4:])), 3)],
                      "worst_error_s": max(r["worst_error_s"] for r in rows)}))


if __name__ == "__main__":
    main()
