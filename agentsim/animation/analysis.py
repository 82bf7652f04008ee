"""Where the motion really has its stroke, measured on evaluated poses, against the stroke feedback.

For a gesture the ictus is the frame where the wrist is lowest between strokeStart and strokeEnd (its
vertical velocity turns from down to up); for a nod the frame where the head points lowest; for a shake
or a tilt the first extreme of the head's yaw or roll after strokeStart; for pointing the first frame
where the arm points exactly at the target. Only the world positions and orientations of the evaluated
poses are used, so this checks the whole chain (key times, motion, kinematics).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from agentsim.animation.output import PoseStream


@dataclass
class StrokeMeasure:
    """One stroke: the time the realizer reported and the time the motion shows it (seconds)."""

    block: str
    behaviour: str
    type: str
    lexeme: str
    side: str
    feedback: float
    motion: float
    refined: float
    #: the unit held its DOFs through its whole stroke (no other behaviour took them meanwhile)
    intact: bool = True

    @property
    def error(self) -> float:
        """Motion minus feedback, at frame resolution (seconds)."""
        return self.motion - self.feedback

    @property
    def refined_error(self) -> float:
        """Motion minus feedback with the ictus found between frames (seconds)."""
        return self.refined - self.feedback

    def as_dict(self) -> dict:
        d = asdict(self)
        d["error"] = self.error
        d["refined_error"] = self.refined_error
        return d


def head_orientation(stream: PoseStream) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World head (pitch down, yaw left, roll) in degrees per frame, from the skull's axes (a window of
    frames at a time)."""
    pitch, yaw, roll = (np.empty(stream.n_frames) for _ in range(3))
    for a, values in stream.windows():
        rot = stream.body.forward_kinematics(values, ["skullbase"])["skullbase"][0]
        fwd, up = rot[:, :, 2], rot[:, :, 1]
        b = a + len(values)
        pitch[a:b] = -np.degrees(np.arcsin(np.clip(fwd[:, 1], -1, 1)))
        yaw[a:b] = np.degrees(np.arctan2(fwd[:, 0], fwd[:, 2]))
        roll[a:b] = np.degrees(np.arctan2(-up[:, 0], up[:, 1]))
    return pitch, yaw, roll


