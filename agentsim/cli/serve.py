"""``agentsim serve``: a live realizer behind a WebSocket endpoint (see :mod:`agentsim.live.server`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agentsim.cli import options
from agentsim.errors import Unavailable, UsageError


def add_parsers(commands) -> None:
    serve = commands.add_parser(
        "serve", help="a live realizer that programs send BML to over a WebSocket and people watch",
        description="Realize BML live on the real-time clock: each text message sent to ws://HOST:PORT/ is one "
                    "BML document; its feedback goes to its sender (and to clients that sent {\"subscribe\": "
                    "\"feedback\"}) as one JSON message each (the objects 'agentsim realize' prints), its "
                    "warnings to its sender alone. http://HOST:PORT/ shows the agent moving. On 127.0.0.1 (the "
                    "default) only programs on this machine and the viewer's page (or pages of --allow-origin) "
                    "may connect; any other --host exposes the realizer to the network, and without --token "
                    "a token is made up and printed in the URLs.")
    serve.add_argument("--host", default="127.0.0.1",
                       help="address to listen on (127.0.0.1: this machine only; another address, e.g. 0.0.0.0, "
                            "lets the network drive the realizer and watch it, with a token)")
    serve.add_argument("--port", type=int, default=8765, help="port to listen on (8765; 0: any free port)")
    serve.add_argument("--audio", default="default", metavar="DEVICE|none",
                       help="where speech and sound files play: a sounddevice output device, or none (default: "
                            "the default device)")
    serve.add_argument("--calibrate", metavar="INPUT",
                       help="before serving, play clicks and record them from this input device (the output's "
                            "loop back: a cable, or a PulseAudio monitor such as 'pulse' with PULSE_SOURCE set) "
                            "to measure what the device adds to its reported latency, and make up for it")
    serve.add_argument("--token", metavar="TOKEN",
                       help="clients must send ?token=TOKEN on the WebSocket URL and the viewer's URL (the page "
                            "passes it on); made up when --host is not loopback and no token is given")
    serve.add_argument("--allow-origin", action="append", default=[], metavar="URL", dest="allow_origins",
                       help="a web page's origin (https://host[:port]) that may connect besides the viewer's own "
                            "(repeatable); programs that send no Origin are always taken")
    serve.add_argument("--media", metavar="DIR",
                       help="the directory <bmlt:audiofile fileName> reads sound files from (relative paths "
                            "inside it only); without it clients' audiofile behaviours are refused")
    options.add_anticipators(serve)
    serve.add_argument("--input", metavar="DEVICE",
                       help="listen to this live input device (a name or number; 'default': the system's default "
                            "input) with the audio beat anticipator, whose beats clients' BML pegs to as "
                            "anticipators:beats:next1, anticipators:beats:beat3 (as --anticipator "
                            "audio:beats,input=DEVICE); an input that is dead, or silent from the start, stops the "
                            "service within 2 s")
    from agentsim.live import limits as live

    limits = serve.add_argument_group(
        "how much speech one block may ask for (a block past a limit is refused whole, with one warning to its "
        "sender; seconds are estimated from the characters before synthesis, and checked against the audio)")
    limits.add_argument("--max-speech-chars", type=int, default=live.SPEECH_CHARACTERS, metavar="N",
                        help=f"characters of text in one speech ({live.SPEECH_CHARACTERS:,})")
    limits.add_argument("--max-speech-seconds", type=float, default=live.SPEECH_SECONDS, metavar="S",
                        help=f"seconds one speech may last ({live.SPEECH_SECONDS:g})")
    limits.add_argument("--max-block-chars", type=int, default=live.BLOCK_CHARACTERS, metavar="N",
                        help=f"characters of text in a block's speeches together ({live.BLOCK_CHARACTERS:,})")
    limits.add_argument("--max-block-seconds", type=float, default=live.BLOCK_SECONDS, metavar="S",
                        help=f"seconds a block's speeches may last together ({live.BLOCK_SECONDS:g})")
    options.add_tts(serve)
    options.add_lexicon(serve)
    serve.add_argument("--strict", action="store_true", help="read pure BML 1.0 only")
    serve.add_argument("--fps", type=float, default=30.0, help="poses per second streamed to viewers (30)")
    from agentsim.cli.realize import add_physics

    add_physics(serve, csv=False, where=" (the viewer shows the physical body; pushes at the realizer's clock)")
    serve.set_defaults(handler=run_server)


def run_server(args: argparse.Namespace) -> int:
    import signal

    from agentsim.live.service import Service
    from agentsim.live.devices import GET_A_DEVICE, NoAudioDevice

    # A service is stopped with SIGTERM as with Ctrl-C: it closes what it started (the poses' evaluator
    # process, the audio stream) instead of leaving them behind.
    signal.signal(signal.SIGTERM, signal.default_int_handler)

    if not 0 <= args.fps <= options.MAX_FPS:  # (0: no poses)
        raise UsageError(f"--fps must be between 0 and {options.MAX_FPS:g} poses per second, got {args.fps:g}")
    from agentsim.live.access import origin_of

    for origin in args.allow_origins:  # a usage error before anything starts
        origin_of(origin)
    if args.token is not None and not args.token.strip():
        raise UsageError("--token must not be empty")
    if args.media is not None and not Path(args.media).is_dir():
        raise UsageError(f"--media names the directory sound files are read from; {args.media!r} is not one")
    if args.calibrate and args.audio == "none":
        raise UsageError("--calibrate measures the sound device's delay: it needs --audio DEVICE, not --audio none")
    if args.input is not None:
        if not args.input.strip() or "," in args.input:
            raise UsageError(f"--input names one input device, got {args.input!r}")
        args.anticipator.append(f"audio:beats,input={args.input.strip()}")
    from agentsim.live.limits import Limits

    limits = Limits(args.max_speech_chars, args.max_speech_seconds, args.max_block_chars, args.max_block_seconds)
    from agentsim.cli.realize import physics_options

    pushes = physics_options(args)  # a malformed --push: said before anything starts
    lexicon = options.lexicon(args)  # a file that cannot be used: said before anything starts
    anticipators = options.anticipators(args)  # one that cannot be made: said before anything starts
    try:
        tts = options.backend(args.tts, args.voice)
        service = Service(host=args.host, port=args.port, audio=args.audio, tts=tts,
                          strict=args.strict, fps=args.fps, calibrate=args.calibrate,
                          token=args.token, allow_origins=args.allow_origins, media=args.media,
                          anticipators=anticipators, limits=limits, lexicon=lexicon,
                          physics=pushes if args.physics else None)
    except NoAudioDevice as exc:  # say which option chooses the device, and how to do without one
        if exc.kind == "input":
            raise Unavailable(f"{exc.problem}. Leave --calibrate out, or {GET_A_DEVICE} and name its input "
                              "with --calibrate INPUT (e.g. --calibrate pulse with PULSE_SOURCE set)") from None
        raise Unavailable(f"{exc.problem}. Serve without sound with --audio none, or {GET_A_DEVICE} and name "
                          "its device with --audio DEVICE (e.g. --audio pulse)") from None
    print(f"speech: {options.describe_backend(service.live.backend)}", file=sys.stderr)
    import asyncio

    async def serve_until_a_signal() -> bool:
        """Serve until SIGTERM or SIGINT, then close the server and its connections in order (a signal
        raised as KeyboardInterrupt inside the loop could leave a connection's task hanging at exit);
        whether a signal stopped it."""
        stop, signalled = asyncio.Event(), []
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, lambda sig=sig: (signalled.append(sig), stop.set()))
        await service.serve(ready=lambda: print(service.describe(), file=sys.stderr, flush=True), stop=stop)
        return bool(signalled)

    try:
        if asyncio.run(serve_until_a_signal()):
            raise KeyboardInterrupt  # stopped as asked: exit status 130, as with Ctrl-C
    finally:
        service.close()
    return 0
