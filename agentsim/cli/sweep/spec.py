"""A sweep's spec (``SPEC.toml``): the command, the grid and the fixed options, checked against the real parser
of the command before any work, and expanded into points, each with its command line and its cache key.

The format::

    command = ["eval", "speech-sync"]       # any agentsim command that prints --json
    keep_outputs = false                    # keep each point's --out folder in DIR/outputs/<point>/,
                                            # <point> its values: strategy=best,seed=1,condition=A
    [grid]                                  # every combination of these is one point
    strategy = ["best", "chang-naive"]
    seed = [1, 2, 3]
    [grid.condition]                        # a named axis: each name sets several options at once
    A = { delay = 0.05, jitter = 0.03 }
    B = { delay = 0.05, jitter = 0.10 }
    [fixed]                                 # the same for every point
    tts = "builtin"
    text = "story.txt"                      # a file: relative to the spec's folder
    [report]                                # defaults of 'agentsim sweep report'
    metrics = ["error_ms.p95", "snaps"]
    axis = "condition"
    by = "strategy"
    over = ["seed"]

A key is an option of the command by its long name (``burst-hold`` or ``burst_hold``) or its destination,
or a positional argument by its name. ``true`` gives a flag, ``false`` leaves it out; a list under
``[fixed]`` repeats an option that may be repeated. ``json`` and ``out`` are the sweep's: it asks every
point for ``--json`` and gives each its own ``--out``.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import itertools
import json
import re
import shlex
import tomllib
from contextlib import redirect_stderr, redirect_stdout
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from agentsim.errors import UsageError

#: Keys of a spec's top level and of its [report] table.
TOP_KEYS = ("command", "grid", "fixed", "report", "keep_outputs")
REPORT_KEYS = ("metrics", "axis", "by", "over")
#: Options the sweep sets itself.
SWEEP_OPTIONS = ("json", "out", "help")
#: Columns every row has beside the grid's and the metrics'.
ROW_COLUMNS = ("status", "error", "seconds", "worker", "attempts", "point", "command")
#: The most points a sweep runs unless ``--max-points N`` allows more. The points are made as they are sent to
#: the workers, but each one's row is kept in memory until the results are written.
MAX_POINTS = 10_000
#: From how many points a sweep says their count before it checks the grid's values.
SAY_COUNT = 1_000


@dataclass(frozen=True)
class Point:
    """One point of the grid: its values (a named axis by its name), the command line that computes it
    (with ``--json``; the sweep adds ``--out`` where the command takes one) and its cache key."""

    values: dict
    argv: tuple[str, ...]
    key: str
    at: tuple[int, ...] = field(default=(), compare=False, repr=False)  # the index of each value in its axis


@dataclass
class Spec:
    """A checked sweep spec."""

    path: Path
    command: tuple[str, ...]
    grid: dict  # key -> list of values, or {name: {key: value}} for a named axis
    fixed: dict
    report: dict = field(default_factory=dict)
    keep_outputs: bool = False
    takes_out: bool = False  # the command writes into --out
    points: "Points | list[Point]" = field(default_factory=list)

    @property
    def name(self) -> str:
        return " ".join(self.command)

    def to_json(self) -> dict:
        """What ``agentsim sweep report`` needs to know of the spec (written to ``DIR/sweep.json``)."""
        return {"spec": str(self.path), "command": list(self.command), "grid": self.grid, "fixed": self.fixed,
                "report": self.report, "keep_outputs": self.keep_outputs, "points": len(self.points)}


@lru_cache(maxsize=1)
def work_parser() -> argparse.ArgumentParser:
    """The parser of the commands a sweep can run (built once per process)."""
    from agentsim.cli.commands import build_parser

    return build_parser()


def subparser_of(command: tuple[str, ...]) -> argparse.ArgumentParser | None:
    """The parser of ``command`` (``("eval", "speech-sync")``), or None if there is no such command."""
    parser = work_parser()
    for word in command:
        choices = subparsers_of(parser)
        if word not in choices:
            return None
        parser = choices[word]
    return None if subparsers_of(parser) else parser  # a group of commands ("eval") is no command


# argparse offers no public way to walk its commands and options: these four read its attributes.
def subparsers_of(parser: argparse.ArgumentParser) -> dict:
    """The commands under ``parser`` by name ({} for a command)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def flags_of(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """The options of ``parser`` by each of their flags."""
    return dict(parser._option_string_actions)


def actions_of(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return list(parser._actions)


def exclusive_groups(parser: argparse.ArgumentParser) -> list[set[str]]:
    """The destinations of the options of each mutually exclusive group of ``parser``."""
    return [{action.dest for action in group._group_actions} for group in parser._mutually_exclusive_groups]


def json_commands() -> list[str]:
    """Every command whose parser has ``--json``, by its words."""
    found = []

    def walk(parser, words):
        children = subparsers_of(parser)
        if not children and "--json" in flags_of(parser):
            found.append(" ".join(words))
        for name, child in children.items():
            walk(child, words + [name])

    walk(work_parser(), [])
    return found


def find_action(parser: argparse.ArgumentParser, key: str) -> argparse.Action | None:
    """The option or positional argument of ``parser`` that a spec key names."""
    flags = flags_of(parser)
    for flag in (f"--{key}", f"--{key.replace('_', '-')}"):
        if flag in flags:
            return flags[flag]
    for action in actions_of(parser):
        if action.dest == key.replace("-", "_"):
            return action
    return None


def count(grid: dict) -> int:
    """How many points ``grid`` makes (the product of its axes' lengths), without making them."""
    total = 1
    for values in grid.values():
        total *= len(values)
    return total


def load(path: str | Path, max_points: int | None = None, say=None) -> Spec:
    """Read and check a spec; every mistake is a :class:`UsageError` of one line naming it. The grid's
    points are counted first (``say`` is told how many, from :data:`SAY_COUNT` on) and refused past
    ``max_points`` (default :data:`MAX_POINTS`) before any is made; then every value of the grid is checked
    (:class:`Points`), and the points are made only when they are asked for."""
    path = Path(path)
    where = f"sweep spec {str(path)!r}"
    if not path.exists() and len(path.parts) == 1:
        from scenarios import sweeps

        path = sweeps.find(path.name) or path
    if not path.is_file():
        raise UsageError(f"no {where}")
    try:
        from agentsim.core.inputs import read_text

        data = tomllib.loads(read_text(path, what=where))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"{where} is not TOML: {exc}") from None
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise UsageError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(TOP_KEYS)})")
    command = data.get("command")
    if isinstance(command, str):
        command = command.split()
    if not command or not isinstance(command, list) or not all(isinstance(w, str) for w in command):
        raise UsageError(f"{where}: 'command' must name a command, e.g. command = [\"eval\", \"speech-sync\"]")
    command = tuple(command)
    parser = subparser_of(command)
    if parser is None:
        raise UsageError(f"{where}: unknown command {' '.join(command)!r}; a sweep runs one of: "
                         f"{', '.join(json_commands())}")
    if "--json" not in flags_of(parser):
        raise UsageError(f"{where}: 'agentsim {' '.join(command)}' prints no --json; a sweep runs one of: "
                         f"{', '.join(json_commands())}")
    grid, fixed, report = data.get("grid", {}), data.get("fixed", {}), data.get("report", {})
    for name, table in (("grid", grid), ("fixed", fixed), ("report", report)):
        if not isinstance(table, dict):
            raise UsageError(f"{where}: [{name}] must be a table")
    keep = data.get("keep_outputs", False)
    if not isinstance(keep, bool):
        raise UsageError(f"{where}: keep_outputs must be true or false")
    spec = Spec(path=path.resolve(), command=command, grid=grid, fixed=fixed, report=report, keep_outputs=keep,
                takes_out="--out" in flags_of(parser))
    check_keys(spec, parser, where)
    check_report(spec, where)
    total, most = count(grid), MAX_POINTS if max_points is None else max_points
    if say is not None and total >= SAY_COUNT:
        say(f"agentsim: {where}: {total} points of 'agentsim {spec.name}', checking the grid's values")
    if total > most:
        raise UsageError(f"{where}: the grid makes {total} points, more than the {most} a sweep runs"
                         + (" without --max-points N" if max_points is None else " with this --max-points")
                         + f" (give --max-points {total} to run them all)")
    spec.points = Points(spec, parser, where)
    return spec


