"""The ``agentsim run conductor`` command's run: simulate (or listen live), measure, write the files.

:func:`main` takes the parsed options of ``agentsim run conductor [--config FILE] [--strategy S |
--compare] [--seed N] [--out DIR] [--input DEVICE]`` (declared in :mod:`agentsim.cli.scenarios`): it runs the
conductor scenario (the default configuration: a 4/4 piece with a 120 BPM target and an ensemble that
starts and drags 10 % below it) and writes ``metrics.json``, ``tempo.png``, ``timeline.png``,
``ensemble.wav``, ``conductor.bvh`` and ``feedback.jsonl`` to ``--out``. Without ``--strategy`` the
configuration's strategy runs (``best`` unless it says otherwise). ``--compare`` runs every strategy on
the same seed, writes each into ``--out/<strategy>/`` (all files but the timeline) and prints a table.
``--live`` conducts what an input device plays, in real time, instead of the simulated ensemble.
On a terminal, stderr says which stage is under way (simulating, with a bar of simulated seconds, measuring,
audio, poses/BVH, report, pictures; with ``--compare`` one bar of the strategies that names the stage);
elsewhere nothing more is printed. ``--json`` prints the figures written (``metrics.json``, or with
``--compare`` the list of ``compare.json``) as JSON on stdout, and the table on stderr instead.
Shipped configurations: ``configs/default.toml``, ``configs/waltz_3_4.toml``, ``configs/march_2_4.toml``
and ``configs/falls_apart.toml`` (the conductor stops the piece).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from agentsim.errors import AgentsimError
from agentsim.core.progress import Stages
from agentsim.media import AXIS, GLOSSARY
from scenarios import write_comparison
from scenarios.conductor.names import STRATEGIES


def _summary_row(m: dict) -> str:
    asy = m.get("ensemble_asynchrony_ms") or {}
    ant = m.get("anticipator") or {}

    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    recovered = "never" if m.get("beats_to_recover") is None else str(m["beats_to_recover"])
    return (f"{m['strategy']:<8} {recovered:>9} {f(m.get('final_tempo_error_pct'), '+.2f'):>10} "
            f"{f(asy.get('mean'), '.1f'):>8} {f(asy.get('sd'), '.1f'):>7} "
            f"{f(ant.get('f_measure'), '.3f'):>6} {f(ant.get('mae_ms'), '.1f'):>7} "
            f"{f(m.get('stopped_at_s'), '.1f') + ' s' if m.get('stopped') else '-':>8}")


TABLE_HEADER = (f"{'strategy':<8} {'recovered':>9} {'final err%':>10} {'asy mean':>8} {'asy sd':>7} {'F':>6} "
                f"{'MAE ms':>7} {'stopped':>8}")


def main(args: argparse.Namespace) -> int:
    """Run ``agentsim run conductor`` with parsed ``args``; returns the exit status."""
    from scenarios.conductor.config import load_config

    overrides = {"piece": {"tempo": getattr(args, "target_bpm", None), "meter": getattr(args, "meter", None),
                           "bars": getattr(args, "bars", None)},
                 "ensemble": {"start_bpm": getattr(args, "start_bpm", None)},
                 "conductor": {"fps": getattr(args, "fps", None)}}
    flags = {"--target-bpm": "target_bpm", "--start-bpm": "start_bpm", "--meter": "meter", "--bars": "bars",
             "--fps": "fps"}
    described = " ".join(f"{flag} {getattr(args, key):g}" if isinstance(getattr(args, key), float)
                         else f"{flag} {getattr(args, key)}" for flag, key in flags.items()
                         if getattr(args, key, None) is not None)
    config = load_config(args.config, overrides, described)  # a bad configuration fails here, before anything runs
    out = Path(args.out)
    as_json = getattr(args, "json", False)
    table = sys.stderr if as_json else sys.stdout  # with --json, stdout carries the JSON alone
    from agentsim.media.files import check_writable

    check_writable(folders=[out])  # an output folder that cannot be written is said before any work
    live = args.live or args.device is not None
    if args.seconds is not None and not live:
        raise AgentsimError("--seconds only applies to --input")
    if getattr(args, "sample_rate", None) is not None and not live:
        raise AgentsimError("--sample-rate only applies to --input")
    from agentsim.written import staged_folder

    # written into a staging folder beside --out that replaces the old run once this one has finished
    with staged_folder(out, inputs=[args.config]) as staging:
        return _run(args, config, out, staging, live, as_json, table)


def _run(args, config, shown: Path, out: Path, live: bool, as_json: bool, table) -> int:
    """The run of :func:`main`, written into ``out`` (the staging folder that becomes ``shown``)."""
    from scenarios.conductor.scenario import collect_metrics, listen_live, simulate, write_outputs

    if live:
        if args.compare:
            raise AgentsimError("--compare cannot be used with --input (a live ensemble plays once)")
        device = None if args.device in (None, "default") else args.device
        if device is not None and str(device).isdigit():
            device = int(device)
        if getattr(args, "sample_rate", None):
            from dataclasses import replace

            config = replace(config, audio=replace(config.audio, sample_rate=args.sample_rate))
        started = time.perf_counter()
        run = listen_live(config, args.strategy, args.seconds, device)
        metrics = collect_metrics(run)
        write_outputs(run, metrics, out, physics=getattr(args, "physics_pushes", None))
        _report(metrics, shown, time.perf_counter() - started, table)
        if as_json:
            print(json.dumps({**metrics, "time_axis": AXIS, "glossary": GLOSSARY}))  # as metrics.json
        return 0
    strategies = STRATEGIES if args.compare else (args.strategy or config.conductor.strategy,)
    rows = []
    stages = Stages()
    pictures = not getattr(args, "no_pictures", False)
    from scenarios.conductor.scenario import begin

    # one run: what it needs before the piece plays (the renderer's process, the sound check) begins now, and
    # the processes that draw its pictures get ready while it is simulated
    physics = getattr(args, "physics_pushes", None)
    begun = None if args.compare else begin(config, physics=physics is not None)
    if not args.compare and pictures:
        from agentsim.animation.pictures import warm_workers

        warm_workers()
    import agentsim.realizer  # noqa: F401  (what a run imports, imported now: see below)
    import scenarios.conductor.ensemble  # noqa: F401
    from agentsim.core.gcpause import keep_out_of_collections

    keep_out_of_collections()  # the modules, classes and tables stay for the process's life
    for name in stages.over(list(strategies), "strategies", unit="strategy") if args.compare else strategies:
        started = time.perf_counter()
        run = simulate(config, name, args.seed, stages=stages, begun=begun)
        with stages("measuring"):
            metrics = collect_metrics(run)
        folder = out / name if args.compare else out
        write_outputs(run, metrics, folder, pictures=not args.compare, plots=pictures, stages=stages,
                      physics=physics, process=begun and begun.physics)
        rows.append(metrics)
        if not args.compare:
            _report(metrics, shown, time.perf_counter() - started, table)
        else:
            stages.write(f"{name}: {time.perf_counter() - started:.1f} s")
    if args.compare:
        write_comparison(out, shown, rows, f"{config.piece.title}: target {config.piece.tempo:g} BPM, ensemble "
                         f"starts at {config.ensemble.start_bpm:g} BPM, seed {args.seed}", TABLE_HEADER,
                         [_summary_row(m) for m in rows], table)
    if as_json:
        print(json.dumps(rows if args.compare else {**rows[0], "time_axis": AXIS, "glossary": GLOSSARY}))  # as compare.json, metrics.json
    return 0


def _report(metrics: dict, folder: Path, seconds: float, file=None) -> None:
    file = file or sys.stdout
    print(TABLE_HEADER, file=file)
    print(_summary_row(metrics), file=file)
    extra = []
    if metrics.get("louder_gestures"):
        extra.append(f"{len(metrics['louder_gestures'])} 'play louder' gesture(s)")
    if metrics.get("stopped"):
        extra.append(f"stopped the piece at {metrics['stopped_at_s']:.2f} s (the tracker lost the beat)")
    if extra:
        print("; ".join(extra), file=file)
    print(f"written to {folder} in {seconds:.1f} s", file=file)
