"""GEML, the gestures of de Melo's Expression Markup Language, as MURML gestures (:mod:`agentsim.bml.eml`
reads the rest of a document).

A ``<gesture-key time duration handedness>`` is a gesticulation keyframe: sequences of hand shapes
(``<hand-shapes><key time id/>``, Portuguese Sign Language shapes by number), palm orientations
(``<palms><key time a x y z/>``: the palm faces along (x, y, z), the fingers turned ``a`` degrees about it)
and positions (``<motion coords="speaker"><key time x y z/>``), each key ``time`` seconds after the key's
start (or spread evenly over its duration when none is given). It becomes one ``<murmlgesture>`` whose
stroke is at the key's time and whose stroke phase lasts its duration: each slot moves through its keys
from where the previous key on that hand left it, on a grid of equal parts of the stroke (MURML's
sequences share the stroke equally) on which every key's time falls. The coordinates, the palm's
reference and the hand shapes are data: ``agentsim/bml/data/eml.toml``.
"""

from __future__ import annotations

import functools
import json
import math
import re
import tomllib
from pathlib import Path

from agentsim.animation.murml_form import MURML_NAMESPACE, MurmlError, parse_shape, read_description
from agentsim.core.xmltree import Node
from agentsim.errors import AgentsimError

#: The file the EML tables are read from.
TABLE_PATH = Path(__file__).resolve().parent / "data" / "eml.toml"
#: The most equal parts the stroke is cut into so that every key's time falls on a boundary.
MAX_PARTS = 24
SLOTS = ("HandShape", "PalmOrientation", "ExtFingerOrientation", "HandLocation")
SIDES = {"right": ("r",), "left": ("l",), "both": ("r", "l")}
SCOPE = {"r": "right_arm", "l": "left_arm"}
_PERCENT = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*%\s*$")
_SECONDS = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(s|ms)?\s*$")


def read_table(text: str) -> dict:
    """The EML table's text read and checked (:class:`~agentsim.errors.AgentsimError` naming what is wrong)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AgentsimError(f"{TABLE_PATH}: not TOML: {exc}") from None
    if set(data) != {"speaker", "palms", "handshapes", "unsupported"}:
        raise AgentsimError(f"{TABLE_PATH}: expected the tables speaker, palms, handshapes and unsupported")
    shapes = data["handshapes"].get("shapes", {})
    for number, entry in shapes.items():
        if not number.isdigit() or not {"name", "description", "murml"} <= set(entry):
            raise AgentsimError(f"{TABLE_PATH}: hand shape {number!r} needs a number, name, description and murml")
        try:
            parse_shape(entry["murml"])
        except MurmlError as exc:
            raise AgentsimError(f"{TABLE_PATH}: hand shape {number}: {exc}") from None
    parse_shape(data["handshapes"]["neutral"])
    return data


TABLE = read_table(TABLE_PATH.read_text(encoding="utf-8"))
#: Portuguese Sign Language hand shapes by number: (name, MURML hand shape).
HAND_SHAPES: dict[str, tuple[str, str]] = {
    n: (e["name"], e["murml"]) for n, e in TABLE["handshapes"].get("shapes", {}).items()}
NEUTRAL_SHAPE: str = TABLE["handshapes"]["neutral"]
UNSUPPORTED: dict[str, str] = TABLE["unsupported"]


@functools.lru_cache(maxsize=1)
def figure() -> tuple[float, float]:
    """(metres per unit of the thesis's model, height of the speaker frame's origin above the floor) for the
    default figure: its arm over the model's, its sacroiliac joint at rest."""
    from agentsim.animation.body import Body

    body = Body()
    origin = body.forward_kinematics(body.rest_pose()[None], ["sacroiliac"])["sacroiliac"][1][0]
    return body.arm_reach("r") / float(TABLE["speaker"]["arm"]), float(origin[1])


def _vec(values) -> str:
    return " ".join(f"{v:.4f}" for v in values)


def location(x: float, y: float, z: float, world: bool = False) -> tuple[float, float, float]:
    """A point of speaker (or world: from the floor) coordinates in the body's frame (metres; X the
    character's left, Y up from the floor, Z forward)."""
    unit, origin = figure()
    return x * unit, (0.0 if world else origin) + y * unit, -z * unit


