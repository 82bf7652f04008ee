"""The gesture lexicon as data: what ``<gesture lexeme="NAME">`` plays, read from ``data/lexicon.toml`` and
from the files users add (``agentsim realize --lexicon FILE``, :func:`agentsim.animation.arms.use_lexicon`), like Greta's gestuary
or SmartBody's gesture map. The file's comments say what a lexeme holds: a stroke (the wrist's path into
and out of its ictus) or a form (a MURML description, played as :mod:`agentsim.animation.murml` plays a
``<murmlgesture>``), and the conducting patterns.

Reading needs no numpy: the planner asks :func:`murml_form` for a lexeme's form when it times a gesture.
"""

from __future__ import annotations

import functools
import json
import re
import sys
import tomllib
from importlib import resources

from agentsim.errors import UsageError

STROKE_KEYS = {"top": 3, "bottom": 3, "rebound": 3}
STROKE_NUMBERS = {"wrist": -5.0, "flick": 10.0, "curl": 15.0, "twist": 0.0}
BUILTIN = "built in"

#: A lexeme's MURML form (JSON, as :func:`agentsim.animation.murml_form.read_description` gives it), by name.
MURML_LEXEMES: dict[str, str] = {}
#: Where each lexeme was last defined (``built in`` or a file), by name.
SOURCES: dict[str, str] = {}


def _fail(source: str, text: str):
    raise UsageError(f"lexicon {source}: {text}")


def _stroke(name: str, entry: dict, source: str) -> dict:
    out = {}
    for key, n in STROKE_KEYS.items():
        v = entry.get(key)
        if not (isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) for x in v)):
            _fail(source, f"[gesture.{name}] needs {key} = [outward, up, forward] (metres)")
        out[key] = tuple(float(x) for x in v)
    for key, default in STROKE_NUMBERS.items():
        v = entry.get(key, default)
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            _fail(source, f"[gesture.{name}] {key} must be a number (degrees)")
        out[key] = float(v)
    unknown = set(entry) - set(STROKE_KEYS) - set(STROKE_NUMBERS)
    if unknown:
        _fail(source, f"[gesture.{name}] has {', '.join(sorted(unknown))}, which a stroke does not "
                      f"(top, bottom, rebound, {', '.join(STROKE_NUMBERS)}; or murml for a form)")
    return out


def _form(name: str, text: str, source: str) -> str:
    from agentsim.animation.murml_form import MurmlError, read_description
    from agentsim.core.xmltree import read_forest
    from agentsim.errors import BMLError

    if not isinstance(text, str):
        _fail(source, f"[gesture.{name}] murml must be the text of a <murml-description>")
    try:
        root = read_forest(text.strip().encode())[0]
    except BMLError as exc:
        _fail(source, f"[gesture.{name}] murml is not XML: {exc}")
    if root.local != "murml-description":
        _fail(source, f"[gesture.{name}] murml must be a <murml-description>, not <{root.local}>")
    try:
        form = read_description(root, "gesture")
    except MurmlError as exc:
        _fail(source, f"[gesture.{name}] {exc}")
    if form["keyframing"] is not None:
        _fail(source, f"[gesture.{name}] a lexeme's form is movement constraints, not a <keyframing>")
    return json.dumps(form, separators=(",", ":"))


def read_lexicon(text: str, source: str) -> dict:
    """A lexicon file's lexemes: ``{"strokes": {NAME: {...}}, "forms": {NAME: json}, "conducting": {...}}``;
    :class:`UsageError` naming the file and the table for anything it cannot use."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        _fail(source, f"not TOML: {exc}")
    unknown = set(data) - {"gesture", "conducting"}
    if unknown:
        _fail(source, f"has [{', '.join(sorted(unknown))}]; a lexicon has [gesture.NAME] tables and [conducting]")
    strokes, forms = {}, {}
    for name, entry in data.get("gesture", {}).items():
        if not isinstance(entry, dict):
            _fail(source, f"gesture.{name} must be a table")
        key = name.upper()
        if "murml" in entry:
            if set(entry) != {"murml"}:
                _fail(source, f"[gesture.{name}] a form has murml alone")
            forms[key] = _form(name, entry["murml"], source)
        else:
            strokes[key] = _stroke(name, entry, source)
    conducting = data.get("conducting")
    if conducting is not None:
        patterns = conducting.get("patterns", {})
        try:
            center = tuple(float(x) for x in conducting["center"])
            parsed = {int(k): [(tuple(float(x) for x in b["ictus"]), float(b["fall"]), float(b["rise"]))
                               for b in v] for k, v in patterns.items()}
        except (KeyError, TypeError, ValueError) as exc:
            _fail(source, f"[conducting] needs center = [outward, up, forward] and patterns of "
                          f"{{ ictus = [..], fall = .., rise = .. }} by meter ({exc})")
        if len(center) != 3 or any(len(b[0]) != 3 for v in parsed.values() for b in v):
            _fail(source, "[conducting] points have three coordinates")
        conducting = {"center": center, "patterns": parsed}
    return {"strokes": strokes, "forms": forms, "conducting": conducting}


@functools.lru_cache(maxsize=1)
def builtin() -> dict:
    """The lexicon the package comes with."""
    text = resources.files("agentsim.animation").joinpath("data/lexicon.toml").read_text()
    lexicon = read_lexicon(text, BUILTIN)
    for name in (*lexicon["strokes"], *lexicon["forms"]):
        SOURCES.setdefault(name, BUILTIN)
    for name, form in lexicon["forms"].items():
        MURML_LEXEMES.setdefault(name, form)
    return lexicon


_CONDUCT = re.compile(r"^CONDUCT(?:ING)?_(\d+)_(\d+)(?:_(\d+))?$")


def conducting_meter(lexeme: str) -> tuple[int, int | None] | None:
    """(beats per bar, beat in the bar or None) for a lexeme like ``CONDUCT_4_4`` or ``CONDUCT_3_4_2``."""
    m = _CONDUCT.match((lexeme or "").upper())
    if not m:
        return None
    return int(m.group(1)), (int(m.group(3)) if m.group(3) else None)


def stroke_names():
    """The gesture lexemes that are strokes now: :data:`agentsim.animation.arms.GESTURE_FORMS` once that module
    is loaded (with the lexicons added since), before then the lexicon's own strokes, which are what it starts
    with (read without numpy)."""
    arms = sys.modules.get("agentsim.animation.arms")
    forms = getattr(arms, "GESTURE_FORMS", None) if arms is not None else None
    return forms if forms is not None else builtin()["strokes"]


def murml_form(lexeme: str) -> str | None:
    """The MURML form (JSON) of a gesture lexeme that is one, else None."""
    builtin()
    return MURML_LEXEMES.get(lexeme.strip().upper())
