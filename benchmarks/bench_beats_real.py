"""Benchmark of beat trackers on real music with human beat annotations; prints JSON.

Two development sets, read from ``../shared`` beside the checkout (``--shared`` elsewhere); they are for
research use and are never copied into the project. A set that is not there is reported as missing.

- ``real``: ``beats-real-dev/`` (50 GTZAN excerpts and a Ballroom waltz, ``<id>.flac`` with ``<id>.beats``).
- ``asap``: ``asap/dev/`` (real pianists' MIDI performances with their beats), rendered as its README
  says: ``fluidsynth -ni -r 22050`` with the General MIDI soundfont
  (:func:`agentsim.music.rendering.render_midi_file`, FluidSynth's default gain), mixed to mono, cut to
  30 s, peak-normalised to 0.9; the annotated beats within those 30 s. Renders are cached outside the
  project (``~/.cache/agentsim/asap-renders``, or ``$AGENTSIM_CACHE/asap-renders``). The most expressive
  third (largest coefficient of variation of the annotated inter-beat intervals) is reported apart.

Protocol (``beats-real-dev/README.md``): each tracker hears the clip causally, block by block (512
samples); its committed sequence at lead L (every beat b it predicted at an update at u with
``u <= b - L < u_next``, :func:`anticipators.beats.evaluation.committed_beats`) is trimmed at 5 s and
scored with ``mir_eval.beat``: F-measure (70 ms), CMLt, AMLt, P-score; a clip without a committed beat
scores 0 and counts as silent. L = 0.2 s is the figure that counts; F at L = 0 is reported beside it.
``time_to_4`` is when four consecutive annotated beats were first each hit by a committed beat (from the
start, untrimmed; a clip where that never happens counts as infinitely late in the median; ``never_4``
counts them); ``time_to_4_hits`` is when the fourth annotated beat was hit, consecutive or not. The
real-time factor is CPU time over audio time (reading and rendering not counted).

Trackers: ``causal`` (the default tracker), ``causal-net`` (its joint filter observing the learned
activation), ``causal-comb`` (the tracker before the joint filter), ``baseline`` (the inter-onset-interval baseline), ``aubio``
(aubio's online ``tempo``, when aubio is installed: the ``bench`` extra) and ``librosa_offline``
(librosa's ``beat_track``, which sees the whole clip: one update at 0 s). Paired bootstrap intervals
(``scipy.stats.bootstrap``, 95 %, BCa, 10,000 resamples, a seeded generator) give each tracker's mean
per-clip difference to aubio and to librosa in F and AMLt.

Usage::

    PYTHONPATH=. python benchmarks/bench_beats_real.py [--sets real,asap] [--trackers causal,aubio,...]
        [--lookahead 0.2] [--per-clip] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from anticipators.beats.baselines import aubio_available  # noqa: E402
from anticipators.beats.evaluation import committed_beats, score_beats, time_to_correct, track_file  # noqa: E402

TRACKERS = ("causal", "causal-net", "causal-comb", "baseline", "aubio", "librosa_offline")
SKIP = 5.0
WINDOW = 0.07
ASAP_SECONDS = 30.0
ASAP_RATE = 22050
BOOTSTRAP_SEED = 20240
BOOTSTRAP_RESAMPLES = 10000

#: The issue's targets (development sets; the held-out sets are checked the same way).
TARGETS = {
    "real": {"f_measure": 0.80, "amlt": 0.85, "silent": 0, "median_time_to_4": 2.5},
    "asap": {"f_measure": 0.60, "amlt": 0.55, "expressive_third_f_measure": 0.50},
    "real_time_factor": 0.005,
}


def shared_dir(given: str | None) -> Path:
    return Path(given) if given else (ROOT.parent / "shared")


def cache_dir() -> Path:
    base = os.environ.get("AGENTSIM_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "agentsim")
    path = Path(base) / "asap-renders"
    path.mkdir(parents=True, exist_ok=True)
    return path


def load_real(folder: Path) -> list[dict]:
    import soundfile as sf

    clips = []
    for audio_path in sorted(folder.glob("*.flac")):
        beats_path = audio_path.with_suffix(".beats")
        if not beats_path.is_file():
            continue
        audio, sr = sf.read(audio_path, dtype="float32", always_2d=True)
        clips.append({"id": audio_path.stem, "audio": audio.mean(axis=1), "sample_rate": int(sr),
                      "beats": np.loadtxt(beats_path, ndmin=1)})
    return clips


def render_asap(midi: Path, cache: Path) -> tuple[np.ndarray, int]:
    """The protocol's render of the first 30 s of a performance (cached)."""
    import soundfile as sf

    from agentsim.music.rendering import DEFAULT_SOUNDFONT, render_midi_file

    cached = cache / f"{midi.stem}.flac"
    if cached.is_file():
        audio, sr = sf.read(cached, dtype="float32")
        return audio, int(sr)
    audio, sr = render_midi_file(midi, sample_rate=ASAP_RATE, soundfont=DEFAULT_SOUNDFONT, gain=0.2)
    audio = audio[: int(ASAP_SECONDS * sr)]
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if peak > 0:
        audio = (audio * (0.9 / peak)).astype(np.float32)
    tmp = cached.with_suffix(".tmp.flac")
    sf.write(tmp, audio, sr, subtype="PCM_24")
    os.replace(tmp, cached)
    audio, sr = sf.read(cached, dtype="float32")  # as every later run reads it
    return audio, int(sr)


