"""One run of the trainer scenario and the files it writes.

:func:`simulate` drives on one SimPy clock the realizer (the trainer's BML), the simulated user (or a
recording played at its own pace) and the repetition anticipator that hears the user's phone every 50 ms.
:func:`collect_metrics` measures the run against the user's true key points (a recording has none: there the
key points the anticipator found after the fact stand for them). :func:`write_outputs` writes
``metrics.json``, ``trainer.bvh``, ``narration.wav``, ``motion.csv`` (the user's signal), ``repetitions.csv``
(the user's and the trainer's key points and the counts side by side), ``signal.png``, ``feedback.jsonl``
and ``report.html`` with its folder.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from anticipators.reps import RepetitionAnticipator
from scenarios.trainer.names import TARGET_TEMPO
from scenarios.trainer.trainer import Plan, Trainer
from scenarios.trainer.user import SimulatedUser, UserModel

#: Seconds between two hearings of the user's phone.
BLOCK = 0.05
#: The repetitions of a set.
SET = 20
LEXICON = Path(__file__).with_name("exercises.toml")


@dataclass
class Run:
    exercise: str
    strategy: str
    seed: int
    target_tempo: float
    realizer: object
    reps: RepetitionAnticipator
    trainer: Trainer
    user: SimulatedUser | None
    signal: tuple = ()
    wall_seconds: float = 0.0
    extra: dict = field(default_factory=dict)


class Spoken(dict):
    """Text -> (its stressed syllable's onset, its duration) in seconds as the voice says it, synthesised when
    first asked for."""

    def __init__(self, tts):
        super().__init__()
        self.tts = tts

    def __missing__(self, text: str) -> tuple[float, float]:
        from speech_timing.backend import SpeechText

        utterance = self.tts.synthesize(SpeechText(text))
        stressed = [p.start for p in utterance.phonemes if p.stressed]
        onset = stressed[0] if stressed else (utterance.words[0].start if utterance.words else 0.0)
        self[text] = (float(onset), float(utterance.duration))
        return self[text]


def simulate(exercise: str = "squat", strategy: str = "follow", target_tempo: float | None = None, seed: int = 0,
             recording: tuple | None = None) -> Run:
    """The trainer and the user, as fast as the computer allows. ``recording``: ``(times, samples)`` of a
    user's phone played instead of the simulated user (from time 0)."""
    from agentsim.core.clock import make_environment, run_until
    from agentsim.realizer import Realizer
    from speech_timing.choice import default_backend

    started = time.perf_counter()
    target_tempo = float(target_tempo or TARGET_TEMPO[exercise])
    target_period = 60.0 / target_tempo
    env = make_environment(False)
    reps = RepetitionAnticipator("reps")
    plan = None if strategy == "follow" else Plan("trainer", strategy, reps, target_period)
    tts = default_backend()
    realizer = Realizer(env=env, tts=tts, anticipators=[reps] + ([plan] if plan else []), lexicon=LEXICON)
    if recording is None:
        user = SimulatedUser(UserModel.draw(target_period, seed, SET), exercise, seed)
        repetitions = SET
    else:
        user = None
        repetitions = 999  # as many as the recording holds
    trainer = Trainer(realizer, reps, plan, exercise, repetitions, Spoken(tts))
    if user is not None:
        realizer.feedback.listen(lambda f: f.get("type") == "syncPointProgress"
                                 and str(f.get("id", "")).endswith(f":move:{trainer.key_sync}")
                                 and user.see(float(f["globalTime"])))
    heard_t, heard_a = [], []

    def hear():
        k = 0
        while True:
            k += 1
            t = k * BLOCK
            if t > env.now:
                yield env.timeout(t - env.now)
            if user is not None:
                times, samples = user.samples(t)
                end = user.end
            else:
                times, samples = recording
                lo, hi = np.searchsorted(times, [t - BLOCK, t], side="right")
                times, samples = times[lo:hi], samples[lo:hi]
                end = float(recording[0][-1])
            if len(times):
                heard_t.append(times)
                heard_a.append(samples)
                reps.push(times, samples)
                trainer.step(env.now)
            if t >= end:
                return

    def finish():
        yield env.process(hear())
        yield realizer.all_ended() | env.timeout(3.0)

    run_until(env, env.process(finish()))
    times = np.concatenate(heard_t) if heard_t else np.zeros(0)
    samples = np.concatenate(heard_a) if heard_a else np.zeros((0, 3))
    run = Run(exercise, strategy, seed, target_tempo, realizer, reps, trainer, user, (times, samples))
    run.wall_seconds = time.perf_counter() - started
    return run


# ---------------------------------------------------------------------------------------------- metrics
def user_keys(run: Run) -> np.ndarray:
    """The user's key points: the simulated user's true ones, or those the anticipator found in a recording."""
    if run.user is not None:
        return np.array(run.user.keys)
    return np.array(run.reps.tracker.repetitions)


def count_times(run: Run) -> dict[int, float]:
    """Repetition -> when its count word's stressed syllable was said (s)."""
    out = {}
    for heard in run.realizer.recording().speech:
        if heard.behaviour != "count" or not re.fullmatch(r"(recount|count)\d+", heard.block):
            continue
        stressed = [p.start for p in heard.utterance.phonemes if p.stressed]
        n = int(re.sub(r"^(recount|count)", "", heard.block))
        out[n] = float(heard.t0) + (stressed[0] if stressed else 0.0)  # a count said again replaces the first
    return out


def _tempo(keys: np.ndarray, restarts: set[int]) -> list[tuple[int, float]]:
    """(repetition, tempo a minute over the interval that ends at it), leaving out intervals over a pause."""
    return [(i + 1, 60.0 / (keys[i] - keys[i - 1])) for i in range(1, len(keys)) if i not in restarts]


def collect_metrics(run: Run) -> dict:
    """The figures of a finished run (no wall-clock times: the same for the same seed)."""
    keys = user_keys(run)
    restarts = set(run.user.pauses) if run.user is not None else {
        i for i in range(1, len(keys)) if keys[i] - keys[i - 1] > 1.6 * np.median(np.diff(keys))}
    # the repetitions the trainer could anticipate: from the third on, none the first after a pause
    judged = [n for n in range(3, len(keys) + 1) if (n - 1) not in restarts]
    trainer = np.array(sorted(run.trainer.key_points.values()))
    # each of the user's key points against the trainer's nearest one
    asynchrony = np.array([trainer[np.argmin(np.abs(trainer - keys[n - 1]))] - keys[n - 1] for n in judged]
                          if trainer.size else []) * 1000.0
    counts = count_times(run)
    count_error = np.array([abs(counts[n] - keys[n - 1]) for n in judged if n in counts]) * 1000.0
    said = np.array(sorted(counts.values()))
    missed = 0
    for n in range(4, len(keys) + 1):  # a repetition with no count word nearer to it than to its neighbours
        lo = (keys[n - 2] + keys[n - 1]) / 2
        hi = (keys[n - 1] + keys[n]) / 2 if n < len(keys) else keys[n - 1] + 1.0
        if not ((said >= lo) & (said < hi)).any():
            missed += 1
    tempi = _tempo(keys, restarts)
    target = run.target_tempo
    final = float(np.mean([60.0 / tempo for _, tempo in tempi[-3:]])) if tempi else None
    recovered = None
    if run.strategy != "follow" and tempi:
        outside = [n for n, tempo in tempi if abs(tempo / target - 1.0) > 0.05]
        last_out = max(outside) if outside else 0
        recovered = last_out + 1 if last_out < tempi[-1][0] else None
    round3 = lambda v: None if v is None or not np.isfinite(v) else round(float(v), 3)  # noqa: E731
    return {
        "exercise": run.exercise, "strategy": run.strategy, "seed": run.seed,
        "user": "simulated" if run.user is not None else "recording",
        "target_tempo": target,
        "user_start_tempo": round3(60.0 / run.user.model.start_period) if run.user is not None else None,
        "asynchrony_ms": {"mean": round3(asynchrony.mean()) if asynchrony.size else None,
                          "sd": round3(asynchrony.std()) if asynchrony.size else None, "n": int(asynchrony.size)},
        "count_error_ms": {"p50": round3(np.percentile(count_error, 50)) if count_error.size else None,
                           "p95": round3(np.percentile(count_error, 95)) if count_error.size else None,
                           "n": int(count_error.size)},
        "tempo_error_percent": None if final is None else round3(100.0 * (60.0 / final / target - 1.0)),
        "recovered_after": recovered,
        "user_repetitions": len(run.reps.tracker.repetitions),
        "missed_counts": missed,
        "trainer_repetitions": int(trainer.size),
        "remarks": [{"after": n, "words": words} for n, words in run.trainer.remarks],
        "remarks_left_out": [{"after": n, "words": words} for n, words in run.trainer.skipped],
        "left_out_of_timing": sorted(n + 1 for n in restarts),
        "warnings": len(run.realizer.feedback.warnings()),
        "simulated_seconds": round(float(run.realizer.env.now), 3),
    }
