"""Scenarios that use the realizer: the virtual conductor, the virtual storyteller, and the speech-sync
measurement (beats on every content word)."""

from __future__ import annotations

from pathlib import Path


def first_comment(path: Path) -> str:
    """The first non-empty ``#`` comment line of a shipped TOML file (what ``--list-configs`` and
    ``--list-specs`` print beside its name), or ''."""
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.lstrip("#").strip()
        if line.startswith("#") and text:
            return text
    return ""