def load_asap(folder: Path, jobs: int) -> list[dict]:
    cache = cache_dir()
    midis = [m for m in sorted(folder.glob("*.mid")) if m.with_suffix(".beats").is_file()]
    with ThreadPoolExecutor(max(jobs, 1)) as pool:  # fluidsynth runs as its own process
        renders = list(pool.map(lambda m: render_asap(m, cache), midis))
    clips = []
    for midi, (audio, sr) in zip(midis, renders):
        beats = np.loadtxt(midi.with_suffix(".beats"), ndmin=1)
        beats = beats[beats <= audio.size / sr]
        ibi = np.diff(beats)
        cv = float(np.std(ibi) / np.mean(ibi)) if ibi.size > 1 else 0.0
        clips.append({"id": midi.stem, "audio": audio, "sample_rate": sr, "beats": beats, "ibi_cv": cv})
    return clips


#: Keyword arguments for the trackers whose names start with ``causal`` (``--options``).
CAUSAL_OPTIONS: dict = {}


def run_clip(clip: dict, tracker: str, lookahead: float) -> dict:
    options = CAUSAL_OPTIONS if tracker.startswith("causal") else None
    run = track_file(clip["audio"], tracker, 512, sample_rate=clip["sample_rate"], tracker_options=options)
    end = run["audio_seconds"]
    committed = committed_beats(run["updates"], lookahead, end)
    res = score_beats(clip["beats"], committed, SKIP, WINDOW)
    zero = score_beats(clip["beats"], committed_beats(run["updates"], 0.0, end), SKIP, WINDOW, continuity=False)
    return {
        "f_measure": res["f_measure"], "cmlt": res["cmlt"], "amlt": res["amlt"], "p_score": res["p_score"],
        "f_measure_lead_0": zero["f_measure"], "silent": res["silent"], "mae_ms": res["mae_ms"],
        "time_to_4": time_to_correct(clip["beats"], committed, 4, WINDOW),
        "time_to_4_hits": time_to_correct(clip["beats"], committed, 4, WINDOW, consecutive=False),
        "n_committed": int(committed.size), "n_reference": res["n_reference"],
        "audio_seconds": run["audio_seconds"], "cpu_seconds": run["cpu_seconds"],
        "real_time_factor": run["cpu_seconds"] / max(run["audio_seconds"], 1e-9),
    }


