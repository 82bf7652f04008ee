"""``agentsim realize``, ``agentsim plot timeline`` and ``agentsim anticipators list``: BML files in,
feedback, motion and pictures out."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agentsim.cli import options
from agentsim.errors import AgentsimError, UsageError


def _times(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated seconds, got {text!r}") from None
    if any(v < 0 or v != v for v in values):
        raise argparse.ArgumentTypeError("times must be non-negative seconds")
    return values


def add_parsers(commands) -> None:
    realize = commands.add_parser(
        "realize", help="realize BML files and print their feedback as JSON lines",
        description="Send each FILE as a BML block (at the --at times, default all at 0, in order), run until "
                    "every block has ended (or --until), and print the feedback to stdout, one JSON object "
                    "per line. Diagnostics go to stderr.")
    realize.add_argument("files", nargs="+", metavar="FILE",
                         help="BML files ('-' reads standard input): BML 1.0, or BML written for Greta, SmartBody, "
                              "the Virtual Human Toolkit, EMBR or the BML drafts, or EML (de Melo's Expression "
                              "Markup Language) (each adaptation is reported)")
    realize.add_argument("--strict", action="store_true",
                         help="read pure BML 1.0 only (one block a file; no adaptation of other dialects)")
    realize.add_argument("--at", type=_times, metavar="T1,T2,...", help="submission time of each file (seconds)")
    realize.add_argument("--until", type=float, metavar="SECONDS", help="stop the run at this simulated time")
    realize.add_argument("--realtime", action="store_true", help="run in real time instead of simulated time")
    options.add_anticipators(realize)
    options.add_tts(realize)
    realize.add_argument("--no-cache", action="store_true",
                         help="synthesise every speech again and write no cache (by default espeak-ng's, Festival's "
                              "and Piper's speech is kept in the storyteller's speech cache, ~/.cache/agentsim/tts "
                              "or $AGENTSIM_CACHE, and a speech asked for again is read from it exactly as it was "
                              "said)")
    add_outputs(realize)
    options.add_fps(realize, "--bvh/--poses/--report")
    options.add_seed(realize, "the background motion (blinks, sway)")
    options.add_lexicon(realize)
    add_physics(realize)
    realize.set_defaults(handler=realize_files, done_at_exit=True)

    plot = commands.add_parser(
        "plot", help="pictures of a realization",
        description="Realize FILE and draw its timeline: behaviours, phases, pegs, feedback, the words heard "
                    "and the poses. --from/--to draw only that window of the run; without them a run longer "
                    "than 60 s is drawn as an overview in OUT.png plus one picture per 30 s next to it "
                    "(OUT_0000-0030s.png, ...).")
    plot.add_argument("what", choices=["timeline"], help="what to draw: timeline")
    plot.add_argument("file", metavar="FILE", help="a BML file")
    options.add_out(plot, None, "the picture to write", metavar="OUT.png")
    plot.add_argument("--from", dest="start", metavar="SECONDS",
                      help="draw the run from this time on (seconds of the run; default its start)")
    plot.add_argument("--to", dest="end", metavar="SECONDS",
                      help="draw the run up to this time (seconds of the run; default its end)")
    options.add_anticipators(plot)
    options.add_tts(plot)
    options.add_lexicon(plot)
    plot.set_defaults(handler=plot_timeline)

    lexicon = commands.add_parser("lexicon", help="the lexicon: what gesture, face and posture lexemes, FACS "
                                                  "units and visemes play",
                                  description="The lexicon's entries (built in, and those of --lexicon files): "
                                              "gestures (strokes and MURML forms), the conducting patterns, face "
                                              "lexemes, FACS units, postures, visemes and face channels, each with "
                                              "its name, kind and the file it comes from (as 'lexicon list' "
                                              "says them).")
    options.add_lexicon(lexicon)
    lexicon.set_defaults(handler=list_lexicon)
    lexicon_actions = lexicon.add_subparsers(dest="action")
    lexicon_list = lexicon_actions.add_parser("list", help="every entry, its kind and source",
                                              description="One line an entry: name, kind, source.")
    options.add_lexicon(lexicon_list, nested=True)
    lexicon_list.set_defaults(handler=list_lexicon)

    anticipators = commands.add_parser("anticipators", help="installed anticipators, and a new plugin",
                                       description="The anticipators BML can peg behaviours to "
                                                   "(anticipators:ID:SYNC), built in and installed as plugins.")
    actions = anticipators.add_subparsers(dest="action", required=True)
    listing = actions.add_parser("list", help="the installed anticipators with their parameters",
                                 description="Each installed anticipator: its name, its class, and the "
                                             "parameters --anticipator NAME:ID,KEY=VALUE takes (type = default).")
    listing.set_defaults(handler=list_anticipators)
    new = actions.add_parser("new", help="write a complete, installable anticipator plugin",
                             description="Write the folder agentsim-NAME: a pyproject.toml registering the "
                                         "anticipator, its module, a test and a README. 'pip install -e "
                                         "agentsim-NAME' and 'agentsim anticipators list' shows it.")
    new.add_argument("name", help="the anticipator's name (lower case letters, digits, underscores)")
    new.add_argument("--dir", default=".", help="where to write the folder (default: here)")
    new.set_defaults(handler=new_anticipator)

    examples = commands.add_parser("examples", help="the example documents and programs the documentation uses",
                                   description="List the installed examples (a command given examples/NAME "
                                               "that is not where it runs reads the installed one), or copy "
                                               "them into DIR/examples.")
    examples.add_argument("action", nargs="?", choices=["list", "copy"], default="list",
                          help="list them with what each is (the default), or copy them into DIR/examples/")
    examples.add_argument("dir", nargs="?", default=".", help="where 'copy' puts the examples folder (here)")
    examples.set_defaults(handler=examples_command)


def add_outputs(parser: argparse.ArgumentParser) -> None:
    """The files a run can write, all on its time axis (simulated time 0 = WAV sample 0 = frame 0)."""
    parser.add_argument("--wav", metavar="OUT.wav", help="write what a listener of the run heard (needs a backend "
                                                         "that makes sound: --tts espeak, festival or piper)")
    parser.add_argument("--bvh", metavar="OUT.bvh", help="write the motion as BVH")
    parser.add_argument("--poses", metavar="OUT.npz", help="write joint angles per frame (numpy .npz)")
    parser.add_argument("--textgrid", metavar="OUT.TextGrid", help="write words, phones, marks and strokes as a "
                                                                   "Praat TextGrid")
    parser.add_argument("--csv", metavar="DIR", help="write gestures.csv (one row per pegged behaviour) and visemes.csv "
                        "(one row per phoneme heard, with its viseme) into DIR")
    parser.add_argument("--report", metavar="OUT.html", help="write a report to watch and hear in a browser (with "
                                                             "a folder OUT_files beside it)")
    parser.add_argument("--environment-csv", metavar="OUT.csv",
                        help="write the camera, light and music that <ex:emotion> behaviours chose, one row at 0 s "
                             "and one at each change")
    parser.add_argument("--no-environment", action="store_true",
                        help="leave the camera, light and music of emotions out of --wav and --report")


def add_physics(parser: argparse.ArgumentParser, csv: bool = True, where: str = "") -> None:
    """``--physics``, ``--push`` and (``csv``) ``--physics-csv`` (:mod:`agentsim.physics`); ``where``: what
    ``--physics`` adds to a scenario's folder."""
    group = parser.add_argument_group("physics (mixed dynamics: a physical body under the animation)")
    group.add_argument("--physics", action="store_true",
                       help="play the motion on a physically simulated body: the pelvis, legs and spine "
                            "physical under a BalanceController, the neck, head, arms and hands as animated; "
                            "<bmlt:controller> behaviours make parts physical while they are active" + where)
    group.add_argument("--push", action="append", default=[], metavar="TIME:FX,FY,FZ:DURATION",
                       help="push the pelvis with a force (newtons; +Y up, +Z the way the body faces, +X its "
                            "left) from TIME for DURATION seconds (repeatable; needs --physics)")
    if not csv:
        return
    group.add_argument("--physics-csv", metavar="OUT.csv",
                       help="write the centre of mass, support polygon, pelvis height and whether the body has "
                            "fallen, one row a frame (needs --physics)")


