"""Motion drivers from recorded BML behaviours: which driver plays each behaviour, on which hand, until when.

:func:`build_drivers` turns what a realizer played (its recording) into drivers on a
:class:`~agentsim.animation.manager.DriverManager`; gestures and pointing get their hands chosen,
conducting beats numbered and coarticulation on each hand; visemes (``lips``) hand the mouth on from one to
the next.
"""

from __future__ import annotations

import bisect
import collections
import json

import math
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from agentsim.animation.arms import GestureDriver, PointingDriver, conducting_path, stroke_path
from agentsim.animation.drivers import PRIORITY
from agentsim.animation.head import GazeDriver, HeadDriver, HeadTurnDriver
from agentsim.animation.lexicon import conducting_meter
from agentsim.animation.lips import LipsDriver, SpeechMouthDriver, curves_driver, lips_values
from agentsim.animation.manager import DriverManager
from agentsim.animation.motion import KeyTimes, ReplacementGroup
from agentsim.animation.murml import Form, MurmlDriver, MurmlKeyframeDriver, form_of, keyframe_channels
from agentsim.animation.pose import LocomotionDriver, PoseDriver, SpeechJawDriver, TransitionDriver, face_values
from agentsim.animation.scene import Scene, offset_target
from agentsim.animation.time_source import TimeSource
from agentsim.animation.units import repetition


@dataclass
class UnitInfo:
    """What became of one recorded behaviour: its keys, the drivers playing it, hands, and when it stopped."""

    block: str
    id: str
    type: str
    lexeme: str
    keys: dict[str, float]
    drivers: list[str] = field(default_factory=list)
    sides: list[str] = field(default_factory=list)
    stop: float | None = None
    target: list[float] | None = None
    note: str = ""
    form: object = field(default=None, repr=False)  # a MURML gesture's form (agentsim.animation.murml.Form)

    def as_dict(self) -> dict:
        return {"block": self.block, "id": self.id, "type": self.type, "lexeme": self.lexeme,
                "keys": dict(self.keys), "drivers": list(self.drivers), "sides": list(self.sides),
                "stop": self.stop, "target": self.target, "note": self.note}


def _beat_index(behaviour) -> int | None:
    meter = conducting_meter(behaviour.attributes.get("lexeme", ""))
    if meter and meter[1]:
        return meter[1]
    for k, v in behaviour.attributes.items():
        if k.lower().split(":")[-1] == "beat":
            try:
                return int(float(v))
            except ValueError:
                return None
    return None


