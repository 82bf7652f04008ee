"""One run of the conductor scenario, simulated or live, and the files it writes.

Simulated (:func:`simulate`): one SimPy clock drives the realizer (the conductor's BML), the ensemble's
musicians and the audio. Every ``block_seconds`` the notes played so far are rendered by FluidSynth and
pushed into the conductor's ears (the beat tracker); the conductor knows nothing else of the ensemble.
Live (:func:`listen_live`): the ears listen to an input device in real time and the conductor conducts
whatever it hears; there is no simulated ensemble and no ground truth.

:func:`write_outputs` writes ``metrics.json``, ``tempo.png`` (tempo, recovery and asynchrony),
``timeline.png`` (an overview of the run, with ``timeline_0000-0015s.png``, ... the detail of each
``TIMELINE_WINDOW`` seconds), ``ensemble.wav``, ``conductor.bvh``, ``beats.csv``, ``gestures.csv``,
``report.html`` and ``feedback.jsonl``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import simpy

from agentsim.core.progress import Stages
from agentsim.errors import AgentsimError
from agentsim.music.score import DYNAMICS_DB, velocity_scale
from scenarios.conductor.config import Piece, ScenarioConfig
from scenarios.conductor.conductor import Conductor
from scenarios.conductor.hearing import Ears
from scenarios.conductor.strategies import make_strategy

#: Seconds rendered after the ensemble's last beat.
TAIL_SECONDS = 1.0
#: Seconds of each detailed timeline picture (two beats a second make one row each).
TIMELINE_WINDOW = 15.0


@dataclass
class Run:
    """Everything a finished run holds: its parts and what they recorded."""

    config: ScenarioConfig
    strategy_name: str
    seed: int
    realizer: object
    ears: Ears
    conductor: Conductor
    strategy: object
    ensemble: object = None
    live: bool = False
    wall_seconds: float = 0.0
    extra: dict = field(default_factory=dict)


def _soundfont(config: ScenarioConfig) -> str:
    from agentsim.music.rendering import DEFAULT_SOUNDFONT

    return config.audio.soundfont or DEFAULT_SOUNDFONT


def _renderer(config: ScenarioConfig, apart: bool = False):
    """The ensemble's synthesizer; ``apart``: in a process of its own where one can start (called before this
    process starts threads), as the piece is rendered while the simulation works."""
    from agentsim.music.process import renderer
    from agentsim.music.rendering import FluidSynthRenderer

    programs = {m.channel: m.program for m in config.ensemble.musicians if m.program >= 0}
    return (renderer if apart else FluidSynthRenderer)(config.audio.sample_rate, _soundfont(config),
                                                        config.audio.gain, reverb=config.audio.reverb,
                                                        programs=programs)


def sound_check(config: ScenarioConfig) -> dict[str, float]:
    """Expected RMS level (dBFS) of the ensemble at each marking of the piece.

    Renders the first two bars of the score at its tempo and at each marking's nominal velocities (as a
    recording of the piece played as marked would sound) and measures them as the conductor's ears do.
    """
    from scenarios.conductor.ensemble import part_notes

    piece = config.piece
    markings = sorted({m for _, m in piece.dynamics} | {"mf"})
    notes = part_notes(piece, [m.part for m in config.ensemble.musicians])
    bars = min(2, piece.bars)
    period = 60.0 / piece.tempo
    seg = bars * piece.beats_per_bar * period
    gap = 1.5
    renderer = _renderer(config)
    out = {}
    try:
        for k, marking in enumerate(markings):
            t0 = 0.2 + k * (seg + gap)
            scale = velocity_scale(DYNAMICS_DB[marking])
            for m in config.ensemble.musicians:
                for beat in range(bars * piece.beats_per_bar):
                    for note in notes[m.part][beat]:
                        v = int(np.clip(round(note.velocity * scale), 1, 127))
                        renderer.note(t0 + (beat + note.offset) * period, m.channel, note.key, v,
                                      note.duration * period)
        audio = renderer.render_until(0.2 + len(markings) * (seg + gap))
    finally:
        renderer.close()
    sr = config.audio.sample_rate
    for k, marking in enumerate(markings):
        a = int((0.2 + k * (seg + gap)) * sr)
        x = audio[a:a + int(seg * sr)].astype(np.float64)
        ms = float(np.mean(x * x)) if x.size else 0.0
        out[marking] = 10.0 * np.log10(ms) if ms > 0 else -120.0
    return out


class Begun:
    """What a run needs before its piece plays, under way while the caller imports and prepares
    (:func:`begin`): the ensemble's renderer, in a process of its own (:func:`_renderer`), and on a thread of
    its own the sound check, then the measure of the renderer's onset offsets. FluidSynth works without
    Python's lock; each has a synthesizer of its own, so what each renders is the same as one after the
    other (one thread, so that fewer synthesizers of this process are at work at once: libfluidsynth has
    crashed once in a thread of a run). With ``physics``, the process that will simulate the physical body
    (:func:`~agentsim.physics.process.physics_process`, None where none can be forked), which imports MuJoCo
    meanwhile: :func:`write_outputs` takes it as ``process``. Use it once, as a context manager (which waits
    for them all at its end)."""

    def __init__(self, config: ScenarioConfig, physics: bool = False) -> None:
        from concurrent.futures import ThreadPoolExecutor

        from agentsim.music.onsets import beat_onset_offset

        self.config = config
        self.renderer = _renderer(config, apart=True)  # (first: its process is forked before any thread starts)
        self.physics = None
        if physics:
            from agentsim.physics.process import physics_process

            self.physics = physics_process()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="begin")
        self.checked = self._pool.submit(sound_check, config)
        self._pool.submit(beat_onset_offset, config.audio.sample_rate, _soundfont(config))

    def __enter__(self) -> Begun:
        return self

    def __exit__(self, *exc) -> None:
        self._pool.shutdown(wait=True)
        self.renderer.close()  # (closed by the run that took it; here, that of a run that did not)


def begin(config: ScenarioConfig, physics: bool = False) -> Begun:
    """Begin what a run of ``config`` needs before its piece plays (:class:`Begun`; ``physics``: a run on the
    physical body); :func:`simulate` takes it."""
    return Begun(config, physics)


def simulate(config: ScenarioConfig, strategy_name: str | None = None, seed: int = 0,
             stages: Stages | None = None, begun: Begun | None = None) -> Run:
    """Run the closed loop once, as fast as the computer allows; returns the finished :class:`Run`.
    ``stages``: where to say on a terminal how many seconds of the piece have been simulated. ``begun``:
    what :func:`begin` began for this run's ``config`` (by default it is begun here)."""
    started = time.perf_counter()
    name = strategy_name or config.conductor.strategy
    # the sound check and the renderer's onset offsets go on while the piece plays; the conductor waits for
    # the sound check's levels when it first needs them (its first downbeat)
    with begun or begin(config) as ready:
        return _simulate(config, name, seed, started, renderer=ready.renderer,
                         reference=Later(ready.checked), stages=stages or Stages.off())


