"""What a run report's page is given: the run's timeline as JSON and the joint positions as quantized binary.

The page is opened from ``file://``, where a browser loads data only through classic ``<script>`` tags, so
each payload is written as a small JavaScript file that assigns one global:

* ``data.js`` sets ``window.REPORT_DATA``: the run's duration, its behaviours with their sync points, the
  words as they were heard, the feedback, the drops, the per-gesture error table and the skeleton's
  points (names and parents). Times are seconds on the run's axis, rounded to the microsecond.
* ``poses.js`` sets ``window.REPORT_POSES``: the world positions of every joint (and the end sites that
  show the head, the jaw, the hands and the feet) at a subset of the stream's frames: every frame of a
  grid of at most :data:`MAX_FPS` frames per second, plus the two frames either side of every stroke, so
  that the page shows a stroke's extreme as the stream has it. Positions are integers of ``scale`` metres
  (1 mm) from ``origin``, little-endian Int16, base64; frames are the stream's frame indices, Uint32.

:func:`pose_payload` and :func:`timeline_payload` build the two as Python values, :func:`js_assignment`
writes either, :func:`read_js_assignment` and :func:`decode_poses` read them back.
"""

from __future__ import annotations

import base64
import json
import math
import tempfile
from typing import Iterable, Iterator

import numpy as np

from agentsim.animation.body import FINGERS, HAND_JOINTS

#: Highest frame rate of the regular grid of frames sent to the page (strokes add frames of their own).
MAX_FPS = 30.0
#: Leaf joints whose end site the page draws as a point of its own (head top, jaw, finger and thumb tips, toes,
#: the brows and the mouth corners, which move by turning about their joint).
END_SITES = ("skullbase", "temporomandibular", *(f"{s}_{f}3" for s in "lr" for f in ("thumb", *FINGERS)),
             "l_ankle", "r_ankle", "l_eyebrow", "r_eyebrow", "l_lip_corner", "r_lip_corner",
             "upper_lip", "lower_lip")  # the lips' edges: the visemes show in the mouth's opening
#: Joints of the face and of the hands: drawn smaller.
FACE = ("temporomandibular", "lower_lip", "upper_lip", "l_lip_corner", "r_lip_corner", "l_eyeball", "r_eyeball",
        "l_eyelid", "r_eyelid", "l_eyebrow", "r_eyebrow", *(f"{s}_{j}" for s in "lr" for j in HAND_JOINTS))
#: The sync point names of a phase's start, and what the phase that starts there is called.
PHASES = {"start": "preparation", "ready": "pre-stroke hold", "strokeStart": "stroke", "stroke": "stroke",
          "strokeEnd": "post-stroke hold", "relax": "retraction", "attackPeak": "stroke"}


def _num(x, digits: int = 6):
    """A float for JSON: rounded, None where it is None, NaN or infinite."""
    if x is None:
        return None
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def stroke_times(recording, gestures: Iterable = ()) -> list[float]:
    """Times (s) at which a stroke happened: every behaviour's passed ``stroke`` and every pegged sync point
    of ``gestures`` (:class:`~agentsim.media.tables.GestureRow`) that happened."""
    times = []
    for record in recording.behaviours:
        for sync, t, passed in zip(record.sync_ids, record.times, record.passed):
            if sync == "stroke" and passed and t is not None and math.isfinite(t):
                times.append(float(t))
    times += [float(g.happened_s) for g in gestures if g.happened_s is not None and math.isfinite(g.happened_s)]
    return sorted(set(times))


def point_names(body) -> tuple[list[str], list[int]]:
    """The points the page draws for ``body``: every joint (BVH order) then the end sites of
    :data:`END_SITES` (named ``joint.end``), and each point's parent index (-1 for the root)."""
    names = [j.name for j in body.joints]
    parents = [names.index(j.parent) if j.parent else -1 for j in body.joints]
    for name in END_SITES:
        if name in body.joint and body.joint[name].end_site is not None:
            parents.append(names.index(name))
            names.append(f"{name}.end")
    return names, parents


