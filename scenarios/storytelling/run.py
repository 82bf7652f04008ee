"""``agentsim run storytelling``: tell a story with its gestures on the stressed syllables, and measure it.

``main(args)`` reads the story (a ``.story`` file of the annotation format, a shipped story by name, or
a Praat TextGrid with ``words`` and ``gestures`` tiers), compiles it to BML, realizes it with an
animator-time strategy under an event-delivery condition, and writes to ``--out``:

=====================  ==============================================================================
``metrics.json``       the figures: words, gestures, duration, strategy, sync error (p50, p95, max, ms)
                       overall and per kind, snaps, stalls, warnings, wall time and its stages
``narration.wav``      the speech where the run's listener heard it (from ``audio_start_s``, drifting)
``story.TextGrid``     words, phones, gestures (planned), strokes (realized)
``story.bvh``          the body's motion
``gestures.csv``       one row per gesture: its word, when it sounded, when its stroke came, the error
``report.html``        the run to watch and hear in a browser (with ``report_files/``)
``timeline.png``       an overview of the behaviours of the whole story, and ``timeline_0000-0030s.png``,
                       ... behaviours, phases, pegs, feedback and words of each ``--window`` seconds
``sync_errors.png``    every gesture's sync error over the whole story
``feedback.jsonl``     the BML feedback, one JSON object per line
``story.bml``          the BML block that was realized
``compare.json``       with ``--compare``: the figures of every strategy on the same seed
``environment.csv``    a story with emotions: the camera, light and music they chose (one row at 0 s and
                       one at each change), and ``music.wav``, the music exactly as mixed under the speech
                       in ``narration.wav`` and the report (not with ``--no-environment``)
=====================  ==============================================================================

With ``--compare`` each strategy's files (all but the timeline pictures) go to ``--out/<strategy>/`` and only
``compare.json`` beside them. On a terminal, stderr says which stage is under way (synthesising speech,
simulating, with a bar of simulated seconds, poses/BVH, audio, report, pictures; with ``--compare`` one bar
of the strategies that names the stage); elsewhere nothing more is printed.

With ``--json`` the figures written (``metrics.json``, or with ``--compare`` those of ``compare.json``) are
printed as JSON on stdout, and what is otherwise printed goes to stderr.

The files are written into a staging folder beside ``--out`` (``.NAME.staging-XXXXXXXX``) that replaces the
old run only once every file is whole (:func:`agentsim.written.staged_folder`): a killed run leaves
the old run as it was, and the next run deletes what the killed one staged.

Every file is on the run's one time axis: simulated time 0 is WAV sample 0, BVH frame 0 and feedback
``globalTime`` 0 (the TextGrid says so in its ``axis`` tier, ``metrics.json`` in ``time_axis``).

Wall time counts everything from reading the story to the last file written except the first-time
synthesis of the speech, which is cached on disk (``--cache``) and reported separately.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import json
import math
import sys
import tempfile
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from agentsim.written import save_figure
from agentsim.errors import AgentsimError
from agentsim.media.files import write_text
from agentsim.core.progress import Stages
from agentsim.media import AXIS, GLOSSARY
from scenarios.storytelling.markup import Story, StoryError, read_story
from scenarios.storytelling.names import DEFAULT_OUT
from scenarios.storytelling.telling import Telling, make_voice, syllable_times, tell

__all__ = ["STORIES_DIR", "DEFAULT_OUT", "main", "resolve_story", "load_story", "shipped_stories", "write_outputs",
           "comparison_table"]

#: Where the shipped stories live.
STORIES_DIR = Path(__file__).resolve().parent / "stories"


# ----------------------------------------------------------------------------------------------------
# Stories.


def shipped_stories() -> dict[str, Path]:
    """The shipped stories by name (file stem)."""
    return {p.stem: p for p in sorted(STORIES_DIR.glob("*.story"))}


def resolve_story(spec: str | None) -> Path:
    """The story file that ``spec`` names: a path, a shipped story's name, or (None) the longest shipped
    story. Raises :class:`StoryError` with the known names if there is none."""
    shipped = shipped_stories()
    if spec is None:
        if not shipped:
            raise StoryError(f"no stories in {STORIES_DIR}")
        return max(shipped.values(), key=lambda p: (len(read_story(p).words), p.name))
    path = Path(spec).expanduser()
    if path.is_file():
        return path
    stem = path.name[:-len(".story")] if path.name.endswith(".story") else path.name
    if str(path) in (stem, f"{stem}.story") and stem in shipped:
        return shipped[stem]
    raise StoryError(f"no story file or shipped story {spec!r}; shipped stories: {', '.join(shipped) or 'none'}")


def load_story(path: Path, scene: dict | None = None) -> Story:
    """Read a story file, or a TextGrid with ``words`` and ``gestures`` tiers (whose extra targets come
    from ``scene``)."""
    if path.suffix.lower() == ".textgrid":
        from scenarios.storytelling.praat import import_textgrid

        try:
            return import_textgrid(path, scene=scene)
        except StoryError as exc:
            if "unknown target" in str(exc):
                raise StoryError(f"{exc}; for a TextGrid, --scene names a story whose @scene lines declare "
                                 f"them") from None
            raise
    story = read_story(path)
    if scene:
        story.scene = {**scene, **story.scene}
    return story


def main(args: argparse.Namespace) -> int:
    """Run ``agentsim run storytelling`` with the options :mod:`agentsim.cli.scenarios` declares (and
    ``args.delivery``, the event-delivery condition they make); returns the exit status.

    Raises :class:`AgentsimError` (a missing story, a bad tag, an unknown strategy) before anything is
    synthesised or realized.
    """
    from speech_timing.animator_time import check_strategy

    started = time.perf_counter()
    strategy = check_strategy(getattr(args, "strategy", "best") or "best")
    if not 0 < args.fps <= 1000:
        raise AgentsimError(f"--fps must be positive and at most 1000 frames per second, got {args.fps:g}")
    if not args.window > 0:
        raise AgentsimError("--window must be positive")
    delivery = args.delivery
    scene_path = resolve_story(args.scene) if getattr(args, "scene", None) else None
    scene = read_story(scene_path).scene if scene_path else None
    story_path = resolve_story(args.story)
    story = load_story(story_path, scene)
    out = Path(args.out)
    from agentsim.written import staged_folder
    from agentsim.media.files import check_writable

    check_writable(folders=[out])  # an output folder that cannot be written is said before any work
    # the run is written into a staging folder beside --out, which replaces the old run once this one has
    # finished: a killed run leaves the old one whole (agentsim.written)
    with staged_folder(out, inputs=[story_path, scene_path, args.cache]) as staging:
        return _run(args, story, strategy, delivery, out, staging, started)


def _run(args: argparse.Namespace, story: Story, strategy: str, delivery, out: Path, staging: Path,
         started: float) -> int:
    """The run of :func:`main` into ``staging`` (which becomes ``out`` once it has returned)."""
    from speech_timing.animator_time import STRATEGIES

    voice = make_voice(args.tts, cache_dir=args.cache, cache=not args.no_cache, voice=getattr(args, "voice", None))
    as_json = getattr(args, "json", False)
    printed = sys.stderr if as_json else sys.stdout  # with --json, stdout carries the JSON alone
    stages = Stages()
    plots = not getattr(args, "no_pictures", False)
    if not args.compare:
        if plots:
            from agentsim.animation.pictures import warm_workers

            warm_workers()  # the processes that draw the timeline pictures get ready while the story is told
        telling = tell(story, strategy=strategy, delivery=delivery, seed=args.seed, voice=voice, anchor=args.anchor,
                       timing=args.timing, stages=stages)
        stages_seconds = write_outputs(telling, staging, fps=args.fps, window=args.window, seed=args.seed,
                                       plots=plots, stages=stages, physics=getattr(args, "physics_pushes", None),
                                       environment=not getattr(args, "no_environment", False))
        wall = time.perf_counter() - started - voice.backend.synthesis_seconds
        metrics = _metrics(telling, args, voice, stages_seconds, wall)
        write_text(staging / "metrics.json", json.dumps(_clean(metrics), indent=2) + "\n")
        print(_summary(story, metrics, voice, f"{out}/"), file=printed)
        if as_json:
            print(json.dumps(_clean(metrics)))
        return 0
    # --compare: each strategy's files in a folder of its own (as one run's, but for the timeline pictures),
    # and beside them only compare.json
    tellings: dict[str, Telling] = {}
    every: dict[str, OrderedDict] = {}
    for name in stages.over(list(STRATEGIES), "strategies", unit="strategy"):
        begun = time.perf_counter()
        synthesis = voice.backend.synthesis_seconds
        tellings[name] = t = tell(story, strategy=name, delivery=delivery, seed=args.seed, voice=voice,
                                  anchor=args.anchor, timing=args.timing, stages=stages)
        stages_seconds = write_outputs(t, staging / name, fps=args.fps, window=args.window, seed=args.seed,
                                       plots=plots, pictures=False, stages=stages,
                                       environment=not getattr(args, "no_environment", False),
                                       physics=getattr(args, "physics_pushes", None))
        every[name] = _metrics(t, args, voice, stages_seconds,
                               time.perf_counter() - begun - (voice.backend.synthesis_seconds - synthesis))
    wall = time.perf_counter() - started - voice.backend.synthesis_seconds
    rows = OrderedDict((name, _row(t)) for name, t in tellings.items())
    metrics = every[strategy]
    compared = _clean(OrderedDict(story=story.title, seed=args.seed, anchor=args.anchor, timing=args.timing,
                                  delivery=metrics["delivery"], strategies=rows))
    for name, m in every.items():
        m["compare_wall_seconds"] = wall
        write_text(staging / name / "metrics.json", json.dumps(_clean(m), indent=2) + "\n")
    write_text(staging / "compare.json", json.dumps(compared, indent=2) + "\n")
    print(comparison_table(rows), file=printed)
    print(_summary(story, metrics, voice, f"{out}/<strategy>/ and {out / 'compare.json'}"), file=printed)
    if as_json:
        print(json.dumps(compared))
    return 0


def _metrics(telling: Telling, args: argparse.Namespace, voice, stages: "OrderedDict[str, float]",
             wall: float) -> "OrderedDict":
    """What ``metrics.json`` holds for ``telling``, whose run took ``wall`` seconds (synthesis excluded)."""
    cache = voice.backend
    metrics = telling.metrics()
    metrics["wall_seconds"] = wall
    metrics["wall_fraction_of_story"] = metrics["wall_seconds"] / metrics["duration_s"]
    metrics["synthesis_seconds"] = cache.synthesis_seconds
    metrics["cached"] = cache.key(telling.story.text) not in cache.synthesised  # the speech came from the cache
    metrics["cache_load_seconds"] = cache.load_seconds
    metrics["stages_seconds"] = OrderedDict([("simulation", telling.wall_seconds)] + list(stages.items()))
    metrics["fps"] = args.fps
    speaker = cache.backend  # what speaks behind the cache
    metrics["speech_backend"] = OrderedDict(tts=getattr(speaker, "name", ""), voice=getattr(speaker, "voice", None),
                                            sample_rate=telling.speech.utterance.sample_rate)
    metrics["time_axis"] = AXIS
    metrics["glossary"] = GLOSSARY
    metrics.update(telling.extra)
    return metrics


def _summary(story: Story, metrics: dict, voice, written: str) -> str:
    """The line a run prints: the story, the strategy's figures, the wall time and where the files went."""
    e = metrics["sync_error_ms"]
    synthesis = voice.backend.synthesis_seconds
    return (f"{story.title}: {metrics['words']} words, {metrics['gestures']} gestures, "
            f"{metrics['duration_s']:.1f} s of speech; strategy {metrics['strategy']}: sync error p50 {e['p50']:.2f} ms, "
            f"p95 {e['p95']:.2f} ms, max {e['max']:.2f} ms; {metrics['snaps']} snaps, {metrics['warnings']} warnings, "
            f"{metrics['missed']} missed; wall {metrics['wall_seconds']:.2f} s "
            f"({100 * metrics['wall_fraction_of_story']:.2f} % of the story)"
            + (f", first synthesis {synthesis:.2f} s" if synthesis else "") + f"; written to {written}")