class Later(Mapping):
    """A mapping computed elsewhere (a future of a dict), waited for when first read."""

    def __init__(self, future):
        self.future = future

    def __getitem__(self, key):
        return self.future.result()[key]

    def __iter__(self):
        return iter(self.future.result())

    def __len__(self):
        return len(self.future.result())


def _simulate(config: ScenarioConfig, name: str, seed: int, started: float, renderer, reference: Later,
              stages: Stages) -> Run:
    from agentsim.core.clock import make_environment, run_until
    from agentsim.realizer import Realizer
    from scenarios.conductor.ensemble import Ensemble

    env = make_environment(False)
    ens_cfg = config.ensemble
    ears = Ears("band", sample_rate=config.audio.sample_rate, origin=ens_cfg.start_time - 0.1,
                block_seconds=config.audio.block_seconds, **config.conductor.tracker_options())
    strategy = make_strategy(name, config.piece, config.conductor, ears)
    realizer = Realizer(env=env, anticipators=[ears, *strategy.anticipators])
    ensemble = Ensemble(env, config, renderer, seed)
    realizer.feedback.listen(ensemble.see)
    conductor = Conductor(realizer, ears, strategy, config.piece, config.conductor, reference)
    realizer.feedback.listen(conductor.see)
    block = config.audio.block_seconds

    def hear():
        k = 0
        end = None
        while True:
            k += 1
            t = k * block
            if t > env.now:
                yield env.timeout(t - env.now)
            ears.push(renderer.render_until(t))
            renderer.render_ahead(ensemble.quiet_until())  # while the tracker and the realizer work
            if end is None and ensemble.finished.triggered:
                end = env.now + TAIL_SECONDS
            if end is not None and t >= end:
                return

    def finish():
        yield env.process(hear())
        yield realizer.all_ended() | env.timeout(5.0)

    # the bar's end: the score played at its tempo (an ensemble that drags takes longer: the bar grows)
    length = ens_cfg.start_time + float(config.piece.score_offsets()[-1]) + TAIL_SECONDS
    try:
        with stages("simulating", total=length) as advance:
            run_until(env, env.process(finish()), advance if stages.enabled else None)
    finally:
        renderer.close()
    run = Run(config, name, seed, realizer, ears, conductor, strategy, ensemble=ensemble)
    run.extra["reference_db"] = dict(reference)  # (a sound check that failed raises here)
    run.wall_seconds = time.perf_counter() - started
    return run


