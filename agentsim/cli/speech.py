"""The ``agentsim eval speech-sync`` and ``agentsim speech`` commands."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from agentsim.cli import options
from agentsim.errors import AgentsimError, UsageError
from agentsim.core.progress import Stages

DEFAULT_MODEL = Path("linear_model.json")

#: The units of ``eval speech-sync``'s figures (docs/reference/glossary.md says what each one is).
SYNC_UNITS = {"error_ms": "ms (|stroke - the word's onset as heard|; signed_mean keeps the sign, positive: late)",
              "snaps": "frames (60 per s) in which animator time jumps a frame ahead of the clock or goes back",
              "stall_s": "s (clock time in frames where animator time ran at under half speed)",
              "rate": "animator seconds per clock second", "missed": "count (strokes never reached)",
              "wall_seconds": "s (this machine's time to compute)", "speech_seconds": "s (of speech)",
              "delivery": "latency, delay, jitter, burst_hold, start_jitter in s; drift_ppm in ppm; "
                          "burst_probability, loss as probabilities"}


def add_parsers(commands) -> None:
    evaluate = commands.add_parser("eval", help="measure synchronisation",
                                    description="Measure synchronisation: 'eval speech-sync' scores beat gestures "
                                                "on every content word of a text against the speech as heard.")
    kinds = evaluate.add_subparsers(dest="kind", required=True)
    sync = kinds.add_parser(
        "speech-sync", help="beats on every content word: how far from their words do the strokes land?",
        description="Peg a beat gesture's stroke to every content word of the text, realize it with an "
                    "animator-time strategy while progress events arrive late, scattered and in bursts, and "
                    "report the sync error (stroke minus word onset as heard), snaps, stalls and rates.")
    sync.add_argument("--text", metavar="FILE", help="text to speak (default: a bundled text)")
    options.add_tts(sync)
    options.add_strategy(sync, ", or 'all'")
    sync.add_argument("--list-strategies", action="store_true", help="name the strategies and exit")
    options.add_timing(sync)
    options.add_delivery(sync)
    options.add_seed(sync, "the playback start and the event channel")
    sync.add_argument("--model", metavar="FILE", help="linear model from 'agentsim speech calibrate'")
    sync.add_argument("--json", action="store_true", help="print JSON")
    sync.add_argument("--plot", metavar="FILE.png", help="draw the error distribution of each strategy")
    sync.set_defaults(handler=speech_sync)

    speech = commands.add_parser("speech", help="speech tools",
                                  description="Speech tools: 'speech calibrate' fits Chang's linear model, "
                                              "'speech export' writes a text's audio and Praat TextGrid.")
    tools = speech.add_subparsers(dest="tool", required=True)
    calibrate_parser = tools.add_parser("calibrate", help="fit Chang's linear characters-to-time model",
                                        description="Speak calibration texts and fit seconds = multiplier * "
                                                    "characters + offset by least squares over every word's onset.")
    options.add_tts(calibrate_parser)
    calibrate_parser.add_argument("--texts", metavar="FILE", help="calibration texts, one per line (default: bundled)")
    options.add_out(calibrate_parser, str(DEFAULT_MODEL), "where to save the model", metavar="FILE")
    calibrate_parser.set_defaults(handler=calibrate)
    export_parser = tools.add_parser(
        "export", help="speak a text; write its audio (WAV) and timeline (Praat TextGrid)",
        description="Speak the text of FILE and write what was spoken, on one time axis: --wav its audio, "
                    "--textgrid its words and phonemes with their times (tiers words and phones; open both in "
                    "Praat). At least one of the two is needed.")
    export_parser.add_argument("text", metavar="FILE", help="a plain UTF-8 text file (examples/story.txt is one)")
    options.add_tts(export_parser)
    export_parser.add_argument("--wav", metavar="FILE.wav",
                               help="the audio, 16-bit PCM at the backend's sample rate (needs --tts espeak, "
                                    "festival or piper)")
    export_parser.add_argument("--textgrid", metavar="FILE.TextGrid",
                               help="the words and phonemes as Praat interval tiers, from the speech's start")
    export_parser.set_defaults(handler=export)


def read_text(path: str | None) -> str:
    if path is None:
        from speech_timing.linear_model import TEXTS_DIR

        return (TEXTS_DIR / "clocks.txt").read_text(encoding="utf-8")
    from agentsim.examples import resolve

    p = resolve(path)
    if not p.is_file():
        raise UsageError(f"{path!r} is a folder, not a text file" if p.is_dir() else f"no text file {path!r}")
    from agentsim.core.inputs import read_text as read_limited

    try:
        text = read_limited(p, what=f"the text {path!r}")
    except UnicodeDecodeError as exc:
        raise AgentsimError(f"{path!r} is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    if not text.strip():
        raise AgentsimError(f"{path!r} has no text")
    return text


def speech_sync(args: argparse.Namespace) -> int:
    from scenarios.speech_sync import speech_sync as run
    from speech_timing.animator_time import STRATEGIES, check_strategy
    from speech_timing.linear_model import LinearModel

    if args.list_strategies:
        for name in STRATEGIES:
            print(name)
        return 0
    names = list(STRATEGIES) if args.strategy == "all" else [check_strategy(args.strategy)]
    delivery = options.delivery(args)
    model = None
    if args.model:
        if not Path(args.model).is_file():
            raise AgentsimError(f"no linear model {args.model!r}: make one with 'agentsim speech calibrate'")
        from agentsim.core.inputs import read_text as read_limited

        try:  # weighed before it is read, as every input
            model = LinearModel.from_json(read_limited(args.model, what=f"the linear model {args.model!r}"))
        except (ValueError, TypeError, AttributeError) as exc:  # not JSON, not a model's fields or values
            raise UsageError(f"the linear model {args.model!r} is not one 'agentsim speech calibrate' writes "
                             f"({exc})") from None
    text, tts = read_text(args.text), options.backend(args.tts, args.voice)
    results = []
    stages = Stages()  # on a terminal: which strategy is under way (with 'all', a bar of them)
    for name in stages.over(names, "strategies", unit="strategy") if len(names) > 1 else names:
        with stages(f"simulating {name}" if len(names) == 1 else "simulating"):
            result = run(text, tts, name, delivery, timing=args.timing, seed=args.seed, linear_model=model)
        results.append(result)
    from dataclasses import asdict

    condition = asdict(delivery)
    report = [options.explained({**{k: v for k, v in r.items() if k not in ("errors_s",)}, "delivery": condition},
                                SYNC_UNITS) for r in results]
    if args.plot:
        plot_errors(results, args.plot)
    if args.json:
        print(json.dumps(report[0] if args.strategy != "all" else report))
    else:
        print(f"{'strategy':14} {'p50 ms':>7} {'p95 ms':>7} {'max ms':>7} {'snaps':>6} {'stall s':>8} "
              f"{'rate x':>11}")
        for r in report:
            e = r["error_ms"]
            print(f"{r['strategy']:14} {e['p50']:7.1f} {e['p95']:7.1f} {e['max']:7.1f} {r['snaps']:6d} "
                  f"{r['stall_s']:8.2f} {r['rate']['min']:5.2f}-{r['rate']['max']:<5.2f}")
        print(f"{report[0]['gestures']} strokes on {report[0]['words']} words; error = stroke minus the word's "
              "onset as heard (positive: late); rate = animator seconds per clock second", file=sys.stderr)
    return 0


def plot_errors(results: list[dict], path: str) -> None:
    """Box plots of absolute sync error per strategy (ms)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = [abs(r["errors_s"]) * 1000 for r in results]
    fig, ax = plt.subplots(figsize=(1.4 * len(results) + 2, 4))
    ax.boxplot(data, showfliers=True)
    ax.set_xticks(range(1, len(results) + 1), [r["strategy"] for r in results], rotation=20)
    ax.set_yscale("symlog", linthresh=10)
    ax.set_ylim(bottom=0)
    ax.set_ylabel("|stroke - word onset| (ms)")
    ax.set_title(f"speech-gesture sync, timing={results[0]['timing']}, seed={results[0]['seed']}")
    fig.tight_layout()
    from agentsim.written import save_figure

    save_figure(fig, path, dpi=100)
    plt.close(fig)