def point_positions(stream, frames: np.ndarray | None = None) -> np.ndarray:
    """World positions (frames, points, 3) in metres of :func:`point_names` at the stream's ``frames``
    (indices; all frames by default), a stretch of frames at a time."""
    from agentsim.animation.body import FK_ROWS

    if frames is None:
        return body_points(stream.body, stream.values)
    frames = np.asarray(frames)
    parts = [body_points(stream.body, stream.take("values", frames[a:a + FK_ROWS]))
             for a in range(0, len(frames), FK_ROWS)]
    return np.concatenate(parts) if parts else body_points(stream.body, stream.take("values", frames))


def body_points(body, values: np.ndarray) -> np.ndarray:
    """World positions (frames, points, 3) in metres of :func:`point_names` for poses ``values`` (frames x
    DOFs, as in a PoseStream), computed :data:`~agentsim.animation.body.FK_ROWS` frames at a time."""
    from agentsim.animation.body import FK_ROWS

    values = np.atleast_2d(np.asarray(values, dtype=float))
    ends = [name for name in END_SITES if name in body.joint and body.joint[name].end_site is not None]
    result = np.empty((len(values), len(body.joints) + len(ends), 3))
    for a in range(0, len(values), FK_ROWS):
        fk = body.forward_kinematics(values[a:a + FK_ROWS])
        out = [fk[j.name][1] for j in body.joints]
        for name in ends:
            rot, pos = fk[name]
            out.append(pos + rot @ np.asarray(body.joint[name].end_site, dtype=float))
        result[a:a + FK_ROWS] = np.stack(out, axis=1)
    return result


def report_frames(stream, max_fps: float = MAX_FPS, keep: Iterable[float] = ()) -> np.ndarray:
    """The stream's frame indices sent to the page: a grid of at most ``max_fps`` frames per second (with
    the last frame), plus the frames either side of each time in ``keep``."""
    n = stream.n_frames
    if n == 0:
        return np.zeros(0, np.uint32)
    step = max(1, int(math.ceil(stream.fps / max_fps - 1e-9)))
    chosen = set(range(0, n, step))
    chosen.add(n - 1)
    t0 = float(stream.times[0])
    for t in keep:
        x = (t - t0) * stream.fps
        for k in (math.floor(x + 1e-9), math.ceil(x - 1e-9)):
            if 0 <= k < n:
                chosen.add(int(k))
    return np.array(sorted(chosen), np.uint32)


def _quantized_poses(stream, max_fps: float, keep: Iterable[float]) -> tuple[dict, Iterator[str]]:
    """``window.REPORT_POSES`` without its ``xyz``, and ``xyz`` as pieces of base64 text to be joined, made
    :data:`~agentsim.animation.body.FK_ROWS` frames at a time: the positions (in metres) go to a temporary
    file while their extent is found, and come back from it to be quantized and encoded (a long run's
    positions are never held whole). Each piece encodes a whole number of frames, a multiple of 3 bytes
    (6 bytes a point), so the pieces join into the text of the whole."""
    from agentsim.animation.body import FK_ROWS

    frames = report_frames(stream, max_fps, keep)
    names, _ = point_names(stream.body)
    spill = tempfile.TemporaryFile()
    lo = hi = None
    shapes = []
    for a in range(0, len(frames), FK_ROWS):
        positions = body_points(stream.body, stream.take("values", frames[a:a + FK_ROWS]))
        flat = positions.reshape(-1, 3)
        if flat.size:
            lo = flat.min(axis=0) if lo is None else np.minimum(lo, flat.min(axis=0))
            hi = flat.max(axis=0) if hi is None else np.maximum(hi, flat.max(axis=0))
        shapes.append(positions.shape)
        spill.write(np.ascontiguousarray(positions).tobytes())
    if lo is not None:
        origin = np.round((lo + hi) / 2.0, 3)
        span = float(np.max(hi - lo))
    else:
        origin, span = np.zeros(3), 0.0
    # 1 mm steps unless the run covers more than an Int16 of millimetres (65 m)
    scale = 0.001 if span < 65.0 else math.ceil(span / 65.0 * 1000.0) / 1000.0
    payload = {
        "fps": float(stream.fps),
        "t0": float(stream.times[0]) if stream.n_frames else 0.0,
        "count": int(len(frames)),
        "points": len(names),
        "origin": [float(x) for x in origin],
        "scale": scale,
        "frames": base64.b64encode(frames.astype("<u4").tobytes()).decode("ascii"),
    }

    def pieces() -> Iterator[str]:
        with spill:
            spill.seek(0)
            for shape in shapes:
                positions = np.fromfile(spill, dtype=np.float64, count=int(np.prod(shape))).reshape(shape)
                q = np.clip(np.round((positions - origin) / scale), -32767, 32767).astype("<i2")
                yield base64.b64encode(q.tobytes()).decode("ascii")

    return payload, pieces()