def _window(times: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """Indices of the frames from ``t0`` to ``t1`` (1 ns either side). Frame times increase, so the frames
    are found by bisection, not by looking at every frame of a long stream."""
    eps = 1e-9
    first = int(np.searchsorted(times, t0 - eps, side="left"))
    last = int(np.searchsorted(times, t1 + eps, side="right"))
    return np.arange(first, max(first, last), dtype=np.intp)


def _refine_vertex(times: np.ndarray, y: np.ndarray, k: int) -> float:
    """The vertex of a V through frame k: where the line through frames k-2, k-1 meets the line through
    frames k+1, k+2 (for a bounce); frame time k when that is not possible."""
    if k < 2 or k + 2 >= len(y):
        return float(times[k])
    sl = (y[k - 1] - y[k - 2]) / (times[k - 1] - times[k - 2])
    sr = (y[k + 2] - y[k + 1]) / (times[k + 2] - times[k + 1])
    if sl >= 0 or sr <= 0:
        return float(times[k])
    # y = y[k-1] + sl (t - t[k-1]) = y[k+1] + sr (t - t[k+1])
    t = (y[k + 1] - y[k - 1] + sl * times[k - 1] - sr * times[k + 1]) / (sl - sr)
    return float(np.clip(t, times[k - 1], times[k + 1]))


def lowest(times: np.ndarray, y: np.ndarray, t0: float, t1: float, prominence: float = 0.002
           ) -> tuple[float, float]:
    """(frame time, refined time) of the ictus of ``y`` over frames in [t0, t1]: the lowest frame where
    ``y`` turns from falling to rising by at least ``prominence`` (over two frames on each side); the
    lowest frame if there is no such turn."""
    idx = _window(times, t0, t1)
    if len(idx) == 0:
        return float("nan"), float("nan")
    turns = [k for k in idx if 2 <= k < len(y) - 2 and y[k - 1] > y[k] <= y[k + 1]
             and y[k - 2] - y[k] >= prominence and y[k + 2] - y[k] >= prominence]
    if turns:
        k = int(min(turns, key=lambda j: y[j]))
    else:
        k = int(idx[np.argmin(y[idx])])
    return float(times[k]), _refine_vertex(times, y, k)


def first_extreme(times: np.ndarray, y: np.ndarray, t0: float, t1: float) -> float:
    """Frame time of the first clear extreme of ``y`` after ``t0`` (within [t0, t1]): the first local
    extreme of the deviation from y(t0) that reaches half of the largest deviation."""
    idx = _window(times, t0, t1)
    if len(idx) < 3:
        return float("nan")
    dev = y[idx] - y[idx[0]]
    big = np.abs(dev) >= 0.5 * np.abs(dev).max()
    for j in range(1, len(idx) - 1):
        if big[j] and abs(dev[j]) >= abs(dev[j - 1]) and abs(dev[j]) >= abs(dev[j + 1]):
            return float(times[idx[j]])
    return float(times[idx[int(np.argmax(np.abs(dev)))]])


def pointing_arrival(stream: PoseStream, side: str, target, t0: float, t1: float, tolerance: float = 1e-6) -> float:
    """First frame time in [t0, t1] where the shoulder-to-wrist line points at ``target`` (radians off
    less than ``tolerance``)."""
    window = _window(stream.times, t0, t1)  # only the frames of the window: the stream may be long
    shoulder = stream.position(f"{side}_shoulder", window)
    wrist = stream.position(f"{side}_wrist", window)
    a = wrist - shoulder
    b = np.asarray(target, dtype=float) - shoulder
    cos = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    off = np.arccos(np.clip(cos, -1.0, 1.0))
    for j, k in enumerate(window):
        if off[j] < tolerance:
            return float(stream.times[k])
    return float("nan")


def measure_strokes(stream: PoseStream, sync_times: dict[str, float] | None = None) -> list[StrokeMeasure]:
    """The stroke of every gesture, head movement and pointing in ``stream``, as reported (``sync_times``:
    ``block:behaviour:stroke`` -> global time, e.g. ``realizer.feedback.sync_times()``; default: the
    unit's key) and as shown by the motion."""
    out: list[StrokeMeasure] = []
    times = stream.times
    head = None
    wrist_height: dict[str, np.ndarray] = {}  # per side, read once (the stream may live in files)
    by_name = {name: uid for uid, name in stream.driver_names.items()}

    def intact(driver: str, dof: str, t0: float, t1: float) -> bool:
        if stream.writers is None or driver not in by_name:
            return True
        idx = _window(times, t0, t1)
        idx = idx[times[idx] < t1 - 1e-9]  # at strokeEnd a head movement may already hand back
        col = stream.channels.index(dof)
        return bool(np.all(stream.take("writers", idx)[:, col] == by_name[driver]))

    for u in stream.units:
        kind = u["type"]
        if kind not in ("gesture", "head", "pointing") or u.get("stop") is not None:
            continue
        keys = u["keys"]
        if "stroke" not in keys:
            continue
        fb = (sync_times or {}).get(f"{u['block']}:{u['id']}:stroke", keys["stroke"])
        t0, t1 = keys["strokeStart"], keys["strokeEnd"]
        lex = (u.get("lexeme") or "").upper()
        if kind == "gesture":
            for side, driver in zip(u["sides"], u["drivers"]):
                if side not in wrist_height:
                    wrist_height[side] = stream.tracked(f"{side}_wrist")[:, 1]
                y = wrist_height[side]
                t, refined = lowest(times, y, t0, t1)
                out.append(StrokeMeasure(u["block"], u["id"], kind, lex, side, fb, t, refined,
                                         intact(driver, f"{side}_shoulder.pitch", t0, t1)))
        elif kind == "head":
            if head is None:
                head = head_orientation(stream)
            pitch, yaw, roll = head
            if lex == "SHAKE":
                t = first_extreme(times, yaw, t0, t1)
                refined = t
            elif lex == "TILT":
                t = first_extreme(times, roll, t0, t1)
                refined = t
            else:  # the first nod's lowest point (with repetitions, every nod goes as low)
                t = first_extreme(times, pitch, t0, t1)
                k = int(np.searchsorted(times, t - 1e-9))
                refined = _refine_vertex(times, -pitch, k)
            axis = {"SHAKE": "yaw", "TILT": "roll"}.get(lex, "pitch")
            out.append(StrokeMeasure(u["block"], u["id"], kind, lex or "NOD", "head", fb, t, refined,
                                     intact(u["drivers"][0], f"skullbase.{axis}", t0, t1)))
        else:
            side = u["sides"][0]
            t = pointing_arrival(stream, side, u["target"], t0, t1 + 0.5)
            out.append(StrokeMeasure(u["block"], u["id"], kind, lex, side, fb, t, t,
                                     intact(u["drivers"][0], f"{side}_shoulder.pitch", t0, t1)))
    return out
