"""Speech-gesture synchronisation measured through the realizer: a beat on every content word.

:func:`speech_sync` writes a BML block whose speech has a ``<sync>`` before every content word and a beat
gesture whose stroke is tied to it, realizes it with an animator-time strategy under a delivery
condition, and scores when each stroke was passed against when its word was really heard.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any
from xml.sax.saxutils import escape

import numpy as np

from agentsim.bml.speech_text import normalize_space
from agentsim.errors import AgentsimError
from agentsim.engines.speech import SpeechConfig
from agentsim.realizer import Realizer
from speech_timing.delivery import DeliveryModel
from speech_timing.harness import is_content_word
from speech_timing.linear_model import written_words
from speech_timing.metrics import evaluate, sync_errors

#: The speech starts this long after the block (seconds).
SPEECH_START = 1.0
FRAME = 1.0 / 60.0


def beats_on_content_words(text: str, block_id: str = "sync") -> tuple[str, list[int]]:
    """A BML block: ``text`` spoken with a beat gesture whose stroke is on every content word.

    Returns the BML and, for each gesture ``g<k>``, the index ``k`` of its word in ``written_words(text)``.
    """
    text = normalize_space(text)[0]
    pieces, targets, last = [], [], 0
    for k, (a, b) in enumerate(written_words(text)):
        if is_content_word(text[a:b]):
            pieces.append(escape(text[last:a]) + f'<sync id="w{k}"/>')
            last = a
            targets.append(k)
    pieces.append(escape(text[last:]))
    gestures = "".join(f'<gesture id="g{k}" lexeme="BEAT" mode="RIGHT_HAND" stroke="speech1:w{k}"/>'
                       for k in targets)
    bml = (f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="{block_id}">'
           f'<speech id="speech1" start="{SPEECH_START}"><text>{"".join(pieces)}</text></speech>{gestures}</bml>')
    return bml, targets


def speech_sync(text: str, backend, strategy: str, delivery: DeliveryModel, timing: str = "tts",
                seed: int = 0, linear_model=None) -> dict[str, Any]:
    """Realize beats on every content word and measure their synchronisation with the speech.

    Returns ``{"strategy", "timing", "seed", "words", "gestures", "missed", "error_ms": {p50, p95, max,
    mean, signed_mean, n}, "snaps", "stall_s", "rate": {"min", "max"}, "wall_seconds", "speech_seconds",
    "errors_s"}`` (the last: signed errors in seconds, an array).
    """
    import time

    bml, targets = beats_on_content_words(text)
    config = SpeechConfig(strategy=strategy, delivery=delivery, timing=timing, linear_model=linear_model,
                          seed=seed, trace_frame=FRAME)
    realizer = Realizer(tts=backend, speech=config)
    started = time.perf_counter()
    realizer.submit(bml)
    realizer.run()
    wall = time.perf_counter() - started
    recording = realizer.recording()
    if not recording.speech:
        raise AgentsimError("the speech did not play: " + "; ".join(
            w["description"] for w in realizer.feedback.warnings()))
    speech = recording.speech[0]
    utterance = speech.utterance
    strokes = recording.sync_times()
    passed, truth = [], []
    for k in targets:
        stroke = strokes.get(f"sync:g{k}:stroke")
        if stroke is None:
            continue
        passed.append(stroke)
        truth.append(speech.true_time(utterance.mark_time(f"w{k}")))
    t = np.array([f for f, _ in speech.trace])
    t_a = np.array([p for _, p in speech.trace])
    return OrderedDict(
        strategy=strategy, timing=timing, seed=seed, words=len(utterance.words), gestures=len(targets),
        missed=len(targets) - len(passed), **evaluate(passed, truth, t, t_a, FRAME), wall_seconds=wall,
        speech_seconds=utterance.duration, errors_s=sync_errors(passed, truth),
    )