def pose_payload(stream, max_fps: float = MAX_FPS, keep: Iterable[float] = ()) -> dict:
    """``window.REPORT_POSES`` for a PoseStream: see the module's docstring. ``keep``: stroke times."""
    payload, pieces = _quantized_poses(stream, max_fps, keep)
    payload["xyz"] = "".join(pieces)
    return payload


def write_poses(path, stream, comment: str = "", max_fps: float = MAX_FPS, keep: Iterable[float] = ()) -> dict:
    """Write ``poses.js``: the text of ``js_assignment("REPORT_POSES", pose_payload(stream, max_fps, keep),
    comment)``, its positions quantized, encoded and written a stretch of frames at a time (never the text of
    a long run's positions whole). Returns the payload without ``xyz``."""
    from agentsim.written import written

    payload, pieces = _quantized_poses(stream, max_fps, keep)
    marker = "\x00xyz\x00"  # JSON writes it escaped, as no base64 text could be
    text = js_assignment("REPORT_POSES", {**payload, "xyz": marker}, comment)
    head, tail = text.split(json.dumps(marker))
    with written(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(head + '"')
        for piece in pieces:
            f.write(piece)
        f.write('"' + tail)
    return payload


def decode_poses(payload: dict) -> tuple[np.ndarray, np.ndarray]:
    """Frame indices and positions (frames, points, 3) in metres back from a :func:`pose_payload`."""
    frames = np.frombuffer(base64.b64decode(payload["frames"]), "<u4")
    q = np.frombuffer(base64.b64decode(payload["xyz"]), "<i2").reshape(payload["count"], payload["points"], 3)
    return frames, q * float(payload["scale"]) + np.asarray(payload["origin"], dtype=float)


def js_assignment(name: str, value, comment: str = "") -> str:
    """A JavaScript file that assigns JSON ``value`` to ``window.<name>`` (one line, with ``comment``
    above it); ``</`` is escaped so the text could never close a script element."""
    text = json.dumps(value, separators=(",", ":"), ensure_ascii=False, allow_nan=False).replace("</", "<\\/")
    head = f"/* {comment} */\n" if comment else ""
    return f"{head}window.{name} = {text};\n"


def read_js_assignment(text: str, name: str):
    """The JSON value a :func:`js_assignment` file assigns to ``window.<name>``."""
    marker = f"window.{name} = "
    start = text.index(marker) + len(marker)
    end = text.rindex(";")
    return json.loads(text[start:end].replace("<\\/", "</"))


# ------------------------------------------------------------------------------------------ the timeline
def run_duration(recording, stream=None, track=None) -> float:
    """How long the run lasts on its axis: the end of its sound, its motion, its last known sync point or
    feedback, whichever is last (s)."""
    ends = [0.0, float(getattr(recording, "now", 0.0) or 0.0)]
    if track is not None:
        ends.append(track.duration)
    if stream is not None and stream.n_frames:
        ends.append(float(stream.times[-1]))
    for record in recording.behaviours:
        ends += [float(t) for t in record.times if t is not None and math.isfinite(t)]
    ends += [float(f["globalTime"]) for f in recording.feedback
             if isinstance(f.get("globalTime"), (int, float)) and math.isfinite(f["globalTime"])]
    return max(ends)


def heard_words(recording) -> list[tuple[float, float, str, int, bool]]:
    """Every word of every speech as heard on the run's axis: (onset, end, text, speech index, cut), where
    onset is ``t0 + start * (1 + drift_ppm * 1e-6)`` and ``cut`` says an interruption stopped the speech
    before the word's onset."""
    words = []
    for i, heard in enumerate(recording.speech):
        speed = 1.0 + heard.drift_ppm * 1e-6
        for w in heard.utterance.words:
            onset = heard.t0 + w.start * speed
            cut = heard.stopped is not None and onset > heard.stopped + 1e-9
            words.append((onset, heard.t0 + w.end * speed, w.text, i, cut))
    return words


def summary(gestures) -> dict:
    """Figures of the gesture table: how many rows, how many measured, dropped, and statistics of the absolute errors (ms)."""
    errors = np.array([abs(g.error_ms) for g in gestures if g.error_ms is not None and math.isfinite(g.error_ms)])
    out = {"gestures": len(gestures), "measured": int(errors.size), "dropped": sum(1 for g in gestures if g.dropped)}
    if errors.size:
        out.update(median_ms=_num(np.median(errors), 3), p95_ms=_num(np.percentile(errors, 95), 3),
                   max_ms=_num(errors.max(), 3))
    return out


#: Columns of the gesture table as the page shows them: (field of GestureRow, heading).
GESTURE_COLUMNS = (("block", "block"), ("behaviour", "behaviour"), ("type", "type"), ("sync", "sync"),
                   ("tied_to", "tied to"), ("word", "word"), ("sounded_s", "sounded (s)"),
                   ("happened_s", "happened (s)"), ("error_ms", "error (ms)"), ("dropped", "dropped"),
                   ("reason", "reason"))


def timeline_payload(recording, gestures=(), duration: float | None = None) -> dict:
    """The timeline part of ``window.REPORT_DATA``: behaviours, words, feedback, drops and the gesture table."""
    drops = {(d.block, d.behaviour): d for d in recording.drops}
    speeches = {(h.block, h.behaviour): i for i, h in enumerate(recording.speech)}
    behaviours = []
    for record in recording.behaviours:
        drop = drops.get((record.block, record.id))
        attributes = record.behaviour.attributes
        behaviours.append({
            "name": record.name, "type": record.type,
            "lexeme": attributes.get("lexeme") or attributes.get("name") or "",
            "sync": list(record.sync_ids), "t": [_num(t) for t in record.times],
            "inf": [t is not None and math.isinf(t) for t in record.times] if any(
                t is not None and math.isinf(t) for t in record.times) else None,
            "passed": [bool(p) for p in record.passed], "state": record.state,
            "stopped": _num(record.stopped if record.stopped is not None else (drop.time if drop else None)),
            "dropped": record.state == "dropped", "interrupted": bool(record.interrupted),
            "reason": drop.reason if drop else "",
            "speech": speeches.get((record.block, record.id)),
        })
    words = heard_words(recording)
    kinds: list[str] = []
    ft, fk = [], []
    warnings = []
    for f in recording.feedback:
        t = f.get("globalTime")
        if not isinstance(t, (int, float)) or not math.isfinite(t):
            continue
        kind = str(f.get("type", ""))
        if kind not in kinds:
            kinds.append(kind)
        ft.append(_num(t))
        fk.append(kinds.index(kind))
        if kind == "warningFeedback":
            warnings.append({"t": _num(t), "id": str(f.get("id", "")), "type": str(f.get("warningType", "")),
                             "text": str(f.get("description", ""))[:300]})
    rows = []
    for g in gestures:
        row = []
        for field, _ in GESTURE_COLUMNS:
            v = getattr(g, field)
            row.append(_num(v, 3 if field.endswith("_ms") else 6) if isinstance(v, float) else v)
        rows.append(row)
    return {
        "duration": _num(duration if duration is not None else run_duration(recording)),
        "behaviours": behaviours,
        "words": {"t": [_num(w[0]) for w in words], "end": [_num(w[1]) for w in words],
                  "text": [w[2] for w in words], "speech": [w[3] for w in words], "cut": [w[4] for w in words]},
        "speeches": [{"name": f"{h.block}:{h.behaviour}", "t0": _num(h.t0), "drift_ppm": _num(h.drift_ppm, 3),
                      "stopped": _num(h.stopped)} for h in recording.speech],
        "feedback": {"types": kinds, "t": ft, "kind": fk},
        "warnings": warnings,
        "drops": [{"name": f"{d.block}:{d.behaviour}", "t": _num(d.time), "type": d.warning_type,
                   "reason": d.reason} for d in recording.drops],
        "gestures": {"columns": [c for c, _ in GESTURE_COLUMNS], "headings": [h for _, h in GESTURE_COLUMNS],
                     "rows": rows},
        "summary": summary(gestures),
    }