def pooled(rows: list[dict]) -> dict:
    if not rows:
        return {}
    out = {k: round(float(np.mean([r[k] for r in rows])), 4)
           for k in ("f_measure", "cmlt", "amlt", "p_score", "f_measure_lead_0")}
    t4 = [r["time_to_4"] if r["time_to_4"] is not None else math.inf for r in rows]
    median = float(np.median(t4))
    hits = float(np.median([r["time_to_4_hits"] if r["time_to_4_hits"] is not None else math.inf for r in rows]))
    out.update(
        clips=len(rows),
        silent=int(sum(r["silent"] for r in rows)),
        median_time_to_4=round(median, 3) if math.isfinite(median) else None,
        never_4=int(sum(not math.isfinite(t) for t in t4)),
        median_time_to_4_hits=round(hits, 3) if math.isfinite(hits) else None,
        real_time_factor=round(sum(r["cpu_seconds"] for r in rows) / sum(r["audio_seconds"] for r in rows), 5),
    )
    return out


def paired_interval(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of ``a - b`` with a paired BCa bootstrap 95 % interval (seeded)."""
    from scipy.stats import bootstrap

    d = np.asarray(a, float) - np.asarray(b, float)
    mean = float(d.mean())
    if d.size < 3 or np.all(d == d[0]):
        return {"mean": round(mean, 4), "low": round(mean, 4), "high": round(mean, 4)}
    res = bootstrap((np.asarray(a, float), np.asarray(b, float)), lambda x, y, axis=-1: np.mean(x - y, axis=axis),
                    paired=True, vectorized=True, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=0.95,
                    method="BCa", random_state=np.random.default_rng(BOOTSTRAP_SEED))
    ci = res.confidence_interval
    return {"mean": round(mean, 4), "low": round(float(ci.low), 4), "high": round(float(ci.high), 4)}


def compare(per_clip: dict[str, list[dict]]) -> dict:
    out = {}
    for ref in ("aubio", "librosa_offline"):
        if ref not in per_clip:
            continue
        for name, rows in per_clip.items():
            if name == ref:
                continue
            out[f"{name}_minus_{ref}"] = {
                key: paired_interval(np.array([r[key] for r in rows]), np.array([r[key] for r in per_clip[ref]]))
                for key in ("f_measure", "amlt")}
    return out


def run_set(name: str, clips: list[dict], trackers: list[str], lookahead: float, per_clip_out: bool) -> dict:
    per_clip: dict[str, list[dict]] = {t: [] for t in trackers}
    for clip in clips:
        line = []
        for tracker in trackers:
            res = run_clip(clip, tracker, lookahead)
            per_clip[tracker].append(res)
            line.append(f"{tracker} F={res['f_measure']:.2f}")
        print(f"{name} {clip['id']}: " + ", ".join(line), file=sys.stderr)
    report = {"clips": len(clips), "pooled": {t: pooled(rows) for t, rows in per_clip.items()},
              "paired_bootstrap": compare(per_clip)}
    if name == "asap" and clips:
        order = np.argsort([-c["ibi_cv"] for c in clips])
        third = sorted(int(i) for i in order[: math.ceil(len(clips) / 3)])
        report["expressive_third"] = {
            "clips": [clips[i]["id"] for i in third],
            "min_ibi_cv": round(min(clips[i]["ibi_cv"] for i in third), 4),
            "pooled": {t: pooled([rows[i] for i in third]) for t, rows in per_clip.items()},
        }
    if per_clip_out:
        report["per_clip"] = {
            clip["id"]: {t: {k: (round(v, 4) if isinstance(v, float) else v) for k, v in per_clip[t][i].items()}
                         for t in trackers} for i, clip in enumerate(clips)}
    return report


def check_targets(sets: dict) -> dict:
    out = {}
    causal = {name: rep["pooled"].get("causal", {}) for name, rep in sets.items() if "pooled" in rep}
    if causal.get("real"):
        c, t = causal["real"], TARGETS["real"]
        out["real"] = {
            "f_measure": {"target": t["f_measure"], "value": c["f_measure"], "holds": c["f_measure"] >= t["f_measure"]},
            "amlt": {"target": t["amlt"], "value": c["amlt"], "holds": c["amlt"] >= t["amlt"]},
            "silent": {"target": t["silent"], "value": c["silent"], "holds": c["silent"] <= t["silent"]},
            "median_time_to_4": {"target": t["median_time_to_4"], "value": c["median_time_to_4"],
                                 "holds": c["median_time_to_4"] is not None
                                 and c["median_time_to_4"] <= t["median_time_to_4"]},
        }
    if causal.get("asap"):
        c, t = causal["asap"], TARGETS["asap"]
        e = sets["asap"]["expressive_third"]["pooled"]["causal"]
        out["asap"] = {
            "f_measure": {"target": t["f_measure"], "value": c["f_measure"], "holds": c["f_measure"] >= t["f_measure"]},
            "amlt": {"target": t["amlt"], "value": c["amlt"], "holds": c["amlt"] >= t["amlt"]},
            "expressive_third_f_measure": {"target": t["expressive_third_f_measure"], "value": e["f_measure"],
                                           "holds": e["f_measure"] >= t["expressive_third_f_measure"]},
        }
    if any(causal.values()):
        rtf = max(c["real_time_factor"] for c in causal.values() if c)
        out["real_time_factor"] = {"target": TARGETS["real_time_factor"], "value": rtf,
                                   "holds": rtf <= TARGETS["real_time_factor"]}
    out["all_hold"] = bool(out) and all(v["holds"] for group in out.values() if isinstance(group, dict)
                                        for v in (group.values() if "holds" not in group else [group]))
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", help="folder holding beats-real-dev/ and asap/ (default: ../shared beside the checkout)")
    ap.add_argument("--sets", default="real,asap", help="real, asap or both (default)")
    ap.add_argument("--trackers", default=",".join(TRACKERS), help="trackers to run (default: all available)")
    ap.add_argument("--lookahead", type=float, default=0.2, help="lead of the committed sequence, s (0.2)")
    ap.add_argument("--per-clip", action="store_true", help="include every clip's figures")
    ap.add_argument("--jobs", type=int, default=2, help="FluidSynth renders at a time (2)")
    ap.add_argument("--options", default="{}", help="JSON keyword arguments for the causal tracker (for trials)")
    ap.add_argument("--quick", type=int, default=0, metavar="N",
                    help="every N-th clip only, for iteration (0: every clip; report full-set figures)")
    args = ap.parse_args(argv)
    CAUSAL_OPTIONS.clear()
    CAUSAL_OPTIONS.update(json.loads(args.options))
    shared = shared_dir(args.shared)
    trackers = [t for t in args.trackers.split(",") if t]
    skipped = []
    if "aubio" in trackers and not aubio_available():
        trackers.remove("aubio")
        skipped.append("aubio (not installed: pip install 'agentsim[bench]')")
        print("aubio is not installed; its tracker is left out", file=sys.stderr)
    from anticipators.beats.baselines import librosa_offline_beats

    librosa_offline_beats(np.zeros(22050 * 5, np.float32), 22050)  # compile librosa's beat tracker first
    load = [os.getloadavg()[0]]
    sets: dict[str, dict] = {}
    for name in [s for s in args.sets.split(",") if s]:
        folder = shared / ("beats-real-dev" if name == "real" else "asap/dev")
        if not folder.is_dir():
            print(f"{folder} is not there: the {name} set is left out", file=sys.stderr)
            sets[name] = {"available": False, "looked_in": str(folder)}
            continue
        t0 = time.perf_counter()
        clips = load_real(folder) if name == "real" else load_asap(folder, args.jobs)
        if args.quick > 1:
            clips = clips[:: args.quick]
        loaded = time.perf_counter() - t0
        sets[name] = {"available": True, "folder": str(folder), "load_seconds": round(loaded, 1),
                      **run_set(name, clips, trackers, args.lookahead, args.per_clip)}
    load.append(os.getloadavg()[0])
    result = {
        "benchmark": "beats_real",
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "load_average_1min": [round(x, 2) for x in load],
        "causal_options": CAUSAL_OPTIONS, "quick": args.quick,
        "lookahead_s": args.lookahead, "skip_s": SKIP, "f_measure_window_s": WINDOW, "block_size": 512,
        "trackers": trackers, "trackers_left_out": skipped,
        "sets": sets,
        "targets": TARGETS,
        "targets_hold": check_targets(sets),
    }
    print(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
