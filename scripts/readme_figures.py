#!/usr/bin/env python3
"""The result tables of the documentation's "Measured" page (``docs/measured.md``), made from fresh runs, so
that they cannot go stale.

Each table the script owns sits in the page between ``<!-- figures:NAME -->`` and ``<!-- /figures:NAME -->``.
``python scripts/readme_figures.py`` runs what each table reports and writes the tables into the page;
``--check`` writes nothing and exits 1, printing the difference, when a table differs from a fresh run (CI's
system tests run it); ``--only NAME`` does one table.

Tables:

``storyteller-strategies``
    ``agentsim run storytelling --compare`` (the longest shipped story, every animator-time strategy, seed 0,
    espeak-ng): p50, p95 and max sync error, snaps and stall of each strategy, the best one in bold.
``speech-sync``, ``conductor``
    ``agentsim sweep NAME`` of the shipped sweep spec into a new folder (324 points of ``eval speech-sync``
    with espeak-ng; 40 of ``run conductor``), then ``agentsim sweep report DIR --markdown``: the table as the
    report prints it.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import difflib
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The page whose tables the script owns.
README = ROOT / "docs" / "measured.md"


def figure(value: float) -> str:
    """A figure as the page prints it: three or four significant digits, never a lost integer part."""
    if abs(value) >= 1000:
        return f"{value:.0f}"
    if abs(value) >= 1:
        return f"{value:.1f}"
    return f"{value:.2f}"


def storyteller_strategies() -> str:
    with tempfile.TemporaryDirectory() as tmp:  # the run's folder and its speech cache side by side
        proc = subprocess.run([sys.executable, "-m", "agentsim", "run", "storytelling", "--compare", "--json",
                               "--out", str(Path(tmp) / "run"), "--cache", str(Path(tmp) / "cache")],
                              capture_output=True, text=True, timeout=1800)
    if proc.returncode != 0:
        raise SystemExit(f"readme_figures: run storytelling --compare failed: {proc.stderr.strip()}")
    rows = json.loads(proc.stdout)["strategies"]
    lines = ["| strategy | p50 (ms) | p95 (ms) | max (ms) | snaps | stall (s) |", "|---|---|---|---|---|---|"]
    for name, r in rows.items():
        cells = [name, figure(r["p50_ms"]), figure(r["p95_ms"]), figure(r["max_ms"]), str(r["snaps"]),
                 f"{r['stall_s']:.2f}"]
        if name == "best":
            cells = [f"**{c}**" for c in cells]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def swept(spec: str) -> str:
    """The Markdown table of ``agentsim sweep report`` for a fresh run of the shipped sweep ``spec``."""
    with tempfile.TemporaryDirectory() as out:
        for command in (["sweep", spec, "--out", out, "--quiet"], ["sweep", "report", out, "--markdown",
                                                                    "--png", str(Path(out) / "summary.png")]):
            proc = subprocess.run([sys.executable, "-m", "agentsim", *command], capture_output=True, text=True,
                                  timeout=3600)
            if proc.returncode != 0:
                raise SystemExit(f"readme_figures: agentsim {' '.join(command[:2])} failed: {proc.stderr.strip()}")
    return proc.stdout.strip()


TABLES = {"storyteller-strategies": storyteller_strategies,
          "speech-sync": lambda: swept("speech_sync"),
          "conductor": lambda: swept("conductor")}


def place(text: str, name: str, table: str) -> str:
    pattern = re.compile(rf"(<!-- figures:{re.escape(name)} -->\n).*?(\n<!-- /figures:{re.escape(name)} -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"readme_figures: {README.name} has no '<!-- figures:{name} -->' ... "
                         f"'<!-- /figures:{name} -->' block")
    return pattern.sub(lambda m: m.group(1) + table + m.group(2), text, count=1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs from a run")
    parser.add_argument("--only", choices=sorted(TABLES), help="one table only")
    args = parser.parse_args(argv)
    old = README.read_text(encoding="utf-8")
    new = old
    names = [args.only] if args.only else list(TABLES)
    # each table is a run of processes of its own: they run side by side (each waits for its cluster, its
    # synthesis, its files at times the others compute)
    with concurrent.futures.ThreadPoolExecutor(len(names)) as pool:
        tables = dict(zip(names, pool.map(lambda name: TABLES[name](), names)))
    for name in names:
        new = place(new, name, tables[name])
    if new == old:
        print("readme_figures: every table matches a fresh run", file=sys.stderr)
        return 0
    if args.check:
        sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), new.splitlines(True),
                                                   README.name, f"{README.name} (fresh run)"))
        print("readme_figures: the tables of docs/measured.md differ from a fresh run; "
              "run 'python scripts/readme_figures.py' to update them", file=sys.stderr)
        return 1
    README.write_text(new, encoding="utf-8")
    print(f"readme_figures: {README.name} updated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
