"""The lexicon as data: what the lexemes of BML play, read from files like Greta's gestuary or SmartBody's
gesture map, so that people tune and extend it without Python.

The package's files (``agentsim/animation/data``), whose comments say what an entry holds:

* ``lexicon.toml``: gesture lexemes (``[gesture.NAME]``: a stroke, the wrist's path into and out of its
  ictus, or a form, a MURML description played as :mod:`agentsim.animation.murml` plays a
  ``<murmlgesture>``) and the conducting patterns (``[conducting]``);
* ``faces.toml``: face lexemes (``[face.NAME]``) and FACS action units (``[facs.N]``), as angles of the
  face's degrees of freedom;
* ``postures.toml``: postures (``[posture.NAME]``);
* ``visemes.toml``: the mouth shapes of visemes (``[viseme]``) and of the other face channels of
  ``<curves>`` (``[channel]``).

A :class:`Lexicon` holds every entry with the file it comes from. A user's lexicon file has any of those
tables; :meth:`Lexicon.load` extends the built-in lexicon with it, its entries replacing those of the same
name. A realizer plays its own (``Realizer(lexicon=...)``, ``agentsim realize --lexicon FILE``): two
realizers in one process may play one lexeme differently. Reading needs no numpy: the BML reader asks which
lexemes are known, the planner a lexeme's MURML form.
"""

from __future__ import annotations

import functools
import json
import math
import re
import tomllib
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

from agentsim.errors import UsageError

BUILTIN = "built in"
#: The package's lexicon files, in the order they are read.
BUILTIN_FILES = ("lexicon.toml", "faces.toml", "postures.toml", "visemes.toml")
#: The tables a lexicon file may have, and what the listing calls their entries.
TABLES = {"gesture": "gesture", "conducting": "conducting", "face": "face lexeme", "facs": "FACS unit",
          "posture": "posture", "viseme": "viseme", "channel": "face channel"}
STROKE_KEYS = {"top": 3, "bottom": 3, "rebound": 3}
STROKE_NUMBERS = {"wrist": -5.0, "flick": 10.0, "curl": 15.0, "twist": 0.0}
#: The axes of a mouth shape (degrees): jaw opening, corner spread, upper lip lowered, lower lip raised.
MOUTH_AXES = ("jaw", "spread", "upper", "lower")
#: The lexemes of the BML 1.0 standard's ``faceLexeme`` (all in the built-in face table).
BML_FACE_LEXEMES = ("OBLIQUE_BROWS", "RAISE_BROWS", "RAISE_LEFT_BROW", "RAISE_RIGHT_BROW", "LOWER_BROWS",
                    "LOWER_LEFT_BROW", "LOWER_RIGHT_BROW", "LOWER_MOUTH_CORNERS", "LOWER_LEFT_MOUTH_CORNER",
                    "LOWER_RIGHT_MOUTH_CORNER", "RAISE_MOUTH_CORNERS", "RAISE_RIGHT_MOUTH_CORNER",
                    "RAISE_LEFT_MOUTH_CORNER", "OPEN_MOUTH", "OPEN_LIPS", "WIDEN_EYES", "CLOSE_EYES")
#: The axes of a degree of freedom named ``joint.axis``.
DOF_AXES = ("roll", "pitch", "yaw", "tx", "ty", "tz")
#: The attributes of a lexicon, each a read-only mapping by name (:class:`Lexicon`).
FIELDS = ("strokes", "forms", "conducting", "faces", "facs", "postures", "visemes", "channels", "sources")

_CONDUCT = re.compile(r"^CONDUCT(?:ING)?_(\d+)_(\d+)(?:_(\d+))?$")


def conducting_meter(lexeme: str) -> tuple[int, int | None] | None:
    """(beats per bar, beat in the bar or None) for a lexeme like ``CONDUCT_4_4`` or ``CONDUCT_3_4_2``."""
    m = _CONDUCT.match((lexeme or "").upper())
    if not m:
        return None
    return int(m.group(1)), (int(m.group(3)) if m.group(3) else None)


def _fail(source: str, text: str):
    raise UsageError(f"lexicon {source}: {text}")


