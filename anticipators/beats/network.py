"""A small learned causal beat activation: per-band spectral flux into causal dilated convolutions.

:class:`BandFluxEnvelope` is the tracker's log-mel spectral flux (:class:`~anticipators.beats.envelope.
SpectralFluxEnvelope`) that also keeps each band's half-wave rectified flux, the network's input (40 mel
bands, 100 frames a second). :class:`BeatActivationNetwork` turns those frames into a beat activation in
``(0, 1)``, one value a frame, seeing only frames heard so far:

    h0 = tanh(conv(x; kernel 3))                        40 bands -> C channels
    h_l = h_(l-1) + tanh(conv(h_(l-1); kernel 2, dilation d_l))   d_l = 1, 2, 4, ..., 64
    a = sigmoid(w . h_L + b)

Every convolution is causal (the output at frame t reads frames t, t - d, ...), so the receptive field
is about 1.3 s back from the frame, and the activation at a frame never changes when later audio does.
:meth:`BeatActivationNetwork.stream` keeps each layer's last inputs so that it runs on any number of new
frames at a time with the same result as on the whole sequence at once; inference is numpy.

The shipped weights (``activation_net.npz`` beside this module, :func:`load_network`) were made by
``scripts/train_beat_activation.py`` from a fixed seed: FluidSynth renders of the project's ensemble
(tempo ramps, steps and rubato, drums, bass, piano and strings in several combinations) and of ASAP's
``train`` performances (real pianists' MIDI, CC BY-NC-SA 4.0, rendered with piano and other General MIDI
programs); the weights carry that data set's attribution and share-alike terms. No development or held-out
recording was used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from anticipators.beats.envelope import BAND_FMAX, BandFluxEnvelope

__all__ = ["FMAX", "BandFluxEnvelope", "BeatActivationNetwork", "NetworkActivation", "WEIGHTS_PATH", "load_network",
           "band_flux"]

WEIGHTS_PATH = Path(__file__).with_name("activation_net.npz")
"""The shipped network's weights."""

FMAX = BAND_FMAX
"""Highest frequency of the network's mel bands (Hz): half of 22.05 kHz, at which it was trained."""


def band_flux(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """The network's input frames of a whole recording: ``(frames, 40)`` rectified log-mel flux per band,
    exactly as :class:`BandFluxEnvelope` computes them while hearing it."""
    x = np.asarray(audio, np.float32).reshape(-1)
    env = BandFluxEnvelope(sample_rate, keep_seconds=x.size / sample_rate + 2.0,
                           keep_audio_seconds=1.0)
    out = []
    step = sample_rate * 5
    for a in range(0, x.size, step):
        env.append(x[a : a + step])
        n0 = env.n_frames
        env.update()
        out.append(env.bands(n0, env.n_frames).copy())
    return np.concatenate(out) if out else np.zeros((0, env.n_mels), np.float32)


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


class BeatActivationNetwork:
    """Causal dilated convolutions from per-band flux to a beat activation (numpy inference).

    Parameters
    ----------
    weights : dict of numpy.ndarray
        ``w0`` ``(3, n_in, C)``, ``b0`` ``(C,)``; ``w1 .. wL`` ``(2, C, C)`` with ``b1 .. bL``; ``wo`` ``(C,)``,
        ``bo`` ``()``; ``dilations`` ``(L,)``; ``scale`` ``(n_in,)``, the input's scaling.
    """

    def __init__(self, weights: dict) -> None:
        self.w0 = np.asarray(weights["w0"], np.float32)
        self.b0 = np.asarray(weights["b0"], np.float32)
        self.dilations = [int(d) for d in np.asarray(weights["dilations"]).reshape(-1)]
        self.ws = [np.asarray(weights[f"w{i + 1}"], np.float32) for i in range(len(self.dilations))]
        self.bs = [np.asarray(weights[f"b{i + 1}"], np.float32) for i in range(len(self.dilations))]
        self.wo = np.asarray(weights["wo"], np.float32).reshape(-1)
        self.bo = float(np.asarray(weights["bo"]).reshape(()))
        self.scale = np.asarray(weights["scale"], np.float32).reshape(-1)
        self.n_in = self.w0.shape[1]
        self.channels = self.w0.shape[2]
        self.reset()

    @property
    def receptive_field(self) -> int:
        """Frames (the current one included) that one output depends on."""
        return self.w0.shape[0] + sum(self.dilations)

    def reset(self) -> None:
        """Forget every frame heard (the history is silence: zero flux)."""
        k0 = self.w0.shape[0] - 1
        self._hist = [np.zeros((k0, self.n_in), np.float32)]
        self._hist += [np.zeros((d, self.channels), np.float32) for d in self.dilations]

    def stream(self, frames) -> np.ndarray:
        """Activations of the next frames (``(n, n_in)`` per-band flux), continuing the frames before."""
        x = np.asarray(frames, np.float32).reshape(-1, self.n_in) * self.scale
        n = x.shape[0]
        if n == 0:
            return np.zeros(0, np.float64)
        hist = self._hist
        ext = np.concatenate([hist[0], x])
        k0 = self.w0.shape[0]
        h = ext[k0 - 1 :] @ self.w0[k0 - 1]
        for k in range(k0 - 1):
            h += ext[k : k + n] @ self.w0[k]
        h += self.b0
        np.tanh(h, out=h)
        hist[0] = ext[n:]
        for i, d in enumerate(self.dilations):
            ext = np.concatenate([hist[i + 1], h])
            w = self.ws[i]
            z = ext[:n] @ w[0]
            z += ext[d:] @ w[1]
            z += self.bs[i]
            h = h + np.tanh(z, out=z)
            hist[i + 1] = ext[n:]
        return _sigmoid(h @ self.wo + self.bo).astype(np.float64)

    def run(self, frames) -> np.ndarray:
        """Activations of a whole sequence of frames from silence (the network's state is reset first)."""
        self.reset()
        out = self.stream(frames)
        self.reset()
        return out


def load_network(path: "str | Path | None" = None) -> BeatActivationNetwork:
    """The network with the weights in ``path`` (default: the shipped :data:`WEIGHTS_PATH`)."""
    path = Path(path) if path is not None else WEIGHTS_PATH
    with np.load(path) as data:
        return BeatActivationNetwork({k: data[k] for k in data.files})


class NetworkActivation:
    """A fresh :class:`BeatActivationNetwork` (the shipped weights, or those in ``path``) as the joint
    filter's observation: called with each new stretch of per-band flux frames, it returns their activations
    raised to ``power`` and floored at ``floor`` (a frame the network rules out is unlikely, not impossible,
    to hold a beat). The tracker's ``network_mix`` mixes it with the hand-made flux activation."""

    _cache: dict = {}

    def __init__(self, floor: float = 0.01, power: float = 1.0, path: "str | Path | None" = None) -> None:
        key = str(path or WEIGHTS_PATH)
        weights = self._cache.get(key)
        if weights is None:
            with np.load(key) as data:
                weights = self._cache[key] = {k: data[k] for k in data.files}
        self.net = BeatActivationNetwork(weights)
        self.floor = float(floor)
        self.power = float(power)

    def __call__(self, bands) -> np.ndarray:
        a = self.net.stream(bands)
        if self.power != 1.0:
            a = a ** self.power
        return self.floor + (1.0 - self.floor) * a