def build_drivers(manager: DriverManager, records: Iterable, animator_time: TimeSource | None = None) -> list[UnitInfo]:
    """Create the motion drivers that play ``records`` and add them to ``manager``.

    ``records``: what each behaviour did (:class:`~agentsim.core.recording.BehaviourRecord`, as in a
    realizer's recording). A behaviour that never started is left out; one that was dropped or cut after
    it started plays until then. Behaviours tied to speech are advanced by ``animator_time`` when given.
    Their lexemes play as the manager's lexicon has them.
    """
    records = list(records)
    scene = manager.scene
    lexicon = manager.lexicon
    speech_ids = {r.name for r in records if r.type == "speech"}
    groups = {"gaze": ReplacementGroup("gaze")}
    infos: list[UnitInfo] = []
    arm_items: list[tuple] = []
    lips_items: list[tuple] = []

    for record in sorted(records, key=lambda x: (x.start if x.start is not None else math.inf, x.order)):
        b = record.behaviour
        if b.type == "wait":
            continue
        if record.state == "dropped" and not record.started:
            continue
        stop = None
        if record.state == "dropped":
            passed = [t for t, p in zip(record.times, record.passed) if p]
            stop = record.stopped if record.stopped is not None else (passed[-1] if passed else None)
        try:
            keys = KeyTimes.from_record(record, fill=stop, lexicon=lexicon)
        except ValueError:
            continue
        lexeme = b.attributes.get("lexeme", "")
        info = UnitInfo(record.block, record.id, b.type, lexeme, keys.as_dict(), stop=stop)
        infos.append(info)
        ts = animator_time if (animator_time is not None and (b.type == "speech" or speech_ids & set(record.tied_to))) \
            else None
        name = f"{record.block}:{record.id}"
        common = {"stop": stop, "time_source": ts}
        if b.type in ("murmlgesture", "murmlface"):
            form = form_of(b)
            if form.get("keyframing"):
                channels, unknown = keyframe_channels(form, manager.body, lexicon)
                if unknown:
                    info.note = f"no DOFs for {', '.join(unknown)}"
                if channels:
                    drv = manager.add(MurmlKeyframeDriver(name, keys, channels, **common))
                    info.drivers.append(drv.name)
                continue
            info.form = Form(form, manager.body)
            arm_items.append((record, keys, info, common))
            continue
        if b.type in ("gesture", "pointing"):
            form = lexicon.form(lexeme) if b.type == "gesture" and lexeme else None
            if form is not None:  # a lexeme whose lexicon entry is a MURML form (its mode may mirror it)
                mode = b.attributes.get("mode", "").upper()
                hand = "l" if mode in ("LEFT_HAND", "LEFT") else "r" if mode in ("RIGHT_HAND", "RIGHT") else None
                info.form = Form(json.loads(form), manager.body, hand)
            arm_items.append((record, keys, info, common))
            continue
        if b.type == "lips":
            lips_items.append((record, keys, info, common))
            continue
        if b.type == "speech":
            phonemes = getattr(record, "phonemes", ())
            if phonemes:  # the visemes of what it said; without phonemes, the jaw at syllable rate
                drv = manager.add(SpeechMouthDriver(name, keys, phonemes, record.preferred, lexicon, **common))
            else:
                drv = manager.add(SpeechJawDriver(name, keys, **common))
        elif b.type == "head":
            try:
                amount = float(b.attributes.get("amount", "0.5"))
            except ValueError:
                amount = 0.5
            amount *= amplitude(record, keys)
            drv = manager.add(HeadDriver(name, keys, lexeme or "NOD", 28.0 * amount, repetition(b), **common))
        elif b.type in ("gaze", "gazeShift"):
            target = _bml_target(scene, b)
            info.target = [float(x) for x in target]
            drv = manager.add(GazeDriver(name, keys, target, b.attributes.get("influence", "HEAD"),
                                         arrive="ready" if b.type == "gaze" else "end", shift=b.type == "gazeShift",
                                         group=groups["gaze"], **common))
        elif b.type == "headDirectionShift":
            drv = manager.add(HeadTurnDriver(name, keys, _bml_target(scene, b), arrive="end", shift=True, **common))
        elif b.type in ("faceLexeme", "faceFacs", "face", "faceShift"):
            values = face_values("faceFacs" if b.type == "faceFacs" else "faceLexeme", b.attributes, lexicon)
            if not values:
                info.note = "no DOFs for this expression"
                continue
            if b.type == "faceShift":
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["shift"], "end", release=None, **common))
            else:
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["behaviour"], "attackPeak", **common))
        elif b.type in ("posture", "postureShift"):
            label = (b.attributes.get("lexeme") or b.attributes.get("type") or "WEIGHT_SHIFT").upper()
            values = lexicon.postures.get(label, lexicon.postures["WEIGHT_SHIFT"])
            if b.type == "posture":
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["behaviour"], "ready", **common))
            else:
                drv = manager.add(PoseDriver(name, keys, values, PRIORITY["shift"], "end", release="end",
                                             rest_after=True, **common))
        elif b.type == "curves":
            drv, note = curves_driver(name, keys, b, lexicon, **common)
            info.note = note
            if drv is None:
                continue
            manager.add(drv)
        elif b.type == "locomotion":
            drv = manager.add(LocomotionDriver(name, keys, _bml_target(scene, b), **common))
        elif b.type == "transition":
            joints = set(b.params.get("joints", "").split() or ["skullbase", "vc4"])
            dofs = [d for d in manager.body.dof_names if d.split(".")[0] in joints and ".t" not in d]
            if not dofs:
                info.note = "none of its joints is in this body"
                continue
            drv = manager.add(TransitionDriver(name, keys, dofs, **common))
        else:
            info.note = "no motion for this behaviour type"
            continue
        info.drivers.append(drv.name)

    _build_arms(manager, arm_items, scene)
    _build_lips(manager, lips_items)
    return infos


