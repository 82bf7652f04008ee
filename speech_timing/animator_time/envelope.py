"""Lower-envelope estimates from evidence whose errors are one-sided delays: a line and an offset."""

from __future__ import annotations

import numpy as np

__all__ = ["lower_envelope_line", "envelope_intercept"]


def lower_envelope_line(p: np.ndarray, y: np.ndarray, p_ref: float) -> tuple[float, float]:
    """The line below all points ``(p_i, y_i)`` that is highest at ``p_ref``.

    This is the edge of the lower convex hull above ``p_ref`` and the solution of the linear
    programme ``max a + b * p_ref`` subject to ``a + b * p_i <= y_i``, which is the same as
    minimising the sum of the vertical distances to the points when ``p_ref`` is their mean. With
    delays that are never negative, it estimates the fastest-delivery line through noisy arrivals.

    Parameters
    ----------
    p, y : numpy.ndarray
        Abscissae and ordinates (any order; at least one point).
    p_ref : float
        Where the line should be highest.

    Returns
    -------
    (float, float)
        Intercept ``a`` and slope ``b``. A single point (or all at one abscissa) gives slope 1.
    """
    order = np.lexsort((y, p))
    p, y = np.asarray(p, float)[order], np.asarray(y, float)[order]
    hull: list[int] = []
    for i in range(len(p)):
        if hull and p[hull[-1]] == p[i]:
            continue  # same abscissa, higher ordinate: not on the lower hull
        while len(hull) >= 2:
            j, k = hull[-2], hull[-1]
            if (y[k] - y[j]) * (p[i] - p[j]) >= (y[i] - y[j]) * (p[k] - p[j]):
                hull.pop()  # k is on or above the segment j-i
            else:
                break
        hull.append(i)
    if len(hull) == 1:
        return float(y[hull[0]] - p[hull[0]]), 1.0
    xs = p[hull]
    e = int(np.clip(np.searchsorted(xs, p_ref) - 1, 0, len(hull) - 2))
    j, k = hull[e], hull[e + 1]
    slope = (y[k] - y[j]) / (p[k] - p[j])
    return float(y[j] - slope * p[j]), float(slope)


def envelope_intercept(residuals) -> float:
    """Lowest of ``residuals`` less a small-sample correction: the median excess over the lowest, divided by
    their number. With one-sided jitter, it estimates the offset of the fastest delivery."""
    r = np.asarray(residuals, dtype=float)
    low = float(r.min())
    return low - (float(np.median(r)) - low) / len(r)
