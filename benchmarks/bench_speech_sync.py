"""Benchmark of animator-time strategies: beat gestures on content words of espeak-ng, Festival and Piper speech;
prints JSON.

Each backend (``--tts``, default espeak-ng and Festival with its default voice, us-slt-hts; ``piper``, Piper's
voice joe, with the ``piper`` extra) speaks the same texts, and every strategy of :data:`speech_timing.animator_time.STRATEGIES` is run on the bundled texts
(``speech_timing/texts/*.txt`` except ``calibration.txt``, about 420 words and two minutes each),
under the delivery conditions A, B and C of :data:`speech_timing.delivery.CONDITIONS`, with the plan from the backend's own timeline (``tts``) and from Chang's
linear characters-to-time model calibrated on ``calibration.txt`` with that backend (``linear``). Each
text is synthesised once per backend; all strategies see the same delivered events (same seed per
text). ``side_by_side`` puts the backends' figures next to each other, row by row, and ``speech`` gives
each backend's speaking rate (words per minute of speech), synthesis real-time factor (wall seconds
of synthesis per second of speech, each text synthesised once in a process that had not spoken it; and in CPU
seconds of this process, which other work on the machine does not inflate, for Piper, which synthesises in it) and
first-synthesis latency (wall seconds from the import of the backend to the end of its first sentence, in a new
process: what a user waits for before the first word);
``--storyteller`` adds each backend's storyteller runs (every shipped story, ``best``). Errors of all
texts are pooled before the percentiles are taken; snaps and stall time are summed over the texts.

All conditions share a nominal latency of 80 ms with an unknown extra 0-40 ms and an audio clock
drift of +500 ppm; strategies know the nominal latency and the base delay only.

Usage::

    PYTHONPATH=. python benchmarks/bench_speech_sync.py [--quick] [--seeds 1] [--tts espeak,festival,piper]
        [--jitter-distribution exponential] [--table] [--storyteller]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from collections import OrderedDict
from dataclasses import asdict

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from speech_timing.animator_time import STRATEGIES  # noqa: E402
from speech_timing.delivery import CONDITIONS, PLAYBACK  # noqa: E402
from speech_timing.choice import named  # noqa: E402
from speech_timing.harness import TIMINGS, run_sync_eval, synthesize_cached  # noqa: E402
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


#: Backends compared, by ``--tts`` name, with what the JSON calls them.
BACKENDS = {"espeak": "espeak-ng", "festival": "festival", "piper": "piper"}
#: The sentence whose first synthesis in a new process is timed.
FIRST_SENTENCE = "The lamp on the hill was lit before the boats came home."
#: The figures of a strategy row put side by side.
SIDE_BY_SIDE = ("p50_ms", "p95_ms", "max_ms", "snaps", "stall_s")


def strategy_table(backend, texts: OrderedDict, model, args) -> OrderedDict:
    """``{timing: {condition: {strategy: row}}}`` of one backend."""
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
    return table


#: Backends that synthesise in this process, whose CPU time is measured (espeak-ng synthesises in forks of an
#: engine process of its own, Festival in a server process).
IN_PROCESS = frozenset({"piper"})


def speech_figures(backend, texts: OrderedDict) -> OrderedDict:
    """Speaking rate and synthesis real-time factor of ``backend`` on ``texts`` (each synthesised here, once,
    and kept for the strategy runs), in wall seconds and in CPU seconds (None but for a backend of
    :data:`IN_PROCESS`)."""
    words = seconds = wall = cpu = 0.0
    sample_rate = 0
    for text in texts.values():
        started, cpu_started = time.perf_counter(), time.process_time()
        utterance = synthesize_cached(backend, text)
        wall += time.perf_counter() - started
        cpu += time.process_time() - cpu_started
        words += len(utterance.words)
        seconds += utterance.duration
        sample_rate = utterance.sample_rate
    return OrderedDict(words=int(words), speech_s=round(seconds, 2), words_per_minute=round(60.0 * words / seconds, 1),
                       synthesis_s=round(wall, 3), real_time_factor=round(wall / seconds, 4),
                       cpu_real_time_factor=round(cpu / seconds, 4) if backend.name in IN_PROCESS else None,
                       sample_rate=sample_rate)


def first_synthesis(name: str) -> float:
    """Wall seconds from importing backend ``name`` to the end of its first synthesis of :data:`FIRST_SENTENCE`,
    in a new Python process (the import of the backend's packages and the loading of its voice included)."""
    code = ("import time; started = time.perf_counter()\n"
            "from speech_timing.choice import named\nfrom speech_timing.backend import SpeechText\n"
            f"named({name!r}).synthesize(SpeechText({FIRST_SENTENCE!r}))\n"
            "print(time.perf_counter() - started)")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, check=True,
                          env={**os.environ, "PYTHONPATH": root})
    return float(done.stdout.split()[-1])