def amplitude(record, keys: KeyTimes) -> float:
    """A motion's BMLA amplitude at its stroke (or start): the latest change that had started by then."""
    t = keys.time("stroke") if keys.has("stroke") else keys.start
    value = 1.0
    for param, start, end, kind, initial, target in getattr(record, "parameters", ()):
        if param == "amplitude" and start is not None and t >= start:
            linear = kind == "linear" and end is not None and end > start and t < end
            value = initial + (target - initial) * (t - start) / (end - start) if linear else target
    return value


def _bml_target(scene: Scene, behaviour) -> np.ndarray:
    attrs = behaviour.attributes
    point = scene.point(attrs.get("target", ""))
    try:
        angle = float(attrs.get("offsetAngle", "0"))
    except ValueError:
        angle = 0.0
    if angle:
        point = offset_target(point, np.array([0.0, 1.665, 0.085]), angle, attrs.get("offsetDirection", "RIGHT"))
    return point


def _build_lips(manager: DriverManager, items: list[tuple]) -> None:
    """Visemes, in the order they start: each holds its shape until the next one takes over when that
    starts during its relax..end, so consecutive visemes blend from one shape into the next."""
    items = sorted(items, key=lambda it: (it[1].start, it[0].order))
    for k, (record, keys, info, common) in enumerate(items):
        values, note = lips_values(record.behaviour.attributes, manager.lexicon)
        info.note = note
        following = items[k + 1][1].start if k + 1 < len(items) else None
        hold_until = following if following is not None and following < keys.end else None
        drv = manager.add(LipsDriver(f"{record.block}:{record.id}", keys, values, hold_until, **common))
        info.drivers.append(drv.name)


class _Busy:
    """The times a hand is taken, ``(start, end)`` each: whether any overlaps a stretch, ``a < end`` and
    ``start < e`` for one of them, asked in a time that grows with the log of their number (a prefix
    maximum of the ends by start, over the starts that can come, given beforehand)."""

    def __init__(self, starts: list[float]):
        self.exact = all(math.isfinite(x) for x in starts)
        self.starts = sorted(set(starts)) if self.exact else []
        self.tree = [-math.inf] * (len(self.starts) + 1)  # Fenwick tree of the largest end, by start
        self.spans: list[tuple[float, float]] = []

    def add(self, start: float, end: float) -> None:
        if not (self.exact and math.isfinite(end)):
            self.exact = False
        self.spans.append((start, end))
        i = bisect.bisect_left(self.starts, start) + 1
        if self.exact and not (i <= len(self.starts) and self.starts[i - 1] == start):
            self.exact = False  # a start not given beforehand
        if self.exact:
            while i < len(self.tree):
                self.tree[i] = max(self.tree[i], end)
                i += i & -i

    def overlaps(self, start: float, end: float) -> bool:
        if not self.exact:  # a time that is not a number: look at every one
            return any(a < end and start < e for a, e in self.spans)
        i = bisect.bisect_left(self.starts, end)  # the spans starting before ``end``
        best = -math.inf
        while i > 0:
            best = max(best, self.tree[i])
            i -= i & -i
        return start < best