def check_keys(spec: Spec, parser: argparse.ArgumentParser, where: str) -> None:
    """Every key names an option of the command, and each option is set in one place only."""
    places: list[tuple[str, str]] = [(key, "[fixed]") for key in spec.fixed]
    for key, values in spec.grid.items():
        if key in ROW_COLUMNS:
            raise UsageError(f"{where}: grid key {key!r} is the name of a column of the results; call it otherwise")
        if isinstance(values, dict):  # a named axis: its name is no option, the options of each name are
            if not values or not all(isinstance(v, dict) and v for v in values.values()):
                raise UsageError(f"{where}: named axis {key!r} must map each name to a table of options, "
                                 f"e.g. A = {{ delay = 0.05, jitter = 0.03 }}")
            options = dict.fromkeys(k for v in values.values() for k in v)
            places += [(option, f"[grid] {key}") for option in options]
        elif not isinstance(values, list) or not values:
            raise UsageError(f"{where}: grid key {key!r} must be a list of at least one value")
        else:
            places.append((key, "[grid]"))
    seen: dict[str, tuple[str, str]] = {}
    for key, place in places:
        action = find_action(parser, key)
        if action is None:
            raise UsageError(f"{where}: unknown option {key!r} of 'agentsim {spec.name}'")
        if action.dest in SWEEP_OPTIONS:
            raise UsageError(f"{where}: option {key!r} is the sweep's own (it gives every point --json and its "
                             f"own --out)")
        if action.dest in seen:
            other, other_place = seen[action.dest]
            raise UsageError(f"{where}: option {key!r} is set both in {other_place} and in {place}"
                             if other == key else f"{where}: {key!r} and {other!r} are the same option")
        seen[action.dest] = (key, place)