def orientation(a: float, x: float, y: float, z: float) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """(palm normal, finger direction) in the body's frame of a palm key; None for a zero axis."""
    n = (x, y, -z)
    length = math.sqrt(sum(c * c for c in n))
    if length < 1e-9:
        return None
    n = tuple(c / length for c in n)
    ref = TABLE["palms"]["fingers_at_zero"]
    ref = (ref[0], ref[1], -ref[2])
    if abs(sum(p * q for p, q in zip(n, ref))) > 0.999:
        alt = TABLE["palms"]["fingers_if_vertical"]
        ref = (alt[0], alt[1], -alt[2])
    dot = sum(p * q for p, q in zip(n, ref))
    f = tuple(r - dot * c for r, c in zip(ref, n))
    fl = math.sqrt(sum(c * c for c in f))
    f = tuple(c / fl for c in f)
    # a left-handed turn of a about n is a right-handed one of -a (Rodrigues)
    t = math.radians(-a)
    cross = (n[1] * f[2] - n[2] * f[1], n[2] * f[0] - n[0] * f[2], n[0] * f[1] - n[1] * f[0])
    fingers = tuple(f[i] * math.cos(t) + cross[i] * math.sin(t) for i in range(3))
    return n, fingers


def mirror(slot: str, value):
    """A value of the dominant (right) hand for the other one, as in a mirror on the sagittal plane."""
    if slot == "HandShape":
        return value
    return (-value[0], value[1], value[2])