def _row(t: Telling) -> "OrderedDict":
    m = t.metrics()
    return OrderedDict(gestures=m["gestures"], missed=m["missed"], warnings=m["warnings"],
                       p50_ms=m["sync_error_ms"]["p50"], p95_ms=m["sync_error_ms"]["p95"],
                       max_ms=m["sync_error_ms"]["max"], signed_mean_ms=m["sync_error_ms"]["signed_mean"],
                       snaps=m["snaps"], stall_s=m["stall_s"], simulation_s=t.wall_seconds)


def comparison_table(rows: dict) -> str:
    """A plain-text table of the strategies' figures (one row per strategy)."""
    head = (f"{'strategy':<14}{'gestures':>9}{'missed':>8}{'p50 ms':>10}{'p95 ms':>10}{'max ms':>10}"
            f"{'snaps':>8}{'stall s':>9}{'sim s':>8}")
    lines = [head, "-" * len(head)]
    for name, r in rows.items():
        lines.append(f"{name:<14}{r['gestures']:>9d}{r['missed']:>8d}{r['p50_ms']:>10.2f}{r['p95_ms']:>10.2f}"
                     f"{r['max_ms']:>10.2f}{r['snaps']:>8d}{r['stall_s']:>9.2f}{r['simulation_s']:>8.2f}")
    return "\n".join(lines)


