"""The sweep specs that reproduce the measured tables (``docs/measured.md``), shipped with the package:
``agentsim sweep NAME`` runs one by its short name (``speech_sync``, ``conductor``), ``agentsim sweep
--list-specs`` lists them."""

from __future__ import annotations

from pathlib import Path

#: Where the shipped specs are.
HOME = Path(__file__).resolve().parent


def names() -> list[str]:
    """The short names of the shipped specs, sorted."""
    return sorted(p.stem for p in HOME.glob("*.toml"))


def find(name: str) -> Path | None:
    """The shipped spec of that short name (``speech_sync`` or ``speech_sync.toml``), or None."""
    path = HOME / (name if name.endswith(".toml") else f"{name}.toml")
    return path if "/" not in name and path.is_file() else None


def describe(name: str) -> str:
    """The first line of a shipped spec's opening comment."""
    from scenarios import first_comment

    return first_comment(HOME / f"{name}.toml")
