"""MURML as AsapRealizer reads it inside BML: ``<murmlgesture>`` and ``<murmlface>`` with a
``<murml-description>`` (namespace :data:`MURML_NAMESPACE`), read into a form that the animation makes a
motion unit of (:mod:`agentsim.animation.murml`).

A description holds either movement constraints or a key frame animation:

* ``<static slot="S" value="V" scope="right_arm"/>``: slot ``HandShape`` (a basic shape of the symbol
  table, with modifiers in parentheses: ``BSfist (ThExt)``), ``HandLocation`` (``LocShoulder LocCenterRight
  LocNorm``, or three numbers), ``PalmOrientation`` (``PalmU``, ``DirLU``, three numbers),
  ``ExtFingerOrientation`` (``DirA``, ...), held through the stroke;
* ``<dynamic slot="S" scope=".."><dynamicElement type="linear|curve"> <value type="start|end|normal|shape|
  extension" name=".."/> ...</dynamicElement></dynamic>``: the slot moves from its start to its end value
  through the stroke (a curve bulges to the side its ``shape`` says, ``LeftC``/``RightC``/..., by
  ``extension`` times half its chord, in the plane across its ``normal``);
* ``<parallel>`` (all at once), ``<sequence>`` (one after the other, sharing the stroke) and
  ``<symmetrical dominant="right_arm" symmetry="SymMS">`` (the other arm mirrors the dominant one:
  ``SymMS`` left and right, ``SymMT`` up and down, ``SymMF`` front and back, and their combinations);
* ``<keyframing><phase><frame ftime="t"><posture>Humanoid (joint n v1 .. vn) ...</posture></frame>...``:
  joint values at times (seconds from the start): three values are a joint's rotation in degrees as
  AsapRealizer reads them, roll about its Z axis, pitch about X and yaw about Y (the joint turned by
  Ry(yaw) Rx(pitch) Rz(roll)); one value a face channel (a DOF such as ``l_eyebrow.pitch``, or a viseme or
  face channel of :mod:`agentsim.animation.lips`, at weights 0..100).

:func:`read_description` returns the form as plain JSON-able values or raises :class:`MurmlError` with a
one-line reason naming the element and the symbol.
"""

from __future__ import annotations

import functools
import re
import tomllib
from importlib import resources

#: MURML, the form language of gestures AsapRealizer reads inside BML.
MURML_NAMESPACE = "http://www.techfak.uni-bielefeld.de/ags/soa/murml"

__all__ = ["MURML_NAMESPACE", "MurmlError", "read_description", "symbols"]
SLOTS = ("HandShape", "HandLocation", "PalmOrientation", "ExtFingerOrientation")
SCOPES = {"right_arm": "r", "left_arm": "l", "right_hand": "r", "left_hand": "l", "right": "r", "left": "l"}
SYMMETRIES = {"Sym": "", "SymMS": "x", "SymMT": "y", "SymMF": "z", "SymMST": "xy", "SymMSF": "xz", "SymMTF": "yz",
              "SymMSTF": "xyz"}
CURVE_SHAPES = ("LeftC", "RightC", "LeftS", "RightS", "UpC", "DownC")
VALUE_TYPES = ("start", "end", "normal", "shape", "extension")
_NUMBERS = re.compile(r"^\s*[+-]?\d+(\.\d*)?(\s+[+-]?\d+(\.\d*)?){2}\s*$")


class MurmlError(ValueError):
    """A MURML description that cannot be read, with the reason."""


@functools.lru_cache(maxsize=1)
def symbols() -> dict:
    """The symbol table (``agentsim/animation/data/murml_symbols.toml``)."""
    return tomllib.loads(resources.files("agentsim.animation").joinpath("data/murml_symbols.toml").read_text())


def _numbers(text: str) -> list[float] | None:
    return [float(x) for x in text.split()] if _NUMBERS.match(text) else None


def check_location(value: str) -> None:
    if _numbers(value) is not None:
        return
    table = symbols()
    words = value.split()
    if len(words) != 3:
        raise MurmlError(f"hand location {value!r}: three symbols (height side distance) or three numbers")
    for word, kind in zip(words, ("heights", "sides", "distances")):
        if word not in table[kind]:
            raise MurmlError(f"hand location {value!r}: no {kind[:-1]} {word!r} (known: {', '.join(table[kind])})")