def live_piece(piece: Piece, seconds: float) -> Piece:
    """The piece as conducted live: the score's first tempo and meter for as many bars as ``seconds`` allow."""
    import dataclasses

    bars = int(seconds * piece.tempo / 60.0 / piece.beats_per_bar) + 8
    tempo_map = dataclasses.replace(piece.tempo_map, changes=())
    return dataclasses.replace(piece, bars=bars, tempo_map=tempo_map, dynamics=((1, "mf"),))


def listen_live(config: ScenarioConfig, strategy_name: str | None = None, seconds: float | None = None,
                device=None) -> Run:
    """Conduct what an input device plays, in real time, for ``seconds`` (default: the piece's length)."""
    from agentsim.core.clock import make_environment
    from agentsim.realizer import Realizer
    from anticipators.audio import DeviceSource

    started = time.perf_counter()
    name = strategy_name or config.conductor.strategy
    piece = config.piece
    if seconds is None:
        seconds = float(piece.score_offsets()[-1]) + 4.0
    if not seconds > 0:
        raise AgentsimError("--seconds must be positive")
    piece = live_piece(piece, seconds)
    source = DeviceSource(device, config.audio.sample_rate, config.audio.block_seconds)
    source.check()
    env = make_environment(True)
    ears = Ears("band", source=source, block_seconds=config.audio.block_seconds,
                **config.conductor.tracker_options())
    strategy = make_strategy(name, piece, config.conductor, ears)
    realizer = Realizer(env=env, anticipators=[ears, *strategy.anticipators])
    conductor = Conductor(realizer, ears, strategy, piece, config.conductor, None, downbeats_known=False)
    realizer.feedback.listen(conductor.see)
    env.run(until=seconds)
    ears.stop()  # close the input stream: the interrupt ends the listening process
    try:
        env.run(until=seconds + 0.05)
    except simpy.Interrupt:
        pass
    run = Run(config, name, 0, realizer, ears, conductor, strategy, live=True)
    run.config = ScenarioConfig(piece, config.ensemble, config.audio, config.conductor, config.source)
    run.wall_seconds = time.perf_counter() - started
    return run