def _clean(value):
    """``value`` with NaN and infinities as None and numpy scalars as Python numbers (for JSON)."""
    if isinstance(value, dict):
        return OrderedDict((k, _clean(v)) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


# ----------------------------------------------------------------------------------------------------
# Outputs.


def write_outputs(telling: Telling, out: Path, fps: float = 60.0, window: float = 30.0,
                  seed: int = 0, plots: bool = True, pictures: bool = True,
                  stages: Stages | None = None, environment: bool = True,
                  physics: list | None = None) -> "OrderedDict[str, float]":
    """Write a telling's files (all but ``metrics.json``) to ``out``; returns the wall seconds of each
    stage. ``plots``: draw the timeline and sync-error pictures too; ``pictures``: the timeline pictures
    among them. ``stages``: where to say on a terminal which stage is under way. ``environment``: show the
    story's emotions through camera, light and music (``environment.csv``, ``music.wav``). ``physics``: the
    pushes of a run on the physical body (its poses the physical body's, and ``physics.csv``); None: the
    animation's."""
    out.mkdir(parents=True, exist_ok=True)
    # the poses are evaluated into files of a scratch folder (removed at the end) and read back a window
    # of frames at a time by everything that uses them: a long story's poses are never held whole
    with tempfile.TemporaryDirectory(dir=out, prefix=".poses-") as scratch:
        return _write_outputs(telling, out, Path(scratch), fps, window, seed, plots, pictures,
                              stages or Stages.off(), environment, physics)


def _write_outputs(telling: Telling, out: Path, scratch: Path, fps: float, window: float, seed: int,
                   plots: bool, pictures: bool, say: Stages, environment: bool = True,
                   physics: list | None = None) -> "OrderedDict[str, float]":
    from agentsim.animation import evaluate_poses, write_bvh
    from agentsim.media.audio import run_track_stream
    from agentsim.media.files import write_feedback, write_wav
    from agentsim.media.report import write_report
    from agentsim.media.report.page import start_audio
    from agentsim.media.tables import gesture_rows, write_csv
    from scenarios.storytelling.praat import export_textgrid

    stages: OrderedDict[str, float] = OrderedDict()

    def stage(name, started):
        stages[name] = time.perf_counter() - started
        return time.perf_counter()

    if plots and pictures:  # the processes that draw the timeline pictures get ready meanwhile
        from agentsim.animation.pictures import warm_workers

        warm_workers()
    t = time.perf_counter()
    utterance = telling.utterance
    # the track is made a stretch at a time, for the WAV and again for the report: never held whole; both
    # sound files are written on a thread of their own (mixing and encoding mostly run outside the
    # interpreter) while the poses and the rest are made, and waited for where they were written before
    rows, music = _environment(telling, out, seed, environment)
    track = (run_track_stream(telling.recording, music) if utterance.audio is not None or music else None)
    # the timeline pictures are drawn by worker processes from when the poses are known while the rest is
    # written, and waited for at the end
    with contextlib.ExitStack() as drawing, concurrent.futures.ThreadPoolExecutor(1) as sound:
        # where the listener heard it: late by the playback latency, drifting
        wav = sound.submit(write_wav, out / "narration.wav", track) if track is not None else None
        ogg = start_audio(out / "report.html", track, sound)
        with say("poses/BVH"):
            write_text(out / "story.bml", telling.bml)
            write_feedback(out / "feedback.jsonl", telling.recording.feedback)
            t = stage("feedback", t)
            body = None  # the physical body's figures (--physics)
            if physics is None:
                stream = evaluate_poses(telling.recording, fps=fps, seed=seed, scene=telling.story.scene,
                                        folder=scratch)
            else:
                from agentsim.physics.run import scenario_poses

                stream, body = scenario_poses(telling.recording, fps, seed, physics, out,
                                              scene=telling.story.scene, folder=scratch)
            timelines = (drawing.enter_context(start_window(telling, out / "timeline.png", stream, window))
                         if plots and pictures else None)
            t = stage("poses", t)
            write_bvh(out / "story.bvh", stream)
            t = stage("bvh", t)
            telling.extra["motion_strokes"] = motion_strokes(telling, stream)
            t = stage("motion check", t)
        with say("audio"):
            if wav is not None:
                wav.result()
            t = stage("wav", t)  # what was left of writing it
        with say("report"):
            speech = telling.speech
            _, planned, _ = syllable_times(telling.story, utterance)
            export_textgrid(out / "story.TextGrid", telling.story, utterance, planned, telling.passed, telling.ids,
                            to_axis=speech.true_time, axis=AXIS)
            gestures = gesture_rows(telling.recording)
            write_csv(out / "gestures.csv", gestures)
            t = stage("textgrid", t)
            extra = {}
            if rows:
                from agentsim.media.environment import report_environment

                extra["environment"] = report_environment(rows, stream)
            write_report(out / "report.html", recording=telling.recording, stream=stream, track=track,
                         gestures=gestures, title=f"{telling.story.title} (strategy {telling.strategy})", audio=ogg,
                         physics=body, **extra)
            sound.shutdown(wait=True)  # the report's sound is encoded
        t = stage("report", t)
        if plots:
            with say("pictures"):
                plot_errors(telling, out / "sync_errors.png")
                if timelines is not None:
                    timelines.result()
            stage("plots", t)
    return stages


def _environment(telling: Telling, out: Path, seed: int, enabled: bool) -> tuple[list, list]:
    """A story with emotions (and ``enabled``): ``environment.csv`` and ``music.wav`` written into ``out``; its
    rows and the music's source to mix (a list of at most one). Without emotions: nothing done, two empty lists."""
    from agentsim.media.environment import music_for, run_environment

    rows = run_environment(telling.recording, seed, enabled) if telling.story.emotions else None
    if not rows:
        return [], []
    from agentsim.expression.environment import write_environment_csv
    from agentsim.media.audio import Track, file_sources, mix_stream, speech_sources
    from agentsim.media.files import write_wav

    write_environment_csv(out / "environment.csv", rows)
    sounds = [*speech_sources(telling.recording), *file_sources(telling.recording)]
    music = music_for(rows, sounds, max((s.end for s in sounds), default=telling.recording.now))
    if music is None:
        return rows, []
    # as long as the narration it is mixed into (whose length the mix rounds up)
    length = mix_stream([*sounds, music], music.rate).length
    write_wav(out / "music.wav", Track(np.pad(music.samples, (0, max(0, length - len(music.samples)))), music.rate))
    return rows, [music]


def motion_strokes(telling: Telling, stream) -> "OrderedDict":
    """Where the evaluated motion has its strokes (the wrist's lowest point, the head's first extreme,
    the arm's arrival at the target) against the stroke feedback: how many were measured, how many kept
    their arm or head through the stroke (``intact``: no other behaviour took it over meanwhile), and the
    absolute difference of the intact ones in ms (between frames where the extreme can be interpolated)."""
    from agentsim.animation.analysis import measure_strokes

    measures = measure_strokes(stream, telling.recording.sync_times())
    intact = [m for m in measures if m.intact]
    error = np.abs([m.refined_error for m in intact]) * 1000.0
    summary = OrderedDict(measured=len(measures), intact=len(intact),
                          taken_over=[f"{m.behaviour} ({m.side})" for m in measures if not m.intact])
    if len(error):
        summary.update(p50_ms=float(np.percentile(error, 50)), p95_ms=float(np.percentile(error, 95)),
                       max_ms=float(error.max()))
    return summary


def plot_window(telling: Telling, png: Path, stream, window: float = 30.0) -> list[Path]:
    """The telling's timeline as pictures that read (:func:`~agentsim.animation.plot_timelines`): in ``png``
    an overview of the whole story, and next to it each ``window`` seconds in detail, with the words
    heard under the speech and the poses of that window (a whole story in one picture would need one row
    per gesture, hundreds of rows). Returns the files written, the overview first."""
    with start_window(telling, png, stream, window) as drawing:
        return drawing.result()


def start_window(telling: Telling, png: Path, stream, window: float = 30.0):
    """Begin drawing the pictures of :func:`plot_window` in worker processes
    (:func:`~agentsim.animation.pictures.start_timelines`); its ``result()`` waits for them and returns the
    files, the overview first. ``stream`` is read here: it may be gone before the pictures are drawn."""
    from agentsim.animation.pictures import start_timelines

    return start_timelines(telling.recording, png, stream=stream, window=window, threshold=window, width=16.0,
                           title=f"{telling.story.title} (strategy {telling.strategy})")


def plot_errors(telling: Telling, png: Path) -> Path:
    """Every gesture's sync error (ms) against when it was heard, by kind, with the p95 band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = np.isfinite(telling.passed) & np.isfinite(telling.heard)  # a NaN would reach the p95 in the legend
    heard = telling.heard[ok]
    errors = 1000.0 * (telling.passed[ok] - heard)
    kinds = np.array([g.kind for g in telling.story.gestures])[ok]
    fig, ax = plt.subplots(figsize=(12, 3.6))
    for kind in dict.fromkeys(kinds):
        sel = kinds == kind
        ax.plot(heard[sel], errors[sel], ".", markersize=4, label=f"{kind} ({int(sel.sum())})")
    if len(errors):
        p95 = float(np.percentile(np.abs(errors), 95))
        ax.axhspan(-p95, p95, color="#deebf7", zorder=0, label=f"|error| <= p95 = {p95:.1f} ms")
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xlabel("when the stressed syllable was heard (s)")
    ax.set_ylabel("stroke - syllable (ms)")
    ax.set_title(f"{telling.story.title}: sync error of {len(errors)} gestures (strategy {telling.strategy})")
    if len(errors):  # a story without gestures has nothing to name (matplotlib would warn)
        ax.legend(fontsize=7, ncol=5, loc="upper right")
    fig.tight_layout()
    save_figure(fig, png, dpi=110)
    plt.close(fig)
    return png