def check_report(spec: Spec, where: str) -> None:
    report = spec.report
    unknown = [k for k in report if k not in REPORT_KEYS]
    if unknown:
        raise UsageError(f"{where}: unknown key {unknown[0]!r} in [report] (known: {', '.join(REPORT_KEYS)})")
    for key in ("over", "metrics"):
        if isinstance(report.get(key), str):
            report[key] = [report[key]]
    for key in ["axis", "by"] + [f"over {k}" for k in report.get("over", [])]:
        name = report.get(key) if not key.startswith("over ") else key[5:]
        if name is not None and name not in spec.grid:
            raise UsageError(f"{where}: [report] {key.split()[0]} = {name!r} is no grid key")


class Points(Sequence):
    """The grid's points, in the order of its keys (the last varies fastest), each made only when it is asked
    for: a grid of a million points costs what its axes cost until its points are sent.

    Made, it checks every value of the grid before any work, without making every point: each value of
    each axis in a point whose other axes take their first value, read by the command's own parser (the
    last axis first, so that the value named is the one of the first bad point in the grid's order), and
    every pair of values of two axes that set options of one mutually exclusive group (the only options
    argparse weighs against each other). What a command's handler refuses of a combination is a failed row.

    Two values of an axis that give the same options (``seed = [1, 1]``, or two names of a named axis with the
    same table) give points of one command line: :meth:`firsts` yields only the first point of each command
    line, which is computed once and whose outcome the others share."""

    def __init__(self, spec: Spec, parser: argparse.ArgumentParser, where: str):
        self.spec, self.where = spec, where
        self.names = list(spec.grid)
        self.axes = [list(spec.grid[k]) for k in self.names]  # a named axis by its names
        self.sizes = [len(axis) for axis in self.axes]
        self.version = project_version()
        self.digests: dict[str, str | None] = {}  # each file a point names, hashed once
        self.positional_order = [a.dest for a in actions_of(parser) if not a.option_strings]
        base = spec.path.parent
        self._fixed = fragment(parser, spec.fixed, base, where)
        self._fragments: list[dict[int, tuple]] = [{} for _ in self.axes]

        def made(axis: int, index: int) -> tuple:
            done = self._fragments[axis]
            if index not in done:
                key, value = self.names[axis], self.axes[axis][index]
                done[index] = fragment(parser, spec.grid[key][value] if isinstance(spec.grid[key], dict)
                                       else {key: value}, base, where)
            return done[index]

        for axis in range(len(self.axes)):  # the first point's values, as the first point would meet them
            made(axis, 0)
        checked: set[tuple[str, ...]] = set()

        def check(indices: tuple[int, ...]) -> None:
            for axis, index in enumerate(indices):
                made(axis, index)
            argv = self.argv(indices)
            if argv not in checked:
                check_argv(argv, self.values(indices), where)
                checked.add(argv)

        zero = (0,) * len(self.axes)
        check(zero)  # the fixed options, and a grid of no keys
        for axis in reversed(range(len(self.axes))):
            for index in range(self.sizes[axis]):
                check(zero[:axis] + (index,) + zero[axis + 1:])
        for first, second in self.exclusive_pairs(parser):
            for i in range(self.sizes[first]):
                for j in range(self.sizes[second]):
                    indices = list(zero)
                    indices[first], indices[second] = i, j
                    check(tuple(indices))
        # values of an axis that give the same arguments: the first of them stands for the others
        self.firsts_of: list[list[int]] = []
        for done in self._fragments:
            seen: dict[tuple, int] = {}
            self.firsts_of.append([seen.setdefault(freeze(done[i]), i) for i in range(len(done))])

    def exclusive_pairs(self, parser: argparse.ArgumentParser) -> list[tuple[int, int]]:
        """The pairs of axes (in the grid's order) that both set an option of one mutually exclusive group."""
        pairs = set()
        for dests in exclusive_groups(parser):
            touching = []
            for axis, key in enumerate(self.names):
                options = self.spec.grid[key]
                keys = [k for v in options.values() for k in v] if isinstance(options, dict) else [key]
                parser_dests = {find_action(parser, k).dest for k in keys}
                if parser_dests & dests:
                    touching.append(axis)
            pairs |= set(itertools.combinations(touching, 2))
        return sorted(pairs)

    def __len__(self) -> int:
        return count(self.spec.grid)

    @property
    def distinct(self) -> int:
        """How many different command lines the points have (the points :meth:`firsts` yields)."""
        total = 1
        for firsts in self.firsts_of:
            total *= len(set(firsts))
        return total

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if index < 0:
            index += len(self)
        if not 0 <= index < len(self):
            raise IndexError("point index out of range")
        indices = []
        for size in reversed(self.sizes):
            index, rest = divmod(index, size)
            indices.append(rest)
        return self.point(tuple(reversed(indices)))

    def __iter__(self):
        for indices in itertools.product(*(range(n) for n in self.sizes)):
            yield self.point(indices)

    def firsts(self):
        """The first point of each command line, in the grid's order."""
        for indices in itertools.product(*(sorted(set(firsts)) for firsts in self.firsts_of)):
            yield self.point(indices)

    def values(self, indices: tuple[int, ...]) -> dict:
        return {key: axis[i] for key, axis, i in zip(self.names, self.axes, indices)}

    def argv(self, indices: tuple[int, ...]) -> tuple[str, ...]:
        flags, positionals = list(self._fixed[0]), dict(self._fixed[1])
        for done, index in zip(self._fragments, indices):
            flags += done[index][0]
            positionals.update(done[index][1])
        ordered = [word for dest in self.positional_order for word in positionals.get(dest, ())]
        return tuple(self.spec.command) + tuple(flags) + ("--json",) + tuple(ordered)

    def point(self, indices: tuple[int, ...]) -> Point:
        argv = self.argv(indices)
        return Point(values=self.values(indices), argv=argv, key=point_key(argv, self.version, self.digests),
                     at=indices)