# ---------------------------------------------------------------------------------------------- metrics
def collect_metrics(run: Run) -> dict:
    """The figures of a finished run (deterministic: no wall-clock times)."""
    from agentsim.music.onsets import beat_onset_offset
    from scenarios.conductor import metrics as M

    config = run.config
    piece = config.piece
    conductor = run.conductor
    ictus = dict(sorted(conductor.ictus.items()))
    target = piece.target_bpm()
    first = conductor.first_beat
    out: dict = {
        "strategy": run.strategy_name,
        "seed": run.seed,
        "live": run.live,
        "config": config.source,
        "piece": piece.title,
        "meter": str(piece.meter),
        "bars": piece.bars,
        "target_bpm": piece.tempo,
        "start_bpm": None if run.live else config.ensemble.start_bpm,
    }
    if run.live:
        heard = run.ears.observed
        n = max(heard) if heard else 0
        beats = np.full(n, np.nan)
        for b, t in heard.items():
            beats[b - 1] = t
        reference = beats
        onsets = beats[None, :]
        out["reference_beats"] = "heard onsets (live: no ground truth)"
    else:
        onsets = run.ensemble.onset_matrix()
        beats = run.ensemble.beat_times()
        reference = beats + beat_onset_offset(config.audio.sample_rate, _soundfont(config))
        out["reference_beats"] = "mean onset of the musicians plus the renderer's beat onset offset"
    target = np.resize(target, beats.size) if beats.size else target
    if run.live and beats.size:
        target = np.full(beats.size, piece.tempo)
    first_index = (first - 1) if first else beats.size
    summary = M.tempo_summary(beats, target, first_index)
    early = M.local_tempo(beats)
    measured_start = None
    if first and np.isfinite(early[: max(first - 1, 0)]).any():
        measured_start = round(float(np.nanmean(early[: max(first - 1, 0)])), 2)
    out.update({
        "ensemble_start_bpm_measured": measured_start,
        "beats_to_recover": summary["beats_to_recover"],
        "final_tempo_error_pct": summary["final_tempo_error_pct"],
        "ensemble_asynchrony_ms": M.asynchrony(onsets, ictus),
        "anticipator": M.anticipator_scores(run.ears.updates, reference),
        "first_conducted_beat": first,
        "join_time_s": None if conductor.join_time is None else round(conductor.join_time, 4),
        "beats_conducted": len(ictus),
        "louder_gestures": conductor.louder,
        "stopped": conductor.stopped_at is not None,
        "stopped_at_s": None if conductor.stopped_at is None else round(conductor.stopped_at, 4),
        "warnings": len(run.realizer.feedback.warnings()),
        "strategy_details": run.strategy.describe(),
        "simulated_seconds": round(float(run.realizer.env.now), 3),
    })
    if not run.live:
        out["ensemble_stopped_at_beat"] = run.ensemble.stopped_at_beat
        out["reference_levels_db"] = {k: round(v, 2) for k, v in run.extra.get("reference_db", {}).items()}
        out["bar_levels_db"] = conductor.levels
    run.extra["tempo"] = summary["tempo"]
    run.extra["beats"] = beats
    run.extra["target"] = target
    run.extra["first_index"] = first_index
    run.extra["onsets"] = onsets
    return _clean(out)


def _clean(value):
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return None if not np.isfinite(v) else round(v, 6)
    if isinstance(value, np.integer):
        return int(value)
    return value


def ensemble_source(run: Run):
    """The ensemble as the conductor heard it: its first sample where hearing began (s, the run's axis)."""
    from agentsim.media.audio import Source

    return Source(run.ears.recording(), int(run.ears.sample_rate), float(run.ears.start), label="ensemble")


def sounded_beats(run: Run) -> np.ndarray:
    """When each beat of the piece really sounded (s; index 0 is beat 1; NaN if it was not played): the
    musicians' mean onset plus the renderer's onset offset (live: the onsets heard)."""
    from agentsim.music.onsets import beat_onset_offset

    if run.live:
        heard = run.ears.observed
        beats = np.full(max(heard) if heard else 0, np.nan)
        for b, t in heard.items():
            beats[b - 1] = t
        return beats
    return run.ensemble.beat_times() + beat_onset_offset(run.config.audio.sample_rate, _soundfont(run.config))


