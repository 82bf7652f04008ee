"""Scenarios that use the realizer: the virtual conductor, the virtual storyteller, the reactive trainer, and
the speech-sync measurement (beats on every content word)."""

from __future__ import annotations

import json
from pathlib import Path


def first_comment(path: Path) -> str:
    """The first non-empty ``#`` comment line of a shipped TOML file (what ``--list-configs`` and
    ``--list-specs`` print beside its name), or ''."""
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.lstrip("#").strip()
        if line.startswith("#") and text:
            return text
    return ""


def write_comparison(out: Path, shown: Path, rows: list[dict], heading: str, header: str, lines: list[str],
                     table) -> None:
    """The end of a run of every strategy: ``heading``, the table's ``header`` and a line per strategy printed to
    ``table``, the strategies' figures (``rows``) written to ``out/compare.json``, and where it all is (``shown``:
    the folder as the user named it)."""
    from agentsim.media.files import write_text

    print(heading, file=table)
    print(header, file=table)
    for line in lines:
        print(line, file=table)
    write_text(Path(out) / "compare.json", json.dumps(rows, indent=2) + "\n")
    print(f"written to {shown}/<strategy>/ and {Path(shown) / 'compare.json'}", file=table)