def _build_arms(manager: DriverManager, items: list[tuple], scene: Scene) -> None:
    """Gestures and pointing: choose hands, number conducting beats, coarticulate on each hand."""
    # Hands: the mode says, else the right hand (pointing: the hand on the target's side), unless that
    # hand is busy then and the other is free. Behaviours with a mode are placed first.
    starts = [it[1].start for it in items]
    busy = {"l": _Busy(starts), "r": _Busy(starts)}
    planned: list[tuple[str, tuple]] = []
    explicit_modes = {"LEFT_HAND": ["l"], "LEFT": ["l"], "RIGHT_HAND": ["r"], "RIGHT": ["r"],
                      "BOTH_HANDS": ["l", "r"], "BOTH": ["l", "r"]}
    ordered = sorted(items, key=lambda it: it[0].behaviour.attributes.get("mode", "").upper() not in explicit_modes)
    for item in ordered:
        record, keys, info, common = item
        b = record.behaviour
        sides = info.form.sides if info.form is not None else explicit_modes.get(b.attributes.get("mode", "").upper())
        if sides is None:
            if b.type == "pointing":
                first = "l" if scene.point(b.attributes.get("target", ""))[0] > 0 else "r"
            else:
                first = "r"
            other = "l" if first == "r" else "r"
            clash = lambda s: busy[s].overlaps(keys.start, keys.end)  # noqa: E731
            sides = [other] if clash(first) and not clash(other) else [first]
        for s in sides:
            busy[s].add(keys.start, keys.end)
            planned.append((s, item))
    # Conducting: number the beats of each hand in stroke order, unless the lexeme or an attribute says.
    counters: dict[tuple[str, int], int] = {}
    beat_of: dict[tuple[str, int], int] = {}
    for s, item in sorted(planned, key=lambda x: x[1][1].time("stroke")):
        b = item[0].behaviour
        meter = conducting_meter(b.attributes.get("lexeme", "")) if b.type == "gesture" else None
        if meter is None:
            continue
        explicit = _beat_index(b)
        n = counters.get((s, meter[0]), 0)
        beat = explicit if explicit is not None else n % max(meter[0], 1) + 1
        counters[(s, meter[0])] = beat
        beat_of[(s, id(item))] = beat
    # Coarticulation: a gesture taking over a hand whose previous gesture is past its stroke starts at
    # once (dropping that one's retraction); one arriving during the previous stroke waits for its end.
    last: dict[str, tuple] = {}
    hands = collections.Counter(id(item) for _, item in planned)  # how many hands each item was given
    for s, item in sorted(planned, key=lambda x: (x[1][1].start, x[1][0].order)):
        record, keys, info, common = item
        b = record.behaviour
        acquire = keys.start
        prev = last.get(s)
        if prev is not None and prev[1].end > keys.start:
            prev_end = prev[1].time("strokeEnd")
            if prev_end <= keys.time("strokeStart"):
                acquire = max(keys.start, prev_end)
                info.note = (info.note + " coarticulated").strip()
        last[s] = item
        name = f"{record.block}:{record.id}" + (f" ({'left' if s == 'l' else 'right'})" if hands[id(item)] > 1
                                                else "")
        if info.form is not None:
            drv = MurmlDriver(name, keys, s, info.form, acquire=acquire, **common)
        elif b.type == "pointing":
            target = _bml_target(scene, b)
            info.target = [float(x) for x in target]
            drv = PointingDriver(name, keys, s, target, acquire=acquire, **common)
        else:
            lexeme = b.attributes.get("lexeme", "").upper() or "BEAT"
            meter = conducting_meter(lexeme)
            if meter is not None:
                try:
                    amount = float(b.attributes.get("amount", "1"))
                except ValueError:
                    amount = 1.0
                path = conducting_path(manager.lexicon, meter[0], beat_of.get((s, id(item)), 1), amount)
                info.note = (info.note + f" beat {beat_of.get((s, id(item)), 1)} of {meter[0]}").strip()
            else:
                path = stroke_path(manager.lexicon, lexeme)
            scale = amplitude(record, keys)
            if scale != 1.0:
                path = path.scaled(scale)
                info.note = (info.note + f" amplitude {scale:g}").strip()
            drv = GestureDriver(name, keys, s, path, acquire=acquire, **common)
        manager.add(drv)
        info.drivers.append(drv.name)
        info.sides.append(s)