def beat_sounded(run: Run):
    """For the gesture table: when the beat an anticipator's ``beat<n>`` peg names really sounded."""
    sounded = sounded_beats(run)

    def lookup(anticipator: str, sync: str) -> float | None:
        if not sync.startswith("beat") or not sync[4:].isdigit():
            return None
        n = int(sync[4:])
        return float(sounded[n - 1]) if 1 <= n <= sounded.size and np.isfinite(sounded[n - 1]) else None

    return lookup


def beat_rows(run: Run) -> list[dict]:
    """One row per beat of the piece: the conductor's ictus, when the beat sounded (the ensemble's mean
    onset with the renderer's offset), each musician's onset, the asynchrony (ms), what the tracker heard."""
    sounded = sounded_beats(run)
    onsets = None if run.live else run.ensemble.onset_matrix()
    names = [] if run.live else [m.name for m in run.ensemble.musicians]
    n = max([sounded.size, *run.conductor.ictus.keys(), 0])
    rows = []
    for beat in range(1, n + 1):
        ictus = run.conductor.ictus.get(beat)
        s = float(sounded[beat - 1]) if beat <= sounded.size and np.isfinite(sounded[beat - 1]) else None
        row = {"beat": beat, "ictus_s": ictus, "sounded_s": s,
               "asynchrony_ms": (s - ictus) * 1000.0 if s is not None and ictus is not None else None,
               "heard_onset_s": run.ears.observed.get(beat)}
        for i, name in enumerate(names):
            value = onsets[i, beat - 1] if beat <= onsets.shape[1] else np.nan
            row[f"onset_{name}_s"] = float(value) if np.isfinite(value) else None
        rows.append(row)
    return rows


def run_tempo_figure(run: Run, metrics: dict):
    """The tempo figure of a finished run (:func:`~scenarios.conductor.metrics.tempo_figure`):
    its tempo curves, where it recovered (or a title that says it did not), its asynchrony, and the
    conductor's "play louder" and stop gestures."""
    from scenarios.conductor.metrics import tempo_figure

    return tempo_figure(*tempo_figure_arguments(run, metrics))


def tempo_figure_arguments(run: Run, metrics: dict) -> tuple:
    """The arguments of :func:`~scenarios.conductor.metrics.tempo_figure` for a finished run (what a process
    drawing it is handed)."""
    from scenarios.conductor.metrics import recovery_phrase

    if "tempo" not in run.extra:
        collect_metrics(run)
    events = [(g["time"], "louder") for g in run.conductor.louder]
    if run.conductor.stopped_at is not None:
        events.append((run.conductor.stopped_at, "stop"))
    title = (f"{run.config.piece.title}: {run.strategy_name}, seed {run.seed} "
             f"({recovery_phrase(metrics.get('beats_to_recover'))})")
    return (run.extra["beats"], run.extra["tempo"], run.extra["target"], dict(run.conductor.ictus), title, events,
            run.extra["first_index"], run.extra["onsets"])


def physical_poses(recording, fps: float, seed: int, pushes: list, out: Path, progress=None, process=None):
    """The run's poses on the physical body and its figures, its ``physics.csv`` written in ``out``: the left arm hangs
    (a HangController) while the right hand conducts alone, and is taken back by the animation for the
    gestures with the left or both hands ("play louder", stop). ``process``: the
    :class:`~agentsim.physics.process.PhysicsProcess` that simulates the body (None: this thread does)."""
    from agentsim.animation.timeline import run_duration
    from agentsim.physics.run import hanging_left_arm, scenario_poses

    hang = hanging_left_arm(recording, run_duration(recording) + 2.0)
    return scenario_poses(recording, fps, seed, pushes, out, controllers=hang, progress=progress, process=process)


