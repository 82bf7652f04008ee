"""Fuzz the realizer with mutated BML: no document may stop it, hang it or lose feedback.

Seed documents (the BML 1.0 examples of the test suite and a few built here, with speech, anticipator
references, BMLA and constraints) are mutated by a seeded numpy Generator: bytes inserted, deleted or
repeated, spans swapped or spliced from another document, numbers replaced by huge, negative, NaN or
many-digit ones, ids given colons or lone surrogates, elements nested deep, compositions changed. Each case
submits two mutated documents (at 0 and 0.5 s) to a realizer with a metronome, under an animator-time
strategy one case in three, and runs it to its end (or 600 simulated seconds).

A case is checked for feedback losses: every block that started ended (unless the run was cut short at
600 s); no feedback is sent twice; a block's end comes after its sync points; every behaviour that started
got its end or a warning naming it.

Prints JSON: cases, uncaught exceptions, cases over 10 s, feedback losses, the slowest case, and the first
few failures (their seed and mutation, to reproduce them). Targets: 0, 0, 0.

Usage: python benchmarks/fuzz_bml.py [--cases 10000] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import re
import time
import traceback
from pathlib import Path

import numpy as np

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
BMLA = 'xmlns:bmla="http://www.asap-project.org/bmla"'
ROOT = Path(__file__).resolve().parent.parent
#: Simulated seconds a case may run before it is cut short.
HORIZON = 600.0
#: Wall seconds over which a case counts as too slow.
SLOW = 10.0

BUILT = [
    f'<bml {NS} id="s1"><speech id="sp"><text>Hello <sync id="m1"/>there my <sync id="m2"/>friend.</text></speech>'
    '<gesture id="g" lexeme="BEAT" stroke="sp:m1"/><head id="h" lexeme="NOD" start="g:end+0.5"/></bml>',
    f'<bml {NS} id="a1" composition="APPEND"><gesture id="g" lexeme="BEAT" stroke="anticipators:metronome:beat3"/>'
    '<faceLexeme id="f" lexeme="smile" start="g:stroke" end="g:end+1"/></bml>',
    f'<bml {NS} id="r1" composition="REPLACE"><gaze id="z" target="camera" start="0" end="2"/>'
    '<constraint id="c"><synchronize ref="z:ready"><sync ref="n:stroke"/></synchronize></constraint>'
    '<head id="n" lexeme="SHAKE" repetition="2"/></bml>',
    f'<bml {NS} {BMLA} id="i1" bmla:interrupt="s1" bmla:onStart="p1"><speech id="sp"><text>Stop.</text></speech>'
    '</bml>',
    f'<bml {NS} {BMLA} id="p1" bmla:preplan="true"><wait id="w" start="0" end="1"/>'
    '<required><head id="n" lexeme="NOD" start="w:end"/></required></bml>',
    f'<bml {NS} id="c1"><speech id="s"><text>one two three four</text></speech><gesture id="g1" lexeme="BEAT" '
    'start="s:start" end="s:end"/><constraint><before ref="s:end"><sync ref="g2:start"/></before>'
    '<after ref="g1:end"><sync ref="g2:end"/></after></constraint><gesture id="g2" lexeme="BEAT"/></bml>',
]
NUMBERS = ["1e400", "-1e400", "nan", "inf", "-5", "0", "9" * 40, "9" * 400, "1e-320", "0.0000001", "1e5",
           "3.5", "-0.0", "1" * 20]
NAMES = ["a:b", "h\ud800", "x" * 300, "", "1", "anticipators", "bml", "g", "s1", "metronome", "é"]
#: How often each mutation is made: most keep the document well-formed, so that it reaches the scheduler.
WEIGHTS = [0.03, 0.03, 0.06, 0.05, 0.2, 0.12, 0.08, 0.2, 0.09, 0.04, 0.1]
TAGS = ["required", "constraint", "speech", "text", "sync", "gesture", "bml", "x"]


def seeds() -> list[str]:
    found = []
    for folder in (ROOT / "tests" / "bml-examples", ROOT / "tests" / "bml"):
        for path in sorted(folder.glob("*.xml")):
            found.append(path.read_text(encoding="utf-8", errors="replace"))
    return found + BUILT


def mutate(text: str, rng: np.random.Generator, others: list[str]) -> tuple[str, list[str]]:
    """One to four mutations of ``text``; returns the document and what was done."""
    done = []
    for _ in range(int(rng.integers(1, 5))):
        kind = int(rng.choice(11, p=WEIGHTS))
        n = len(text)
        i, j = sorted(int(x) for x in rng.integers(0, n + 1, 2)) if n else (0, 0)
        if kind == 0:  # random characters
            chars = "".join(chr(int(c)) for c in rng.integers(0, 0x2FF, int(rng.integers(1, 8))))
            text = text[:i] + chars + text[i:]
        elif kind == 1:  # delete a span
            text = text[:i] + text[j:]
        elif kind == 2:  # repeat a span
            text = text[:j] + text[i:j] * int(rng.integers(2, 50)) + text[j:]
        elif kind == 3:  # splice a span of another document
            other = others[int(rng.integers(len(others)))]
            a, b = sorted(int(x) for x in rng.integers(0, len(other) + 1, 2))
            text = text[:i] + other[a:b] + text[j:]
        elif kind == 4:  # a number replaced
            numbers = list(re.finditer(r"\d+(?:\.\d+)?", text))
            if numbers:
                m = numbers[int(rng.integers(len(numbers)))]
                text = text[:m.start()] + NUMBERS[int(rng.integers(len(NUMBERS)))] + text[m.end():]
        elif kind == 5:  # an id replaced
            ids = list(re.finditer(r'id="([^"]*)"', text))
            if ids:
                m = ids[int(rng.integers(len(ids)))]
                text = text[:m.start(1)] + NAMES[int(rng.integers(len(NAMES)))] + text[m.end(1):]
        elif kind == 6:  # deep nesting
            tag = TAGS[int(rng.integers(len(TAGS)))]
            depth = int(rng.choice([10, 100, 300, 2000]))
            text = text[:i] + f"<{tag}>" * depth + f"</{tag}>" * depth + text[i:]
        elif kind == 7:  # a sync attribute pointing somewhere
            ref = rng.choice(["anticipators:metronome:beat2", "anticipators:metronome:beat0", "anticipators:x:y",
                              "s1:sp:m1", "g:end+1e9", "nobody:start", "g:stroke-2", "sp:end", "b:g:relax"])
            text = re.sub(r'<(gesture|head|faceLexeme|gaze) ', rf'<\1 stroke="{ref}" ', text, count=1)
        elif kind == 8:  # composition
            text = text.replace("<bml ", f'<bml composition="{rng.choice(["APPEND", "REPLACE", "MERGE", "X"])}" ', 1)
        elif kind == 10:  # speech text: many marks, many words, or none
            at = text.find("<text>")
            if at >= 0:
                at += len("<text>")
                k = int(rng.choice([0, 5, 500, 3000]))
                filler = rng.choice([" ".join(f'<sync id="q{m}"/>w{m}' for m in range(k)), "word " * k, "...",
                                     "<sync id='q'/>" * 3])
                text = text[:at] + filler + text[at:]
        else:  # a declaration or doctype in front
            text = rng.choice(['<?xml version="1.0" encoding="bogus"?>', '<?xml version="1.0" encoding="latin-1"?>',
                               '<!DOCTYPE bml [<!ATTLIST bml id CDATA "dtd">]>', '<!DOCTYPE bml SYSTEM "x.dtd">',
                               "\ufeff", ""]) + text
        done.append(["chars", "delete", "repeat", "splice", "number", "id", "nest", "ref", "composition",
                     "prolog", "text"][kind])
    return text, done


def losses(realizer, cut_short: bool) -> list[str]:
    """What the feedback of a finished run lost or said wrong."""
    found = []
    items = realizer.feedback.items
    seen = set()
    current: dict[str, set[str]] = {}  # block id -> what its current run fed back (an id may be used again)
    for f in items:
        if f["type"] in ("blockProgress", "syncPointProgress"):
            block = f["id"].split(":")[0]
            if f["type"] == "blockProgress" and f["id"].endswith(":start"):
                current[block] = set()
            mine = current.setdefault(block, set())
            if f["id"] in mine:
                found.append(f"sent twice: {f['id']}")
            mine.add(f["id"])
            seen.add(f["id"])
    started = {f["id"][:-6] for f in items if f["type"] == "blockProgress" and f["id"].endswith(":start")}
    ended = {f["id"][:-4]: f["globalTime"] for f in items if f["type"] == "blockProgress" and f["id"].endswith(":end")}
    warned = {w["id"] for w in items if w["type"] == "warningFeedback"}
    if not cut_short:
        for block in started - set(ended):
            if block not in warned:
                found.append(f"block {block} started and never ended")
    running: set[str] = set()  # blocks between their start and their end
    for f in items:
        block = f["id"].split(":")[0] if f["type"] in ("blockProgress", "syncPointProgress") else None
        if f["type"] == "blockProgress":
            (running.add if f["id"].endswith(":start") else running.discard)(block)
        elif f["type"] == "syncPointProgress" and block not in running:
            found.append(f"{f['id']} outside its block's start and end")
            break
    if not cut_short:
        for run in realizer.scheduler.book.all_runs:
            for timed in run.timed:
                name = f"{run.id}:{timed.id}"
                if timed.passed[0] is not None and f"{name}:{timed.sync_ids[-1]}" not in seen and name not in warned:
                    found.append(f"{name} started and never ended, without a warning")
    return found


def run_case(case: int, seed: int, docs: list[str]) -> dict:
    """One case: two mutated documents; returns what happened."""
    from anticipators.metronome import Metronome
    from agentsim.engines.speech import SpeechConfig
    from agentsim.realizer import Realizer
    from speech_timing.builtin import BuiltinBackend

    rng = np.random.default_rng([seed, case])
    texts, mutations = [], []
    for _ in range(2):
        text, done = mutate(docs[int(rng.integers(len(docs)))], rng, docs)
        texts.append(text)
        mutations.append(done)
    strategy = rng.choice(["best", "chang-naive", "skip-70ms", "linear-model"]) if case % 3 == 0 else None
    result = {"case": case, "mutations": mutations, "strategy": strategy}
    start = time.perf_counter()
    try:
        realizer = Realizer(anticipators=[Metronome(bpm=float(rng.uniform(60, 180)))], tts=BuiltinBackend(),
                            speech=SpeechConfig(strategy=strategy) if strategy else None, strict=case % 7 == 0)
        realizer.submit_at(0.0, texts[0])
        realizer.submit_at(0.5, texts[1].encode("utf-8", "surrogatepass") if case % 5 == 0 else texts[1])
        realizer.run(until=HORIZON)
        result["losses"] = losses(realizer, cut_short=realizer.env.now >= HORIZON)
        result["synced"] = any(f["type"] == "syncPointProgress" for f in realizer.feedback.items)
    except Exception as exc:  # what the fuzz looks for
        result["exception"] = f"{type(exc).__name__}: {exc}"
        result["traceback"] = traceback.format_exc(limit=-4)
    result["seconds"] = time.perf_counter() - start
    return result


def fuzz(cases: int, seed: int = 0) -> dict:
    docs = seeds()
    exceptions, slow, lost, synced, failures = 0, 0, 0, 0, []
    slowest = (0.0, None)
    for case in range(cases):
        r = run_case(case, seed, docs)
        bad = False
        if "exception" in r:
            exceptions += 1
            bad = True
        if r["seconds"] > SLOW:
            slow += 1
            bad = True
        if r.get("losses"):
            lost += 1
            bad = True
        synced += bool(r.get("synced"))
        if r["seconds"] > slowest[0]:
            slowest = (r["seconds"], case)
        if bad and len(failures) < 10:
            failures.append({k: v for k, v in r.items()})
    return {"cases": cases, "seed": seed, "uncaught_exceptions": exceptions, "over_10_s": slow,
            "feedback_losses": lost, "cases_that_played_something": synced, "slowest_case": {"case": slowest[1], "seconds": round(slowest[0], 3)},
            "failures": failures}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    start = time.perf_counter()
    report = fuzz(args.cases, args.seed)
    report["wall_s"] = round(time.perf_counter() - start, 1)
    print(json.dumps(report, indent=1, default=str))


if __name__ == "__main__":
    main()