def direction_letters(value: str) -> str | None:
    """The letters of a direction symbol (``DirLU`` -> ``LU``, ``PalmAD`` -> ``AD``), None if it is none."""
    for prefix in ("Dir", "Palm"):
        if value.startswith(prefix) and value[len(prefix):] and set(value[len(prefix):]) <= set("UDLRAT"):
            return value[len(prefix):]
    return None


def check_direction(value: str) -> None:
    if _numbers(value) is not None or direction_letters(value.strip()) is not None:
        return
    raise MurmlError(f"direction {value!r}: Dir or Palm followed by U, D, L, R, A, T (DirLU, PalmD), or three numbers")


def parse_shape(value: str) -> tuple[str, list[str]]:
    """A hand shape value as (basic shape, modifiers): ``"BSfist (ThExt IExt)"`` -> ``("BSfist", ["ThExt", "IExt"])``."""
    match = re.match(r"^\s*([A-Za-z0-9_]+)\s*(?:\((.*)\))?\s*$", value)
    if not match:
        raise MurmlError(f"hand shape {value!r}: a shape name with modifiers in parentheses (BSfist (ThExt))")
    table = symbols()
    shape, modifiers = match.group(1), (match.group(2) or "").replace(",", " ").split()
    if shape not in table["shapes"]:
        raise MurmlError(f"hand shape {shape!r} is not in the symbol table (known: {', '.join(table['shapes'])})")
    for m in modifiers:
        if m not in table["modifiers"]:
            raise MurmlError(f"hand shape modifier {m!r} is not in the symbol table "
                             f"(known: {', '.join(table['modifiers'])})")
    return shape, modifiers


def check_value(slot: str, value: str) -> None:
    if slot == "HandShape":
        parse_shape(value)
    elif slot == "HandLocation":
        check_location(value)
    else:
        check_direction(value)


def _scope(node, inherited: str) -> str:
    scope = node.attrs.get("scope", "").strip()
    if not scope:
        return inherited
    if scope not in SCOPES:
        raise MurmlError(f"<{node.local}> scope {scope!r}: one of {', '.join(SCOPES)}")
    return SCOPES[scope]


def _constraint(node, scope: str) -> dict:
    local = node.local
    if local in ("parallel", "sequence"):
        children = [_constraint(c, scope) for c in node.elements()]
        if not children:
            raise MurmlError(f"<{local}> has nothing in it")
        return {"op": local, "children": children}
    if local == "symmetrical":
        dominant = SCOPES.get(node.attrs.get("dominant", "right_arm").strip())
        if dominant is None:
            raise MurmlError(f"<symmetrical> dominant {node.attrs.get('dominant')!r}: right_arm or left_arm")
        symmetry = node.attrs.get("symmetry", "SymMS").strip()
        if symmetry not in SYMMETRIES:
            raise MurmlError(f"<symmetrical> symmetry {symmetry!r}: one of {', '.join(SYMMETRIES)}")
        children = [_constraint(c, dominant) for c in node.elements()]
        if not children:
            raise MurmlError("<symmetrical> has nothing in it")
        return {"op": "symmetrical", "dominant": dominant, "mirror": SYMMETRIES[symmetry], "children": children}
    if local == "static":
        slot = node.attrs.get("slot", "").strip()
        if slot not in SLOTS:
            raise MurmlError(f"<static> slot {slot!r}: one of {', '.join(SLOTS)}")
        value = node.attrs.get("value", "").strip()
        check_value(slot, value)
        return {"op": "static", "slot": slot, "value": value, "side": _scope(node, scope)}
    if local == "dynamic":
        slot = node.attrs.get("slot", "").strip()
        if slot not in SLOTS:
            raise MurmlError(f"<dynamic> slot {slot!r}: one of {', '.join(SLOTS)}")
        side = _scope(node, scope)
        elements = []
        for e in node.elements():
            if e.local != "dynamicElement":
                raise MurmlError(f"<dynamic> holds <dynamicElement>s, not <{e.local}>")
            kind = e.attrs.get("type", "linear").strip() or "linear"
            if kind not in ("linear", "curve"):
                raise MurmlError(f"<dynamicElement> type {kind!r}: linear or curve")
            values: dict[str, str] = {}
            for v in e.elements():
                vtype, name = v.attrs.get("type", "").strip(), v.attrs.get("name", "").strip()
                if v.local != "value" or vtype not in VALUE_TYPES:
                    raise MurmlError(f"<dynamicElement> value type {vtype!r}: one of {', '.join(VALUE_TYPES)}")
                values[vtype] = name
            for needed in ("start", "end"):
                if needed not in values:
                    raise MurmlError(f"<dynamicElement> of {slot} has no {needed} value")
                check_value(slot, values[needed])
            if kind == "curve":
                if slot != "HandLocation":
                    raise MurmlError(f"a curve moves the hand's location, not its {slot}")
                check_direction(values.get("normal", "DirU"))
                if values.get("shape", "LeftC") not in CURVE_SHAPES:
                    raise MurmlError(f"curve shape {values['shape']!r}: one of {', '.join(CURVE_SHAPES)}")
                try:
                    float(values.get("extension", "0.5"))
                except ValueError:
                    raise MurmlError(f"curve extension {values['extension']!r} is not a number") from None
            elements.append({"type": kind, "values": values, "side": _scope(e, side)})
        if not elements:
            raise MurmlError(f"<dynamic> of {slot} has no <dynamicElement>")
        return {"op": "dynamic", "slot": slot, "side": side, "elements": elements}
    raise MurmlError(f"<{local}> is not a MURML movement constraint")


