"""Train the causal beat-activation network (anticipators/beats/network.py) and write its weights.

Training material, and nothing else (the development and held-out recordings are for measuring only):

- the project's ensemble renders (:func:`agentsim.music.ensemble.render_ensemble_full`): tempi 62-190 BPM,
  4/4, 3/4 and 2/4, tempo ramps, sudden steps and rubato, drums, bass, piano and strings in random
  combinations, hi-hats on eighths or beats; their reference beats are exact;
- ASAP's ``train`` performances (``../shared/asap/train``, real pianists' MIDI with beat annotations, CC
  BY-NC-SA 4.0), 40 s of each (from the start, or from a random point), rendered by FluidSynth with the
  General MIDI soundfont as acoustic piano or another program (electric piano, harpsichord, vibraphone,
  guitars, harp, marimba, strings, flute). Annotated tempi above 200 BPM are halved (the beats on the
  downbeats' parity), below 50 BPM doubled, to the tracker's range.

The inputs are the rectified log-mel flux per band (:func:`anticipators.beats.network.band_flux`, exactly
as the tracker computes it while hearing); the target is 1 at the frame of each beat and 0.5 at its two
neighbours; the loss is binary cross-entropy. Training is numpy (Adam, hand-written gradients, a seeded
Generator for the data, the crops and the initial weights), so the same seed gives the same weights.
Renders and their features are cached outside the project (``~/.cache/agentsim/beat-train`` or
``$AGENTSIM_CACHE/beat-train``).

Usage::

    PYTHONPATH=. python scripts/train_beat_activation.py [--seed 24] [--out anticipators/beats/activation_net.npz]
        [--asap 220] [--ensemble 140] [--steps 3000]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from anticipators.beats.network import WEIGHTS_PATH, BeatActivationNetwork, band_flux  # noqa: E402

SR = 22050
HOP = int(round(0.01 * SR))
N_FFT = int(2 ** round(math.log2(0.03 * SR)))
CLIP_SECONDS = 40.0
PROGRAMS = (4, 6, 11, 24, 25, 26, 46, 12, 2, 48, 73)
DILATIONS = (1, 2, 4, 8, 16, 32, 64)
CHANNELS = 20
CROP = 800
WARMUP = 130  # frames at the start of a crop not scored (their history is not silence)


def cache_dir() -> Path:
    base = os.environ.get("AGENTSIM_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "agentsim")
    path = Path(base) / "beat-train"
    path.mkdir(parents=True, exist_ok=True)
    return path


def frame_of(t: np.ndarray) -> np.ndarray:
    return np.rint((np.asarray(t) * SR - N_FFT / 2) / HOP).astype(int)


def targets(beats: np.ndarray, n: int) -> np.ndarray:
    y = np.zeros(n, np.float32)
    f = frame_of(beats)
    for off, v in ((-1, 0.5), (1, 0.5), (0, 1.0)):
        g = f + off
        g = g[(g >= 0) & (g < n)]
        y[g] = np.maximum(y[g], v)
    return y


def to_range(beats: np.ndarray, downbeats: np.ndarray) -> np.ndarray:
    """Annotated beats at the tracker's metrical level: tempi above 200 BPM halved, below 50 doubled."""
    if beats.size < 3:
        return beats
    ibi = float(np.median(np.diff(beats)))
    if ibi < 0.3:
        near = [np.sum(np.min(np.abs(beats[p::2][:, None] - downbeats[None, :]), axis=0) < 0.02) if downbeats.size
                else 0 for p in (0, 1)]
        return beats[int(np.argmax(near))::2]
    if ibi > 1.2:
        mid = 0.5 * (beats[1:] + beats[:-1])
        return np.sort(np.concatenate([beats, mid]))
    return beats


