"""Many sync marks in one speech: wall time of reading, planning and playing a speech with a ``<sync>`` after
every word, for 3,000, 6,000 and 12,000 marks; prints JSON.

The realizer's own work is measured with the built-in timing model (what synthesising 12,000 words, some
70 minutes of speech, costs espeak-ng is the synthesiser's: ``bench_speech.py`` measures its real-time
factor). ``--espeak`` measures the same with espeak-ng too, synthesis included.

Target: 12,000 marks in under 2 s, and linear: 12,000 marks cost at most 6 times what 3,000 do.

Usage::

    PYTHONPATH=. python benchmarks/bench_speech_marks.py [--espeak] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time

from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
WORDS = "the quick brown fox jumps over a lazy dog and then".split()
SIZES = (3000, 6000, 12000)
TARGET_S = 2.0
TARGET_RATIO = 6.0


def document(marks: int) -> str:
    """A speech of ``marks`` words with a sync mark after each; a full stop every 11 words."""
    words = (f'{WORDS[i % len(WORDS)]}{"." if i % len(WORDS) == len(WORDS) - 1 else ""} <sync id="m{i}"/>'
             for i in range(marks))
    return f'<bml {NS} id="b"><speech id="s"><text>{" ".join(words)}</text></speech></bml>'


def realize(bml: str, tts) -> tuple[float, int]:
    """Wall seconds of submitting and running ``bml``, and the sync points passed."""
    started = time.perf_counter()
    realizer = Realizer(tts=tts)
    realizer.submit(bml)
    realizer.run()
    wall = time.perf_counter() - started
    assert not realizer.feedback.warnings(), realizer.feedback.warnings()[:1]
    return wall, len(realizer.feedback.of_type("syncPointProgress"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--espeak", action="store_true", help="measure with espeak-ng too (synthesis included)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each size; the fastest is kept")
    args = parser.parse_args()
    realize(document(100), BuiltinBackend())  # imports and first calls out of the way
    builtin = {}
    for n in SIZES:
        bml = document(n)
        walls = []
        for _ in range(args.repeats):
            wall, passed = realize(bml, BuiltinBackend())
            assert passed == n + 2  # every mark, and the speech's start and end
            walls.append(wall)
        builtin[n] = min(walls)
    ratio = builtin[SIZES[-1]] / builtin[SIZES[0]]
    result = {
        "benchmark": "speech_marks",
        "builtin_s": {str(n): round(t, 3) for n, t in builtin.items()},
        "builtin_us_per_mark": {str(n): round(1e6 * t / n, 1) for n, t in builtin.items()},
        "ratio_12000_to_3000": round(ratio, 2),
        "target_s": TARGET_S,
        "target_ratio": TARGET_RATIO,
        "meets_target": builtin[SIZES[-1]] < TARGET_S and ratio <= TARGET_RATIO,
    }
    if args.espeak:
        from speech_timing.espeak import EspeakBackend

        realize(document(100), EspeakBackend())
        result["espeak_s"] = {str(n): round(realize(document(n), EspeakBackend())[0], 3) for n in SIZES}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