def physics_options(args: argparse.Namespace) -> list:
    """The pushes of ``--push`` (a usage error naming --push for a malformed one, or for --push or
    --physics-csv without --physics)."""
    if not getattr(args, "physics", False):
        for flag, given in (("--push", getattr(args, "push", None)), ("--physics-csv", getattr(args, "physics_csv",
                                                                                              None))):
            if given:
                raise UsageError(f"{flag} needs --physics")
        return []
    from agentsim.physics.run import parse_push

    pushes = []
    for text in args.push:
        try:
            pushes.append(parse_push(text))
        except ValueError as exc:
            raise UsageError(f"--push: {exc}") from None
    return pushes


#: The prefix of the scratch folder (in the system's temporary folder) the poses are evaluated into.
POSES_SCRATCH = "agentsim-scratch-poses-"


def run_outputs(args: argparse.Namespace) -> list[str]:
    """The files (and the ``--csv`` folder, with a slash) that ``args`` asks :func:`write_run_outputs` for."""
    return [f"{name}/" if name == args.csv else name
            for name in (args.wav, args.bvh, args.poses, args.textgrid, args.csv, args.report,
                         getattr(args, "physics_csv", None) if getattr(args, "physics", False) else None,
                         getattr(args, "environment_csv", None)) if name]


