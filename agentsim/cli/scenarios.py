"""``agentsim run conductor``, ``agentsim run storytelling`` and ``agentsim demo``: the scenarios' options,
handed to the scenarios' own runs."""

from __future__ import annotations

import argparse
from pathlib import Path

from agentsim.cli import options
from agentsim.cli.realize import add_physics

#: Where ``agentsim demo`` writes, one folder per scenario inside.
DEMO_OUT = "out/demo"


def add_parsers(commands) -> None:
    run = commands.add_parser("run", help="run a scenario (conductor, storytelling, trainer)",
                              description="Run a scenario end to end in simulated time and write its results: "
                                          "'run conductor', 'run storytelling', 'run trainer' (each with its own --help).")
    scenarios = run.add_subparsers(dest="scenario", required=True)
    add_conductor(scenarios)
    add_storytelling(scenarios)
    from agentsim.cli.trainer import add_trainer

    add_trainer(scenarios)
    demo = commands.add_parser(
        "demo", help="the conductor and the storyteller, end to end in simulated time",
        description="The virtual conductor leading a dragging ensemble back to tempo, then the virtual storyteller "
                    "telling the longest shipped story, each with its defaults: 'agentsim run conductor --out "
                    "DIR/conductor' and 'agentsim run storytelling --out DIR/storytelling', which write into "
                    "conductor/ and storytelling/ inside --out what their help says.")
    options.add_out(demo, DEMO_OUT, "where to write the results")
    add_physics(demo, csv=False, where=" (both scenarios; each writes physics.csv)")
    demo.set_defaults(handler=lambda args: demo_handler(commands, args))


def add_conductor(scenarios) -> argparse.ArgumentParser:
    from scenarios.conductor.names import DEFAULT_OUT, STRATEGIES

    parser = scenarios.add_parser(
        "conductor", help="the virtual orchestra conductor leads a simulated ensemble back to tempo",
        description="A virtual conductor beats time with BML conducting gestures pegged to anticipator beats, "
                    "hears a simulated ensemble (FluidSynth audio through a causal beat tracker) and re-times "
                    "its beats to lead the ensemble to the score's tempo. Writes to --out: metrics.json, tempo.png, "
                    "timeline.png (an overview) with timeline_0000-0015s.png, ... (each 15 s in detail), "
                    "ensemble.wav, conductor.bvh, beats.csv, gestures.csv, feedback.jsonl and report.html with "
                    "its folder report_files/; with --compare, compare.json and a folder of those per strategy "
                    "(follow/, target/, lead/, best/).")
    parser.add_argument("--config", metavar="FILE|NAME",
                        help="scenario configuration: a TOML file, or a shipped one by its short name "
                             "(--config waltz_3_4; see --list-configs); default: default")
    parser.add_argument("--list-configs", action="store_true",
                        help="list the shipped configurations, with what each is, and exit")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--strategy", choices=STRATEGIES,
                       help="where the strokes go: follow, target, lead or best (default: the configuration's, "
                            "best)")
    which.add_argument("--compare", action="store_true", help="run every strategy on the same seed and print a table")
    options.add_seed(parser, "the musicians' noise")
    options.add_out(parser, DEFAULT_OUT)
    knobs = parser.add_argument_group("the music (each overrides the configuration's piece or ensemble)")
    knobs.add_argument("--target-bpm", type=float, metavar="BPM", help="the score's tempo (the piece's, 120)")
    knobs.add_argument("--start-bpm", type=float, metavar="BPM",
                       help="the tempo the ensemble starts at, and drags back to (the ensemble's, 108)")
    knobs.add_argument("--meter", metavar="N/4", help="2/4, 3/4 or 4/4 (the piece's)")
    knobs.add_argument("--bars", type=int, metavar="N", help="how many bars the piece lasts (the piece's, 24)")
    options.add_fps(parser, "conductor.bvh and the timeline (the configuration's, 30)", default=None)
    parser.add_argument("--input", metavar="DEVICE", dest="device",
                        help="conduct what a live input device plays (a name or number, as 'anticipate beats "
                             "--input' takes; 'default': the system's default input) instead of the simulated "
                             "ensemble; a dead or silent input stops the run within 2 s")
    parser.add_argument("--live", action="store_true", help="--input default (also: --live --device DEVICE)")
    parser.add_argument("--device", metavar="DEVICE", dest="device", help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, metavar="S",
                        help="--input: how long to listen (default: the piece's length at its tempo)")
    parser.add_argument("--sample-rate", type=int, metavar="HZ",
                        help="--input: the sample rate to record at (default: the configuration's)")
    add_no_pictures(parser)
    add_json(parser)
    add_physics(parser, csv=False, where=PHYSICS_FILE + "; the left arm hangs while the right conducts alone")
    parser.set_defaults(handler=run_conductor, done_at_exit=True)
    return parser