def freeze(made: tuple) -> tuple:
    flags, positionals = made
    return tuple(flags), tuple(sorted(positionals.items()))


def fragment(parser: argparse.ArgumentParser, options: dict, base: Path, where: str) -> tuple[list, dict]:
    """What ``options`` add to a command line: their flags in the spec's order, and the values of each
    positional argument (by its destination)."""
    flags, positionals = [], {}
    for key, value in options.items():
        action = find_action(parser, key)
        value = resolve(value, base)
        if not action.option_strings:
            words = value if isinstance(value, list) else [value]
            for word in words:
                if text(word).startswith("-"):
                    raise UsageError(f"{where}: {action.dest!r} cannot start with '-': {word!r}")
            positionals[action.dest] = tuple(text(word) for word in words)
            continue
        flag = max(action.option_strings, key=len)
        if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
            if not isinstance(value, bool):
                raise UsageError(f"{where}: {key!r} is a flag: give true or false, not {value!r}")
            if value == isinstance(action, argparse._StoreTrueAction):
                flags.append(flag)
        elif isinstance(value, list):
            if isinstance(action, argparse._AppendAction):
                for item in value:
                    flags += [flag, text(item)]
            elif action.nargs in ("+", "*") or isinstance(action.nargs, int):
                flags += [flag] + [text(v) for v in value]
            else:
                raise UsageError(f"{where}: {key!r} takes one value, not a list (the values to sweep go in [grid])")
        else:
            flags += [flag, text(value)]
    return flags, positionals


