"""The files of a trainer run: its figures, poses, narration, the user's signal and the report.

``metrics.json``; ``trainer.bvh`` (the trainer's motion); ``narration.wav`` (the counting and the remarks);
``motion.csv`` (the user's phone: time and ax, ay, az); ``repetitions.csv`` (per repetition of the user:
their key point, the trainer's nearest, the count word's stressed syllable, and the differences);
``signal.png`` (the user's signal with their key points beside the trainer's and the counts);
``gestures.csv``, ``feedback.jsonl`` and ``report.html`` with its folder ``report_files/``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scenarios.trainer.scenario import Run, count_times, user_keys

#: Frames a second of the BVH (and of the physical body's simulation).
FPS = 30.0


def repetition_rows(run: Run) -> list[dict]:
    """One row per repetition of the user: key points, count, differences (ms)."""
    keys = user_keys(run)
    trainer = np.array(sorted(run.trainer.key_points.values()))
    counts = count_times(run)
    rows = []
    for n, key in enumerate(keys, 1):
        near = float(trainer[np.argmin(np.abs(trainer - key))]) if trainer.size else None
        count = counts.get(n)
        rows.append({"repetition": n, "user_key_s": float(key), "trainer_key_s": near,
                     "asynchrony_ms": None if near is None else (near - key) * 1000.0,
                     "count_stress_s": count, "count_error_ms": None if count is None else (count - key) * 1000.0,
                     "found_s": run.reps.tracker.repetitions[n - 1] if n <= len(run.reps.tracker.repetitions)
                     else None})
    return rows


def upward(run: Run) -> np.ndarray:
    """The user's acceleration along the recording's mean gravity, less gravity (m/s²; a coordinate as it is)."""
    times, samples = run.signal
    if samples.ndim == 2 and samples.shape[1] == 3:
        g = samples.mean(axis=0)
        norm = float(np.linalg.norm(g)) or 1.0
        return samples @ g / norm - norm
    return samples.reshape(len(times), -1)[:, 0]


def signal_figure(run: Run, metrics: dict):
    """The user's signal and key points beside the trainer's key points and the count words."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    times, _ = run.signal
    fig = Figure(figsize=(12, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(times, upward(run), color="0.55", lw=0.8, label="user's phone (along gravity)")
    keys = user_keys(run)
    ax.vlines(keys, 0, 1, transform=ax.get_xaxis_transform(), color="tab:blue", lw=1.6, label="user's key points")
    trainer = sorted(run.trainer.key_points.values())
    ax.vlines(trainer, 0, 0.75, transform=ax.get_xaxis_transform(), color="tab:orange", lw=1.6,
              label="trainer's key points")
    counts = count_times(run)
    ax.plot(list(counts.values()), [0.9] * len(counts), "v", color="tab:green", transform=ax.get_xaxis_transform(),
            label="count words (stressed syllable)")
    asy = metrics.get("asynchrony_ms") or {}
    ax.set_title(f"{run.exercise}, {run.strategy}, seed {run.seed}: asynchrony {asy.get('mean')} ± {asy.get('sd')} ms, "
                 f"count error p95 {(metrics.get('count_error_ms') or {}).get('p95')} ms", fontsize=10)
    ax.set_xlabel("time (s, the run's axis)")
    ax.set_ylabel("m/s²")
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    fig.tight_layout()
    return fig


def write_outputs(run: Run, metrics: dict, out: str | Path, pictures: bool = True, physics: bool = False) -> Path:
    """Write the run's files into ``out`` (created if needed); ``pictures``: ``signal.png`` too; ``physics``: the
    trainer's motion played through the physical body (mixed dynamics), ``physics.csv`` written and its figures
    added to ``metrics`` (``physics``: fallen, when, and the share of frames whose centre of mass is over the
    support) before ``metrics.json`` is."""
    import concurrent.futures

    from agentsim.animation import evaluate_poses, write_bvh
    from agentsim.media import AXIS, GLOSSARY
    from agentsim.media.audio import run_track
    from agentsim.media.files import write_feedback, write_text, write_wav
    from agentsim.media.report import write_report
    from agentsim.media.report.page import start_audio
    from agentsim.media.tables import gesture_rows, write_csv
    from agentsim.written import save_figure

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    recording = run.realizer.recording()
    manager = None
    if physics:
        from agentsim.physics.run import PhysicalManager, run_controllers

        manager = PhysicalManager(run_controllers(recording), [], fps=FPS, seed=run.seed, lexicon=recording.lexicon)
        stream = evaluate_poses(recording, fps=FPS, seed=run.seed, manager=manager)
        result = manager.result
        rows = np.array([row[8] for row in result.rows], dtype=float)
        metrics["physics"] = {"fallen": result.fell_at is not None, "fell_at": result.fell_at,
                              "com_inside": round(float(rows.mean()), 4) if rows.size else None,
                              "frames": int(rows.size)}
        from agentsim.physics.run import write_physics_csv

        write_physics_csv(out / "physics.csv", result)
    else:
        stream = None
    write_text(out / "metrics.json", json.dumps({**metrics, "time_axis": AXIS, "glossary": GLOSSARY}, indent=2) + "\n")
    write_feedback(out / "feedback.jsonl", recording.feedback)
    times, samples = run.signal
    columns = ["ax", "ay", "az"] if samples.ndim == 2 and samples.shape[1] == 3 else ["value"]
    write_csv(out / "motion.csv", [dict(zip(["time", *columns], row)) for row in
                                   np.column_stack([times, samples.reshape(len(times), -1)]).tolist()])
    rows = repetition_rows(run)
    write_csv(out / "repetitions.csv", rows)
    keys = user_keys(run)

    def lookup(anticipator: str, sync: str) -> float | None:  # the user's key point a peg stands for
        number = sync[3:] if sync.startswith(("rep", "key")) else ""
        if anticipator == "trainer" and run.strategy == "fixed" or not number.isdigit():
            return None
        n = int(number)
        return float(keys[n - 1]) if 1 <= n <= len(keys) else None

    with concurrent.futures.ThreadPoolExecutor(1) as sound:
        track = run_track(recording)
        ogg = start_audio(out / "report.html", track, sound)
        write_wav(out / "narration.wav", track)
        if stream is None:
            stream = evaluate_poses(recording, fps=FPS, seed=run.seed)
        write_bvh(out / "trainer.bvh", stream)
        gestures = gesture_rows(recording, lookup)
        write_csv(out / "gestures.csv", gestures)
        asy = metrics["asynchrony_ms"]
        notes = [f"{metrics['user']} user, {metrics['user_repetitions']} repetitions, target "
                 f"{metrics['target_tempo']:g} a minute; asynchrony {asy['mean']} ± {asy['sd']} ms, count error "
                 f"p95 {metrics['count_error_ms']['p95']} ms, missed counts {metrics['missed_counts']}",
                 "signal.png: the user's signal and key points beside the trainer's; repetitions.csv: each "
                 "repetition's key points and count"]
        write_report(out / "report.html", recording=recording, stream=stream, track=track, gestures=gestures,
                     title=f"trainer: {run.exercise} ({run.strategy}, seed {run.seed})", notes=notes, audio=ogg)
        sound.shutdown(wait=True)
    if pictures:
        save_figure(signal_figure(run, metrics), out / "signal.png", dpi=110)
    return out
