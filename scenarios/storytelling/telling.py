"""Telling a story: realize its BML under an event-delivery condition and score every gesture against
the stressed syllable it aims at.

:func:`tell` compiles a :class:`~scenarios.storytelling.markup.Story` to one BML block (one speech,
one behaviour per gesture), realizes it with an animator-time strategy while the speech's progress
events arrive late, scattered and in bursts, and returns a :class:`Telling`. A gesture's *sync error* is
the time its syllable sync point was passed (stroke; attack peak of a face; end of a gaze shift) minus
the time its word's stressed vowel was really heard, ``playback.true_time(stressed_phoneme.start)``
(the word's onset for a word without a stressed vowel).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agentsim.core.progress import Stages
from agentsim.core.recording import Recording
from agentsim.engines.speech import HeardSpeech, SpeechConfig
from agentsim.errors import AgentsimError
from agentsim.realizer import Realizer
from scenarios.storytelling.markup import Story, anchor_sync, compile_bml, gesture_ids
from scenarios.storytelling.voice import CachedBackend, PhonemeMarks, stressed_onset, word_after
from speech_timing.backend import SpeechText, Utterance
from speech_timing.delivery import CONDITIONS, DeliveryModel
from speech_timing.metrics import error_summary, evaluate

__all__ = ["DEFAULT_DELIVERY", "FRAME", "SPEECH_START", "BLOCK_ID", "Telling", "tell", "make_voice",
           "stress_offsets", "syllable_times"]

#: The default event-delivery condition: condition A of :data:`speech_timing.delivery.CONDITIONS`.
DEFAULT_DELIVERY = CONDITIONS["A"]
#: Frame period (s) at which animator time is sampled for the snap and stall metrics.
FRAME = 1.0 / 60.0
#: The speech starts this long (s) after the block: room for the first gestures' preparation.
SPEECH_START = 1.0
#: Id of the story's BML block.
BLOCK_ID = "story"


def make_voice(tts: str | None = None, cache_dir=None, cache: bool = True, voice: str | None = None,
               rate: int = 175):
    """The storyteller's backend: ``tts`` ("espeak", "festival", "piper" or "builtin"; by default espeak-ng when it
    is installed, as everywhere) speaking with ``voice`` (None: the backend's default; espeak-ng at ``rate``
    words per minute) behind the disk cache, with phoneme-level marks
    (:class:`~scenarios.storytelling.voice.PhonemeMarks`)."""
    if tts is None:
        from speech_timing.choice import default_name

        tts = default_name()
    if tts == "espeak":
        from speech_timing.espeak import EspeakBackend

        backend = EspeakBackend(voice=voice or "en", rate=rate)
    elif tts == "festival":
        from speech_timing.festival import FestivalBackend

        try:
            backend = FestivalBackend(voice=voice)
        except ValueError as exc:
            raise AgentsimError(str(exc)) from None
    elif tts == "piper":
        from speech_timing.piper import PiperBackend

        backend = PiperBackend() if voice is None else PiperBackend(voice=voice)
    elif tts == "builtin":
        from speech_timing.builtin import BuiltinBackend

        if voice is not None:
            raise AgentsimError("the built-in backend has no voices: --voice needs --tts espeak, festival or piper")

        backend = BuiltinBackend()
    else:
        raise AgentsimError(f"unknown speech backend {tts!r}: use espeak, festival, piper or builtin")
    return PhonemeMarks(CachedBackend(backend, cache_dir=cache_dir, enabled=cache))


def _cache_of(voice) -> CachedBackend | None:
    while voice is not None and not isinstance(voice, CachedBackend):
        voice = getattr(voice, "backend", None)
    return voice


def syllable_times(story: Story, utterance: Utterance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each gesture: its word's onset and stressed-vowel onset in ``utterance`` (s, speech time), and
    whether the word has a stressed vowel."""
    onsets, stressed, has = [], [], []
    for g in story.gestures:
        k = word_after(utterance, story.words[g.word][0])
        if k is None:
            raise AgentsimError(f"the voice did not say the word {story.word_text(g.word)!r} of gesture {g.label}")
        s, ok = stressed_onset(utterance, k)
        onsets.append(utterance.words[k].start)
        stressed.append(s)
        has.append(ok)
    return np.array(onsets), np.array(stressed), np.array(has, dtype=bool)


