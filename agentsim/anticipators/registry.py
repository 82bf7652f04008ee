"""Finding anticipators: the built-in ones and third-party plugins, through the entry-point group
``agentsim.anticipators``."""

from __future__ import annotations

from importlib.metadata import entry_points

from agentsim.core.errors import AgentsimError

GROUP = "agentsim.anticipators"


def available() -> dict[str, str]:
    """Installed anticipators: entry-point name -> ``module:Class``."""
    return {ep.name: ep.value for ep in entry_points(group=GROUP)}


def create(name: str, anticipator_id: str | None = None, **params):
    """Instantiate the anticipator registered as ``name`` with BML id ``anticipator_id`` (default: name)."""
    found = {ep.name: ep for ep in entry_points(group=GROUP)}
    if name not in found:
        known = ", ".join(sorted(found)) or "none"
        raise AgentsimError(f"no anticipator named {name!r} is installed (installed: {known}); a plugin "
                            f"registers one in the {GROUP!r} entry-point group")
    cls = found[name].load()
    try:
        return cls(anticipator_id or name, **params)
    except (TypeError, ValueError) as exc:
        raise AgentsimError(f"anticipator {name!r}: {exc}") from None


def parse_spec(spec: str) -> tuple[str, str, dict[str, object]]:
    """``name[:id][,key=value...]`` -> (name, id, params); numbers become floats."""
    head, *pairs = spec.split(",")
    name, _, anticipator_id = head.partition(":")
    params: dict[str, object] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise AgentsimError(f"anticipator option {pair!r} in {spec!r}: expected key=value")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            params[key.strip()] = value.strip()
    return name.strip(), (anticipator_id or name).strip(), params
