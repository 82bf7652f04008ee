"""Outputs under kill -9: storyteller runs and sweeps killed at random times, and what each left.

Prints JSON. A storyteller run (a short story, the built-in backend) into a folder that holds a complete
earlier run, killed -9 (its whole process group) at times drawn by a seeded numpy Generator over the length
of a whole run; after each kill the folder must hold the earlier run or the new one, whole (every file
parses, the BVH has all its frames, the PNGs end, the seed-dependent files match one of the two runs), with
nothing beside it but staging folders; the next run must clear those. The same for a sweep of four points
(results.csv whole or absent, every cached point whole). The same for ``realize --report --bvh`` over an
earlier report: the page and its folder must be of one run (or the page absent), the BVH whole, and the next
run must clear the staging folders and the temporary files of killed writers. Also: the memory and time of
refusing an endless standard input and a behaviour a million seconds in.

    python benchmarks/bench_faults.py [--runs 20] [--sweeps 20] [--reports 20] [--seed 28]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import test_outputs_faults as faults  # noqa: E402 - the loops the tests run, counted here


def refusal(args: list[str], stdin=None) -> dict:
    """Exit status, wall seconds and peak memory (MB, of that process alone: GNU time's %M, as a child forked
    from this process would count this one's pages) of a command that should refuse its input."""
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, "far.xml").write_text(faults.GOOD.format(start=999999))
        started = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-f", "peak_kb=%M", sys.executable, "-m", "agentsim", *args],
                              cwd=folder, env=faults.env(), stdin=stdin, capture_output=True, text=True)
    lines = proc.stderr.strip().splitlines()
    peak = int(lines[-1].removeprefix("peak_kb="))
    said = [line for line in lines if line.startswith("agentsim:")]
    return {"exit": proc.returncode, "seconds": round(time.perf_counter() - started, 2),
            "peak_rss_mb": round(peak / 1024, 1), "said": said[-1] if said else ""}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="storyteller runs to kill (20)")
    parser.add_argument("--sweeps", type=int, default=20, help="sweeps to kill (20)")
    parser.add_argument("--reports", type=int, default=20, help="realize --report runs to kill (20)")
    parser.add_argument("--seed", type=int, default=28, help="seed of the kill times (28)")
    args = parser.parse_args()
    report: dict = {}
    with tempfile.TemporaryDirectory() as folder:
        story = faults.storyteller_kills(Path(folder), args.runs, args.seed)
    seen = story["seen"]
    report["storyteller"] = {
        "runs": len(seen), "whole_run_s": round(story["whole_s"], 2),
        "killed": sum(k["status"] is None for k in seen), "ended_before_the_kill": sum(k["status"] == 0 for k in seen),
        "left_the_run_before_it": sum(k["digest"] == k["before"] for k in seen),
        "left_its_own_run_whole": sum(k["digest"] != k["before"] and k["digest"] == story["second"] for k in seen),
        "left_anything_else": sum(k["digest"] not in (story["first"], story["second"]) for k in seen),
        "kills_leaving_a_staging_folder": sum(bool(k["beside"]) for k in seen),
        "left_outside_staging": sum(any(not n.startswith(".st.staging-") for n in k["beside"]) for k in seen),
        "left_after_the_next_run": story["leftovers"]}
    if args.sweeps:
        with tempfile.TemporaryDirectory() as folder:
            sweep = faults.sweep_kills(Path(folder), args.sweeps, args.seed)
        seen = sweep["seen"]
        report["sweep"] = {
            "runs": len(seen), "whole_sweep_s": round(sweep["whole_s"], 2),
            "killed": sum(k["status"] is None for k in seen),
            "results_whole": sum(k["csv"] == 4 for k in seen), "results_absent": sum(k["csv"] is None for k in seen),
            "results_partial": sum(k["csv"] not in (None, 4) for k in seen),
            "damaged_points": sum(k["bad_points"] for k in seen),
            "kills_leaving_temporaries": sum(bool(k["hidden"]) for k in seen),
            "next_sweep": {"exit": sweep["final_status"], **sweep["final"]}}
    if args.reports:
        with tempfile.TemporaryDirectory() as folder:
            pages = faults.report_kills(Path(folder), args.reports, args.seed)
        seen = pages["seen"]
        report["report"] = {
            "runs": len(seen), "whole_run_s": round(pages["whole_s"], 2),
            "killed": sum(k["status"] is None for k in seen),
            "left_the_pair_before_it": sum(k["page"] == k["before"] for k in seen),
            "left_its_own_pair": sum(k["page"] != k["before"] and k["page"] == "b.xml" for k in seen),
            "kills_over_the_first_run": sum(k["before"] == "a.xml" for k in seen),
            "left_no_page": sum(k["page"] is None for k in seen),
            "left_a_page_over_other_files": sum(k["page"] not in (None, "a.xml", "b.xml") for k in seen),
            "left_a_broken_bvh": sum(k["bvh"] == -1 for k in seen),
            "kills_leaving_hidden_files": sum(bool(k["hidden"]) for k in seen),
            "left_after_the_next_run": pages["final"]["hidden"]}
    with open("/dev/zero", "rb") as zero:
        report["endless_stdin"] = refusal(["realize", "--tts", "builtin", "-"], stdin=zero)
    report["bvh_a_million_seconds_in"] = refusal(["realize", "--tts", "builtin", "--bvh", "far.bvh", "far.xml"])
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
