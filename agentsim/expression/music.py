"""The music channel as heard: the pieces the environment chose, each from its valence's start to the next
change, cross-faded over :data:`CROSSFADE` seconds and :data:`UNDER_SPEECH` dB under the speech, as samples
from the run's time 0 (:func:`agentsim.media.environment.music_for` makes them the source mixed into the
narration, and written alone as ``music.wav``)."""

from __future__ import annotations

import numpy as np

from agentsim.expression.environment import EnvironmentRow, valence_spans

#: Seconds over which one piece gives way to the next (and the music comes in or goes out).
CROSSFADE = 1.0
#: How far under the speech the music sits (dB, root mean square over what sounds).
UNDER_SPEECH = 15.0
#: The speech level assumed when the run has no speech audio (the built-in backend): -20 dBFS.
REFERENCE_LEVEL = 0.1


def sounding_level(samples: np.ndarray, rate: int) -> float:
    """The root mean square of the 50 ms frames that sound (within 40 dB of the loudest frame); 0 for silence."""
    samples = np.asarray(samples, np.float32)
    hop = max(1, int(rate * 0.05))
    n = len(samples) // hop
    if n == 0:
        return 0.0
    frames = samples[:n * hop].reshape(n, hop)
    power = np.einsum("ij,ij->i", frames, frames, dtype=np.float64) / hop
    loud = power > power.max() * 1e-4
    return float(np.sqrt(power[loud].mean())) if loud.any() and power.max() > 0 else 0.0


def speech_level(sources) -> float:
    """The sounding level of the speech sources together (:data:`REFERENCE_LEVEL` if they are silent)."""
    levels = [(sounding_level(s.samples, s.rate), len(s.samples)) for s in sources]
    total = sum(n for level, n in levels if level > 0)
    if not total:
        return REFERENCE_LEVEL
    return float(np.sqrt(sum(level ** 2 * n for level, n in levels if level > 0) / total))


def music_samples(rows: list[EnvironmentRow], end: float, rate: int, level: float) -> np.ndarray:
    """The music of ``rows`` at ``rate`` from time 0 to ``end`` plus the last fade (s), each piece's sounding
    level ``UNDER_SPEECH`` dB under ``level``."""
    from agentsim.expression.library import BY_NAME, looped

    spans = valence_spans(rows, end)
    if not spans:
        return np.zeros(0, np.float32)
    fade = int(round(CROSSFADE * rate))
    length = int(np.ceil(max(stop for _, stop, _, _ in spans) * rate)) + fade
    out = np.zeros(length, np.float32)
    target = level * 10.0 ** (-UNDER_SPEECH / 20.0)
    for start, stop, _, name in spans:
        piece = BY_NAME[name]
        a, b = int(round(start * rate)), min(length, int(round(stop * rate)) + fade)
        samples = looped(piece, rate, b - a)
        own = sounding_level(looped(piece, rate, int(piece.period * rate)), rate)
        gain = np.float32(target / own if own > 0 else 0.0)
        samples *= gain
        rise = min(fade, b - a)
        samples[:rise] *= (np.arange(rise) / fade).astype(np.float32)  # comes in over the fade
        tail = b - int(round(stop * rate))  # goes out over the fade after its stop
        if tail > 0:
            samples[-tail:] *= (1.0 - np.arange(1, tail + 1) / fade).astype(np.float32)
        out[a:b] += samples
    return out

