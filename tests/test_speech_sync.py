"""Speech timing in the realizer: strokes pegged to words land where animator time says, measured."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from agentsim.bml.speech_text import normalize_space
from agentsim.engines.speech import SpeechConfig
from agentsim.realizer import Realizer
from speech_timing.animator_time import make_strategy
from speech_timing.builtin import BuiltinBackend
from speech_timing.delivery import CONDITIONS
from scenarios.speech_sync import beats_on_content_words, speech_sync
from speech_timing.linear_model import TEXTS_DIR

TEXT = normalize_space((TEXTS_DIR / "orchard.txt").read_text())[0]
CONDITION_A = CONDITIONS["A"]


def test_best_strategy_meets_the_target_and_beats_chang_naive():
    best = speech_sync(TEXT, BuiltinBackend(), "best", CONDITION_A, seed=1)
    naive = speech_sync(TEXT, BuiltinBackend(), "chang-naive", CONDITION_A, seed=1)
    assert best["gestures"] > 200 and best["missed"] == 0
    assert best["error_ms"]["p95"] <= 15.0 and best["snaps"] == 0
    assert naive["error_ms"]["p95"] > 5 * best["error_ms"]["p95"] and naive["snaps"] > 0


def test_same_seed_same_numbers_other_seed_other_numbers():
    a = speech_sync(TEXT, BuiltinBackend(), "skip-70ms", CONDITION_A, seed=4)
    b = speech_sync(TEXT, BuiltinBackend(), "skip-70ms", CONDITION_A, seed=4)
    c = speech_sync(TEXT, BuiltinBackend(), "skip-70ms", CONDITION_A, seed=5)
    keys = ("error_ms", "snaps", "stall_s", "rate")
    assert [a[k] for k in keys] == [b[k] for k in keys]
    assert np.array_equal(a["errors_s"], b["errors_s"])
    assert not np.array_equal(a["errors_s"], c["errors_s"])


@pytest.mark.parametrize("strategy", ["best", "chang-naive", "chang-smooth"])
def test_each_stroke_is_passed_exactly_when_animator_time_reaches_its_word(strategy):
    bml, targets = beats_on_content_words(TEXT[:600])
    realizer = Realizer(tts=BuiltinBackend(), speech=SpeechConfig(strategy, CONDITION_A, seed=2))
    realizer.submit(bml)
    realizer.run()
    playback = realizer.engines[0].playbacks[0]
    strokes = realizer.feedback.sync_times()
    # Replay the same delivered events into a fresh strategy and find each crossing independently.
    replay = make_strategy(strategy)
    replay.reset(playback.plan, playback.t_request)
    events = list(playback.delivered)
    planned = {f"w{k}": playback.timed.preferred[playback.timed.sync_ids.index(f"w{k}")] for k in targets}
    now, i = playback.t_request, 0
    for k in targets:
        s = planned[f"w{k}"]
        while True:
            cross = replay.crossing(s, now)
            if i < len(events) and events[i].arrival_time <= min(cross, 1e9):
                now = max(now, events[i].arrival_time)
                replay.on_event(events[i], now)
                i += 1
                continue
            break
        expected = cross if math.isfinite(cross) else None
        got = strokes[f"sync:g{k}:stroke"]
        if expected is not None:
            assert got == pytest.approx(max(expected, now), abs=1e-9)
        now = max(now, got)


def test_linear_timing_plans_from_the_model_and_still_syncs_without_snaps():
    result = speech_sync(TEXT, BuiltinBackend(), "best", CONDITION_A, timing="linear", seed=1)
    naive = speech_sync(TEXT, BuiltinBackend(), "chang-naive", CONDITION_A, timing="linear", seed=1)
    assert result["snaps"] == 0 and result["missed"] == 0
    assert result["error_ms"]["p95"] < naive["error_ms"]["p95"]


def test_espeak_speech_through_the_realizer():
    from speech_timing.espeak import EspeakBackend

    result = speech_sync(TEXT[:1200], EspeakBackend(), "best", CONDITION_A, seed=1)
    assert result["gestures"] > 50 and result["missed"] == 0
    assert result["error_ms"]["p95"] <= 15.0 and result["snaps"] == 0


def cli(*args):
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_eval_speech_sync_command(tmp_path):
    text = tmp_path / "t.txt"
    text.write_text(TEXT[:700])
    one = cli("eval", "speech-sync", "--text", str(text), "--tts", "builtin", "--strategy", "best", "--delay",
              "0.05", "--jitter", "0.03", "--burst", "0.03", "--seed", "3", "--json")
    assert one.returncode == 0, one.stderr
    result = json.loads(one.stdout)
    assert {"strategy", "words", "gestures", "error_ms", "snaps", "stall_s", "rate"} <= set(result)
    assert set(result["error_ms"]) >= {"p50", "p95", "max", "mean"} and set(result["rate"]) == {"min", "max"}
    every = cli("eval", "speech-sync", "--text", str(text), "--tts", "builtin", "--strategy", "all", "--json",
                "--plot", str(tmp_path / "errors.png"))
    names = [r["strategy"] for r in json.loads(every.stdout)]
    assert names == cli("eval", "speech-sync", "--list-strategies").stdout.split()
    assert (tmp_path / "errors.png").stat().st_size > 10_000
    bad = cli("eval", "speech-sync", "--strategy", "psychic")
    assert bad.returncode == 1 and "unknown strategy 'psychic'" in bad.stderr and "Traceback" not in bad.stderr


def test_calibrate_and_export(tmp_path):
    out = cli("speech", "calibrate", "--tts", "builtin", "--out", str(tmp_path / "lm.json"))
    assert out.returncode == 0, out.stderr
    model = json.loads((tmp_path / "lm.json").read_text())
    assert 0.03 < model["multiplier"] < 0.12
    text = tmp_path / "t.txt"
    text.write_text("The lighthouse keeper climbed the stairs, slowly.")
    done = cli("speech", "export", str(text), "--wav", str(tmp_path / "s.wav"), "--textgrid", str(tmp_path / "s.TextGrid"))
    assert done.returncode == 0, done.stderr
    import soundfile
    from praatio import textgrid

    grid = textgrid.openTextgrid(str(tmp_path / "s.TextGrid"), includeEmptyIntervals=False)
    words = [entry.label for entry in grid.getTier("words").entries]
    assert words == ["The", "lighthouse", "keeper", "climbed", "the", "stairs", "slowly"]
    info = soundfile.info(str(tmp_path / "s.wav"))
    assert info.duration == pytest.approx(grid.maxTimestamp, abs=0.001)
    assert grid.getTier("phones").entries


@pytest.mark.parametrize("strategy", ["best", "chang-naive", "skip-70ms"])
def test_a_stroke_tied_after_a_passed_speech_sync_keeps_its_offset(strategy):
    """Once animator time has passed a sync point, its time stays put: pegs tied to it at an offset do not
    keep moving with later events."""
    bml, targets = beats_on_content_words(TEXT[:400])
    first = targets[0]
    bml = bml.replace(f'<gesture id="g{first}" lexeme="BEAT" mode="RIGHT_HAND" stroke="speech1:w{first}"/>',
                      f'<gesture id="g{first}" lexeme="BEAT" mode="RIGHT_HAND" stroke="speech1:w{first}+0.6"/>')
    realizer = Realizer(tts=BuiltinBackend(), speech=SpeechConfig(strategy, CONDITION_A, seed=2))
    realizer.submit(bml)
    realizer.run()
    times = realizer.feedback.sync_times()
    assert times[f"sync:g{first}:stroke"] == pytest.approx(times[f"sync:speech1:w{first}"] + 0.6, abs=1e-9)