def write_run_outputs(args: argparse.Namespace, realizer, title: str, extra_sources=(), beat_times=None) -> None:
    """Write the files ``args`` asks for from a finished run, on its time axis: the sound mixed a stretch
    at a time, the poses evaluated a window at a time into a scratch folder (never held whole), after
    :func:`~agentsim.media.budget.check_budget` has said that the files fit."""
    if not run_outputs(args):
        return  # nothing asked for: nothing to load
    from agentsim.written import scratch_folder

    with scratch_folder(POSES_SCRATCH) as scratch:  # a killed run's is removed by the next run's
        _write_run_outputs(args, realizer, title, extra_sources, beat_times, scratch)


def _write_run_outputs(args, realizer, title, extra_sources, beat_times, scratch: Path) -> None:
    from agentsim.animation.timeline import run_duration
    from agentsim.media.audio import run_track_stream
    from agentsim.media.budget import check_budget, frames_of, pose_bytes
    from agentsim.media.files import write_npz, write_textgrid, write_wav
    from agentsim.media.tables import gesture_rows, write_csv

    recording = realizer.recording()
    duration = run_duration(recording)
    environment = None
    if args.wav or args.report or getattr(args, "environment_csv", None):
        from agentsim.media.environment import run_environment

        environment = run_environment(recording, args.seed, not getattr(args, "no_environment", False))
    if environment and (args.wav or args.report):
        extra_sources = [*extra_sources, *_music(recording, environment, extra_sources)]
    track = run_track_stream(recording, extra_sources) if (args.wav or args.report) else None
    physics = getattr(args, "physics", False)
    physics_csv = getattr(args, "physics_csv", None) if physics else None
    poses = pose_bytes(frames_of(duration, args.fps)) if (args.bvh or args.poses or args.report or physics_csv) else {}
    sizes = {}
    if args.wav:
        sizes[f"--wav {args.wav}"] = (Path(args.wav), 44 + 2 * track.length)
    for flag, name, key in (("--bvh", args.bvh, "bvh"), ("--poses", args.poses, "npz"),
                            ("--report", args.report, "report")):
        if name:
            sizes[f"{flag} {name}"] = (Path(name), poses[key] + (2 * track.length if key == "report" else 0))
    check_budget(sizes, duration, (scratch, poses["scratch"]) if poses else None)  # before any file is written
    stream = manager = None
    if poses:
        from agentsim.animation import evaluate_poses

        manager = _physics_manager(args, realizer)
        stream = evaluate_poses(recording, fps=args.fps, seed=args.seed, folder=scratch, manager=manager)
        if manager is not None:
            _physics_said(args, realizer, manager.result)
    gestures = gesture_rows(recording, beat_times) if (args.csv or args.report or args.textgrid) else []
    if args.wav:
        write_wav(args.wav, track)
    if args.bvh:
        from agentsim.animation import write_bvh

        write_bvh(args.bvh, stream)
    if args.poses:
        write_npz(args.poses, stream)
    if args.textgrid:
        write_textgrid(args.textgrid, recording, gestures)
    if args.csv:
        write_csv(Path(args.csv) / "gestures.csv", gestures)
        from agentsim.animation.lips import VisemeRow, speech_visemes

        write_csv(Path(args.csv) / "visemes.csv", speech_visemes(recording), list(VisemeRow.__dataclass_fields__))
    if getattr(args, "environment_csv", None):
        from agentsim.expression.environment import environment_rows, write_environment_csv

        write_environment_csv(args.environment_csv, environment or environment_rows(recording, args.seed))
    if args.report:
        from agentsim.media.report import write_report

        extra = {}
        if environment:
            from agentsim.media.environment import report_environment

            extra["environment"] = report_environment(environment, stream)
        write_report(args.report, recording=recording, stream=stream, track=track if track.duration > 0 else None,
                     gestures=gestures, title=title,
                     physics=manager.result if manager is not None else None, **extra)