def cut_midi(src: Path, dst: str, start: float, seconds: float, program: int) -> None:
    """The stretch ``start .. start + seconds`` of a MIDI file, played by one General MIDI program."""
    import mido

    mid = mido.MidiFile(src)
    out = mido.MidiFile(ticks_per_beat=1000)
    track = mido.MidiTrack()
    out.tracks.append(track)
    track.append(mido.MetaMessage("set_tempo", tempo=500000, time=0))  # 1 tick = 0.5 ms
    channels = sorted({m.channel for m in mid if hasattr(m, "channel")} - {9}) or [0]
    for ch in channels:
        track.append(mido.Message("program_change", channel=ch, program=program, time=0))
    t, last = 0.0, 0
    pedal: dict = {}
    for msg in mid:
        t += msg.time
        if t >= start + seconds:
            break
        if msg.is_meta or msg.type == "program_change":
            continue
        if t < start:
            if msg.type == "control_change":
                pedal[(msg.channel, msg.control)] = msg.value  # the pedals as they stand at the cut
            continue
        if pedal:
            for (ch, ctl), v in pedal.items():
                track.append(mido.Message("control_change", channel=ch, control=ctl, value=v, time=0))
            pedal = {}
        tick = int(round((t - start) * 2000))
        track.append(msg.copy(time=tick - last))
        last = tick
    # every note ends with the stretch (a sustained program would otherwise sound on for ever)
    end = int(round(seconds * 2000))
    for ch in channels:
        for ctl in (64, 123, 120):
            track.append(mido.Message("control_change", channel=ch, control=ctl, value=0, time=max(end - last, 0)))
            last = max(end, last)
    out.save(dst)


def asap_clip(midi: Path, start: float, program: int) -> dict:
    from agentsim.music.rendering import DEFAULT_SOUNDFONT, render_midi_file

    cached = cache_dir() / f"asap_{midi.stem}_{int(start * 10)}_{program}.npz"
    if not cached.is_file():
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "cut.mid")
            cut_midi(midi, path, start, CLIP_SECONDS, program)
            audio, sr = render_midi_file(path, sample_rate=SR, soundfont=DEFAULT_SOUNDFONT, gain=0.2)
        audio = audio[: int(CLIP_SECONDS * sr)]
        peak = float(np.max(np.abs(audio), initial=0.0))
        if peak > 0:
            audio = (audio * (0.9 / peak)).astype(np.float32)
        np.savez(cached, x=band_flux(audio, sr).astype(np.float16))
    x = np.load(cached)["x"].astype(np.float32)
    beats = np.loadtxt(midi.with_suffix(".beats"), ndmin=1)
    downs = np.loadtxt(midi.with_suffix(".downbeats"), ndmin=1) if midi.with_suffix(".downbeats").is_file() else np.zeros(0)
    beats = to_range(beats, downs) - start
    beats = beats[(beats >= 0) & (beats < CLIP_SECONDS)]
    return {"name": f"asap:{midi.stem}", "x": x, "y": targets(beats, x.shape[0])}


def ensemble_clip(i: int, rng: np.random.Generator) -> dict:
    from agentsim.music.ensemble import render_ensemble_full

    bpm = float(np.exp(rng.uniform(math.log(62), math.log(190))))
    meter = str(rng.choice(["4/4", "4/4", "3/4", "2/4"]))
    per_bar = int(meter[0])
    bars = max(int(math.ceil(32.0 * bpm / 60.0 / per_bar)), 4)
    ramp = (int(rng.integers(1, 4)), int(rng.integers(4, max(bars - 4, 5))), float(rng.uniform(-0.15, 0.15))) \
        if rng.random() < 0.5 else None
    steps = [(int(rng.integers(4, max(bars - 2, 5))), float(rng.uniform(0.8, 1.25)))] if rng.random() < 0.2 else []
    rubato = float(rng.uniform(0.0, 0.05))
    parts = [p for p in ("drums", "bass", "piano", "strings") if rng.random() < 0.6] or ["piano"]
    hihat = str(rng.choice(["eighths", "beats"]))
    seed = int(rng.integers(1 << 30))
    lead_in = round(float(rng.uniform(0.1, 1.0)), 3)
    # every draw is made whether or not the render is cached, so that the same seed gives the same data
    key = f"ens_{i}_{seed}_{lead_in}"
    cached = cache_dir() / f"{key}.npz"
    if not cached.is_file():
        r = render_ensemble_full(bpm, meter, bars, ramp=ramp, steps=steps, rubato=rubato, seed=seed, sample_rate=SR,
                                 parts=parts, hihat=hihat, lead_in=lead_in)
        np.savez(cached, x=band_flux(r.audio, SR).astype(np.float16), beats=r.beat_times)
    data = np.load(cached)
    x = data["x"].astype(np.float32)
    return {"name": key, "x": x, "y": targets(data["beats"], x.shape[0])}