def storyteller(name: str) -> list[OrderedDict]:
    """The storyteller with backend ``name``: each shipped story told with ``best`` (condition A, seed 0, strokes
    on the stressed syllables, as ``agentsim run storytelling --tts NAME``), its sync error and snaps."""
    from scenarios.storytelling.markup import read_story
    from scenarios.storytelling.run import shipped_stories
    from scenarios.storytelling.telling import make_voice, tell

    voice = make_voice(name)  # the speech cache: a story synthesised before is read back (the same figures)
    rows = []
    for path in sorted(shipped_stories().values(), key=lambda p: -len(read_story(p).words)):
        story = read_story(path)
        m = tell(story, "best", seed=0, voice=voice).metrics()
        e = m["sync_error_ms"]
        rows.append(OrderedDict(story=story.title, gestures=m["gestures"], speech_s=round(m["duration_s"], 1),
                                p50_ms=round(e["p50"], 2), p95_ms=round(e["p95"], 2), max_ms=round(e["max"], 2),
                                snaps=m["snaps"], missed=m["missed"]))
    return rows


def side_by_side(results: OrderedDict) -> list[OrderedDict]:
    """One row per timing, condition and strategy: each backend's :data:`SIDE_BY_SIDE` figures."""
    first = next(iter(results.values()))
    rows = []
    for timing, conditions in first.items():
        for cond_name, strategies in conditions.items():
            for strategy in strategies:
                row = OrderedDict(timing=timing, condition=cond_name, strategy=strategy)
                for backend, table in results.items():
                    cell = table[timing][cond_name][strategy]
                    row[backend] = OrderedDict((key, cell[key]) for key in SIDE_BY_SIDE)
                rows.append(row)
    return rows


