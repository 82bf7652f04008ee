"""Speech speed: synthesis real-time factor (espeak-ng) and simulation real-time factor of the realizer
playing five or more minutes of speech with a beat on every content word.

Prints JSON. Target: the simulation of five minutes of speech with gestures takes under 3 s.
"""

from __future__ import annotations

import json
import time

from agentsim.bml.speech_text import normalize_space
from speech_timing.backend import SpeechText
from speech_timing.delivery import CONDITIONS
from speech_timing.espeak import EspeakBackend
from scenarios.speech_sync import speech_sync
from speech_timing.linear_model import TEXTS_DIR


def main() -> None:
    text = " ".join(normalize_space((TEXTS_DIR / f"{name}.txt").read_text())[0]
                    for name in ("clocks", "lighthouse", "orchard"))
    backend = EspeakBackend()
    started = time.perf_counter()
    utterance = backend.synthesize(SpeechText(text))
    synthesis = time.perf_counter() - started
    delivery = CONDITIONS["A"]
    rows = {}
    for strategy in ("best", "open-loop", "chang-naive"):
        result = speech_sync(text, backend, strategy, delivery, seed=1)
        # The realizer synthesises the text again (with its sync marks): take that out of the wall time.
        simulation = result["wall_seconds"] - synthesis
        rows[strategy] = {"wall_s": round(result["wall_seconds"], 3), "simulation_s": round(simulation, 3),
                          "per_5_minutes_s": round(simulation * 300 / result["speech_seconds"], 3),
                          "p95_ms": round(result["error_ms"]["p95"], 2), "snaps": result["snaps"],
                          "gestures": result["gestures"]}
    print(json.dumps({
        "benchmark": "speech",
        "speech_seconds": round(utterance.duration, 1),
        "words": len(utterance.words),
        "synthesis_s": round(synthesis, 3),
        "synthesis_real_time_factor": round(synthesis / utterance.duration, 5),
        "simulation": rows,
        "simulation_real_time_factor_best": round(rows["best"]["simulation_s"] / utterance.duration, 5),
        "target_s_per_5_minutes": 3.0,
        "meets_target": rows["best"]["per_5_minutes_s"] < 3.0,
    }, indent=2))


if __name__ == "__main__":
    main()