def stress_offsets(story: Story, utterance: Utterance) -> dict[int, float]:
    """Seconds from each annotated word's onset to its stressed vowel in ``utterance``, by word index."""
    onsets, stressed, _ = syllable_times(story, utterance)
    return {g.word: float(s - o) for g, o, s in zip(story.gestures, onsets, stressed)}


@dataclass
class Telling:
    """One realization of a story and its scores.

    Attributes
    ----------
    story : Story
    bml : str
        The block that was realized.
    realizer : Realizer
        After ``run()``.
    recording : Recording
        What the realizer did (behaviours with their actual key times, drops, feedback, the speech).
    speech : HeardSpeech
        The speech as it was heard (true start, drift, delivered events, animator-time trace).
    ids : list of str
        BML id of each gesture.
    passed : numpy.ndarray
        Clock time (s) at which each gesture's syllable sync point was passed (NaN: never).
    heard : numpy.ndarray
        Clock time (s) at which each gesture's stressed vowel was heard.
    stressed : numpy.ndarray of bool
        Whether the word has a stressed vowel (else ``heard`` is its onset).
    wall_seconds : float
        Wall time of the simulation (compiling, realizing, scoring), synthesis excluded.
    """

    story: Story
    strategy: str
    anchor: str
    timing: str
    seed: int
    delivery: DeliveryModel
    bml: str
    realizer: Realizer
    recording: Recording
    speech: HeardSpeech
    ids: list[str]
    passed: np.ndarray
    heard: np.ndarray
    stressed: np.ndarray
    wall_seconds: float
    synthesis_seconds: float = 0.0
    cached: bool = True
    extra: dict = field(default_factory=dict)

    @property
    def utterance(self) -> Utterance:
        return self.speech.utterance

    @property
    def errors(self) -> np.ndarray:
        """Signed sync error (s) of every gesture whose sync point was passed: positive is late."""
        ok = np.isfinite(self.passed)
        return self.passed[ok] - self.heard[ok]

    @property
    def warnings(self) -> list[dict]:
        return [f for f in self.recording.feedback if f["type"] == "warningFeedback"]

    def trace(self) -> tuple[np.ndarray, np.ndarray]:
        """Animator time ``t_A`` sampled every :data:`FRAME` while the speech played: ``(t, t_A)``."""
        tr = self.speech.trace
        return np.array([t for t, _ in tr]), np.array([a for _, a in tr])

    def metrics(self) -> "OrderedDict[str, Any]":
        """The figures of this telling (times in seconds, sync errors in milliseconds)."""
        t, t_a = self.trace()
        ok = np.isfinite(self.passed)
        overall = evaluate(self.passed[ok], self.heard[ok], t, t_a, FRAME)
        by_kind = OrderedDict()
        kinds = np.array([g.kind for g in self.story.gestures])
        for kind in dict.fromkeys(kinds):
            sel = (kinds == kind) & ok
            summary = error_summary(self.passed[sel] - self.heard[sel])
            by_kind[str(kind)] = OrderedDict(n=int((kinds == kind).sum()), p50=summary["p50"],
                                             p95=summary["p95"], max=summary["max"])
        dropped = [b.id for b in self.recording.behaviours if b.state == "dropped"]
        return OrderedDict(
            story=self.story.title,
            source=self.story.source,
            words=len(self.story.words),
            spoken_words=len(self.utterance.words),
            gestures=len(self.story.gestures),
            gesture_kinds=self.story.counts(),
            duration_s=float(self.utterance.duration),
            strategy=self.strategy,
            anchor=self.anchor,
            timing=self.timing,
            seed=self.seed,
            sync_error_ms=overall["error_ms"],
            sync_error_by_kind_ms=by_kind,
            missed=int((~ok).sum()),
            warnings=len(self.warnings),
            dropped=dropped,
            words_without_stress=int((~self.stressed).sum()),
            snaps=overall["snaps"],
            stall_s=overall["stall_s"],
            rate=overall["rate"],
            audio_start_s=float(self.speech.t0),
            drift_ppm=float(self.speech.drift_ppm),
            delivery=OrderedDict((k, getattr(self.delivery, k)) for k in (
                "latency", "start_jitter", "drift_ppm", "delay", "jitter", "jitter_distribution",
                "burst_probability", "burst_hold", "loss")),
            simulation_seconds=self.wall_seconds,
            synthesis_seconds=self.synthesis_seconds,
            cached=self.cached,
        )