def calibrate(args: argparse.Namespace) -> int:
    from agentsim.media.files import check_writable
    from speech_timing.linear_model import calibrate as fit

    texts = None
    if args.texts:
        texts = [line.strip() for line in read_text(args.texts).splitlines() if line.strip()]
    check_writable([args.out])
    model = fit(options.backend(args.tts, args.voice), texts)
    model.save(args.out)
    print(json.dumps({**json.loads(model.to_json()), "saved": args.out}))  # the keys it saved, as saved
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


def export(args: argparse.Namespace) -> int:
    from agentsim.media.files import check_writable
    from speech_timing.backend import SpeechText
    from speech_timing.exports import write_textgrid, write_wav

    if not (args.wav or args.textgrid):
        raise UsageError("say what to write: --wav FILE.wav and/or --textgrid FILE.TextGrid")
    check_writable([args.wav, args.textgrid])
    text = " ".join(read_text(args.text).split())
    tts = options.backend(args.tts, args.voice)
    if args.wav and tts.name == "builtin":
        raise UsageError("--wav needs a backend that makes sound: the built-in one only times speech; use --tts espeak")
    utterance = tts.synthesize(SpeechText(text))
    written = []
    if args.wav:
        write_wav(args.wav, utterance)
        written.append(args.wav)
    if args.textgrid:
        write_textgrid(args.textgrid, utterance)
        written.append(args.textgrid)
    print(f"wrote {' and '.join(written)} ({utterance.duration:.2f} s of speech)", file=sys.stderr)
    return 0