def init_weights(rng: np.random.Generator, n_in: int) -> dict:
    c = CHANNELS
    w = {"w0": rng.normal(0, 1 / math.sqrt(3 * n_in), (3, n_in, c)), "b0": np.zeros(c),
         "dilations": np.array(DILATIONS), "wo": rng.normal(0, 1 / math.sqrt(c), c), "bo": np.array(-3.0)}
    for i in range(len(DILATIONS)):
        w[f"w{i + 1}"] = rng.normal(0, 0.5 / math.sqrt(2 * c), (2, c, c))
        w[f"b{i + 1}"] = np.zeros(c)
    return {k: (v.astype(np.float32) if k != "dilations" else v) for k, v in w.items()}


def forward_backward(w: dict, x: np.ndarray, y: np.ndarray, m: np.ndarray, pos_weight: float):
    """Loss and gradients of a batch ``x`` ``(B, T, n_in)`` (already scaled), targets ``y`` and mask ``m`` ``(B, T)``."""
    b, t, _ = x.shape
    k0 = w["w0"].shape[0]
    ext0 = np.concatenate([np.zeros((b, k0 - 1, x.shape[2]), np.float32), x], axis=1)
    z = sum(ext0[:, k : k + t] @ w["w0"][k] for k in range(k0)) + w["b0"]
    h = np.tanh(z)
    hs, us = [h], []
    for i, d in enumerate(DILATIONS):
        wi = w[f"w{i + 1}"]
        sh = np.concatenate([np.zeros((b, d, h.shape[2]), np.float32), h[:, :-d]], axis=1)
        u = np.tanh(sh @ wi[0] + h @ wi[1] + w[f"b{i + 1}"])
        h = h + u
        hs.append(h)
        us.append(u)
    logit = h @ w["wo"] + w["bo"]
    p = 0.5 * (1 + np.tanh(0.5 * logit))
    weight = m * (1.0 + (pos_weight - 1.0) * (y > 0))
    norm = max(float(weight.sum()), 1.0)
    eps = 1e-6
    loss = -float(np.sum(weight * (y * np.log(p + eps) + (1 - y) * np.log(1 - p + eps)))) / norm
    dlogit = (weight * (p - y) / norm).astype(np.float32)
    g = {"wo": np.einsum("btc,bt->c", h, dlogit), "bo": np.array(dlogit.sum(), np.float32)}
    dh = dlogit[:, :, None] * w["wo"]
    for i in reversed(range(len(DILATIONS))):
        d = DILATIONS[i]
        wi = w[f"w{i + 1}"]
        hin, u = hs[i], us[i]
        dz = dh * (1 - u * u)
        sh = np.concatenate([np.zeros((b, d, hin.shape[2]), np.float32), hin[:, :-d]], axis=1)
        c = hin.shape[2]
        dz2 = dz.reshape(-1, c)
        g[f"w{i + 1}"] = np.stack([sh.reshape(-1, c).T @ dz2, hin.reshape(-1, c).T @ dz2])
        g[f"b{i + 1}"] = dz2.sum(axis=0)
        dsh = dz @ wi[0].T
        dh = dh + dz @ wi[1].T
        dh[:, :-d] += dsh[:, d:]
    dz0 = dh * (1 - hs[0] * hs[0])
    c = dz0.shape[2]
    dz02 = dz0.reshape(-1, c)
    g["w0"] = np.stack([ext0[:, k : k + t].reshape(-1, ext0.shape[2]).T @ dz02 for k in range(k0)])
    g["b0"] = dz02.sum(axis=0)
    return loss, g


def batches(clips: list[dict], rng: np.random.Generator, size: int):
    while True:
        xs, ys, ms = [], [], []
        for j in rng.integers(len(clips), size=size):
            c = clips[int(j)]
            n = c["x"].shape[0]
            s = 0 if rng.random() < 0.25 or n <= CROP else int(rng.integers(0, n - CROP))
            x, y = c["x"][s : s + CROP], c["y"][s : s + CROP]
            m = np.ones(x.shape[0], np.float32)
            if s > 0:
                m[:WARMUP] = 0
            pad = CROP - x.shape[0]
            if pad > 0:
                x = np.pad(x, ((0, pad), (0, 0)))
                y, m = np.pad(y, (0, pad)), np.pad(m, (0, pad))
            xs.append(x)
            ys.append(y)
            ms.append(m)
        yield np.stack(xs), np.stack(ys), np.stack(ms)


