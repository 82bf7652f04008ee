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
    ("realizer libraries", ("agentsim.bml", "agentsim.music", "agentsim.animation", "agentsim.physics",
                             "agentsim.expression")),
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


#: The scheduler's parts, and the life cycle of the runs and behaviours they share: each attribute a part owns
#: is written (assigned, deleted, an item set, or changed in place by ``append``, ``update`` and the like)
#: only by that class, through ``self``, and set up in its ``__init__`` (no part writes what another part or
#: a mixin base set up). ``(module, class)`` -> the attributes it owns (None: what its ``__init__`` sets on
#: ``self``, but for the collaborators it is handed, bound from a parameter of the same name).
OWNERS: dict[tuple[str, str], tuple[str, ...] | None] = {
    ("agentsim.core.book", "BlockBook"): None,
    ("agentsim.core.reporter", "Reporter"): None,
    ("agentsim.core.composition", "Composer"): None,
    ("agentsim.core.retiming", "Retimer"): None,
    ("agentsim.core.retiming", "Dependants"): None,
    ("agentsim.core.interruption", "Interrupter"): None,
    ("agentsim.core.scheduler", "Scheduler"): None,
    ("agentsim.core.scheduler", "BlockControl"): None,
    ("agentsim.core.timed", "BlockRun"): ("state", "ended_at"),
    ("agentsim.core.timed", "TimedBehaviour"): ("state", "_state"),
}

#: Methods that change a list, dict or set in place.
MUTATORS = frozenset({"append", "extend", "insert", "remove", "pop", "clear", "update", "add", "discard",
                      "setdefault", "popitem", "sort", "reverse"})


def _classes(tree: ast.AST) -> dict[str, ast.ClassDef]:
    return {node.name: node for node in ast.walk(tree) if isinstance(node, ast.ClassDef)}


def _set_up(cls: ast.ClassDef, handed: bool = True) -> set[str]:
    """What a class sets up: the attributes its ``__init__`` assigns on ``self``, and its annotated fields;
    ``handed=False``: not those bound from a parameter of the same name (``self.env = env``)."""
    names = {node.target.id for node in cls.body if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)}
    for method in cls.body:
        if isinstance(method, ast.FunctionDef) and method.name == "__init__":
            for node in ast.walk(method):
                if not isinstance(node, ast.Assign):
                    continue
                for target in node.targets:
                    if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == "self":
                        bound = isinstance(node.value, ast.Name) and node.value.id == target.attr
                        if handed or not bound:
                            names.add(target.attr)
            names |= {node.target.attr for node in ast.walk(method) if isinstance(node, (ast.AugAssign, ast.AnnAssign))
                      and isinstance(node.target, ast.Attribute) and isinstance(node.target.value, ast.Name)
                      and node.target.value.id == "self"}
    return names


def _writes(tree: ast.AST):
    """``(class, receiver, attribute, line)`` of every attribute written in a module (class None: outside any)."""
    def visit(node: ast.AST, cls: str | None):
        for child in ast.iter_child_nodes(node):
            inner = child.name if isinstance(child, ast.ClassDef) else cls
            target = None
            if isinstance(child, ast.Attribute) and isinstance(child.ctx, (ast.Store, ast.Del)):
                target = child
            elif (isinstance(child, ast.Subscript) and isinstance(child.ctx, (ast.Store, ast.Del))
                  and isinstance(child.value, ast.Attribute)):
                target = child.value
            elif (isinstance(child, ast.Call) and isinstance(child.func, ast.Attribute) and child.func.attr in MUTATORS
                  and isinstance(child.func.value, ast.Attribute)):
                target = child.func.value
            if target is not None:
                yield cls, target.value, target.attr, child.lineno
            yield from visit(child, inner)
    yield from visit(tree, None)


def writes_outside_owners(trees: dict[str, ast.AST], owners: dict[tuple[str, str], tuple[str, ...] | None],
                          graph: dict[str, set[str]]) -> list[str]:
    """Every write of an attribute that ``owners`` gives a class, made anywhere but in that class through
    ``self``; and every write through ``self`` by an owner (of all it has) of what its ``__init__`` does not set
    up, or by any other class of an owned name that it does not set up itself (a mixin's).

    Writes through other objects are looked for in the owners' package and the modules that import an
    owner's module (``graph``: the imports of each module), the modules that can know the parts: elsewhere an
    attribute of the same name is another class's.
    """
    owned: dict[tuple[str, str], set[str]] = {}
    for (module, name), attributes in owners.items():
        cls = _classes(trees[module]).get(name)
        assert cls is not None, f"{module} has no class {name}"
        owned[(module, name)] = _set_up(cls, handed=False) if attributes is None else set(attributes)
    anyone = set().union(*owned.values())
    homes = {module for module, _ in owners}
    packages = {module.rpartition(".")[0] for module in homes}
    found = []
    for module, tree in trees.items():
        classes = _classes(tree)
        knows = module.rpartition(".")[0] in packages or bool(graph.get(module, set()) & homes) or module in homes
        for cls, receiver, attribute, line in _writes(tree):
            if isinstance(receiver, ast.Name) and receiver.id == "self" and cls is not None:
                if (module, cls) in owned:
                    if attribute in _set_up(classes[cls]) or owners[(module, cls)] is not None:
                        continue  # its own (a class that owns only some of its attributes: the rest are not checked)
                elif attribute not in anyone or attribute in _set_up(classes[cls]):
                    continue  # another class's attribute, or one of its own that is named as an owned one is
            elif attribute not in anyone or not knows:
                continue
            found.append(f"{module}:{line}: {ast.unparse(receiver)}.{attribute} (in {cls or 'the module'})")
    return found


def test_no_attribute_of_the_schedulers_parts_is_written_outside_its_owner():
    assert writes_outside_owners(TREES, OWNERS, GRAPH) == []


def test_the_ownership_check_catches_what_it_is_meant_to():
    trees = {
        "core.book": ast.parse("class Book:\n    def __init__(self):\n        self.drops = []\n        self.version = 0\n"
                          "    def bump(self):\n        self.version += 1\n"),
        "core.parts": ast.parse("class Part:\n    def __init__(self, book):\n        self.book = book\n"
                           "    def cut(self):\n        self.book.drops.append(1)\n        self.book.version += 1\n"
                           "        self.book.drops[0] = 2\n        self.later = 1\n"
                           "class Mixin:\n    def bump(self):\n        self.version += 1\n"),
        # another class's attribute of the same name, through self or not, in a module that knows no part
        "media.plan": ast.parse("class Plan:\n    def __init__(self):\n        self.drops = []\n"
                                "    def f(self, other):\n        self.drops.append(1)\n        other.drops = []\n"),
        # ... and in a module that imports a part's module
        "media.user": ast.parse("def f(book):\n    book.version = 3\n"),
    }
    graph = {"media.user": {"core.book"}}
    found = writes_outside_owners(trees, {("core.book", "Book"): None, ("core.parts", "Part"): None}, graph)
    assert found == ["core.parts:5: self.book.drops (in Part)", "core.parts:6: self.book.version (in Part)",
                     "core.parts:7: self.book.drops (in Part)", "core.parts:8: self.later (in Part)",
                     "core.parts:11: self.version (in Mixin)", "media.user:2: book.version (in the module)"]