def text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (dict, list)):
        return json.dumps(value)
    return str(value)


def resolve(value, base: Path):
    """A relative path to a file or folder that exists beside the spec (or else in the current folder) as an
    absolute one, so that workers started elsewhere find it; any other value as it is."""
    if isinstance(value, list):
        return [resolve(v, base) for v in value]
    if not isinstance(value, str) or not value or value.startswith("-") or Path(value).is_absolute():
        return value
    for folder in (base, Path.cwd()):
        candidate = folder / value
        if candidate.exists():
            return str(candidate.resolve())
    return value


def check_argv(argv: tuple[str, ...], values: dict, where: str) -> None:
    """Let the command's own parser read the point's command line; its complaint becomes one line."""
    errors = io.StringIO()
    try:
        with redirect_stderr(errors), redirect_stdout(io.StringIO()):
            work_parser().parse_args(list(argv))
    except SystemExit:
        lines = [line for line in errors.getvalue().splitlines() if line.strip()]
        message = lines[-1].split(": error: ", 1)[-1] if lines else "the command's parser refused it"
        point = ", ".join(f"{k}={v}" for k, v in values.items())
        raise UsageError(f"{where}: {message}" + (f" (at {point})" if point else "")) from None


# ----------------------------------------------------------------------------------------------------
# Keys.


