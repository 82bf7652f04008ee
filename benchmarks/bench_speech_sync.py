"""Benchmark of animator-time strategies: beat gestures on content words of espeak-ng speech; prints JSON.

Every strategy of :data:`speech_timing.animator_time.STRATEGIES` is run on the bundled texts
(``speech_timing/texts/*.txt`` except ``calibration.txt``, about 420 words and two minutes each),
under the delivery conditions A, B and C of :data:`speech_timing.delivery.CONDITIONS`, with the plan from espeak-ng's own timeline (``tts``) and from Chang's
linear characters-to-time model calibrated on ``calibration.txt`` (``linear``). Each text is
synthesised once; all strategies see the same delivered events (same seed per text). Errors of all
texts are pooled before the percentiles are taken; snaps and stall time are summed over the texts.

All conditions share a nominal latency of 80 ms with an unknown extra 0-40 ms and an audio clock
drift of +500 ppm; strategies know the nominal latency and the base delay only.

Usage::

    PYTHONPATH=. python benchmarks/bench_speech_sync.py [--quick] [--seeds 1] [--jitter-distribution exponential]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections import OrderedDict
from dataclasses import asdict

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from speech_timing.animator_time import STRATEGIES  # noqa: E402
from speech_timing.delivery import CONDITIONS, PLAYBACK  # noqa: E402
from speech_timing.harness import TIMINGS, run_sync_eval  # noqa: E402
from speech_timing.linear_model import TEXTS_DIR, default_linear_model  # noqa: E402
from speech_timing.metrics import error_summary  # noqa: E402

#: Acceptance targets: (timing, condition, strategy, p95 limit in ms, strict, snaps must be zero).
TARGETS = [
    ("tts", "A", "best", 15.0, False, True),
    ("tts", "B", "best", 30.0, True, False),
    ("linear", "A", "best", 40.0, False, True),
]


def bench_texts(quick: bool) -> OrderedDict:
    """The benchmark texts by name (one in quick mode)."""
    paths = sorted(p for p in TEXTS_DIR.glob("*.txt") if p.stem != "calibration")
    if quick:
        paths = paths[:1]
    return OrderedDict((p.stem, p.read_text(encoding="utf-8")) for p in paths)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one text instead of all")
    ap.add_argument("--seeds", type=int, default=1, help="delivery seeds per text (default 1)")
    ap.add_argument("--jitter-distribution", default="exponential",
                    choices=["exponential", "gamma", "half-normal"])
    ap.add_argument("--stress", action="store_true", help="aim strokes at stressed vowels")
    args = ap.parse_args(argv)

    from speech_timing.espeak import EspeakBackend  # the real backend; raises if espeak-ng is missing

    backend = EspeakBackend()
    texts = bench_texts(args.quick)
    model = default_linear_model(backend)
    started = time.perf_counter()
    table: "OrderedDict[str, OrderedDict]" = OrderedDict()
    for timing in TIMINGS:
        table[timing] = OrderedDict()
        for cond_name, condition in CONDITIONS.items():
            delivery = condition.with_(jitter_distribution=args.jitter_distribution)
            rows = OrderedDict()
            for strategy in STRATEGIES:
                errors, snaps, stall, low, high, gestures, missed, per_text = [], 0, 0.0, [], [], 0, 0, {}
                for t_index, (name, text) in enumerate(texts.items()):
                    for s in range(args.seeds):
                        seed = 1000 * (t_index + 1) + s
                        r = run_sync_eval(text, backend, strategy, delivery, timing=timing, seed=seed,
                                          linear_model=model, stress=args.stress, traces=True)
                        errors.append(r["errors_s"])
                        snaps += r["snaps"]
                        stall += r["stall_s"]
                        low.append(r["rate"]["min"])
                        high.append(r["rate"]["max"])
                        gestures += r["gestures"]
                        missed += r["missed"]
                        per_text[f"{name}/{seed}"] = round(r["error_ms"]["p95"], 2)
                summary = error_summary(np.concatenate(errors))
                rows[strategy] = OrderedDict(
                    p50_ms=round(summary["p50"], 2), p95_ms=round(summary["p95"], 2),
                    max_ms=round(summary["max"], 2), mean_abs_ms=round(summary["mean"], 2),
                    signed_mean_ms=round(summary["signed_mean"], 2), gestures=gestures, missed=missed,
                    snaps=snaps, stall_s=round(stall, 3),
                    rate=OrderedDict(min=round(min(low), 3), max=round(max(high), 3)),
                    p95_ms_per_text=per_text,
                )
            table[timing][cond_name] = rows

    targets = []
    for timing, cond_name, strategy, limit, strict, no_snaps in TARGETS:
        row = table[timing][cond_name][strategy]
        ok = (row["p95_ms"] < limit if strict else row["p95_ms"] <= limit) and (row["snaps"] == 0 or not no_snaps)
        targets.append(OrderedDict(timing=timing, condition=cond_name, strategy=strategy,
                                   p95_limit_ms=limit, zero_snaps=no_snaps, p95_ms=row["p95_ms"],
                                   snaps=row["snaps"], met=bool(ok)))

    words = {name: len(text.split()) for name, text in texts.items()}
    result = OrderedDict(
        benchmark="speech_sync",
        backend="espeak-ng",
        texts=words,
        seeds_per_text=args.seeds,
        stroke_target="stressed vowel" if args.stress else "word onset",
        playback=PLAYBACK,
        conditions=OrderedDict((name, asdict(c)) for name, c in CONDITIONS.items()),
        jitter_distribution=args.jitter_distribution,
        linear_model=OrderedDict(multiplier=model.multiplier, offset=model.offset,
                                 phonemes_per_unit=model.phonemes_per_unit, rms=model.rms),
        results=table,
        targets=targets,
        seconds=round(time.perf_counter() - started, 1),
        python=platform.python_version(),
    )
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
