"""The layers of the four packages: every module's imports point down or sideways, never up, and never in a
circle.

The layers, lowest first (``docs/explanation/architecture.md``, "The layers", says the same in prose):

* the error root: ``agentsim.errors`` (and the ``agentsim`` package itself, which holds only its version),
  which every package can reach;
* ``speech_timing``: text-to-speech backends with word and phoneme timing, event delivery, the linear
  model, animator-time strategies, speech metrics;
* the realizer (``agentsim``), itself in layers: its core (the clock, PegBoard, block model, plan, solver,
  scheduler, feedback, the anticipator interface, the recording); libraries that know nothing of the
  realizer (reading BML, music rendering, animation); engines and media; the realizer that wires them;
* ``anticipators``: the beat tracker (``anticipators.beats``), then the metronome, tap tempo, audio beat
  anticipator, plugin registry and template;
* ``scenarios``: the conductor, the storyteller, the speech-sync measurement;
* on top of everything: the command line (``agentsim.cli``) and the live service (``agentsim.live``).

Every import statement counts, including those inside functions and under ``TYPE_CHECKING``: an
import that is only deferred is still a dependency.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The four top-level packages of the design card.
PACKAGES = ("agentsim", "speech_timing", "anticipators", "scenarios")

LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("root: errors and whole-or-nothing writing", ("agentsim", "agentsim.errors", "agentsim.written")),
    ("speech timing", ("speech_timing",)),
    ("realizer core", ("agentsim.core", "agentsim.examples", "agentsim.anticipators")),
    ("realizer libraries", ("agentsim.bml", "agentsim.music", "agentsim.animation", "agentsim.physics")),
    ("realizer parts", ("agentsim.engines", "agentsim.media")),
    ("realizer", ("agentsim.realizer",)),
    ("beat tracking", ("anticipators.beats",)),
    ("anticipators", ("anticipators",)),
    ("scenarios", ("scenarios",)),
    ("command line and live service", ("agentsim.cli", "agentsim.live", "agentsim.__main__")),
]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


#: Every module of the four packages (files in folders that are not Python names, such as the example plugin
#: ``agentsim/examples/plugins/agentsim-countin``, are programs shipped for users to copy, not modules).
MODULES = {module_name(p): p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))
           if all(part.isidentifier() for part in p.relative_to(ROOT).parent.parts)}


def unit_of(module: str) -> str:
    """The package (or top module) of the layer table that a module belongs to: the longest match."""
    best = ""
    for _, units in LAYERS:
        for unit in units:
            if (module == unit or module.startswith(unit + ".")) and len(unit) > len(best):
                best = unit
    return best


RANK = {unit: rank for rank, (_, units) in enumerate(LAYERS) for unit in units}


def imports_of(module: str) -> set[str]:
    """The agentsim modules that ``module`` imports (a package's ``__init__`` counts as the package)."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module or ""
            # ``from package import submodule`` depends on the submodule; any other name, on the package
            names = [f"{origin}.{a.name}" if f"{origin}.{a.name}" in MODULES else origin for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name and name != module:
                found.add(name)
    return found


GRAPH = {m: imports_of(m) for m in MODULES}


def test_every_module_has_a_layer():
    assert [m for m in MODULES if not unit_of(m)] == []


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every import in ``graph`` that points to a higher layer."""
    upward = []
    for module, targets in graph.items():
        for target in targets:
            source_unit, target_unit = unit_of(module), unit_of(target)
            if RANK[target_unit] > RANK[source_unit]:
                upward.append(f"{module} ({source_unit}) imports {target} ({target_unit})")
    return upward


def test_no_import_points_up():
    assert upward_imports(GRAPH) == []


@pytest.mark.parametrize("module, target", [
    ("speech_timing.backend", "agentsim.core.block"),        # speech timing knows nothing of the realizer
    ("agentsim.errors", "speech_timing.backend"),            # the error root imports nothing
    ("agentsim.core.scheduler", "anticipators.audio"),       # the realizer knows only the interface
    ("agentsim.realizer", "anticipators.registry"),
    ("agentsim.media.report.data", "anticipators.beats.tracking"),
    ("anticipators.beats.tracking", "anticipators.audio"),   # the tracker knows nothing of the anticipator
    ("anticipators.audio", "scenarios.conductor.scenario"),
    ("scenarios.storytelling.run", "agentsim.cli.options"),  # the command line sits on top
    ("scenarios.conductor.hearing", "agentsim.live.sound"),
])
def test_an_import_against_the_layers_fails(module, target):
    assert upward_imports({module: {target}}) != []
    assert upward_imports({target: {module}}) == []


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        top = stack.pop()
                        on_stack.discard(top)
                        component.append(top)
                        if top == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
            elif child not in index:
                index[child] = low[child] = counter
                counter += 1
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(sorted(graph.get(child, ())))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return found


def test_no_import_cycle_between_modules():
    assert _cycles(GRAPH) == []


def test_no_import_cycle_between_packages():
    units: dict[str, set[str]] = {}
    for module, targets in GRAPH.items():
        source = unit_of(module)
        units.setdefault(source, set()).update(unit_of(t) for t in targets if unit_of(t) != source)
    assert _cycles(units) == []


def test_the_checks_catch_what_they_are_meant_to():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert unit_of("agentsim.core.scheduler") == "agentsim.core"
    assert unit_of("agentsim.cli.speech") == "agentsim.cli"
    assert RANK[unit_of("agentsim.engines.speech")] > RANK[unit_of("speech_timing.backend")]
    assert "agentsim.core.pegboard" in GRAPH["agentsim.core.timed"]


@pytest.mark.parametrize("module", sorted(MODULES))
def test_module_says_what_it_is(module):
    """Every module opens with a docstring (one sentence at least) saying what lives there."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    assert ast.get_docstring(tree), f"{module} has no docstring"


def _private_names_defined(tree: ast.AST) -> set[str]:
    """Private names a module defines: attributes it assigns, slots, methods, functions and classes."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("_"):
            names.add(node.value)  # __slots__ entries
    return {n for n in names if n.startswith("_") and not n.startswith("__")}


TREES = {m: ast.parse(p.read_text(encoding="utf-8")) for m, p in MODULES.items()}
OURS = set().union(*(_private_names_defined(t) for t in TREES.values()))


def test_no_module_touches_another_modules_private_names():
    """``obj._name`` only where this module defines ``_name``, and no ``from module import _name``."""
    found = []
    for module, tree in TREES.items():
        own = _private_names_defined(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in PACKAGES:
                found += [f"{module}: from {node.module} import {a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
            elif (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                  and node.attr in OURS and node.attr not in own):
                found.append(f"{module}:{node.lineno}: {ast.unparse(node)}")
    assert found == []
