"""What duration knowledge is worth under Chang's linear plan: the best strategy's error against it; prints JSON.

With ``--timing linear`` the planner knows only Chang's linear characters-to-time model, and the best
strategy must predict each word onset from progress events a delivery delay and a jitter old. This
benchmark gives the plan, beside its linear axis, per-phoneme durations of known quality
(:attr:`speech_timing.plan.SpeechPlan.phoneme_durations`) and measures the best strategy's error
under the first delivery condition of ``bench_speech_sync.py`` (delay 50 ms, jitter 30 ms, bursts):

* ``linear only``: no durations (the strategy learns word durations online);
* ``truth + N ms``: espeak-ng's own durations with Gaussian error of N ms per phoneme
  (:func:`speech_timing.duration_model.noisy_durations`): a text-to-duration model of that accuracy;
* ``calibrated phonetic model``: :class:`speech_timing.duration_model.PhonemeDurationModel` fitted on
  the calibration corpus (about 12,400 words) and given each word's true phonemes, so a perfect
  transcription is assumed; its per-phoneme error on the evaluation texts is reported.

It reports the largest per-phoneme error at which the p95 target of 40 ms still holds. Errors of all
texts are pooled before the percentiles are taken.

Usage::

    PYTHONPATH=. python benchmarks/bench_speech_knowledge.py [--quick] [--seeds 1]
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from bench_speech_sync import bench_texts  # noqa: E402

from speech_timing.delivery import CONDITIONS  # noqa: E402
from speech_timing.duration_model import (PhonemeDurationModel, calibration_corpus, noisy_durations,  # noqa: E402
                                          true_durations)
from speech_timing.harness import run_sync_eval, synthesize_cached  # noqa: E402
from speech_timing.linear_model import default_linear_model  # noqa: E402
from speech_timing.metrics import error_summary  # noqa: E402

#: Per-phoneme errors (s) of the noisy truth.
ERRORS = (0.0, 0.0025, 0.005, 0.0075, 0.01, 0.015, 0.02)
#: The target: p95 at most this (ms) with zero snaps.
TARGET_MS = 40.0


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one text instead of all")
    ap.add_argument("--seeds", type=int, default=1, help="delivery seeds per text (default 1)")
    args = ap.parse_args(argv)

    from speech_timing.espeak import EspeakBackend  # the real backend; raises if espeak-ng is missing

    backend = EspeakBackend()
    texts = bench_texts(args.quick)
    linear = default_linear_model(backend)
    started = time.perf_counter()
    model = PhonemeDurationModel().fit(synthesize_cached(backend, text) for text in calibration_corpus())
    calibrated_at = time.perf_counter() - started
    model_errors = []
    for text in texts.values():
        utterance = synthesize_cached(backend, text)
        for predicted, true in zip(model.predict(utterance), true_durations(utterance)):
            if len(predicted) == len(true):
                model_errors.append(predicted - true)
    model_errors = np.concatenate(model_errors)
    model_rms = float(np.sqrt(np.mean(model_errors ** 2)))

    delivery = CONDITIONS["A"]
    knowledge = OrderedDict([("linear only", None)])
    for error in ERRORS:
        knowledge[f"truth + {1000 * error:g} ms"] = (lambda e: lambda u, rng: noisy_durations(u, e, rng))(error)
    knowledge["calibrated phonetic model"] = lambda u, rng: model.predict(u)
    rows = OrderedDict()
    for label, durations in knowledge.items():
        errors, snaps = [], 0
        for t_index, text in enumerate(texts.values()):
            for s in range(args.seeds):
                r = run_sync_eval(text, backend, "best", delivery, timing="linear", seed=1000 * (t_index + 1) + s,
                                  linear_model=linear, traces=True, durations=durations)
                errors.append(r["errors_s"])
                snaps += r["snaps"]
        summary = error_summary(np.concatenate(errors))
        rows[label] = OrderedDict(p50_ms=round(summary["p50"], 2), p95_ms=round(summary["p95"], 2),
                                  max_ms=round(summary["max"], 2), snaps=snaps,
                                  met=bool(summary["p95"] <= TARGET_MS and snaps == 0))
    met = [1000 * e for e in ERRORS if rows[f"truth + {1000 * e:g} ms"]["met"]]
    result = OrderedDict(
        benchmark="speech_knowledge",
        backend="espeak-ng",
        texts={name: len(text.split()) for name, text in texts.items()},
        seeds_per_text=args.seeds,
        condition=asdict(delivery),
        target_p95_ms=TARGET_MS,
        phonetic_model=OrderedDict(calibration_phonemes=model.n, calibration_s=round(calibrated_at, 1),
                                   rms_error_ms=round(1000 * model_rms, 2),
                                   median_abs_error_ms=round(1000 * float(np.median(np.abs(model_errors))), 2)),
        results=rows,
        largest_error_meeting_target_ms=max(met) if met else None,
        seconds=round(time.perf_counter() - started, 1),
        python=platform.python_version(),
    )
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
