"""The generated pages of the documentation: one per command and nested command (from the argument parser)
and one per public module of the four packages (from the source tree). ``docs/conf.py`` runs
:func:`generate` when a build starts; the pages are written into ``reference/cli`` and ``reference/api``
(folders that are not committed), each only when its text changed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

#: The four top-level packages whose modules get an API page.
PACKAGES = ("agentsim", "speech_timing", "anticipators", "scenarios")


def public_modules(root: Path) -> list[str]:
    """The dotted names of the public modules of :data:`PACKAGES` (no ``_private`` part, no ``__main__``;
    files in folders that are not Python names, such as a plugin shipped as an example, are programs)."""
    names = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if not all(part.isidentifier() for part in parts[:-1]):
                continue
            if parts[-1] == "__init__":
                parts.pop()
            if any(part.startswith("_") for part in parts):
                continue
            names.append(".".join(parts))
    return sorted(names)


def command_paths(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command and nested command of ``parser``, as the words after the program's name."""
    found = [path] if path else []
    for action in parser._actions:  # argparse offers its sub-parsers no other way
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if sub is not parser:
                    found += command_paths(sub, (*path, name))
    return found


def _title(text: str) -> str:
    return f"{text}\n{'=' * len(text)}\n"


def _write(path: Path, text: str) -> None:
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


def _prune(folder: Path, keep: set[str]) -> None:
    for old in folder.glob("*.rst"):
        if old.name not in keep:
            old.unlink()


def generate(docs: Path) -> None:
    root = docs.parent
    api = docs / "reference" / "api"
    modules = public_modules(root)
    keep = {"index.rst"}
    for name in modules:
        keep.add(f"{name}.rst")
        _write(api / f"{name}.rst", _title(name) + f"\n.. automodule:: {name}\n")
    toc = "\n".join(f"   {name}" for name in modules)
    _write(api / "index.rst", _title("API") + "\nEvery public module of the four packages, by its dotted name: its "
           "docstring first, then its classes and functions.\n\n.. toctree::\n   :maxdepth: 1\n\n" + toc + "\n")
    _prune(api, keep)

    from agentsim.cli import build_parser

    cli = docs / "reference" / "cli"
    paths = command_paths(build_parser())
    keep = {"index.rst"}
    for path in paths:
        name = "-".join(path)
        keep.add(f"{name}.rst")
        _write(cli / f"{name}.rst", _title("agentsim " + " ".join(path)) + "\n.. argparse::\n"
               "   :module: agentsim.cli\n   :func: build_parser\n   :prog: agentsim\n"
               f"   :path: {' '.join(path)}\n   :nosubcommands:\n")
    toc = "\n".join(f"   {'-'.join(path)}" for path in paths)
    _write(cli / "index.rst", _title("Commands") + "\nEvery command and nested command of ``agentsim``, each with "
           "its options, generated from the argument parser.\n\n.. argparse::\n   :module: agentsim.cli\n"
           "   :func: build_parser\n   :prog: agentsim\n   :nosubcommands:\n\n.. toctree::\n   :maxdepth: 1\n\n"
           + toc + "\n")
    _prune(cli, keep)
