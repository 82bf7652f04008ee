#!/usr/bin/env python3
"""The result tables of the documentation's "Measured" page (``docs/measured.md``) and of its voices page
(``docs/howto/voices.md``), made from fresh runs, so that they cannot go stale.

Each table the script owns sits in its page between ``<!-- figures:NAME -->`` and ``<!-- /figures:NAME -->``.
``python scripts/readme_figures.py`` runs what each table reports and writes the tables into the pages;
``--check`` writes nothing and exits 1, printing the difference, when a table differs from a fresh run (CI runs
it after the documentation's build, ``.ci/run``); ``--only NAME`` does one table. Columns of wall or CPU time
(:data:`MEASURED`), which another run on a machine shared with other work does not repeat to the digit, are
written but not checked.

Tables:

``storyteller-strategies``
    ``agentsim run storytelling --compare`` (the longest shipped story, every animator-time strategy, seed 0,
    espeak-ng): p50, p95 and max sync error, snaps and stall of each strategy, the best one in bold.
``speech-sync``, ``conductor``
    ``agentsim sweep NAME`` of the shipped sweep spec into a new folder (324 points of ``eval speech-sync``
    with espeak-ng; 40 of ``run conductor``), then ``agentsim sweep report DIR --markdown``: the table as the
    report prints it.
``voices`` (in ``docs/howto/voices.md``)
    ``benchmarks/bench_speech_sync.py --tts espeak,festival,piper --storyteller``: espeak-ng, Festival and Piper
    on the three bundled texts, every strategy side by side; each backend's speaking rate, synthesis real-time
    factor and first-synthesis latency; the storyteller with each backend on every shipped story.
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
#: The page whose tables the script owns (but those of :data:`PAGES`).
README = ROOT / "docs" / "measured.md"
#: Tables on another page, by name.
PAGES = {"voices": ROOT / "docs" / "howto" / "voices.md"}
#: Headers of columns of wall or CPU time: written, not checked.
MEASURED = frozenset({"synthesis s", "real-time factor", "CPU real-time factor", "first synthesis s"})


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


def voices() -> str:
    """espeak-ng, Festival and Piper side by side, from a fresh ``benchmarks/bench_speech_sync.py`` run."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_speech_sync.py"), "--tts",
                           "espeak,festival,piper", "--storyteller"], capture_output=True, text=True, timeout=3600,
                          cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"readme_figures: bench_speech_sync.py failed: {proc.stderr.strip()}")
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from bench_speech_sync import markdown
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return markdown(json.loads(proc.stdout))


TABLES = {"storyteller-strategies": storyteller_strategies,
          "speech-sync": lambda: swept("speech_sync"),
          "conductor": lambda: swept("conductor"),
          "voices": voices}


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


#: The first cells of the header rows of the tables the script writes.
HEADS = ("backend", "timing", "strategy", "story")


def _table_rows(text: str):
    """Each line of ``text`` with the header (cells) of the table it is in, and its own cells: None for a
    header, a rule or a line outside a table."""
    header = None
    for line in text.splitlines():
        cells = None
        if line.startswith("|") and not line.startswith("|---"):
            cells = _cells(line)
            if header is None or cells[0] in HEADS:
                header, cells = cells, None
        elif not line.strip():
            header = None
        yield line, header, cells


def keep_measured(old: str, new: str) -> str:
    """``new`` with the cells of :data:`MEASURED` columns taken from ``old`` (the same table as written before),
    row by row, where both have the row's first cell and the same header."""
    before = {(tuple(header), tuple(cells[:2])): cells for _, header, cells in _table_rows(old) if cells is not None}
    lines = []
    for line, header, cells in _table_rows(new):
        if cells is not None:
            was = before.get((tuple(header), tuple(cells[:2])))
            if was is not None and len(was) == len(cells):
                cells = [w if h in MEASURED else c for h, c, w in zip(header, cells, was)]
                line = "| " + " | ".join(cells) + " |"
        lines.append(line)
    return "\n".join(lines)


def place(text: str, name: str, table: str, keep: bool = False, page: str = "measured.md") -> str:
    """``text`` with the block of table ``name`` replaced by ``table`` (``keep``: its :data:`MEASURED` cells as they
    were)."""
    pattern = re.compile(rf"(<!-- figures:{re.escape(name)} -->\n)(.*?)(\n<!-- /figures:{re.escape(name)} -->)", re.S)
    found = pattern.search(text)
    if not found:
        raise SystemExit(f"readme_figures: {page} has no '<!-- figures:{name} -->' ... "
                         f"'<!-- /figures:{name} -->' block")
    if keep:
        table = keep_measured(found.group(2), table)
    return pattern.sub(lambda m: m.group(1) + table + m.group(3), text, count=1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs from a run")
    parser.add_argument("--only", choices=sorted(TABLES), help="one table only")
    args = parser.parse_args(argv)
    old: dict[Path, str] = {}
    new: dict[Path, str] = {}
    names = [args.only] if args.only else list(TABLES)
    # each table is a run of processes of its own: they run side by side (each waits for its cluster, its
    # synthesis, its files at times the others compute)
    with concurrent.futures.ThreadPoolExecutor(len(names)) as pool:
        tables = dict(zip(names, pool.map(lambda name: TABLES[name](), names)))
    for name in names:
        page = PAGES.get(name, README)
        if page not in old:
            old[page] = new[page] = page.read_text(encoding="utf-8")
        new[page] = place(new[page], name, tables[name], keep=args.check, page=page.name)
    changed = [page for page in old if new[page] != old[page]]
    if not changed:
        print("readme_figures: every table matches a fresh run", file=sys.stderr)
        return 0
    if args.check:
        for page in changed:
            sys.stdout.writelines(difflib.unified_diff(old[page].splitlines(True), new[page].splitlines(True),
                                                       page.name, f"{page.name} (fresh run)"))
        print(f"readme_figures: the tables of {', '.join(p.name for p in changed)} differ from a fresh run; "
              "run 'python scripts/readme_figures.py' to update them", file=sys.stderr)
        return 1
    for page in changed:
        page.write_text(new[page], encoding="utf-8")
        print(f"readme_figures: {page.name} updated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
