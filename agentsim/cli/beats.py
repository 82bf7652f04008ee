"""The ``agentsim anticipate`` commands: run a beat tracker over audio, commit and score its beats."""

from __future__ import annotations

import argparse
import json
import sys

from agentsim.errors import AgentsimError


def add_parsers(commands) -> None:
    anticipate = commands.add_parser("anticipate", help="run anticipators over recorded or live input",
                                     description="Run an anticipator over recorded or live input and print what it "
                                                 "predicts: 'anticipate beats' tracks the beats of audio.")
    kinds = anticipate.add_subparsers(dest="kind", required=True)
    beats = kinds.add_parser(
        "beats", help="predict beats from audio",
        description="Track AUDIO block by block, using only audio up to now, and print every update of the "
                    "predicted upcoming beats. The committed sequence at --lookahead L is every beat b that "
                    "the update in force at b - L predicted (the beats a performer that must act L seconds "
                    "early would play); --beats-out writes it, one time a line; with --reference it is scored "
                    "(mir_eval F-measure with a 70 ms window, CMLt, AMLt, P-score, beats before --skip left "
                    "out; timing errors; real-time factor in CPU time).")
    beats.add_argument("audio", nargs="?", help="audio file (WAV, FLAC, ...)")
    beats.add_argument("--tracker", default="causal",
                       help="causal (default), causal-net, causal-comb, baseline, aubio (when installed) or librosa_offline")
    beats.add_argument("--json", action="store_true", help="print JSON")
    beats.add_argument("--beats-out", metavar="FILE", help="write the committed beats, one time (s) a line")
    beats.add_argument("--reference", metavar="BEATS.txt", help="true beat times, one per line, to score against")
    beats.add_argument("--lookahead", type=float, default=0.2,
                       help="how long before a beat it is committed, seconds (0.2)")
    beats.add_argument("--skip", type=float, default=5.0, help="leave out beats before this time when scoring (5 s)")
    beats.add_argument("--block", type=int, default=512, help="samples per block fed to the tracker")
    beats.add_argument("--input", metavar="DEVICE", help="track a live input device instead of a file (a name or number; "
                                                          "'default': the system's default input); a dead or silent "
                                                          "input stops it within 2 s")
    beats.add_argument("--seconds", type=float, default=10.0, help="how long to listen with --input")
    beats.add_argument("--sample-rate", type=int, default=44100, help="sample rate for --input")
    beats.set_defaults(handler=track_beats)
    from agentsim.cli import reps

    reps.add_parser(kinds)


def track_beats(args: argparse.Namespace) -> int:
    from anticipators.beats.evaluation import committed_beats, score_committed, track_file
    from anticipators.beats.tracking import TRACKER_NAMES

    if args.tracker not in TRACKER_NAMES:
        raise AgentsimError(f"unknown tracker {args.tracker!r}: choose from {', '.join(TRACKER_NAMES)}")
    if args.lookahead < 0:
        raise AgentsimError("--lookahead must be at least 0 seconds")
    if args.tracker == "aubio":
        from anticipators.beats.baselines import aubio_available

        if not aubio_available():
            raise AgentsimError("the aubio tracker needs aubio: pip install 'agentsim[bench]'")
    if args.input is not None:
        run = listen(args)
    else:
        if not args.audio:
            raise AgentsimError("give an AUDIO file, or --input DEVICE to listen live")
        from anticipators.audio import read_audio

        audio, sample_rate = read_audio(args.audio)
        run = track_file(audio, args.tracker, args.block, sample_rate=sample_rate)
    run.pop("sample_rate", None)
    committed = committed_beats(run["updates"], args.lookahead, end=run["audio_seconds"])
    if args.beats_out:
        try:
            from agentsim.media.files import write_text

            write_text(args.beats_out, "".join(f"{b:.6f}\n" for b in committed))
        except OSError as exc:
            raise AgentsimError(f"cannot write {args.beats_out!r}: {exc}") from None
    if args.reference:
        import numpy as np

        try:
            import io

            from agentsim.core.inputs import read_text

            reference = np.loadtxt(io.StringIO(read_text(args.reference, errors="replace")), ndmin=1)
        except (OSError, ValueError) as exc:
            raise AgentsimError(f"cannot read reference beats {args.reference!r}: {exc}") from None
        result = score_committed(run["updates"], reference, lookahead=args.lookahead, skip=args.skip,
                                 end=run["audio_seconds"])
        result = {"tracker": run["tracker"], "audio_seconds": run["audio_seconds"],
                  "wall_seconds": run["wall_seconds"], "cpu_seconds": run["cpu_seconds"],
                  "real_time_factor": run["cpu_seconds"] / max(run["audio_seconds"], 1e-9),
                  "committed": int(committed.size), **result}
        print(json.dumps(result, indent=None if args.json else 2))
        return 0
    if args.json:
        print(json.dumps({"tracker": run["tracker"], "audio_seconds": run["audio_seconds"],
                          "wall_seconds": run["wall_seconds"], "cpu_seconds": run["cpu_seconds"],
                          "lookahead": args.lookahead, "committed": committed.tolist(), "updates": run["updates"]}))
    elif args.beats_out:
        print(f"{run['tracker']}: {committed.size} beats committed {args.lookahead:g} s ahead written to "
              f"{args.beats_out} ({run['audio_seconds']:.1f} s of audio in {run['cpu_seconds']:.3f} s CPU)",
              file=sys.stderr)
    else:
        for update in run["updates"]:
            print(f"{update['t']:9.3f}  " + " ".join(f"{b:.3f}" for b in update["beats"]))
        print(f"{run['tracker']}: {run['audio_seconds']:.1f} s of audio in {run['wall_seconds']:.3f} s",
              file=sys.stderr)
    return 0


def listen(args: argparse.Namespace) -> dict:
    """Track a live device for ``args.seconds`` in real time."""
    import time

    from agentsim.core.clock import make_environment
    from agentsim.core.pegboard import PegBoard
    from anticipators.audio import AudioBeatAnticipator, DeviceSource, device_named

    source = DeviceSource(device_named(args.input), args.sample_rate)
    source.check()
    env = make_environment(realtime=True)
    anticipator = AudioBeatAnticipator("beats", source=source, tracker=args.tracker)
    anticipator.attach(env, PegBoard())
    started, cpu = time.perf_counter(), time.process_time()
    env.run(until=args.seconds)
    return {"tracker": args.tracker, "audio_seconds": anticipator.tracker.time,
            "wall_seconds": time.perf_counter() - started, "cpu_seconds": time.process_time() - cpu,
            "updates": [{"t": t, "beats": b} for t, b in anticipator.updates]}
