"""The motion signal of a person exercising, made from their key points: what a phone on them would report.

Between two key points (the lowest points) the body rises and comes down again along a raised cosine; a
pause stands still at the top. A phone worn at the hip (squat, jumping jack) or held in the hand (arm raise)
reports the acceleration with gravity included in its own tilted frame, with the sensor's noise.

How long one way of a repetition may take depends on the movement. A squat or an arm raise is held by the
muscles all the way and can be done as slowly as the person likes: a slow person, or one starting again after
a pause, takes up to 1.2 s each way. A jumping jack is a hop: once the feet leave the ground the body flies
ballistically, for a time its height fixes (2√(2h/g)), and the push before and the landing after take about
as long whatever the tempo. Its ways take at most 0.6 s, as when the hops follow one another at the jumping
jack's usual 50 a minute; a slower person stands between hops rather than hopping slowly, and one starting
again after a pause hops as quickly as before.
"""

from __future__ import annotations

import math

import numpy as np

G = 9.81
#: How far the key point lies below standing (m) and how long at most one way of a repetition takes (s).
DEPTH = {"squat": 0.35, "jumping-jack": 0.12, "arm-raise": 1.2}
MOVE_MAX = {"squat": 1.2, "jumping-jack": 0.6, "arm-raise": 1.2}


def height(t: np.ndarray, keys: list[float], depth: float, longest: float = 1.2) -> np.ndarray:
    """The worn point's height (m, 0 standing) at times ``t``: at ``-depth`` on every key point, each way of a
    repetition taking half the interval, ``longest`` s at most."""
    t = np.asarray(t, float)
    y = np.zeros_like(t)
    if not keys:
        return y
    k = np.asarray(keys, float)
    i = np.searchsorted(k, t, side="right") - 1
    for j in range(-1, len(k)):
        mask = i == j
        if not mask.any():
            continue
        tt = t[mask]
        if j == -1:  # before the first key point: coming down into it
            half = longest
            phase = np.clip((tt - (k[0] - half)) / half, 0.0, 1.0)
            y[mask] = -depth * (1 - np.cos(math.pi * phase)) / 2
            continue
        if j == len(k) - 1:  # after the last one: up and standing
            half = longest if len(k) < 2 else min(longest, (k[-1] - k[-2]) / 2)
            phase = np.clip((tt - k[j]) / half, 0.0, 1.0)
            y[mask] = -depth * (1 + np.cos(math.pi * phase)) / 2
            continue
        gap = k[j + 1] - k[j]
        half = min(gap / 2, longest)
        up = np.clip((tt - k[j]) / half, 0.0, 1.0)
        down = np.clip((tt - (k[j + 1] - half)) / half, 0.0, 1.0)
        rising = tt < k[j] + gap / 2
        y[mask] = np.where(rising, -depth * (1 + np.cos(math.pi * up)) / 2,
                           -depth * (1 - np.cos(math.pi * down)) / 2)
    return y


def acceleration(t: np.ndarray, keys: list[float], exercise: str, rng: np.random.Generator,
                 noise: float = 0.1, tilt: tuple[float, float] = (0.3, 0.2)) -> np.ndarray:
    """Acceleration with gravity (m/s², shape (n, 3)) as a tilted phone reports it, with noise ``noise``."""
    t = np.asarray(t, float)
    dt = 1e-3
    depth, longest = DEPTH[exercise], MOVE_MAX[exercise]
    up = (height(t + dt, keys, depth, longest) - 2 * height(t, keys, depth, longest)
          + height(t - dt, keys, depth, longest)) / (dt * dt)
    world = np.stack([np.zeros_like(t), np.zeros_like(t), G + up], axis=1)
    a, b = tilt
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    return world @ (ry @ rx).T + rng.normal(0.0, noise, size=world.shape)
