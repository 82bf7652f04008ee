"""The ``agentsim run trainer`` command's run: simulate, measure, write the files.

:func:`main` takes the parsed options of ``agentsim run trainer [--exercise E] [--user simulated|FILE.csv]
[--target-tempo N] [--strategy follow|lead|fixed|all] [--seed S] [--out DIR]`` (declared in
:mod:`agentsim.cli.scenarios`). ``--strategy all`` runs every strategy on the same seed, writes each into
``--out/<strategy>/`` and ``compare.json``, and prints a table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from agentsim.errors import UsageError
from scenarios import write_comparison
from scenarios.trainer.names import STRATEGIES, TARGET_TEMPO

TABLE_HEADER = (f"{'strategy':<8} {'asy mean':>8} {'asy sd':>7} {'count p50':>9} {'count p95':>9} "
                f"{'tempo err%':>10} {'recovered':>9} {'reps':>5} {'missed':>6}")


def _row(m: dict) -> str:
    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    asy, count = m["asynchrony_ms"], m["count_error_ms"]
    recovered = "-" if m["strategy"] == "follow" else ("never" if m["recovered_after"] is None
                                                       else str(m["recovered_after"]))
    return (f"{m['strategy']:<8} {f(asy['mean'], '.1f'):>8} {f(asy['sd'], '.1f'):>7} {f(count['p50'], '.1f'):>9} "
            f"{f(count['p95'], '.1f'):>9} {f(m['tempo_error_percent'], '+.2f'):>10} {recovered:>9} "
            f"{m['user_repetitions']:>5} {m['missed_counts']:>6}")


def main(args: argparse.Namespace) -> int:
    """Run ``agentsim run trainer`` with parsed ``args``; returns the exit status."""
    from agentsim.media.files import check_writable
    from agentsim.written import staged_folder

    if args.target_tempo is not None and not 5 <= args.target_tempo <= 120:
        raise UsageError(f"--target-tempo {args.target_tempo:g}: give repetitions a minute, 5-120")
    recording = None
    if args.user != "simulated":
        from anticipators.reps import read_motion

        recording = read_motion(args.user)
        recording = (recording[0] - recording[0][0], recording[1])
    out = Path(args.out)
    check_writable(folders=[out])
    as_json = getattr(args, "json", False)
    table = sys.stderr if as_json else sys.stdout
    with staged_folder(out, inputs=[None if recording is None else args.user]) as staging:
        return _run(args, recording, out, staging, as_json, table)


def _run(args, recording, shown: Path, out: Path, as_json: bool, table) -> int:
    from scenarios.trainer.outputs import write_outputs
    from scenarios.trainer.scenario import collect_metrics, simulate

    every = args.strategy == "all"
    strategies = STRATEGIES if every else (args.strategy,)
    target = args.target_tempo or TARGET_TEMPO[args.exercise]
    rows = []
    for name in strategies:
        started = time.perf_counter()
        run = simulate(args.exercise, name, target, args.seed, recording=recording)
        metrics = collect_metrics(run)
        write_outputs(run, metrics, out / name if every else out, pictures=not getattr(args, "no_pictures", False),
                      physics=getattr(args, "physics", False))
        rows.append(metrics)
        if not every:
            print(TABLE_HEADER, file=table)
            print(_row(metrics), file=table)
            if "physics" in metrics:
                body = metrics["physics"]
                print(f"physical body: {'fell at %.2f s' % body['fell_at'] if body['fallen'] else 'never fell'}, centre "
                      f"of mass over the support on {100 * (body['com_inside'] or 0):.1f} % of frames", file=table)
            print(f"written to {shown} in {time.perf_counter() - started:.1f} s", file=table)
    if every:
        write_comparison(out, shown, rows, f"{args.exercise}: target {target:g} a minute, {rows[0]['user']} user, "
                         f"seed {args.seed}", TABLE_HEADER, [_row(m) for m in rows], table)
    if as_json:
        print(json.dumps(rows if every else rows[0]))
    return 0