def add_no_pictures(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-pictures", action="store_true",
                        help="write every file but the pictures (the PNGs): for runs whose folder nobody looks at, "
                             "as a sweep's points whose outputs are not kept")


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true",
                        help="also print the figures written (metrics.json; compare.json with --compare) as JSON on "
                             "stdout, and the table on stderr")


#: What ``--physics`` adds to a scenario's folder (said in its help).
PHYSICS_FILE = "; writes physics.csv (the centre of mass, support polygon, pelvis height, fallen: one row a frame)"


def physics(args: argparse.Namespace) -> None:
    """``args.physics_pushes``: the pushes of ``--push`` under ``--physics``, None without it (a usage error
    for a malformed push, or a push without --physics)."""
    from agentsim.cli.realize import physics_options

    pushes = physics_options(args)
    args.physics_pushes = pushes if getattr(args, "physics", False) else None


def run_conductor(args: argparse.Namespace) -> int:
    physics(args)
    if args.list_configs:
        from scenarios import first_comment
        from scenarios.conductor.config import CONFIGS_DIR, config_names

        for name in config_names():
            print(f"{name:<14} {first_comment(CONFIGS_DIR / f'{name}.toml')}".rstrip())
        return 0
    from scenarios.conductor.run import main

    return main(args)


def add_storytelling(scenarios) -> argparse.ArgumentParser:
    from scenarios.storytelling.names import ANCHORS, DEFAULT_OUT

    parser = scenarios.add_parser(
        "storytelling", help="tell a story with gestures on the stressed syllables and measure the sync",
        description="Tell an annotated story (beats, pointing, iconic gestures, nods, gaze shifts, eyebrow "
                    "raises on the stressed syllables of their words) through the realizer while the speech's "
                    "progress events arrive late, scattered and in bursts. Writes to --out: metrics.json, "
                    "narration.wav, story.TextGrid, story.bvh, story.bml (the BML the story compiles to), "
                    "gestures.csv, feedback.jsonl, timeline.png (an overview) with timeline_0000-0030s.png, ... "
                    "(each --window seconds in detail), sync_errors.png and report.html with its folder "
                    "report_files/; with --compare, compare.json and a folder of those per strategy (open-loop/, "
                    "linear-model/, chang-naive/, chang-smooth/, skip-70ms/, best/), without the timeline "
                    "pictures.")
    parser.add_argument("--story", metavar="NAME|FILE",
                        help="a shipped story's name, a .story file or a TextGrid (default: the longest shipped story)")
    parser.add_argument("--scene", metavar="NAME|FILE",
                        help="take extra pointing and gaze targets from this story's @scene lines (for a TextGrid)")
    which = parser.add_mutually_exclusive_group()
    options.add_strategy(which)
    which.add_argument("--compare", action="store_true",
                       help="tell the story with every strategy on the same seed, write each one's files into "
                            "--out/<strategy>/ (all but the timeline pictures), print a table and write "
                            "compare.json")
    options.add_seed(parser, "the playback start and event channel")
    options.add_out(parser, DEFAULT_OUT)
    parser.add_argument("--anchor", choices=ANCHORS, default="stress",
                        help="how strokes reach the stressed syllable: a phoneme-level mark (stress), the word's mark "
                             "plus the planned offset (offset), or the word onset alone (word); default stress")
    options.add_timing(parser)
    options.add_tts(parser)
    parser.add_argument("--cache", metavar="DIR", help="cache of synthesised speech (default ~/.cache/agentsim/tts)")
    parser.add_argument("--no-cache", action="store_true", help="synthesise again; write no cache")
    options.add_fps(parser, "story.bvh")
    parser.add_argument("--window", type=float, default=30.0,
                        help="seconds of each detailed timeline picture, timeline_0000-0030s.png, ... "
                             "(30); timeline.png is the overview of the whole story")
    options.add_delivery(parser)
    add_no_pictures(parser)
    parser.add_argument("--no-environment", action="store_true",
                        help="leave out the camera, light and music of the story's [emotion:...] tags (no "
                             "environment.csv, no music.wav, no music in narration.wav and the report)")
    add_json(parser)
    add_physics(parser, csv=False, where=PHYSICS_FILE)
    parser.set_defaults(handler=run_storytelling)
    return parser


def run_storytelling(args: argparse.Namespace) -> int:
    from scenarios.storytelling.run import main

    options.check_fps(args)
    physics(args)
    args.delivery = options.delivery(args)
    args.tts = options.tts_name(args.tts)
    return main(args)


def demo_handler(commands, args: argparse.Namespace) -> int:
    """Run the conductor, then the storyteller, each with its defaults, into ``--out/<scenario>``."""
    physics(args)
    extra = (["--physics"] + [f"--push={push}" for push in args.push]) if args.physics else []
    for scenario in ("conductor", "storytelling"):
        out = Path(args.out) / scenario
        parser = commands.choices["run"]
        scenario_args = parser.parse_args([scenario, "--out", str(out), *extra])
        print(f"== agentsim run {scenario} --out {out}", flush=True)
        status = scenario_args.handler(scenario_args)
        if status:
            return status
    return 0