def evaluate(w: dict, clips: list[dict], scale: np.ndarray, pos_weight: float) -> float:
    losses = []
    for c in clips:
        x = (c["x"] * scale)[None]
        loss, _ = forward_backward(w, x, c["y"][None], np.ones((1, x.shape[1]), np.float32), pos_weight)
        losses.append(loss)
    return float(np.mean(losses))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=24)
    ap.add_argument("--out", default=str(WEIGHTS_PATH))
    ap.add_argument("--shared", default=str(ROOT.parent / "shared"), help="folder holding asap/train")
    ap.add_argument("--asap", type=int, default=220, help="ASAP train performances rendered")
    ap.add_argument("--ensemble", type=int, default=140, help="ensemble renders")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--batch", type=int, default=12)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--pos-weight", type=float, default=2.0)
    ap.add_argument("--jobs", type=int, default=2, help="FluidSynth renders at a time")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    t0 = time.process_time()
    folder = Path(args.shared) / "asap" / "train"
    midis = sorted(m for m in folder.glob("*.mid") if m.with_suffix(".beats").is_file())
    if not midis:
        sys.exit(f"no ASAP train performances in {folder}")
    chosen = [midis[int(i)] for i in np.sort(rng.choice(len(midis), size=min(args.asap, len(midis)), replace=False))]
    plans = []
    for midi in chosen:
        beats = np.loadtxt(midi.with_suffix(".beats"), ndmin=1)
        late = float(beats[-1]) - CLIP_SECONDS if beats.size else 0.0
        start = 0.0 if rng.random() < 0.5 or late <= 0 else round(float(rng.uniform(0, late)), 1)
        program = 0 if rng.random() < 0.45 else int(rng.choice(PROGRAMS))
        plans.append((midi, start, program))
    with ThreadPoolExecutor(max(args.jobs, 1)) as pool:
        clips = list(pool.map(lambda p: asap_clip(*p), plans))
    clips += [ensemble_clip(i, rng) for i in range(args.ensemble)]
    print(f"{len(clips)} clips, {sum(c['x'].shape[0] for c in clips) / 6000:.1f} min, "
          f"{time.process_time() - t0:.0f} s CPU", file=sys.stderr)
    # validation: every tenth clip (ensemble and ASAP alike)
    val = clips[::10]
    train = [c for i, c in enumerate(clips) if i % 10]
    allx = np.concatenate([c["x"] for c in train])
    scale = (1.0 / (allx.std(axis=0) + 1e-3)).astype(np.float32)
    w = init_weights(rng, allx.shape[1])
    params = [k for k in w if k != "dilations"]
    mom = {k: np.zeros_like(w[k]) for k in params}
    var = {k: np.zeros_like(w[k]) for k in params}
    b1, b2 = 0.9, 0.999
    gen = batches(train, rng, args.batch)
    history = []
    for step in range(1, args.steps + 1):
        x, y, m = next(gen)
        loss, g = forward_backward(w, x * scale, y, m, args.pos_weight)
        lr = args.lr * (0.5 * (1 + math.cos(math.pi * step / args.steps)))  # cosine decay
        for k in params:
            mom[k] = b1 * mom[k] + (1 - b1) * g[k]
            var[k] = b2 * var[k] + (1 - b2) * g[k] * g[k]
            w[k] = (w[k] - lr * (mom[k] / (1 - b1**step)) / (np.sqrt(var[k] / (1 - b2**step)) + 1e-8)).astype(np.float32)
        if step % 250 == 0 or step == args.steps:
            v = evaluate(w, val, scale, args.pos_weight)
            history.append({"step": step, "train_loss": round(loss, 4), "val_loss": round(v, 4)})
            print(json.dumps(history[-1]), file=sys.stderr)
    out = {**w, "scale": scale}
    BeatActivationNetwork(out)  # loads as the tracker will
    np.savez_compressed(args.out, **out)
    print(json.dumps({"out": args.out, "seed": args.seed, "clips": len(clips), "history": history,
                      "cpu_seconds": round(time.process_time() - t0, 1)}, indent=2))


if __name__ == "__main__":
    main()