@lru_cache(maxsize=1)
def project_version() -> str:
    """agentsim's version and a digest of the files of its four packages (code, configurations, stories,
    texts): a checkout whose code changed does not reuse the results of the old one."""
    import importlib.util

    import agentsim

    digest = hashlib.sha256()
    for name in ("agentsim", "speech_timing", "anticipators", "scenarios"):
        package = Path(importlib.util.find_spec(name).origin).resolve().parent
        for path in sorted(package.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix in (
                    ".py", ".toml", ".story", ".txt", ".json", ".js", ".css", ".mid", ".sf2"):
                digest.update(f"{name}/{path.relative_to(package).as_posix()}".encode() + b"\0")
                digest.update(path.read_bytes())
    return f"{agentsim.__version__}+{digest.hexdigest()[:12]}"


def point_key(argv: tuple[str, ...], version: str, digests: dict | None = None) -> str:
    """The cache key of a point: its command line, the project version and the content of every file the
    command line names (``digests`` keeps each file's digest for the next point that names it)."""
    files = {}
    digests = {} if digests is None else digests
    for word in argv:
        if word not in digests:
            digests[word] = file_digest(word)
        if digests[word] is not None:
            files[word] = digests[word]
    blob = json.dumps({"argv": list(argv), "version": version, "files": files}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def file_digest(word: str) -> str | None:
    """The SHA-256 of the file an absolute path names, or None if the word names none."""
    p = Path(word)
    if not (p.is_absolute() and p.is_file()):
        return None
    with open(p, "rb") as f:  # a block at a time: a long audio file is never held whole
        return hashlib.file_digest(f, "sha256").hexdigest()


#: The longest name of a point's folder in ``outputs/`` (file systems take 255 bytes).
MAX_FOLDER_NAME = 200
#: What a grid key or value may keep of itself in a folder name; anything else becomes ``_``.
UNSAFE_IN_NAME = re.compile(r"[^A-Za-z0-9._+-]")


def name_part(key: str, value) -> str:
    """One value's part of a point's folder name: ``seed=1`` (a named axis by its name; the key and the value
    keep letters, digits and ``._+-``, the rest is ``_``). The parts are joined by commas in the grid's key
    order: ``strategy=best,seed=1,jitter=0.03``."""
    return f"{UNSAFE_IN_NAME.sub('_', key)}={UNSAFE_IN_NAME.sub('_', text(value))}"


class OutputFolders:
    """The folder name in ``outputs/`` of each point's ``--out``: each of its values' :func:`name_part`, joined. A name that
    two points of different command lines would share (once made safe, or differing only in case) and a name
    longer than :data:`MAX_FOLDER_NAME` end in ``~`` and the first 8 characters of the point's key instead; a
    grid of no keys is its key. Points of one command line are computed once, into the folder of the first.

    Whether a name is shared is read from the axes, not from the other points: the names are the values'
    parts joined by commas, which no part holds, so two points share a name when each of their axes gives
    the same part, and a point's name is shared when one of its values gives the part of a value of another
    command line. A shortened name that an earlier point already took (the first 191 characters and 8 of
    the key alike) is the point's whole key."""

    def __init__(self, points: Points):
        self.points = points
        self.parts = [[name_part(key, value) for value in axis] for key, axis in zip(points.names, points.axes)]
        self.shared = []
        for parts, firsts in zip(self.parts, points.firsts_of):
            lines: dict[str, set[int]] = {}
            for part, first in zip(parts, firsts):
                lines.setdefault(part.lower(), set()).add(first)
            self.shared.append([len(lines[part.lower()]) > 1 for part in parts])
        self.shortened: set[str] = set()

    def of(self, point: Point) -> str:
        indices = point.at
        name = ",".join(parts[i] for parts, i in zip(self.parts, indices))
        if not name:
            return point.key
        if len(name) <= MAX_FOLDER_NAME and not any(shared[i] for shared, i in zip(self.shared, indices)):
            return name
        short = f"{name[:MAX_FOLDER_NAME - 9]}~{point.key[:8]}"
        if short.lower() in self.shortened:
            return point.key
        self.shortened.add(short.lower())
        return short


def shell_line(argv) -> str:
    """The point's command line as one would type it."""
    return "agentsim " + shlex.join(list(argv))