_POSTURE = re.compile(r"\(([^()]*)\)")


def _posture(text: str) -> dict[str, list[float]]:
    values: dict[str, list[float]] = {}
    for spec in _POSTURE.findall(text):
        words = spec.split()
        if len(words) < 2:
            raise MurmlError(f"posture ({spec}): a joint and its values")
        try:
            if len(words) == 2:
                values[words[0]] = [float(words[1])]
            else:
                n = int(words[1])
                numbers = [float(x) for x in words[2:]]
                if n != len(numbers) or n not in (1, 3):
                    raise MurmlError(f"posture ({spec}): {n} values announced, {len(numbers)} given (1 or 3)")
                values[words[0]] = numbers
        except ValueError:
            raise MurmlError(f"posture ({spec}): values must be numbers") from None
    if not values:
        raise MurmlError(f"posture {text.strip()!r} has no (joint n values)")
    return values


def _keyframing(node) -> dict:
    frames = []
    for phase in node.elements():
        if phase.local != "phase":
            raise MurmlError(f"<keyframing> holds <phase>s, not <{phase.local}>")
        for frame in phase.elements():
            if frame.local != "frame":
                raise MurmlError(f"<phase> holds <frame>s, not <{frame.local}>")
            try:
                ftime = float(frame.attrs.get("ftime", ""))
            except ValueError:
                raise MurmlError(f"<frame> ftime {frame.attrs.get('ftime')!r} is not a number") from None
            postures = [p for p in frame.elements() if p.local == "posture"]
            if not postures:
                raise MurmlError(f"<frame ftime=\"{ftime:g}\"> has no <posture>")
            values: dict[str, list[float]] = {}
            for p in postures:
                values.update(_posture("".join(c for c in p.children if isinstance(c, str))))
            frames.append({"ftime": ftime, "values": values})
    if not frames:
        raise MurmlError("<keyframing> has no frames")
    frames.sort(key=lambda f: f["ftime"])
    if frames[0]["ftime"] < 0:
        raise MurmlError("a <frame> ftime is negative")
    return {"frames": frames}


def read_description(node, kind: str) -> dict:
    """The form of a ``<murml-description>`` element (a :class:`~agentsim.core.xmltree.Node`) of a
    ``murmlgesture`` or ``murmlface``."""
    parts = node.elements()
    if not parts:
        raise MurmlError("<murml-description> is empty")
    form: dict = {"kind": kind, "constraints": [], "keyframing": None}
    for part in parts:
        if part.local == "dynamic" and part.elements() and part.elements()[0].local == "keyframing":
            part = part.elements()[0]
        if part.local == "keyframing":
            if form["keyframing"] is not None:
                raise MurmlError("more than one <keyframing>")
            form["keyframing"] = _keyframing(part)
        elif kind == "face":
            raise MurmlError(f"<murmlface> holds a <keyframing>, not <{part.local}>")
        else:
            form["constraints"].append(_constraint(part, "r"))
    if form["keyframing"] is not None and form["constraints"]:
        raise MurmlError("a description is either movement constraints or a <keyframing>, not both")
    return form