def _music(recording, environment, extra_sources) -> list:
    """The music of the environment under the run's speech (a list of one source, or none)."""
    from agentsim.media.audio import file_sources, speech_sources
    from agentsim.media.environment import music_for

    sounds = [*speech_sources(recording), *file_sources(recording), *extra_sources]
    music = music_for(environment, sounds, max((s.end for s in sounds), default=recording.now))
    return [music] if music is not None else []


def _physics_manager(args, realizer):
    """The manager whose poses are the physical body's (``--physics``), or None."""
    if not getattr(args, "physics", False):
        return None
    from agentsim.animation.output import lexicon_of
    from agentsim.physics.run import PhysicalManager, run_controllers

    recording = realizer.recording()
    return PhysicalManager(run_controllers(recording), physics_options(args), fps=args.fps, seed=args.seed,
                           lexicon=lexicon_of(recording))


def _physics_said(args, realizer, result) -> None:
    """A fall said once as a warning, an unstable simulation on stderr, the CSV written."""
    from agentsim.core import feedback as fb
    from agentsim.physics.run import write_physics_csv

    if result.fell_at is not None:
        realizer.feedback.send(fb.warning("", "BODY_FELL", f"the physical body fell at {result.fell_at:.3f} s",
                                          result.fell_at, "agent"))
    if result.unstable_at is not None:
        print(f"agentsim: the physical body's simulation became unstable at {result.unstable_at:.3f} s and started "
              f"again from its rest pose (MuJoCo: {result.unstable})", file=sys.stderr)
    if args.physics_csv:
        write_physics_csv(args.physics_csv, result)


def check_outputs(args: argparse.Namespace) -> None:
    """Say, before any work, which output cannot be written."""
    from agentsim.media.files import check_writable

    inputs = [resolve(f) for f in args.files]
    check_writable([args.wav, args.bvh, args.poses, args.textgrid, args.report,
                    getattr(args, "physics_csv", None), getattr(args, "environment_csv", None)], [args.csv],
                   inputs=inputs)
    if args.report:  # its folder too: never one that holds someone else's files or the input
        from agentsim.media.report.page import OWN_FILES, report_paths
        from agentsim.written import check_folder

        check_folder(report_paths(args.report)[1], inputs, OWN_FILES)


def read_document(path: str) -> str | bytes:
    """A BML document from a file, or from standard input for ``-``: read no further than
    :data:`~agentsim.core.inputs.MAX_INPUT` (a longer one is refused, before any work, without reading the
    rest)."""
    from agentsim.core.inputs import read_limited

    if path == "-":
        return read_limited("-", what="the BML document on standard input")
    p = resolve(path)
    if p.is_dir():
        raise UsageError(f"{path} is a folder, not a BML file (name the files in it: {path}/*.xml)")
    if not p.exists():
        raise UsageError(f"no such file: {path}")
    try:
        return read_limited(p, what=f"the BML document {path}")
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from None


