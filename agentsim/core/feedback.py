"""BML 1.0 feedback: block progress, sync point progress, predictions and warnings, as plain dicts.

Every feedback is a dict with a ``type`` and the BML 1.0 names (``id``, ``time``, ``globalTime``,
``characterId``, ``warningType``, ...), so that it can be written as one JSON object per line.
"""

from __future__ import annotations

import json
import math
import re
from json.encoder import encode_basestring_ascii as _quoted  # (how the encoder writes a string)
from typing import Any, Callable, Iterable

Feedback = dict[str, Any]

#: BML 1.0 warning types used by the realizer.
WARNING_TYPES = (
    "PARSING_FAILURE",
    "NO_SUCH_TARGET",
    "IMPOSSIBLE_TO_SCHEDULE",
    "BEHAVIOR_TYPE_NOT_SUPPORTED",
    "CUSTOM_ATTRIBUTE_NOT_SUPPORTED",
    "INTERRUPTED",
    # not in BML 1.0: the block was written for another realizer, and read with these adaptations
    "NONSTANDARD_BML",
    # not in BML 1.0: the physically simulated body (--physics) fell
    "BODY_FELL",
)


#: The ``status`` of the end blockProgress of a block an interruption cut short, and of the last
#: syncPointProgress of each behaviour it cut (as BMLA's block progress carries a status): feedback, not a
#: warning, since the interruption was asked for.
INTERRUPTED = "INTERRUPTED"


def block_progress(block_id: str, which: str, global_time: float, character_id: str,
                   status: str | None = None) -> Feedback:
    feedback = {"type": "blockProgress", "id": f"{block_id}:{which}", "globalTime": global_time,
                "characterId": character_id}
    if status is not None:
        feedback["status"] = status
    return feedback


def sync_point_progress(block_id: str, behaviour_id: str, sync_id: str, time: float, global_time: float,
                        character_id: str, status: str | None = None) -> Feedback:
    feedback = {"type": "syncPointProgress", "id": f"{block_id}:{behaviour_id}:{sync_id}", "time": time,
                "globalTime": global_time, "characterId": character_id}
    if status is not None:
        feedback["status"] = status
    return feedback


def warning(target_id: str, warning_type: str, description: str, global_time: float, character_id: str,
            modified: Iterable[str] = (), line: int | None = None, column: int | None = None,
            adaptations: Iterable[str] = ()) -> Feedback:
    """A warning about a block or behaviour; ``line`` and ``column`` locate it in the BML source if known;
    a ``NONSTANDARD_BML`` warning lists its ``adaptations``."""
    if warning_type not in WARNING_TYPES:
        raise ValueError(f"unknown warning type {warning_type!r}")
    feedback = {"type": "warningFeedback", "id": target_id, "warningType": warning_type,
                "description": description, "modifiedBehaviours": list(modified), "globalTime": global_time,
                "characterId": character_id}
    if line is not None:
        feedback["line"], feedback["column"] = line, column
    adaptations = list(adaptations)
    if adaptations:
        feedback["adaptations"] = adaptations
    return feedback


def prediction(block_id: str, global_time: float, character_id: str, block_start: float, block_end: float,
               behaviours: list[dict[str, Any]]) -> Feedback:
    """Predicted timing of a block and its behaviours (global seconds)."""
    return {"type": "predictionFeedback", "id": block_id, "globalTime": global_time, "characterId": character_id,
            "bml": {"id": block_id, "globalStart": block_start, "globalEnd": block_end},
            "behaviours": behaviours}


#: Decimals of the times feedback is printed with: a nanosecond, far below anything a clock here means, and
#: without the float noise of sums (``3.2410000000000005`` is printed ``3.241``).
DECIMALS = 9


#: Types a feedback's values have that JSON writes as they are (looked up by exact type: a subclass of
#: float, numpy's float64, is rounded as a float is).
_AS_IS = frozenset((str, int, bool, type(None)))


def _clean(value: Any) -> Any:
    if type(value) in _AS_IS:  # most values: no call further down for them
        return value
    if isinstance(value, float):
        return round(value, DECIMALS) if math.isfinite(value) else None
    if isinstance(value, dict):
        return _clean_dict(value)
    if isinstance(value, list):
        return [v if type(v) in _AS_IS else _clean_dict(v) if type(v) is dict else _clean(v) for v in value]
    return value


_isfinite = math.isfinite  # (looked up once, not as an attribute for every float)


def _clean_dict(value: dict) -> dict:
    # (what _clean does, with floats and nested dicts, the bulk of a prediction, done here without a call each)
    out = {}
    for k, v in value.items():
        kind = type(v)
        if kind is float:
            out[k] = round(v, DECIMALS) if _isfinite(v) else None
        elif kind in _AS_IS:
            out[k] = v
        elif kind is dict:
            out[k] = _clean_dict(v)
        else:
            out[k] = _clean(v)
    return out


#: The encoder of :func:`to_json` (what ``json.dumps(..., separators=(", ", ": "))`` makes anew each call); it
#: does not look for cycles, which :func:`_clean`, going down every value first, would never come back from.
_ENCODER = json.JSONEncoder(separators=(", ", ": "), check_circular=False)


def to_json(feedback: Feedback) -> str:
    """One line of JSON for a feedback, its times to the nanosecond (:data:`DECIMALS`)."""
    if feedback.get("type") == "predictionFeedback":  # (a block's prediction: thousands of times)
        behaviours = feedback.get("behaviours")
        if type(behaviours) is list and len(behaviours) >= _MANY:
            written = _prediction_json(feedback, behaviours)
            if written is not None:
                return written
    return _ENCODER.encode(_clean(feedback))


