"""``agentsim sweep``: a command run over a grid of options and seeds as Dask tasks, from a laptop's cores to a
cluster, and ``agentsim sweep report``: the results with bootstrap confidence intervals.

=============  ====================================================================================
module         what
=============  ====================================================================================
``spec``       the spec (``SPEC.toml``) checked against the command's own parser; its points and keys
``point``      one point as a Dask task: the command run in the worker's process, its JSON captured
``runner``     the cluster or scheduler, the cache of finished points, the progress bar
``results``    the rows: grid keys, flattened metrics, status and error; parquet and CSV
``report``     means with 95 % bootstrap intervals per strategy, and ``summary.png``
=============  ====================================================================================
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agentsim.cli.sweep.spec import MAX_POINTS
from agentsim.errors import AgentsimError, UsageError

USAGE = ("agentsim sweep SPEC.toml [--workers N | --scheduler ADDRESS] --out DIR [--max-points N] [--quiet]\n"
         "       agentsim sweep report DIR [--metric M ...] [--by KEY] [--axis KEY] [--over KEY ...] [--markdown] "
         "[--png FILE]")


def add_parsers(commands) -> None:
    parser = commands.add_parser(
        "sweep", usage=USAGE, help="run a command over a grid of options and seeds on Dask; 'sweep report DIR'",
        description="Run an agentsim command that prints --json (eval speech-sync, anticipate beats, run "
                    "conductor, run storytelling) at every point of the grid SPEC.toml names, each point a Dask "
                    "task, on a local cluster of --workers processes or through the scheduler at --scheduler. "
                    "Writes DIR/results.parquet and DIR/results.csv (one row per point, failures with their "
                    "error) and DIR/sweep.json (the spec as read), keeps each finished point in DIR/points/, so that "
                    "a rerun computes only what is missing, and with keep_outputs = true each point's --out "
                    "folder in DIR/outputs/<its grid values>/. 'agentsim sweep report DIR' prints the means with 95 % bootstrap intervals per "
                    "strategy and draws DIR/summary.png.")
    parser.add_argument("spec", nargs="?", metavar="SPEC.toml",
                        help="the sweep's spec: a file, or a shipped spec by its short name (speech_sync, "
                             "conductor; see --list-specs); or 'report'")
    parser.add_argument("--list-specs", action="store_true", help="list the shipped specs and exit")
    parser.add_argument("folder", nargs="?", metavar="DIR", help="with 'report': the sweep's folder")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local Dask cluster (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on the Dask scheduler at ADDRESS (tls://host:8786, or tcp:// on a network you "
                            "trust) and its workers instead; the credentials of a TLS scheduler are Dask's "
                            "configuration: DASK_DISTRIBUTED__COMM__TLS__CA_FILE, "
                            "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT and DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY "
                            "(the local cluster of --workers makes its own temporary TLS credentials)")
    parser.add_argument("--out", metavar="DIR", help="the sweep's folder: results, and the cache of finished points")
    parser.add_argument("--max-points", type=int, metavar="N",
                        help=f"run a grid of up to N points (default: at most {MAX_POINTS}; a larger grid is refused "
                             f"before any work)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    report = parser.add_argument_group("report")
    report.add_argument("--metric", action="append", metavar="M",
                        help="a metric column to summarise (repeatable; default: the spec's [report] metrics, "
                             "else the first six that vary)")
    report.add_argument("--by", metavar="KEY", help="one table and one line per value of KEY (default: strategy)")
    report.add_argument("--axis", metavar="KEY", help="the picture's x axis (default: the spec's, else the first "
                                                      "other grid key with several values)")
    report.add_argument("--over", action="append", metavar="KEY",
                        help="replicates the intervals are taken over (repeatable; default: seed)")
    report.add_argument("--markdown", action="store_true", help="print one Markdown table instead")
    report.add_argument("--png", metavar="FILE", help="where to draw the picture (default: DIR/summary.png)")
    parser.set_defaults(handler=sweep_handler)


REPORT_ONLY = ("metric", "by", "axis", "over", "markdown", "png")


def sweep_handler(args: argparse.Namespace) -> int:
    if args.list_specs:
        from scenarios import sweeps

        for name in sweeps.names():
            print(f"{name:<12} {sweeps.describe(name)}".rstrip())
        return 0
    if args.spec is None:
        raise UsageError("name a sweep spec: agentsim sweep SPEC.toml --out DIR (shipped: agentsim sweep --list-specs)")
    if args.spec == "report" and not Path("report").is_file():
        return report_handler(args)
    if args.folder is not None:
        raise UsageError(f"unexpected argument {args.folder!r}: usage: agentsim sweep SPEC.toml --out DIR")
    given = [name for name in REPORT_ONLY if getattr(args, name)]
    if given:
        raise UsageError(f"--{given[0]} is an option of 'agentsim sweep report DIR'")
    if args.out is None:
        raise UsageError("say where the sweep writes: --out DIR")
    if args.workers is not None and args.workers < 1:
        raise UsageError("--workers must be at least 1")
    if args.max_points is not None and args.max_points < 1:
        raise UsageError("--max-points must be at least 1")
    from agentsim.cli.sweep import runner, spec

    # every mistake of the spec is named here, before any work; the count of points first
    checked = spec.load(args.spec, max_points=args.max_points,
                        say=None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True)))
    outcome = runner.run(checked, Path(args.out), workers=args.workers, scheduler=args.scheduler, quiet=args.quiet)
    failed = outcome.failed
    print(f"{outcome.points} points of 'agentsim {checked.name}': {outcome.computed} computed, {outcome.cached} "
          f"from the cache, {failed} failed, in {outcome.seconds:.1f} s; results in {outcome.parquet} and "
          f"{outcome.csv.name}; summary: agentsim sweep report {args.out}", file=sys.stderr)
    if failed:
        raise AgentsimError(f"{failed} of {outcome.points} points failed; their errors are in the 'error' column of "
                            f"{outcome.csv}")
    return 0


def report_handler(args: argparse.Namespace) -> int:
    if args.folder is None:
        raise UsageError("say which sweep: agentsim sweep report DIR")
    if args.workers is not None or args.scheduler or args.out or args.max_points is not None:
        raise UsageError("'agentsim sweep report DIR' takes no --workers, --scheduler, --out or --max-points")
    from agentsim.cli.sweep.report import markdown_table, plot, summarize, text_tables

    folder = Path(args.folder)
    summary = summarize(folder, metrics=args.metric, by=args.by, axis=args.axis, over=args.over)
    print(markdown_table(summary) if args.markdown else text_tables(summary))
    png = plot(summary, Path(args.png) if args.png else folder / "summary.png")
    print(f"drawn: {png}", file=sys.stderr)
    return 0