def resolve(path: str) -> Path:
    """The file ``path`` names: itself, or for ``examples/...`` not found here the installed example."""
    from agentsim.examples import resolve as find

    return path if path == "-" else find(path)


def list_lexicon(args: argparse.Namespace) -> int:
    """``agentsim lexicon list``: the lexicon's entries, one a line (name, kind, source)."""
    rows = options.lexicon(args).rows()
    width = max(len(name) for name, _, _ in rows)
    kinds = max(len(kind) for _, kind, _ in rows)
    for name, kind, source in rows:
        print(f"{name:<{width}}  {kind:<{kinds}}  {source}")
    return 0


def realize_files(args: argparse.Namespace) -> int:
    from agentsim.core.feedback import to_json
    from agentsim.realizer import Realizer

    lexicon = options.lexicon(args)
    documents = [(path, read_document(path)) for path in args.files]
    at = args.at if args.at is not None else [0.0] * len(documents)
    if len(at) != len(documents):
        raise UsageError(f"--at gives {len(at)} times for {len(documents)} files")
    if args.until is not None and not args.until >= 0:
        raise UsageError("--until must be a non-negative number of seconds")
    options.check_fps(args)
    physics_options(args)
    check_outputs(args)
    tts = options.backend(args.tts, args.voice)
    if args.wav and tts.name == "builtin":
        raise UsageError("--wav needs a backend that makes sound: the built-in one only times speech; use --tts espeak")
    print(f"speech: {options.describe_backend(tts)}", file=sys.stderr)
    out = sys.stdout
    if out is None:  # started with its standard output closed
        raise UsageError("standard output is closed: there is nowhere to write the feedback")
    problems: list[str] = []
    made = options.anticipators(args, problems)
    realizer = Realizer(realtime=args.realtime, anticipators=made, strict=args.strict,
                        tts=tts if args.no_cache else speech_cache(tts), lexicon=lexicon,
                        gc_pause=options.collection_pause())

    def emit(feedback):
        out.write(to_json(feedback) + "\n")
        out.flush()

    realizer.feedback.listen(emit)
    from agentsim.core import feedback as fb

    for problem in problems:  # the run goes on without it: what was tied to it is dropped, with warnings
        realizer.feedback.send(fb.warning("", "NO_SUCH_TARGET", problem, 0.0, "agent"))
    order = sorted(range(len(documents)), key=lambda i: (at[i], i))
    for i in order:
        realizer.submit_at(at[i], documents[i][1], source=str(resolve(documents[i][0])))
    realizer.run(until=args.until)
    write_run_outputs(args, realizer, title=", ".join(Path(f).name for f in args.files))
    written = run_outputs(args)
    if written:
        print(f"wrote {', '.join(written)}", file=sys.stderr)
    return 0


def speech_cache(tts):
    """``tts`` behind the speech cache the storyteller keeps
    (:class:`~scenarios.storytelling.voice.WholeSpeechCache`); the built-in backend, which times a text faster
    than a cache file is read, as it is."""
    if getattr(tts, "name", "") == "builtin":
        return tts
    from scenarios.storytelling.voice import WholeSpeechCache

    return WholeSpeechCache(tts)