# A prediction of many behaviours is written by _prediction_json: the same text as the encoder writes of
# _clean(feedback), made with two string formattings instead of a copy of every entry and a rounding and a
# repr of each time. A time is written "%.9f" with its trailing zeros dropped (one left after the point),
# which is the repr of round(t, 9): both take the same nine decimals of t (CPython rounds a float to n
# decimals from the digits it formats it with), and from 1e-4 to 1e6 no shorter decimal is that float
# (a float's spacing there is below 1e-9) and repr writes no exponent. Anything else (other entries, a time
# out of that range or not a float, a string with "%", ".," or ".}") is written by the encoder.

#: Predictions of at least this many behaviours are written by :func:`_prediction_json`.
_MANY = 16
#: The fields of a prediction, and of an entry (with a lexeme or not), in their order.
_PREDICTION = ("type", "id", "globalTime", "characterId", "bml", "behaviours")
_ENTRY = ("id", "type", "globalStart", "globalEnd", "syncs")
_ENTRY_LEXEME = (*_ENTRY, "lexeme")
#: An entry's text with its strings put in (``%s``) and its times left to put (``%%s``), by its fields and its
#: sync points' names.
_ENTRY_TEXT: dict[tuple, str] = {}
#: A time "%.9f" writes from 0 up to 1e-4 (repr writes it with an exponent): the other times do not begin so.
_SMALL = re.compile(r"0\.0000(?!00000)\d")
#: How a time is written before its trailing zeros go (a separator after it): to :data:`DECIMALS` decimals.
_TIME = f"%.{DECIMALS}f\x00"
# (the range the quicker way takes, and _SMALL, are those of nine decimals)
assert DECIMALS == 9


def _entry_text(fields: tuple, syncs: tuple) -> str | None:
    if fields != _ENTRY and fields != _ENTRY_LEXEME:
        return None
    names = [_quoted(name) for name in syncs]  # (a TypeError for a name that is not a string)
    if any("%" in name for name in names):
        return None
    if len(_ENTRY_TEXT) >= 256:
        _ENTRY_TEXT.clear()
    lexeme = ', "lexeme": %s' if len(fields) == 6 else ""
    text = _ENTRY_TEXT[fields, syncs] = (
        '{"id": %s, "type": %s, "globalStart": %%s, "globalEnd": %%s, "syncs": {'
        + ", ".join(f"{name}: %%s" for name in names) + "}" + lexeme + "}")
    return text


def _prediction_json(feedback: Feedback, behaviours: list) -> str | None:
    """:func:`to_json` of a prediction whose entries are all of the usual form, or None."""
    if tuple(feedback) != _PREDICTION:
        return None
    texts: list[str] = []
    times: list = []
    add, more, known = texts.append, times.extend, _ENTRY_TEXT
    try:
        for entry in behaviours:
            syncs = entry["syncs"]
            fields, names = tuple(entry), tuple(syncs)
            form = known.get((fields, names))
            if form is None:
                form = _entry_text(fields, names)
                if form is None:
                    return None
            if len(fields) == 5:
                add(form % (_quoted(entry["id"]), _quoted(entry["type"])))
            else:
                add(form % (_quoted(entry["id"]), _quoted(entry["type"]), _quoted(entry["lexeme"])))
            more((entry["globalStart"], entry["globalEnd"]))
            more(syncs.values())
    except (TypeError, KeyError, AttributeError):  # (an entry that is not a dict, a string that is not one)
        return None
    if set(map(type, times)) != {float} or not _isfinite(sum(times)) or not -1e6 < min(times) <= max(times) < 1e6:
        return None
    written = (_TIME * len(times)) % tuple(times)
    if _SMALL.search(written):
        return None
    body = ", ".join(texts)
    if body.count("%") != len(times) or ".," in body or ".}" in body:  # (no "%" but the times', no point there)
        return None
    body %= tuple([t.rstrip("0") for t in written[:-1].split("\x00")])
    body = body.replace(".,", ".0,").replace(".}", ".0}")
    head = _ENCODER.encode(_clean({**feedback, "behaviours": []}))
    return f"{head[:-3]}[{body}]}}"


class FeedbackLog:
    """Collects feedback in the order it was sent and passes each one to the listeners.

    ``keep``: how many items to keep (None: all); a long-running server forgets the oldest, its listeners
    still get everything.
    """

    def __init__(self, keep: int | None = None) -> None:
        self.items: list[Feedback] = []
        self._listeners: list[Callable[[Feedback], None]] = []
        self.keep = keep

    def listen(self, listener: Callable[[Feedback], None]) -> None:
        self._listeners.append(listener)

    def send(self, feedback: Feedback) -> None:
        self.items.append(feedback)
        if self.keep is not None and len(self.items) > 2 * self.keep:
            del self.items[:len(self.items) - self.keep]
        for listener in self._listeners:
            listener(feedback)

    def of_type(self, kind: str) -> list[Feedback]:
        return [f for f in self.items if f["type"] == kind]

    def sync_times(self) -> dict[str, float]:
        """Global time of every sync point passed, by ``block:behaviour:sync`` id."""
        return {f["id"]: f["globalTime"] for f in self.items if f["type"] == "syncPointProgress"}

    def warnings(self) -> list[Feedback]:
        return self.of_type("warningFeedback")