def tell(story: Story, strategy: str = "best", delivery: DeliveryModel = DEFAULT_DELIVERY, seed: int = 0,
         voice=None, anchor: str = "stress", timing: str = "tts", release: bool = True,
         start: float = SPEECH_START, stages: Stages | None = None) -> Telling:
    """Realize ``story`` and score its gestures.

    Parameters
    ----------
    story : Story
        What to tell.
    strategy : str
        Animator-time strategy (a key of ``speech_timing.animator_time.STRATEGIES``).
    delivery : DeliveryModel
        Playback latency, drift and event channel (default :data:`DEFAULT_DELIVERY`).
    seed : int
        Seed of the playback start and of the event channel.
    voice : TTSBackend, optional
        The backend (default :func:`make_voice`: espeak-ng, cached, with phoneme-level marks). With
        ``anchor="stress"`` it must understand phoneme-level marks.
    anchor : {"stress", "offset", "word"}
        How strokes reach the stressed syllable (:func:`~scenarios.storytelling.markup.compile_bml`).
    timing : {"tts", "linear"}
        What the planner knows in advance.
    release : bool
        Tie each gesture's end to the speech as well (see :func:`~scenarios.storytelling.markup.compile_bml`).
    start : float
        Start of the speech in the block (s).
    stages : Stages, optional
        Where to say on a terminal that the speech is synthesised and how far the simulation has come.

    Returns
    -------
    Telling
    """
    voice = voice if voice is not None else make_voice()
    stages = stages or Stages.off()
    cache = _cache_of(voice)
    synthesis_before = cache.synthesis_seconds if cache is not None else 0.0
    fresh_before = cache is not None and cache.key(story.text) in cache.synthesised
    started = time.perf_counter()
    # The planned utterance (from the cache, or synthesised now: that time is not counted).
    with stages("synthesising speech"):
        utterance = voice.synthesize(SpeechText(story.text))
    bml = compile_bml(story, timeline=utterance, anchor=anchor, release=release, block_id=BLOCK_ID, start=start)
    config = SpeechConfig(strategy=strategy, delivery=delivery, timing=timing, seed=seed, trace_frame=FRAME)
    realizer = Realizer(tts=voice, speech=config)
    realizer.submit(bml, source=story.source)
    # the bar's end: where the speech ends as planned (the run ends when it is heard and the gestures retract)
    with stages("simulating", total=start + utterance.duration) as advance:
        realizer.run(on_time=advance if stages.enabled else None)
    recording = realizer.recording()
    if not recording.speech:
        raise AgentsimError("the story's speech did not play: " + "; ".join(
            w["description"] for w in realizer.feedback.warnings()))
    speech = recording.speech[0]
    _, stressed_s, has = syllable_times(story, speech.utterance)
    heard = np.array([speech.true_time(s) for s in stressed_s])
    times = recording.sync_times()
    ids = gesture_ids(story)
    passed = np.array([times.get(f"{BLOCK_ID}:{gid}:{anchor_sync(g)}", np.nan)
                       for gid, g in zip(ids, story.gestures)], dtype=float)
    synthesis = (cache.synthesis_seconds - synthesis_before) if cache is not None else 0.0
    wall = time.perf_counter() - started - synthesis
    cached = cache is None or fresh_before or cache.key(story.text) not in cache.synthesised
    return Telling(story, strategy, anchor, timing, seed, delivery, bml, realizer, recording, speech, ids, passed,
                   heard, has, wall, synthesis, cached)
