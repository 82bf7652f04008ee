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
from collections import Counter
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
#: The most points a sweep runs unless ``--max-points N`` allows more: each is checked by the command's parser
#: before any work (about 60 microseconds each), and its row kept in memory.
MAX_POINTS = 10_000
#: From how many points a sweep says their count before it checks them (a second's work or more).
SAY_COUNT = 1_000


@dataclass(frozen=True)
class Point:
    """One point of the grid: its values (a named axis by its name), the command line that computes it
    (with ``--json``; the sweep adds ``--out`` where the command takes one) and its cache key."""

    values: dict
    argv: tuple[str, ...]
    key: str


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
    points: list[Point] = field(default_factory=list)

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


# argparse offers no public way to walk its commands and options: these three read its attributes.
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
    ``max_points`` (default
    :data:`MAX_POINTS`) before any is made; then they are made one after another, each checked."""
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
        say(f"agentsim: {where}: {total} points of 'agentsim {spec.name}', checking them")
    if total > most:
        raise UsageError(f"{where}: the grid makes {total} points, more than the {most} a sweep runs"
                         + (" without --max-points N" if max_points is None else " with this --max-points")
                         + f" (give --max-points {total} to run them all)")
    spec.points = list(expand(spec, parser, where))
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


def expand(spec: Spec, parser: argparse.ArgumentParser, where: str):
    """Every combination of the grid, made one at a time in the order of its keys (the last varies
    fastest), each command line checked by the command's own parser (a bad value is named before any
    work)."""
    keys = list(spec.grid)
    axes = [list(spec.grid[k]) if isinstance(spec.grid[k], dict) else spec.grid[k] for k in keys]
    version = project_version()
    checked = set()
    for combination in itertools.product(*axes):
        values, options = {}, dict(spec.fixed)
        for key, value in zip(keys, combination):
            values[key] = value
            if isinstance(spec.grid[key], dict):
                options.update(spec.grid[key][value])
            else:
                options[key] = value
        argv = tuple(spec.command) + tuple(arguments(parser, options, spec.path.parent, where))
        if argv not in checked:
            check_argv(argv, values, where)
            checked.add(argv)
        yield Point(values=values, argv=argv, key=point_key(argv, version))


def arguments(parser: argparse.ArgumentParser, options: dict, base: Path, where: str) -> list[str]:
    """The options as the command's arguments: the flags in the spec's order, ``--json``, the positionals."""
    flags, positionals = [], {}
    for key, value in options.items():
        action = find_action(parser, key)
        value = resolve(value, base)
        if not action.option_strings:
            positionals[action.dest] = value if isinstance(value, list) else [value]
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
    ordered = []
    for action in actions_of(parser):
        for value in positionals.get(action.dest, []) if not action.option_strings else []:
            if text(value).startswith("-"):
                raise UsageError(f"{where}: {action.dest!r} cannot start with '-': {value!r}")
            ordered.append(text(value))
    return flags + ["--json"] + ordered


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


def point_key(argv: tuple[str, ...], version: str) -> str:
    """The cache key of a point: its command line, the project version and the content of every file the
    command line names."""
    files = {}
    for word in argv:
        p = Path(word)
        if p.is_absolute() and p.is_file():
            with open(p, "rb") as f:  # a block at a time: a long audio file is never held whole
                files[word] = hashlib.file_digest(f, "sha256").hexdigest()
    blob = json.dumps({"argv": list(argv), "version": version, "files": files}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


#: The longest name of a point's folder in ``outputs/`` (file systems take 255 bytes).
MAX_FOLDER_NAME = 200
#: What a grid key or value may keep of itself in a folder name; anything else becomes ``_``.
UNSAFE_IN_NAME = re.compile(r"[^A-Za-z0-9._+-]")


def folder_name(values: dict) -> str:
    """A point's values as a folder name, in the grid's key order: ``strategy=best,seed=1,jitter=0.03``
    (a named axis by its name; each key and value keeps letters, digits and ``._+-``, the rest is ``_``)."""
    return ",".join(f"{UNSAFE_IN_NAME.sub('_', key)}={UNSAFE_IN_NAME.sub('_', text(value))}"
                    for key, value in values.items())


def output_folders(points: list[Point]) -> dict[str, str]:
    """The folder name in ``outputs/`` of each point's ``--out``, by its key: :func:`folder_name` of its values.
    Names that two points would share (once made safe, or differing only in case) and names longer than
    :data:`MAX_FOLDER_NAME` end in ``~`` and the first 8 characters of the key instead; a grid of no keys is
    its key. Points of one command line (one key) are computed once, into the folder of the first."""
    names: dict[str, str] = {}
    for point in points:
        names.setdefault(point.key, folder_name(point.values))
    shared = Counter(name.lower() for name in names.values())
    folders = {}
    for key, name in names.items():
        if not name:
            folders[key] = key
        elif len(name) > MAX_FOLDER_NAME or shared[name.lower()] > 1:
            folders[key] = f"{name[:MAX_FOLDER_NAME - 9]}~{key[:8]}"
        else:
            folders[key] = name
    if len({name.lower() for name in folders.values()}) < len(folders):  # shortened alike, keys alike to 8
        return {key: key for key in folders}
    return folders


def shell_line(argv) -> str:
    """The point's command line as one would type it."""
    return "agentsim " + shlex.join(list(argv))