def _number(value, source: str, entry: str, key: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(source, f"[{entry}] {key} must be a finite number ({unit}), not {value!r}")
    return float(value)


def _point(value, source: str, entry: str, key: str) -> tuple[float, float, float]:
    if not (isinstance(value, list) and len(value) == 3):
        _fail(source, f"[{entry}] needs {key} = [outward, up, forward] (metres)")
    return tuple(_number(x, source, entry, key, "metres") for x in value)


def _stroke(entry: dict, source: str, where: str) -> dict:
    out: dict = {key: _point(entry.get(key), source, where, key) for key in STROKE_KEYS}
    for key, default in STROKE_NUMBERS.items():
        out[key] = _number(entry.get(key, default), source, where, key, "degrees")
    unknown = set(entry) - set(STROKE_KEYS) - set(STROKE_NUMBERS)
    if unknown:
        _fail(source, f"[{where}] has {', '.join(sorted(unknown))}, which a stroke does not "
                      f"(top, bottom, rebound, {', '.join(STROKE_NUMBERS)}; or murml for a form)")
    return out


def _form(text, source: str, where: str) -> str:
    from agentsim.animation.murml_form import MurmlError, read_description
    from agentsim.core.xmltree import read_forest
    from agentsim.errors import BMLError

    if not isinstance(text, str):
        _fail(source, f"[{where}] murml must be the text of a <murml-description>")
    try:
        root = read_forest(text.strip().encode())[0]
    except BMLError as exc:
        _fail(source, f"[{where}] murml is not XML: {exc}")
    if root.local != "murml-description":
        _fail(source, f"[{where}] murml must be a <murml-description>, not <{root.local}>")
    try:
        form = read_description(root, "gesture")
    except MurmlError as exc:
        _fail(source, f"[{where}] {exc}")
    if form["keyframing"] is not None:
        _fail(source, f"[{where}] a lexeme's form is movement constraints, not a <keyframing>")
    return json.dumps(form, separators=(",", ":"))


def _conducting(entry: dict, source: str) -> dict:
    if not isinstance(entry, dict) or set(entry) - {"center", "patterns"}:
        _fail(source, "[conducting] has center = [outward, up, forward] and [conducting.patterns] by meter")
    center = _point(entry.get("center"), source, "conducting", "center")
    patterns = entry.get("patterns", {})
    if not isinstance(patterns, dict):
        _fail(source, "[conducting.patterns] is a table of beats by meter")
    parsed = {}
    for meter, beats in patterns.items():
        where = f"conducting.patterns.{meter}"
        if not meter.isdigit() or int(meter) < 1:
            _fail(source, f"[conducting.patterns] {meter!r} is not a number of beats per bar")
        if not (isinstance(beats, list) and beats and all(isinstance(b, dict) and set(b) == {"ictus", "fall", "rise"}
                                                           for b in beats)):
            _fail(source, f"[{where}] needs a list of {{ ictus = [outward, up, forward], fall = .., rise = .. }}")
        parsed[int(meter)] = tuple((_point(b["ictus"], source, where, "ictus"),
                                    _number(b["fall"], source, where, "fall", "metres"),
                                    _number(b["rise"], source, where, "rise", "metres")) for b in beats)
    return {"center": center, "patterns": parsed}


def _angles(entry, source: str, where: str) -> dict[str, float]:
    """A table of degrees of freedom (``"joint.axis" = value``, or dotted keys ``joint.axis = value``)."""
    if not isinstance(entry, dict) or not entry:
        _fail(source, f"[{where}] must be a table of degrees of freedom, as \"l_eyebrow.pitch\" = -12.0")
    out: dict[str, float] = {}
    for key, value in entry.items():
        for dof, v in (((f"{key}.{axis}", x) for axis, x in value.items()) if isinstance(value, dict)
                       else ((key, value),)):
            joint, _, axis = dof.partition(".")
            if not joint or axis not in DOF_AXES:
                _fail(source, f"[{where}] {dof!r} is not a degree of freedom (joint.{'|'.join(DOF_AXES)})")
            out[dof] = _number(v, source, where, dof, "degrees, or metres for a translation")
    return out


def _mouth(entry, source: str, where: str) -> dict[str, float]:
    if not isinstance(entry, dict) or set(entry) - set(MOUTH_AXES):
        _fail(source, f"[{where}] is a mouth shape: {', '.join(MOUTH_AXES)} (degrees; what is left out is 0)")
    return {axis: _number(entry.get(axis, 0.0), source, where, axis, "degrees") for axis in MOUTH_AXES}


def read_tables(text: str, source: str) -> dict[str, dict]:
    """The entries of a lexicon file by table (``stroke``, ``form``, ``conducting``, ``face``, ``facs``,
    ``posture``, ``viseme``, ``channel``), each by name; :class:`UsageError` naming the file and the entry
    for anything it cannot use."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        _fail(source, f"not TOML: {exc}")
    unknown = set(data) - set(TABLES)
    if unknown:
        _fail(source, f"has [{', '.join(sorted(unknown))}]; a lexicon has the tables "
                      f"{', '.join(f'[{t}]' for t in TABLES)}")
    tables: dict[str, dict] = {kind: {} for kind in ("stroke", "form", "conducting", "face", "facs", "posture",
                                                     "viseme", "channel")}
    for table, entries in data.items():
        if table == "conducting":
            tables["conducting"][""] = _conducting(entries, source)
            continue
        if not isinstance(entries, dict):
            _fail(source, f"[{table}] must be a table of entries, as [{table}.NAME]")
        for name, entry in entries.items():
            where = f"{table}.{name}"
            if table == "gesture":
                if not isinstance(entry, dict):
                    _fail(source, f"[{where}] must be a table")
                if "murml" in entry:
                    if set(entry) != {"murml"}:
                        _fail(source, f"[{where}] a form has murml alone")
                    tables["form"][name.upper()] = _form(entry["murml"], source, where)
                else:
                    tables["stroke"][name.upper()] = _stroke(entry, source, where)
            elif table == "facs":
                if not name.isdigit():
                    _fail(source, f"[{where}] a FACS action unit is named by its number, as [facs.12]")
                tables["facs"][int(name)] = _angles(entry, source, where)
            elif table in ("face", "posture"):
                tables[table][name.upper()] = _angles(entry, source, where)
            else:
                tables[table][name.lower()] = _mouth(entry, source, where)
    return tables


def check_dofs(tables: dict[str, dict], dofs, source: str) -> None:
    """:class:`UsageError` if a face lexeme, FACS unit or posture of ``tables`` (read from ``source``) moves a
    degree of freedom that is not among ``dofs`` (the body's)."""
    known = set(dofs)
    for table in ("face", "facs", "posture"):
        for name, angles in tables[table].items():
            unknown = [dof for dof in angles if dof not in known]
            if unknown:
                _fail(source, f"[{table}.{name}] moves {', '.join(unknown)}, which the body has not "
                              "(its degrees of freedom are listed in agentsim.animation.body)")


def _frozen(value):
    if isinstance(value, dict):
        return MappingProxyType({k: _frozen(v) for k, v in value.items()})
    return value


def _thawed(value):
    if isinstance(value, Mapping):
        return {k: _thawed(v) for k, v in value.items()}
    return value


class Lexicon:
    """What the lexemes play, by table, and where each entry comes from; a value that is never changed.

    Attributes
    ----------
    strokes : mapping
        Gesture lexeme -> its stroke: ``top``, ``bottom``, ``rebound`` (outward, up, forward metres from the
        shoulder) and ``wrist``, ``flick``, ``curl``, ``twist`` (degrees).
    forms : mapping
        Gesture lexeme -> its MURML form (JSON, as :func:`agentsim.animation.murml_form.read_description`
        gives it).
    conducting : mapping
        ``center`` (outward, up, forward metres from the shoulder) and ``patterns``: beats per bar -> each
        beat's ``(ictus offset, fall, rise)``.
    faces, postures : mapping
        Lexeme -> degree of freedom -> degrees (metres for a translation).
    facs : mapping
        FACS action unit (a number) -> degree of freedom -> degrees.
    visemes, channels : mapping
        Viseme, face channel (lower case) -> ``jaw``, ``spread``, ``upper``, ``lower`` (degrees).
    sources : mapping
        ``(table, name)`` -> the file the entry comes from, or ``built in`` (``table`` one of :data:`TABLES`;
        the conducting patterns are ``("conducting", "")``).
    """

    __slots__ = FIELDS

    def __init__(self, strokes, forms, conducting, faces, facs, postures, visemes, channels, sources):
        for name, value in zip(FIELDS, (strokes, forms, conducting, faces, facs, postures, visemes, channels,
                                        sources)):
            object.__setattr__(self, name, _frozen(_thawed(value)))

    def __setattr__(self, name, value):
        raise AttributeError("a Lexicon is not changed: extended() makes another")

    def __reduce__(self):
        return Lexicon, tuple(_thawed(getattr(self, name)) for name in FIELDS)

    def __repr__(self) -> str:
        files = ", ".join(dict.fromkeys(self.sources.values()))
        return f"Lexicon({len(self.sources)} entries: {files})"

    @classmethod
    def builtin(cls) -> "Lexicon":
        """The lexicon the package comes with (read once, then shared: it is never changed)."""
        return _builtin()

    @classmethod
    def load(cls, path: str | Path) -> "Lexicon":
        """The built-in lexicon extended with a lexicon file's entries (they win over those of the same name)."""
        return cls.builtin().extended(path)

    def extended(self, path: str | Path) -> "Lexicon":
        """This lexicon with a lexicon file's entries added (replacing those of the same name); a
        :class:`UsageError` naming the file, and the entry, for what cannot be read or used."""
        from agentsim.core.inputs import read_text

        path = Path(path)
        try:  # weighed before it is read, as every input: past 8 MB it is refused unread
            text = read_text(path, what=f"the lexicon {path}")
        except UnicodeDecodeError as exc:
            raise UsageError(f"cannot read the lexicon {path}: it is not UTF-8 text ({exc.reason})") from None
        except OSError as exc:
            raise UsageError(f"cannot read the lexicon {path}: {exc.strerror or exc}") from None
        tables = read_tables(text, str(path))
        if tables["face"] or tables["facs"] or tables["posture"]:
            check_dofs(tables, _body_dofs(), str(path))
        return self._merged(tables, str(path))

    def _merged(self, tables: dict[str, dict], source: str) -> "Lexicon":
        strokes, forms = _thawed(self.strokes), _thawed(self.forms)
        sources = dict(self.sources)
        for table, mine, other in (("stroke", strokes, forms), ("form", forms, strokes)):
            for name, entry in tables[table].items():
                mine[name] = entry
                other.pop(name, None)  # a gesture lexeme is a stroke or a form
                sources[("gesture", name)] = source
        merged = {}
        for field, table, key in (("faces", "face", "face"), ("facs", "facs", "facs"),
                                  ("postures", "posture", "posture"), ("visemes", "viseme", "viseme"),
                                  ("channels", "channel", "channel")):
            merged[field] = {**_thawed(getattr(self, field)), **tables[table]}
            sources.update(((key, name), source) for name in tables[table])
        conducting = tables["conducting"].get("")
        if conducting is not None:
            sources[("conducting", "")] = source
        return Lexicon(strokes, forms, conducting if conducting is not None else self.conducting,
                       merged["faces"], merged["facs"], merged["postures"], merged["visemes"], merged["channels"],
                       sources)

    # ------------------------------------------------------------------ look-ups
    def form(self, lexeme: str) -> str | None:
        """The MURML form (JSON) of a gesture lexeme that is one, else None."""
        return self.forms.get(lexeme.strip().upper())

    def knows_gesture(self, lexeme: str) -> bool:
        """Whether a gesture lexeme has a motion of its own: a stroke, a form or a conducting beat."""
        name = lexeme.strip().upper()
        return name in self.strokes or name in self.forms or conducting_meter(name) is not None

    def source(self, table: str, name) -> str:
        """Where an entry comes from (``built in`` or a file)."""
        return self.sources[(table, name)]

    def rows(self) -> list[tuple[str, str, str]]:
        """``(name, kind, source)`` of every entry: the gestures, the conducting patterns, the face lexemes,
        FACS units, postures, visemes and face channels, each by name."""
        rows = [(name, "gesture stroke", self.source("gesture", name)) for name in sorted(self.strokes)]
        rows += [(name, "gesture form (MURML)", self.source("gesture", name)) for name in sorted(self.forms)]
        meters = ", ".join(str(m) for m in sorted(self.conducting["patterns"]))
        rows.append(("CONDUCT_<beats>_<unit>[_<beat>]", f"conducting (patterns of {meters} beats; others "
                     "alternate)", self.source("conducting", "")))
        for table, field in (("face", "faces"), ("facs", "facs"), ("posture", "postures"), ("viseme", "visemes"),
                             ("channel", "channels")):
            for name in sorted(getattr(self, field)):
                rows.append((f"AU{name}" if table == "facs" else name, TABLES[table], self.source(table, name)))
        return rows


@functools.lru_cache(maxsize=1)
def _builtin() -> Lexicon:
    lexicon = Lexicon({}, {}, None, {}, {}, {}, {}, {}, {})
    for name in BUILTIN_FILES:
        text = resources.files("agentsim.animation").joinpath(f"data/{name}").read_text()
        lexicon = lexicon._merged(read_tables(text, BUILTIN), BUILTIN)
    return lexicon


def _body_dofs() -> list[str]:
    from agentsim.animation.body import Body

    return Body().dof_names


def as_lexicon(lexicon: "Lexicon | str | Path | None") -> Lexicon:
    """A lexicon from what a realizer is given: a :class:`Lexicon`, the path of a lexicon file (the built-in
    lexicon extended with it), or None (the built-in lexicon)."""
    if lexicon is None:
        return Lexicon.builtin()
    if isinstance(lexicon, Lexicon):
        return lexicon
    if isinstance(lexicon, (str, Path)):
        return Lexicon.load(lexicon)
    raise TypeError(f"a lexicon is a Lexicon or the path of a lexicon file, not {type(lexicon).__name__}")
