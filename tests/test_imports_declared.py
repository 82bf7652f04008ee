"""Every module the four packages import is the standard library's, one of the four, a declared dependency, or
an extra's imported lazily with a one-line error naming ``pip install 'agentsim[EXTRA]'``.

The scan reads the source (``ast``), not what happens to be installed: an import of a package that
``pyproject.toml`` does not declare fails here even when the machine has it.
"""

from __future__ import annotations

import ast
import functools
import importlib.metadata as metadata
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("agentsim", "speech_timing", "anticipators", "scenarios")


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement(text: str) -> tuple[str, list[str]]:
    """A requirement's distribution and extras: ``dask[distributed]>=2024.1`` -> ``dask``, ``[distributed]``."""
    match = re.match(r"\s*([A-Za-z0-9_.-]+)\s*(?:\[([^\]]*)\])?", text)
    return _normal(match.group(1)), [e.strip() for e in (match.group(2) or "").split(",") if e.strip()]


def _with_extras(requirements: list[str]) -> set[str]:
    """The distributions named, and those their named extras bring (``dask[distributed]``: distributed)."""
    out = set()
    for text in requirements:
        name, extras = _requirement(text)
        out.add(name)
        try:
            brought = metadata.requires(name) or []
        except metadata.PackageNotFoundError:  # an extra's package not installed here
            brought = []
        for requirement in brought:
            marker = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", requirement)
            if marker and marker.group(1) in extras:
                out.add(_requirement(requirement)[0])
    return out


def _declared() -> tuple[set[str], dict[str, set[str]]]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = {extra: _with_extras(reqs) for extra, reqs in project.get("optional-dependencies", {}).items()}
    return _with_extras(project["dependencies"]), extras


def _imports(path: Path) -> list[tuple[str, bool]]:
    """Top-level names a module imports, each with whether the import is at the module's top level."""
    tree = ast.parse(path.read_text(), str(path))
    top = {id(node) for node in tree.body}
    for node in tree.body:  # imports under a module-level if/try are still made when the module is
        if isinstance(node, (ast.If, ast.Try)):
            top |= {id(n) for n in ast.walk(node)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(alias.name.split(".")[0], id(node) in top) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.module.split(".")[0], id(node) in top))
    return out


@functools.cache
def _installed() -> dict[str, list[str]]:
    return metadata.packages_distributions()


def _distributions(module: str) -> set[str]:
    return {_normal(d) for d in _installed().get(module, [])}


def test_every_import_is_standard_own_declared_or_a_lazy_extra():
    required, extras = _declared()
    problems = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            source = path.read_text()
            for module, at_top in _imports(path):
                if module in sys.stdlib_module_names or module in PACKAGES or module == "__future__":
                    continue
                dists = _distributions(module) or {_normal(module)}
                if dists & required:
                    continue
                named = [extra for extra, members in extras.items() if dists & members]
                where = path.relative_to(ROOT)
                if not named:
                    problems.append(f"{where}: imports {module}, which pyproject.toml does not declare")
                elif at_top:
                    problems.append(f"{where}: imports {module} (extra {named[0]}) when it is imported")
                elif not any(f"pip install 'agentsim[{extra}]'" in source for extra in named):
                    problems.append(f"{where}: imports {module} without naming pip install 'agentsim[{named[0]}]'")
    assert problems == []


def test_the_scan_finds_an_undeclared_import(tmp_path, monkeypatch):
    """The scan is not vacuous: a module importing a package nobody declared is reported."""
    fake = tmp_path / "agentsim"
    fake.mkdir()
    (fake / "m.py").write_text("import yaml\n\n\ndef f():\n    import aubio\n")
    assert _imports(fake / "m.py") == [("yaml", True), ("aubio", False)]
    required, extras = _declared()
    assert "numpy" in required and "distributed" in required  # dask[distributed] brings distributed
    assert not ({"pyyaml", "yaml"} & required) and "aubio" in extras["bench"]