def markdown(result: dict) -> str:
    """The side-by-side table (and the speech figures) as Markdown, for the documentation (docs/howto/voices.md)."""
    backends = list(result["speech"])
    head = ["timing", "condition", "strategy"] + [f"{b} {k}" for b in backends for k in ("p50 / p95 / max ms",
                                                                                     "snaps", "stall s")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in result["side_by_side"]:
        cells = [row["timing"], row["condition"], row["strategy"]]
        for b in backends:
            c = row[b]
            cells += [f"{c['p50_ms']:g} / {c['p95_ms']:g} / {c['max_ms']:g}", str(c["snaps"]), f"{c['stall_s']:g}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", speech_markdown(result)]
    if result.get("storyteller"):
        lines += ["", storyteller_markdown(result)]
    return "\n".join(lines)


def speech_markdown(result: dict) -> str:
    """The speech figures of each backend as a Markdown table."""
    lines = ["| backend | voice | words | speech s | words per minute | synthesis s | real-time factor | "
             "CPU real-time factor | first synthesis s |", "|---|---|---|---|---|---|---|---|---|"]
    for b, sp in result["speech"].items():
        cpu = "-" if sp.get("cpu_real_time_factor") is None else f"{sp['cpu_real_time_factor']:g}"
        lines.append(f"| {b} | {result['voices'][b]} | {sp['words']} | {sp['speech_s']:g} | {sp['words_per_minute']:g} | "
                     f"{sp['synthesis_s']:g} | {sp['real_time_factor']:g} | {cpu} | {sp['first_synthesis_s']:g} |")
    return "\n".join(lines)


def storyteller_markdown(result: dict) -> str:
    """The storyteller's runs of each backend as a Markdown table."""
    lines = ["| backend | story | gestures | speech s | p50 ms | p95 ms | max ms | snaps |", "|---|---|---|---|---|---|---|---|"]
    for b, stories in result["storyteller"].items():
        for st in stories:
            lines.append(f"| {b} | {st['story']} | {st['gestures']} | {st['speech_s']:g} | {st['p50_ms']:g} | "
                         f"{st['p95_ms']:g} | {st['max_ms']:g} | {st['snaps']} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one text instead of all")
    ap.add_argument("--seeds", type=int, default=1, help="delivery seeds per text (default 1)")
    ap.add_argument("--tts", default="espeak,festival",
                    help="backends, comma-separated: espeak, festival, piper (espeak,festival)")
    ap.add_argument("--jitter-distribution", default="exponential",
                    choices=["exponential", "gamma", "half-normal"])
    ap.add_argument("--stress", action="store_true", help="aim strokes at stressed vowels")
    ap.add_argument("--table", action="store_true", help="print the side-by-side table as Markdown after the JSON")
    ap.add_argument("--storyteller", action="store_true",
                    help="also tell each shipped story with each backend (best strategy, condition A)")
    args = ap.parse_args(argv)
    names = [name.strip() for name in args.tts.split(",") if name.strip()]
    unknown = [name for name in names if name not in BACKENDS]
    if unknown or not names:
        ap.error(f"--tts takes {', '.join(BACKENDS)}, comma-separated; not {', '.join(unknown) or 'nothing'}")

    texts = bench_texts(args.quick)
    started = time.perf_counter()
    results: "OrderedDict[str, OrderedDict]" = OrderedDict()
    speech: "OrderedDict[str, OrderedDict]" = OrderedDict()
    models: "OrderedDict[str, OrderedDict]" = OrderedDict()
    voices: "OrderedDict[str, str]" = OrderedDict()
    stories: "OrderedDict[str, OrderedDict]" = OrderedDict()
    for name in names:
        backend = named(name)  # the real backend; raises, saying what to install, if it is missing
        label = BACKENDS[name]
        voices[label] = str(getattr(backend, "voice", ""))
        speech[label] = speech_figures(backend, texts)
        speech[label]["first_synthesis_s"] = round(first_synthesis(name), 3)
        model = default_linear_model(backend)
        models[label] = OrderedDict(multiplier=model.multiplier, offset=model.offset,
                                    phonemes_per_unit=model.phonemes_per_unit, rms=model.rms)
        results[label] = strategy_table(backend, texts, model, args)
        if args.storyteller:
            stories[label] = storyteller(name)

    targets = []
    for label, table in results.items():
        for timing, cond_name, strategy, limit, strict, no_snaps in TARGETS:
            row = table[timing][cond_name][strategy]
            ok = (row["p95_ms"] < limit if strict else row["p95_ms"] <= limit) and (row["snaps"] == 0 or not no_snaps)
            targets.append(OrderedDict(backend=label, timing=timing, condition=cond_name, strategy=strategy,
                                       p95_limit_ms=limit, zero_snaps=no_snaps, p95_ms=row["p95_ms"],
                                       snaps=row["snaps"], met=bool(ok)))

    words = {name: len(text.split()) for name, text in texts.items()}
    result = OrderedDict(
        benchmark="speech_sync",
        backends=list(results),
        voices=voices,
        texts=words,
        seeds_per_text=args.seeds,
        stroke_target="stressed vowel" if args.stress else "word onset",
        playback=PLAYBACK,
        conditions=OrderedDict((name, asdict(c)) for name, c in CONDITIONS.items()),
        jitter_distribution=args.jitter_distribution,
        speech=speech,
        linear_model=models,
        side_by_side=side_by_side(results),
        **({"storyteller": stories} if args.storyteller else {}),
        results=results,
        targets=targets,
        seconds=round(time.perf_counter() - started, 1),
        python=platform.python_version(),
    )
    print(json.dumps(result, indent=2))
    if args.table:
        print(markdown(result))
    return result


if __name__ == "__main__":
    main()
