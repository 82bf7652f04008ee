"""``agentsim anticipate reps``: run the repetition anticipator over a motion recording."""

from __future__ import annotations

import argparse
import json

from agentsim.errors import UsageError


def add_parser(kinds) -> None:
    reps = kinds.add_parser(
        "reps", help="find and predict a person's repetitions in a motion recording",
        description="Follow a motion recording (CSV with a header: time in seconds and ax,ay,az or x,y,z, "
                    "acceleration with gravity as a phone reports it; or one coordinate, a height, named with "
                    "--column) causally, sample rate 10-200 Hz, and print the repetitions' key points (the "
                    "lowest point of each), the predictions committed at least --lookahead seconds before, and "
                    "the tempo.")
    reps.add_argument("recording", metavar="FILE.csv", help="the motion recording")
    reps.add_argument("--lookahead", type=float, default=0.2,
                      help="how long before a key point a prediction is committed, seconds (0.2)")
    reps.add_argument("--column", metavar="NAME", help="follow this one column (a coordinate) instead of three axes")
    reps.add_argument("--json", action="store_true",
                      help='print {"repetitions", "committed", "tempo_per_minute", "count"} as JSON')
    reps.set_defaults(handler=count_reps)


def count_reps(args: argparse.Namespace) -> int:
    from anticipators.reps import read_motion, track

    if not args.lookahead >= 0:
        raise UsageError("--lookahead must be at least 0 seconds")
    times, samples = read_motion(args.recording, args.column)
    found = track(times, samples, args.lookahead)
    if args.json:
        print(json.dumps({key: found[key] for key in ("repetitions", "committed", "tempo_per_minute", "count")}))
        return 0
    tempo = "-" if found["tempo_per_minute"] is None else f"{found['tempo_per_minute']:.1f} a minute"
    print(f"{found['count']} repetitions, tempo {tempo}")
    print("key points (s): " + " ".join(f"{t:.2f}" for t in found["repetitions"]))
    print(f"committed {args.lookahead:g} s ahead: " + " ".join(f"{t:.2f}" for t in found["committed"]))
    return 0