def write_outputs(run: Run, metrics: dict, out: str | Path, pictures: bool = True, plots: bool = True,
                  stages: Stages | None = None, physics: list | None = None, process=None) -> Path:
    """Write the run's files into the folder ``out`` (created if needed); ``pictures``: the timeline
    pictures too, ``plots``: any picture at all (``tempo.png`` and the timeline). ``stages``: where to say
    on a terminal which stage is under way. ``physics``: the pushes of a run on the physical body (its
    poses the physical body's, and ``physics.csv``); None: the animation's poses. ``process``: the process
    that simulates the physical body (:class:`Begun`'s ``physics``)."""
    import concurrent.futures
    import contextlib

    from agentsim.animation import evaluate_poses, write_bvh
    from agentsim.animation.pictures import start_figures, start_timelines, warm_workers
    from agentsim.media.audio import run_track
    from agentsim.media.files import write_feedback, write_text, write_wav
    from agentsim.media.report import write_report
    from agentsim.media.report.page import start_audio
    from agentsim.written import save_figure
    from agentsim.media.tables import gesture_rows, write_csv

    say = stages or Stages.off()
    if plots and pictures:  # the processes that draw the timeline pictures get ready meanwhile
        warm_workers()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from agentsim.media import AXIS, GLOSSARY

    write_text(out / "metrics.json", json.dumps({**metrics, "time_axis": AXIS, "glossary": GLOSSARY}, indent=2) + "\n")
    recording = run.realizer.recording()
    write_feedback(out / "feedback.jsonl", recording.feedback)
    # the report's sound is encoded on a thread of its own (libsndfile does not hold the interpreter) while
    # the poses and the rest are made; the pictures are drawn by worker processes meanwhile, and waited for at
    # the end
    with contextlib.ExitStack() as drawing, concurrent.futures.ThreadPoolExecutor(1) as sound:
        with say("poses/BVH"):  # first: the pictures, the longest to make, begin before the poses
            # the tempo figure, which needs no poses, is begun first, in a process of its own (this one never
            # imports matplotlib's figures)
            from scenarios.conductor.metrics import tempo_figure

            tempo = (drawing.enter_context(start_figures(
                [(out / "tempo.png", tempo_figure, tempo_figure_arguments(run, metrics))]))
                if plots and pictures else None)
            # the timeline pictures begin before the poses: the overview, which shows none, at once, and each
            # window as soon as its poses are made (they come a stretch at a time)
            timelines = (drawing.enter_context(start_timelines(
                recording, out / "timeline.png", window=TIMELINE_WINDOW, threshold=TIMELINE_WINDOW,
                title=f"conductor ({run.strategy_name})", poses_later=True)) if plots and pictures else None)
            body = None  # the physical body's figures (--physics)
            if physics is None:
                stream = evaluate_poses(recording, fps=run.config.conductor.fps, seed=run.seed,
                                        progress=timelines and timelines.follow())
            else:
                stream, body = physical_poses(recording, run.config.conductor.fps, run.seed, physics, out,
                                              progress=timelines and timelines.follow(), process=process)
            if timelines is not None:
                from agentsim.animation.timeline import PosePanel

                timelines.poses_until(PosePanel.of(stream), complete=True)
            write_bvh(out / "conductor.bvh", stream)
        with say("audio"):
            # what the conductor heard, from where it started hearing, on the run's axis (the motion's, the
            # feedback's)
            track = run_track(recording, [ensemble_source(run)])
            ogg = start_audio(out / "report.html", track, sound)
            write_wav(out / "ensemble.wav", track)
        with say("report"):
            write_csv(out / "beats.csv", beat_rows(run))
            gestures = gesture_rows(recording, beat_sounded(run))
            write_csv(out / "gestures.csv", gestures)
            write_report(out / "report.html", recording=recording, stream=stream, track=track, gestures=gestures,
                         title=f"{run.config.piece.title}: conductor ({run.strategy_name}, seed {run.seed})",
                         audio=ogg, physics=body)
            sound.shutdown(wait=True)  # the report's sound is encoded
        if not plots:
            return out
        with say("pictures"):
            if tempo is not None:
                tempo.result()
            else:  # (no timeline pictures: no process is started for this one)
                save_figure(run_tempo_figure(run, metrics), out / "tempo.png")
            if timelines is not None:
                timelines.result()
    return out