class GestureKeys:
    """Writes gesture keys as ``<murmlgesture>`` elements; remembers where each hand was left."""

    def __init__(self, note, warn):
        self.note = note  # note(text, node): an adaptation
        self.warn = warn  # warn(kind, text, node): a warning of its own
        self.last: dict[str, dict[str, object]] = {"r": {}, "l": {}}

    # ------------------------------------------------------------------------------------------- features
    def key_times(self, keys: list[Node], duration: float) -> list[float]:
        """Each key's time (seconds after the key's start): as written (seconds, or a percentage of the
        duration), else spread evenly over the duration."""
        times = []
        for k, key in enumerate(keys):
            text = key.attrs.get("time")
            if text is None:
                times.append(duration * k / (len(keys) - 1) if len(keys) > 1 else 0.0)
                continue
            percent, plain = _PERCENT.match(text), _SECONDS.match(text)
            if percent:
                times.append(duration * float(percent.group(1)) / 100.0)
            elif plain:
                times.append(float(plain.group(1)) / (1000.0 if plain.group(2) == "ms" else 1.0))
            else:
                raise ValueError(f"key time {text!r} (line {key.line}) is not seconds or a percentage")
        return times

    def features(self, node: Node, sides: tuple[str, ...], duration: float) -> dict[str, dict[str, list]]:
        """side -> slot -> [(seconds, value)] of a gesture key's features."""
        out: dict[str, dict[str, list]] = {side: {} for side in sides}
        for feature in node.elements():
            keys = [k for k in feature.elements() if k.local == "key"]
            if feature.local not in ("hand-shapes", "palms", "motion"):
                self.warn("BEHAVIOR_TYPE_NOT_SUPPORTED", f"unknown GEML element <{feature.tag}> in <gesture-key> "
                          "ignored", feature)
                continue
            hand = feature.attrs.get("hand", "").strip()
            if hand and hand not in ("left", "right"):
                raise ValueError(f"<{feature.tag} hand={hand!r}> (line {feature.line}): left or right")
            times = self.key_times(keys, duration)
            world = feature.attrs.get("coords", "speaker").strip() == "world"
            if world:
                self.note("GEML motion in world coordinates read as the speaker's at its place, from the floor "
                          "(the character does not move)", node)
            for t, key in zip(times, keys):
                values = self.values(feature.local, key, world)
                for side in sides:
                    if hand and SIDES[hand][0] != side:
                        continue
                    mirrored = not hand and side == "l" and "r" in sides
                    for slot, value in values.items():
                        value = mirror(slot, value) if mirrored else value
                        out[side].setdefault(slot, []).append((t, value))
        return out

    def values(self, kind: str, key: Node, world: bool) -> dict[str, object]:
        def number(name: str) -> float:
            try:
                value = float(key.attrs.get(name, "0"))
            except ValueError:
                raise ValueError(f"<key {name}={key.attrs.get(name)!r}> (line {key.line}) is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"<key {name}={key.attrs.get(name)!r}> (line {key.line}) is not a number")
            return value

        if kind == "hand-shapes":
            number_id = key.attrs.get("id", "").strip()
            if number_id in HAND_SHAPES:
                name, shape = HAND_SHAPES[number_id]
                self.note(f"Portuguese Sign Language hand shape {number_id} ({name}) played as MURML's {shape}", key)
                return {"HandShape": shape}
            known = ", ".join(sorted(HAND_SHAPES, key=int))
            self.warn("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", f"hand shape id {number_id!r} is not one of the Portuguese "
                      f"Sign Language shapes described here ({known}): the neutral hand ({NEUTRAL_SHAPE}) instead",
                      key)
            return {"HandShape": NEUTRAL_SHAPE}
        if kind == "palms":
            found = orientation(number("a"), number("x"), number("y"), number("z"))
            if found is None:
                raise ValueError(f"<palms> key (line {key.line}) has no axis: x, y and z are all 0")
            return {"PalmOrientation": found[0], "ExtFingerOrientation": found[1]}
        return {"HandLocation": location(number("x"), number("y"), number("z"), world)}

    # ------------------------------------------------------------------------------------------- the form
    def form(self, node: Node, sides: tuple[str, ...], duration: float, name: str) -> Node:
        """The ``<murml-description>`` of a gesture key (its features as constraints on the stroke)."""
        features = self.features(node, sides, duration)
        fractions = sorted({min(max(t / duration, 0.0), 1.0) if duration > 0 else 0.0
                            for slots in features.values() for keys in slots.values() for t, _ in keys})
        parts = next((n for n in range(1, MAX_PARTS + 1)
                      if all(abs(u * n - round(u * n)) < 1e-6 for u in fractions)), None)
        if parts is None:
            parts = MAX_PARTS
            self.note(f"gesture-key key times on a grid of {MAX_PARTS} equal parts of its duration (MURML's "
                      "sequences share the stroke equally)", node)
        if any(t > duration + 1e-9 for slots in features.values() for keys in slots.values() for t, _ in keys):
            self.note("gesture-key keys after its duration played at its end", node)
        constraints: list[Node] = []
        for side in sides:
            slots = features[side]
            for slot in SLOTS:
                keys = [(min(max(t / duration, 0.0), 1.0) if duration > 0 else 0.0, v) for t, v in slots.get(slot, ())]
                before = self.last[side].get(slot)
                if not keys and before is None:
                    continue  # MURML's default for the slot
                constraints.append(self.track(slot, side, sorted(keys, key=lambda k: k[0]), before, parts))
                if keys:
                    self.last[side][slot] = max(keys, key=lambda k: k[0])[1]
        return Node("murml-description", {}, node.line, node.column, {"": MURML_NAMESPACE},
                    [Node("parallel", {}, node.line, node.column, {"": MURML_NAMESPACE}, constraints)])

    def track(self, slot: str, side: str, keys: list[tuple[float, object]], before, parts: int) -> Node:
        """One slot of one hand through the stroke: from ``before`` (where the hand was; None: the first
        key's value) through the keys, held after the last."""
        ns = {"": MURML_NAMESPACE}
        if not keys:
            keys = [(0.0, before)]
        points = list(keys) if keys[0][0] <= 1e-9 or before is None else [(0.0, before), *keys]

        def text(value) -> str:
            return value if isinstance(value, str) else _vec(value)

        def at(u: float):
            """The value at stroke fraction u: positions and directions between keys linearly, a hand
            shape reached by the end of the part before its key."""
            if u <= points[0][0]:
                return points[0][1]
            for (u0, v0), (u1, v1) in zip(points, points[1:]):
                if u <= u1 + 1e-9:
                    if isinstance(v0, str):
                        return v1 if u >= u1 - 1e-9 else v0
                    w = (u - u0) / (u1 - u0) if u1 > u0 else 1.0
                    return tuple(a + (b - a) * w for a, b in zip(v0, v1))
            return points[-1][1]

        def static(value) -> Node:
            return Node("static", {"slot": slot, "value": text(value), "scope": SCOPE[side]}, None, None, ns)

        if all(text(v) == text(points[0][1]) for _, v in points):
            return static(points[0][1])
        items: list[Node] = []
        for k in range(parts):
            a, b = at(k / parts), at((k + 1) / parts)
            if isinstance(a, str) and a == b:
                items.append(static(a))
                continue
            if text(a) == text(b):
                items.append(static(a))
                continue
            element = Node("dynamicElement", {"type": "linear"}, None, None, ns, [
                Node("value", {"type": "start", "name": text(a)}, None, None, ns),
                Node("value", {"type": "end", "name": text(b)}, None, None, ns)])
            items.append(Node("dynamic", {"slot": slot, "scope": SCOPE[side]}, None, None, ns, [element]))
        return items[0] if len(items) == 1 else Node("sequence", {}, None, None, ns, items)


def preparation(description: Node, syncs: dict[str, float]) -> float:
    """When a MURML gesture with these numeric sync times would start (as the planner times it: its
    preferred timing stretched between its known keys)."""
    from agentsim.animation.units import motion_unit
    from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour
    from agentsim.core.engine import stretch_times

    kind = BEHAVIOUR_TYPES["murmlgesture"]
    behaviour = Behaviour("", kind.name, list(kind.syncs), {})
    behaviour.params["murml"] = json.dumps(read_description(description, "gesture"), separators=(",", ":"))
    preferred = motion_unit(behaviour).preferred()
    return stretch_times(preferred, {kind.syncs.index(k): t for k, t in syncs.items()}, 0.0)[0]
