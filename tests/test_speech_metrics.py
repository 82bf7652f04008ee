"""Tests of the synchrony and smoothness metrics (speech_timing.metrics) on hand-made arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from speech_timing.metrics import (
    error_summary,
    evaluate,
    frame_rates,
    rate_range,
    snaps,
    stall_time,
    sync_errors,
)

FRAME = 1.0 / 60.0


def clock(seconds=1.0):
    return np.arange(int(round(seconds * 60)) + 1) * FRAME


def test_sync_errors_are_stroke_minus_onset():
    errors = sync_errors([1.01, 1.98, 3.0], [1.0, 2.0, 3.0])
    assert errors == pytest.approx([0.01, -0.02, 0.0])


def test_sync_errors_validate_input():
    assert sync_errors([], []).shape == (0,)
    with pytest.raises(ValueError):
        sync_errors([1.0], [1.0, 2.0])
    with pytest.raises(ValueError):
        sync_errors([math.nan], [1.0])
    with pytest.raises(ValueError):
        sync_errors([[1.0]], [[1.0]])


def test_error_summary_in_milliseconds():
    s = error_summary([0.01, -0.02, 0.03, 0.0])
    assert list(s) == ["p50", "p95", "max", "mean", "signed_mean", "n"]
    assert s["p50"] == pytest.approx(15.0)
    assert s["p95"] == pytest.approx(np.percentile([10, 20, 30, 0], 95))
    assert s["max"] == pytest.approx(30.0)
    assert s["mean"] == pytest.approx(15.0)
    assert s["signed_mean"] == pytest.approx(5.0)
    assert s["n"] == 4


def test_error_summary_of_nothing_is_nan():
    s = error_summary([])
    assert s["n"] == 0 and all(math.isnan(s[k]) for k in ("p50", "p95", "max", "mean", "signed_mean"))


def test_steady_animation_has_no_snaps_or_stalls():
    t = clock()
    assert snaps(t, t - 0.3) == 0
    assert stall_time(t, t - 0.3) == 0.0
    assert rate_range(t, t) == pytest.approx((1.0, 1.0))


def test_forward_jump_larger_than_a_frame_is_a_snap():
    t = clock()
    t_a = t.copy()
    t_a[30:] += 0.05  # one frame advances by 0.05 + 1/60
    assert snaps(t, t_a) == 1
    small = t.copy()
    small[30:] += 0.01  # less than a frame more than the clock: not visible
    assert snaps(t, small) == 0


def test_backward_jump_is_a_snap():
    t = clock()
    t_a = t.copy()
    t_a[20:] -= 0.04  # that frame goes back by 0.04 - 1/60
    assert snaps(t, t_a) == 1


def test_double_speed_is_the_snap_limit():
    t = clock()
    assert snaps(t, 1.99 * t) == 0
    assert snaps(t, 2.01 * t) == len(t) - 1


def test_stall_time_counts_slow_frames():
    t = clock(2.0)
    t_a = np.where(t < 0.5, t, np.where(t < 1.0, 0.5, t - 0.5))  # stuck from 0.5 s to 1.0 s
    assert stall_time(t, t_a) == pytest.approx(0.5)
    assert stall_time(t, 0.6 * t) == 0.0
    assert stall_time(t, 0.4 * t) == pytest.approx(2.0)


def test_rate_range_and_frame_rates():
    t = clock()
    t_a = np.where(t < 0.5, 0.5 * t, 0.25 + 1.5 * (t - 0.5))
    low, high = rate_range(t, t_a)
    assert low == pytest.approx(0.5) and high == pytest.approx(1.5)
    assert len(frame_rates(t, t_a)) == len(t) - 1
    assert all(math.isnan(v) for v in rate_range([0.0], [0.0]))


def test_trajectories_are_validated():
    with pytest.raises(ValueError):
        snaps([0.0, 0.0], [0.0, 0.1])
    with pytest.raises(ValueError):
        stall_time([0.0, 1.0], [0.0])
    with pytest.raises(ValueError):
        snaps([0.0, 1.0], [0.0, 1.0], frame=0.0)
    assert snaps([], []) == 0 and stall_time([], []) == 0.0


def test_evaluate_gathers_everything_in_order():
    t = clock()
    result = evaluate([0.51, 0.79], [0.5, 0.8], t, t)
    assert list(result) == ["error_ms", "snaps", "stall_s", "rate"]
    assert result["error_ms"]["max"] == pytest.approx(10.0)
    assert result["snaps"] == 0 and result["stall_s"] == 0.0
    assert list(result["rate"]) == ["min", "max"]
