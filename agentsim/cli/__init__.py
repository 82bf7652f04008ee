"""The ``agentsim`` command line."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

from agentsim.core.errors import AgentsimError
from agentsim.core.feedback import to_json


class UsageError(AgentsimError):
    """The command line itself is wrong (exit status 2)."""


def _times(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated seconds, got {text!r}") from None
    if any(v < 0 or v != v for v in values):
        raise argparse.ArgumentTypeError("times must be non-negative seconds")
    return values


def _metronome(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        bpm = float(parts[0])
        start = float(parts[1]) if len(parts) > 1 else 0.0
    except (ValueError, IndexError):
        raise argparse.ArgumentTypeError(f"expected BPM[,START], got {text!r}") from None
    if not bpm > 0:
        raise argparse.ArgumentTypeError("the metronome tempo must be positive")
    return bpm, start


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="agentsim", description="A BML realizer on a discrete-event clock.")
    commands = parser.add_subparsers(dest="command", required=True)
    realize = commands.add_parser(
        "realize", help="realise BML files and print their feedback as JSON lines",
        description="Send each FILE as a BML block (at the --at times, default all at 0, in order), run until "
                    "every block has ended (or --until), and print the feedback to stdout, one JSON object "
                    "per line. Diagnostics go to stderr.")
    realize.add_argument("files", nargs="+", metavar="FILE", help="BML 1.0 files ('-' reads standard input)")
    realize.add_argument("--at", type=_times, metavar="T1,T2,...", help="submission time of each file (seconds)")
    realize.add_argument("--until", type=float, metavar="SECONDS", help="stop the run at this simulated time")
    realize.add_argument("--realtime", action="store_true", help="run in real time instead of simulated time")
    realize.add_argument("--metronome", type=_metronome, metavar="BPM[,START]",
                         help="provide a metronome anticipator (anticipators:metronome:beatN)")
    realize.add_argument("--anticipator", action="append", default=[], metavar="NAME[:ID][,KEY=VALUE...]",
                         help="provide an installed anticipator, e.g. tap:taps,taps=taps.txt or "
                              "metronome:m2,bpm=90 (repeatable; see 'agentsim anticipators list')")
    realize.add_argument("--bvh", metavar="OUT.bvh", help="write the motion as BVH (Blender imports it)")
    realize.add_argument("--poses", metavar="OUT.npz", help="write joint angles per frame (numpy .npz)")
    realize.add_argument("--fps", type=float, default=60.0, help="frame rate of --bvh/--poses (60)")
    realize.add_argument("--seed", type=int, default=0, help="seed of the background motion (blinks, sway)")
    plot = commands.add_parser("plot", help="pictures of a realisation")
    plot.add_argument("what", choices=["timeline"])
    plot.add_argument("file", metavar="FILE", help="a BML file")
    plot.add_argument("--out", metavar="OUT.png", required=True)
    plot.add_argument("--metronome", type=_metronome, metavar="BPM[,START]")
    anticipators = commands.add_parser("anticipators", help="installed anticipators")
    anticipators.add_argument("action", choices=["list"])
    from agentsim.cli import beats as anticipate
    from agentsim.cli import speech as speech

    anticipate.add_parser(commands)
    speech.add_parsers(commands)
    demo = commands.add_parser("demo", help="the conductor and the storyteller, end to end in simulated time")
    demo.add_argument("--out", default="out/demo", help="where to write the results (out/demo)")
    run = commands.add_parser("run", help="run a scenario (conductor, storytelling)")
    scenarios = run.add_subparsers(dest="scenario", required=True)
    for module in ("agentsim.scenarios.conductor.run", "agentsim.scenarios.storytelling.run"):
        try:
            importlib.import_module(module).add_parser(scenarios)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
    return parser


def _read(path: str) -> str | bytes:
    if path == "-":
        return sys.stdin.buffer.read()
    p = Path(path)
    if not p.is_file():
        raise UsageError(f"no such file: {path}")
    return p.read_bytes()


def realize(args: argparse.Namespace) -> int:
    from agentsim.realizer import Realizer

    documents = [(path, _read(path)) for path in args.files]
    at = args.at if args.at is not None else [0.0] * len(documents)
    if len(at) != len(documents):
        raise UsageError(f"--at gives {len(at)} times for {len(documents)} files")
    if args.until is not None and not args.until >= 0:
        raise UsageError("--until must be a non-negative number of seconds")
    if not args.fps > 0:
        raise UsageError("--fps must be positive")
    realizer = Realizer(realtime=args.realtime)
    if args.metronome:
        from agentsim.anticipators.metronome import Metronome
        bpm, start = args.metronome
        realizer.add_anticipator(Metronome("metronome", bpm=bpm, start=start))
    from agentsim.anticipators import registry
    for spec in args.anticipator:
        name, anticipator_id, params = registry.parse_spec(spec)
        realizer.add_anticipator(registry.create(name, anticipator_id, **params))
    out = sys.stdout

    def emit(feedback):
        out.write(to_json(feedback) + "\n")
        out.flush()

    realizer.feedback.listen(emit)
    order = sorted(range(len(documents)), key=lambda i: (at[i], i))
    for i in order:
        realizer.submit_at(at[i], documents[i][1], source=documents[i][0])
    realizer.run(until=args.until)
    if args.bvh or args.poses:
        from agentsim.animation import evaluate_poses, write_bvh, write_npz

        stream = evaluate_poses(realizer, fps=args.fps, seed=args.seed)
        if args.bvh:
            write_bvh(args.bvh, stream)
        if args.poses:
            write_npz(args.poses, stream)
    return 0


def plot_timeline(args: argparse.Namespace) -> int:
    from agentsim.animation import evaluate_poses, plot_timeline as draw
    from agentsim.realizer import Realizer

    realizer = Realizer()
    if args.metronome:
        from agentsim.anticipators.metronome import Metronome

        bpm, start = args.metronome
        realizer.add_anticipator(Metronome("metronome", bpm=bpm, start=start))
    realizer.submit(_read(args.file), source=args.file)
    realizer.run()
    draw(realizer, args.out, stream=evaluate_poses(realizer), title=Path(args.file).name)
    return 0


def list_anticipators() -> int:
    from agentsim.anticipators import registry

    for name, target in sorted(registry.available().items()):
        print(f"{name}\t{target}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "realize":
            return realize(args)
        if args.command == "run":
            return args.handler(args)
        if args.command == "demo":
            for scenario in ("conductor", "storytelling"):
                scenario_args = parser.parse_args(["run", scenario, "--out", str(Path(args.out) / scenario)])
                print(f"== agentsim run {scenario} --out {Path(args.out) / scenario}", flush=True)
                status = scenario_args.handler(scenario_args)
                if status:
                    return status
            return 0
        if args.command == "plot":
            return plot_timeline(args)
        if args.command == "anticipators":
            return list_anticipators()
        if args.command == "anticipate":
            from agentsim.cli import beats as anticipate

            return anticipate.beats(args)
        if args.command in ("eval", "speech"):
            from agentsim.cli import speech as speech

            handler = {"speech-sync": speech.speech_sync, "calibrate": speech.calibrate, "export": speech.export}
            return handler[getattr(args, "kind", None) or args.tool](args)
    except UsageError as exc:
        print(f"agentsim: {exc}", file=sys.stderr)
        return 2
    except AgentsimError as exc:
        print(f"agentsim: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # a bug: one line for the user, the traceback on request
        if os.environ.get("AGENTSIM_DEBUG"):
            raise
        print(f"agentsim: internal error: {type(exc).__name__}: {exc} (set AGENTSIM_DEBUG=1 for the traceback; "
              "please report it)", file=sys.stderr)
        return 70
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
