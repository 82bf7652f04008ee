"""Finding anticipators: the built-in ones and third-party plugins, through the entry-point group
``anticipators``, and the parameters each one declares.

An anticipator declares its parameters in its constructor's signature: ``def __init__(self, anticipator_id,
bpm: float = 120.0, start: float = 0.0)``. The annotation is the type (``float``, ``int``, ``bool``, ``str``;
without one, the default's type), the default is the default. ``--anticipator name:id,key=value`` is read
against that declaration: an unknown key or a value of the wrong type is one line naming the key and the
type expected; a float must be finite.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from importlib.metadata import entry_points

from agentsim.errors import AgentsimError

GROUP = "agentsim.anticipators"

#: Types a parameter can be given on the command line, by their names in annotations.
TYPES = {"float": float, "int": int, "bool": bool, "str": str}


class NotFinite(AgentsimError):
    """A parameter given a value that is not a finite number (``nan``, ``inf``): the value is well formed,
    the anticipator cannot be made with it."""


@dataclass(frozen=True)
class Parameter:
    """One constructor parameter of an anticipator: its name, type (None: not declared) and default
    (:data:`inspect.Parameter.empty` if it must be given)."""

    name: str
    kind: type | None
    default: object = inspect.Parameter.empty

    @property
    def required(self) -> bool:
        return self.default is inspect.Parameter.empty

    def describe(self) -> str:
        """``name: type = default`` as ``anticipators list`` shows it."""
        text = self.name + (f": {self.kind.__name__}" if self.kind is not None else "")
        return text if self.required else f"{text} = {self.default!r}"

    def convert(self, value: object, anticipator: str) -> object:
        """``value`` (a string from the command line, or already a value) as this parameter's type."""
        kind = self.kind
        if not isinstance(value, str):
            if kind is float and isinstance(value, (int, float)) and not isinstance(value, bool):
                value = float(value)
            if kind is float and not math.isfinite(value):
                raise self.error(anticipator, value, "a finite number")
            return value
        text = value.strip()
        if kind is None:  # undeclared: a number if it reads as one, else the text
            try:
                number = float(text)
            except ValueError:
                return text
            if not math.isfinite(number):
                raise self.error(anticipator, value, "a finite number")
            return number
        if kind is bool:
            if text.lower() in ("1", "true", "yes", "on"):
                return True
            if text.lower() in ("0", "false", "no", "off"):
                return False
            raise self.error(anticipator, value, "true or false")
        if kind is int:
            try:
                return int(text)
            except ValueError:
                raise self.error(anticipator, value, "a whole number (int)") from None
        if kind is float:
            try:
                number = float(text)
            except ValueError:
                raise self.error(anticipator, value, "a number (float)") from None
            if not math.isfinite(number):
                raise self.error(anticipator, value, "a finite number (float)")
            return number
        return text

    def error(self, anticipator: str, value: object, expected: str) -> AgentsimError:
        kind = NotFinite if expected.startswith("a finite") else AgentsimError
        return kind(f"anticipator {anticipator!r}: parameter {self.name!r} expects {expected}, "
                             f"got {value!r}")


def available() -> dict[str, str]:
    """Installed anticipators: entry-point name -> ``module:Class``."""
    return {ep.name: ep.value for ep in entry_points(group=GROUP)}


def load(name: str):
    """The class registered as ``name``; AgentsimError naming the installed ones if there is none."""
    found = {ep.name: ep for ep in entry_points(group=GROUP)}
    if name not in found:
        known = ", ".join(sorted(found)) or "none"
        raise AgentsimError(f"no anticipator named {name!r} is installed (installed: {known}); a plugin "
                            f"registers one in the {GROUP!r} entry-point group")
    try:
        return found[name].load()
    except Exception as exc:  # a broken plugin: say which, and why
        raise AgentsimError(f"anticipator {name!r} ({found[name].value}) cannot be loaded: "
                            f"{type(exc).__name__}: {exc}") from None


def parameters(cls) -> list[Parameter]:
    """The parameters ``cls`` declares (its constructor's, after the anticipator id)."""
    try:
        signature = inspect.signature(cls.__init__)
    except (TypeError, ValueError):
        return []
    found = []
    for p in list(signature.parameters.values())[2:]:  # self, anticipator_id
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        kind = _declared_type(p.annotation)
        if kind is None and p.default is not p.empty and type(p.default) in TYPES.values():
            kind = type(p.default)
        if kind is int and isinstance(p.default, float):
            kind = float
        found.append(Parameter(p.name, kind, p.default))
    return found


def _declared_type(annotation) -> type | None:
    """``float``, ``"float"``, ``"int | None"`` -> the type; anything else (a union of several, a
    collection) -> None."""
    if annotation in TYPES.values():
        return annotation
    if not isinstance(annotation, str):  # from __future__ import annotations makes them text
        return None
    parts = [part.strip().replace("builtins.", "") for part in annotation.split("|")]
    parts = [part for part in parts if part != "None"]
    return TYPES.get(parts[0]) if len(parts) == 1 else None


def create(name: str, anticipator_id: str | None = None, **params):
    """Instantiate the anticipator registered as ``name`` with BML id ``anticipator_id`` (default: name),
    its ``params`` read against the parameters it declares."""
    cls = load(name)
    declared = {p.name: p for p in parameters(cls)}
    takes_any = _takes_keywords(cls)
    values = {}
    for key, value in params.items():
        parameter = declared.get(key)
        if parameter is None and not takes_any:
            known = ", ".join(declared) or "none"
            raise AgentsimError(f"anticipator {name!r} has no parameter {key!r} (its parameters: {known})")
        values[key] = (parameter or Parameter(key, None)).convert(value, name)
    try:
        return cls(anticipator_id or name, **values)
    except (TypeError, ValueError) as exc:
        raise AgentsimError(f"anticipator {name!r}: {exc}") from None


def _takes_keywords(cls) -> bool:
    try:
        return any(p.kind == p.VAR_KEYWORD for p in inspect.signature(cls.__init__).parameters.values())
    except (TypeError, ValueError):
        return True


def parse_spec(spec: str) -> tuple[str, str, dict[str, str]]:
    """``name[:id][,key=value...]`` -> (name, id, params); the values stay text for :func:`create` to read
    against the anticipator's declared parameters."""
    head, *pairs = spec.split(",")
    name, _, anticipator_id = head.partition(":")
    params: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise AgentsimError(f"anticipator option {pair!r} in {spec!r}: expected key=value")
        params[key.strip()] = value.strip()
    return name.strip(), (anticipator_id or name).strip(), params
