"""The scene: named points of the world (metres) that behaviours aim at, and BML target offsets."""

from __future__ import annotations

import math
import re
from typing import Mapping, Sequence

import numpy as np

DEFAULT_SCENE: dict[str, tuple[float, float, float]] = {
    # metres, H-Anim frame: +Y up, the character faces +Z, +X is its left
    "bluebox": (0.55, 1.05, 0.9),
    "redbox": (-0.55, 1.05, 0.9),
    "greenbox": (0.0, 0.9, 0.6),
    "table": (0.0, 0.75, 0.7),
    "user": (0.0, 1.65, 1.2),
    "camera": (0.0, 1.6, 2.5),
    "audience": (0.0, 1.6, 3.0),
    "orchestra": (0.0, 1.2, 3.5),
    "violins": (1.6, 1.1, 2.6),
    "violas": (0.6, 1.1, 3.0),
    "cellos": (-0.6, 1.0, 3.0),
    "basses": (-1.6, 1.2, 2.6),
    "left": (2.0, 1.6, 1.0),
    "right": (-2.0, 1.6, 1.0),
    "up": (0.0, 3.0, 1.5),
    "down": (0.0, 0.3, 1.0),
}
#: Where an unknown target is taken to be: a point ahead, a little below eye height.
DEFAULT_POINT = (0.0, 1.3, 2.0)
#: Where the eyes rest.
DEFAULT_GAZE = (0.0, 1.62, 2.0)


class Scene:
    """Named points of the world (metres). Unknown names fall back to :data:`DEFAULT_POINT`; a target may
    also be written as three numbers, ``"0.5 1.2 2"`` or ``"0.5,1.2,2"``."""

    def __init__(self, points: Mapping[str, Sequence[float]] | None = None,
                 default_point=DEFAULT_POINT, default_gaze=DEFAULT_GAZE):
        self.points = {k.lower(): np.asarray(v, dtype=float) for k, v in DEFAULT_SCENE.items()}
        for k, v in (points or {}).items():
            self.points[k.lower()] = np.asarray(v, dtype=float)
        self.default_point = np.asarray(default_point, dtype=float)
        self.default_gaze = np.asarray(default_gaze, dtype=float)

    def known(self, name: str) -> bool:
        return self._parse(name) is not None

    def _parse(self, name: str) -> np.ndarray | None:
        if not name:
            return None
        key = name.strip().lower()
        if key in self.points:
            return self.points[key]
        parts = re.split(r"[\s,;]+", key)
        if len(parts) == 3:
            try:
                return np.array([float(p) for p in parts])
            except ValueError:
                return None
        return None

    def point(self, name: str | None) -> np.ndarray:
        """The point named ``name``, or the default point ahead."""
        p = self._parse(name or "")
        return (p if p is not None else self.default_point).copy()


def offset_target(point: np.ndarray, origin: np.ndarray, angle: float, direction: str) -> np.ndarray:
    """``point`` turned about ``origin`` by ``angle`` degrees (BML offsetAngle / offsetDirection)."""
    if not angle:
        return point
    d = point - origin
    a = math.radians(angle)
    direction = (direction or "RIGHT").upper()
    if direction in ("LEFT", "RIGHT"):
        a = a if direction == "LEFT" else -a
        c, s = math.cos(a), math.sin(a)
        d = np.array([c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]])
    else:
        horizontal = math.hypot(d[0], d[2])
        elev = math.atan2(d[1], horizontal) + (a if direction in ("UP", "UPLEFT", "UPRIGHT") else -a)
        r = float(np.linalg.norm(d))
        az = math.atan2(d[0], d[2])
        d = r * np.array([math.cos(elev) * math.sin(az), math.sin(elev), math.cos(elev) * math.cos(az)])
    return origin + d