def plot_timeline(args: argparse.Namespace) -> int:
    """``agentsim plot timeline``: realize the file and draw its timeline, or the ``--from``/``--to`` window
    of it (a usage error, before anything runs, if the window is not seconds that end after they start)."""
    import math

    lexicon = options.lexicon(args)
    from agentsim.animation import evaluate_poses, plot_timeline as draw, plot_timelines
    from agentsim.animation.timeline import run_duration
    from agentsim.realizer import Realizer

    def seconds(option: str, text: str | None) -> float | None:
        if text is None:
            return None
        try:
            value = float(text)
        except ValueError:
            raise UsageError(f"{option} expects seconds, got {text!r}") from None
        if not (value >= 0 and math.isfinite(value)):
            raise UsageError(f"{option} must be a non-negative number of seconds, got {text}")
        return value

    from agentsim.media.files import check_writable

    start, end = seconds("--from", args.start), seconds("--to", args.end)
    if start is not None and end is not None and not end > start:
        raise UsageError(f"--to ({end:g} s) must come after --from ({start:g} s)")
    check_writable([args.out], inputs=[resolve(args.file)])
    tts = options.backend(args.tts, args.voice)
    realizer = Realizer(anticipators=options.anticipators(args), tts=tts, lexicon=lexicon,
                        gc_pause=options.collection_pause())
    realizer.submit(read_document(args.file), source=str(resolve(args.file)))
    realizer.run()
    recording = realizer.recording()
    stream = evaluate_poses(recording)
    title = Path(args.file).name
    said = f"speech: {options.describe_backend(tts)}"  # said with what was drawn: an error stays one line
    if start is None and end is None:
        written = plot_timelines(recording, args.out, stream=stream, title=title, width=12.0)
        print(said, file=sys.stderr)
        if len(written) > 1:
            print(f"wrote {args.out}: the run lasts {run_duration(recording):.1f} s, so it is its overview, and "
                  f"{len(written) - 1} windows are next to it ({written[1].name}, ...)", file=sys.stderr)
        else:
            print(f"wrote {args.out}", file=sys.stderr)
        return 0
    duration = run_duration(recording)
    start = 0.0 if start is None else start
    if start >= duration:
        raise UsageError(f"--from {start:g} s is after the end of the run ({duration:.2f} s)")
    end = duration if end is None else end
    draw(recording, args.out, stream=stream, title=title, start=start, end=end)
    print(said, file=sys.stderr)
    print(f"wrote {args.out} ({start:g} to {end:g} s of the run)", file=sys.stderr)
    return 0


def list_anticipators(args: argparse.Namespace) -> int:
    from anticipators import registry

    for name, target in sorted(registry.available().items()):
        try:
            declared = ", ".join(p.describe() for p in registry.parameters(registry.load(name)))
        except AgentsimError as exc:  # a broken plugin is listed with why, the others still are
            declared = f"(cannot be loaded: {exc})"
        print(f"{name}\t{target}\t{declared}")
    return 0


def new_anticipator(args: argparse.Namespace) -> int:
    from anticipators.template import write_plugin

    folder = write_plugin(args.name, Path(args.dir))
    print(f"wrote {folder}/ (pyproject.toml, {folder.name.replace('-', '_')}.py, tests/, README.md); "
          f"install it with: pip install -e {folder}", file=sys.stderr)
    return 0


def examples_command(args: argparse.Namespace) -> int:
    import filecmp
    import shutil

    from agentsim.examples import HOME, describe, names

    if args.action == "list":
        for name in names():
            about = describe(name)
            print(f"{name}\t{about}" if about else name)
        return 0
    target = Path(args.dir) / "examples"
    wanted = [name.removeprefix("examples/") for name in names()]
    if target.exists():  # copied before: what is there must be the examples as shipped, else nothing is touched
        if not target.is_dir():
            raise UsageError(f"{target} exists and is not a folder: copy into another folder")
        changed = [name for name in wanted if (target / name).exists() and not filecmp.cmp(
            HOME / name, target / name, shallow=False)]
        if changed:
            raise UsageError(f"{target} exists already and {changed[0]} there differs from the shipped one"
                             f"{f' (and {len(changed) - 1} more)' if len(changed) > 1 else ''}: copy into another "
                             f"folder")
    missing = [name for name in wanted if not (target / name).exists()]
    try:
        for name in missing:
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(HOME / name, target / name)
    except OSError as exc:
        raise UsageError(f"cannot copy the examples into {target}: {exc.strerror or exc}") from None
    if len(missing) == len(wanted):
        print(f"wrote {target}/ ({len(wanted)} files)", file=sys.stderr)
    else:
        print(f"{target}/ holds the examples already; wrote the {len(missing)} that were missing", file=sys.stderr)
    return 0
