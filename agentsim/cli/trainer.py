"""``agentsim run trainer``: the reactive virtual trainer's options, handed to the scenario's run."""

from __future__ import annotations

import argparse

from agentsim.cli import options


def add_trainer(scenarios) -> argparse.ArgumentParser:
    from scenarios.trainer.names import DEFAULT_OUT, EXERCISES, STRATEGIES

    parser = scenarios.add_parser(
        "trainer", help="the reactive virtual trainer exercises with a person at the person's tempo",
        description="A virtual trainer does an exercise with a person whose phone's motion sensor it hears "
                    "through the repetition anticipator: its key points pegged to the predicted ones (follow), "
                    "leading the person towards --target-tempo (lead) or at that tempo regardless (fixed), counting "
                    "so that each number's stressed syllable falls on the person's key point, with remarks between "
                    "repetitions. The person is simulated (seeded) or a recording (--user FILE.csv). Writes to "
                    "--out: metrics.json, trainer.bvh, narration.wav, motion.csv, repetitions.csv, signal.png, "
                    "gestures.csv, feedback.jsonl and report.html with its folder; with --strategy all, a folder "
                    "of those per strategy and compare.json.")
    parser.add_argument("--exercise", choices=EXERCISES, default="squat", help="the exercise (squat)")
    parser.add_argument("--user", default="simulated", metavar="simulated|FILE.csv",
                        help="the simulated user (default), or a recording of a person's phone (CSV: time and "
                             "ax,ay,az or x,y,z) played instead")
    parser.add_argument("--target-tempo", type=float, metavar="N",
                        help="repetitions a minute that lead and fixed aim at (squat 25, jumping-jack 50, "
                             "arm-raise 20)")
    parser.add_argument("--strategy", choices=[*STRATEGIES, "all"], default="follow",
                        help="follow the user (default), lead them to the target tempo, keep the target tempo "
                             "(fixed), or all three on the same seed with a table")
    options.add_seed(parser, "the simulated user")
    options.add_out(parser, DEFAULT_OUT)
    parser.add_argument("--physics", action="store_true",
                        help="play the trainer's motion through a physical body (mixed dynamics: balance under the "
                             "animation); writes physics.csv and adds physics to metrics.json")
    parser.add_argument("--no-pictures", action="store_true", help="write every file but signal.png")
    parser.add_argument("--json", action="store_true",
                        help="also print metrics.json (compare.json with --strategy all) on stdout, the table on "
                             "stderr")
    parser.set_defaults(handler=run_trainer)
    return parser


def run_trainer(args: argparse.Namespace) -> int:
    from scenarios.trainer.run import main

    return main(args)
