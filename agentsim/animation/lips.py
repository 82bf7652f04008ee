"""Lip sync: mouth shapes of visemes and face channels, and the drivers of ``lips`` and ``curves`` behaviours.

Other realizers write lip sync as a row of visemes (SmartBody's ``<lips viseme="Ih" .../>``, read into
``lips`` behaviours) or as keyframed channels (``<curves>``, read into ``curves`` behaviours). Both are
played on the mouth: the jaw (``temporomandibular.pitch``) and the lips (``upper_lip.pitch``,
``lower_lip.pitch``, ``l_lip_corner.yaw``, ``r_lip_corner.yaw``; see :mod:`agentsim.animation.body`).

The viseme table
----------------
A :class:`MouthShape` describes a viseme on the two axes a viseme needs (open/closed and wide/narrow,
the way animators read visemes) plus the lips' closure: how far the jaw opens, how far the corners
spread (positive) or round and protrude (negative), how far the upper lip comes down and the lower lip up.
The shapes are the lexicon's (``data/visemes.toml``, whose comments give the articulation of each viseme
class; :class:`~agentsim.animation.lexicon.Lexicon`), so a user's lexicon file may retune or add them.

An unknown name gets a neutral half-open mouth (jaw 8 degrees) and a note. Names are matched without
regard to case; a few aliases (PBM, FV, EE, OO, KG, S, Sh, Ch, J) name the same shapes.

Face channels (``curves``) use the same table: a channel named like a viseme moves the mouth to that
shape scaled by its value, and the FaceFX channel names map onto it (the lexicon's face channels ``open``:
the jaw alone, ``wide``: the spread alone; ``W``, ``ShCh``, ``PBM``, ``FV``: those visemes). Channels add
up, as blend shapes do. The tongue channels (``tBack``, ``tRoof``, ``tTeeth``) have nothing to move in this
skeleton and are noted, like unknown channels.

Timing and arbitration
----------------------
A viseme blends from the pose it finds to its shape (scaled by ``articulation``) between start and ready
(over at least :data:`MIN_RAMP`: SmartBody writes ready at start), holds it to relax and hands the
mouth back to whoever held it before (the speech jaw, the rest pose), which blends there by end (at
least :data:`MIN_RAMP` after relax). Visemes drive the mouth at priority ``lips``, above the speech jaw,
which therefore yields wherever a viseme is, and above face expressions. Of overlapping
visemes the later takes over when it starts, blending from where the earlier one has the mouth; an
earlier viseme whose follower starts during its relax..end keeps its shape until then, so the mouth goes
straight from one shape to the next rather than towards rest and back.

A curves behaviour's channel keys (seconds from its start, stretched in proportion when the plan gave
the behaviour another duration) are interpolated by a monotone piecewise cubic (Fritsch-Carlson slopes,
zero slope at the first and last key): the weight passes through every key, has a continuous velocity
and never overshoots the keys. Before the first and after the last key a channel keeps that key's
value. Its first :data:`CURVE_BLEND` seconds blend from the pose the curves find.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from agentsim.animation.drivers import EPSILON, PRIORITY
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.motion import KeyTimes, MotionDriver, blend_in
from agentsim.animation.units import curve_keys, curves_duration

#: The DOFs of the mouth, in the order of :class:`MouthShape`'s fields (the corners share ``spread``).
MOUTH_DOFS = ("temporomandibular.pitch", "l_lip_corner.yaw", "r_lip_corner.yaw", "upper_lip.pitch",
              "lower_lip.pitch")
#: Shortest blend (s) of a viseme into its shape: about half the length of a phoneme in fluent speech.
MIN_RAMP = 0.05
#: Blend (s) from the pose a curves behaviour finds into its keyed values.
CURVE_BLEND = 0.04


@dataclass(frozen=True)
class MouthShape:
    """A mouth shape in degrees: ``jaw`` opening, corner ``spread`` (negative: rounded), ``upper`` lip
    lowered and ``lower`` lip raised (both close the lips)."""

    jaw: float = 0.0
    spread: float = 0.0
    upper: float = 0.0
    lower: float = 0.0

    def dofs(self, scale: float = 1.0) -> dict[str, float]:
        """The shape as DOF values (degrees), scaled: the corners mirror each other, the lower lip rises
        with a negative pitch."""
        return {"temporomandibular.pitch": self.jaw * scale, "l_lip_corner.yaw": self.spread * scale,
                "r_lip_corner.yaw": 0.0 - self.spread * scale, "upper_lip.pitch": self.upper * scale,
                "lower_lip.pitch": 0.0 - self.lower * scale}


#: A viseme the table does not know: a neutral half-open mouth.
NEUTRAL = MouthShape(jaw=8)
#: Channels that move the tongue, which this skeleton does not have.
TONGUE_CHANNELS = frozenset({"tback", "troof", "tteeth"})


def viseme_shape(name: str, lexicon: Lexicon) -> MouthShape | None:
    """The mouth shape of a viseme (any case) in ``lexicon``, or None if it does not know it."""
    entry = lexicon.visemes.get(name.strip().lower())
    return None if entry is None else MouthShape(**entry)


def channel_shape(name: str, lexicon: Lexicon) -> MouthShape | None:
    """The mouth shape at weight 1 of a face channel (any case) in ``lexicon``: one of its face channels, or
    else a viseme; None if it knows neither."""
    low = name.strip().lower()
    entry = lexicon.channels.get(low)
    if entry is None:
        entry = lexicon.visemes.get(low)
    return None if entry is None else MouthShape(**entry)


def articulation_of(attrs: Mapping[str, str]) -> tuple[float, str]:
    """A lips behaviour's ``articulation`` (default 1) limited to 0..1, and a note if it had to be changed."""
    text = attrs.get("articulation", "1")
    try:
        value = float(text)
    except ValueError:
        return 1.0, f"articulation {text!r} is not a number: 1 used"
    if not np.isfinite(value):
        return 1.0, f"articulation {text!r} is not a number: 1 used"
    if value < 0.0 or value > 1.0:
        clipped = min(max(value, 0.0), 1.0)
        return clipped, f"articulation {value:g} limited to {clipped:g}"
    return value, ""


def lips_values(attrs: Mapping[str, str], lexicon: Lexicon) -> tuple[dict[str, float], str]:
    """The DOF values a lips behaviour holds (its viseme's shape in ``lexicon`` times its articulation), and
    a note (an unknown viseme, a changed articulation; empty if none)."""
    notes = []
    name = attrs.get("viseme", "")
    shape = viseme_shape(name, lexicon)
    if shape is None:
        shape = NEUTRAL
        notes.append(f"unknown viseme {name!r}: a neutral half-open mouth")
    amount, note = articulation_of(attrs)
    if note:
        notes.append(note)
    return shape.dofs(amount), "; ".join(notes)


@dataclass(frozen=True)
class Channel:
    """One face channel of a curves behaviour: its keys (seconds from the start, weight) and the DOF
    values it moves to at weight 1."""

    name: str
    times: np.ndarray
    weights: np.ndarray
    values: dict[str, float]


def curve_channels(behaviour, lexicon: Lexicon) -> tuple[list[Channel], list[str]]:
    """The channels of a curves behaviour that move the mouth (as ``lexicon`` has their shapes), and notes on
    those that do not (the tongue, names without a mapping, channels without keys)."""
    channels: list[Channel] = []
    notes: list[str] = []
    for name, keys in curve_keys(behaviour).items():
        low = name.strip().lower()
        if not keys:
            notes.append(f"{name}: no keys")
        elif low in TONGUE_CHANNELS:
            notes.append(f"{name}: no tongue in this skeleton")
        elif channel_shape(low, lexicon) is None:
            notes.append(f"{name}: no mapping")
        else:
            values = {d: v for d, v in channel_shape(low, lexicon).dofs().items() if v != 0.0}
            if not values:  # the silence channel: the rest pose, which the mouth returns to anyway
                notes.append(f"{name}: the rest pose, nothing to move")
                continue
            channels.append(Channel(name, np.array([k[0] for k in keys], dtype=float),
                                    np.array([k[1] for k in keys], dtype=float), values))
    return channels, notes


def monotone_cubic(xs: Sequence[float], ys: Sequence[float], t) -> np.ndarray:
    """Interpolate keys ``(xs, ys)`` (increasing ``xs``) at times ``t`` by a monotone piecewise cubic.

    Hermite cubics with Fritsch-Carlson slopes (a weighted harmonic mean of the neighbouring secants where
    they have one sign, zero at a local extremum and at the first and last key): the curve passes through
    every key, has a continuous first derivative and stays between neighbouring keys. Keys at one time
    make a step; outside the keys the value is the nearest key's.
    """
    xs = np.asarray(xs, dtype=float)
    ys = np.asarray(ys, dtype=float)
    t = np.asarray(t, dtype=float)
    if len(xs) == 1:
        return np.full(t.shape, ys[0])
    h = np.diff(xs)
    step = h <= EPSILON
    delta = np.where(step, 0.0, np.diff(ys) / np.where(step, 1.0, h))
    m = np.zeros(len(xs))
    for k in range(1, len(xs) - 1):
        if delta[k - 1] * delta[k] > 0:
            w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
            m[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k])
    tc = np.clip(t, xs[0], xs[-1])
    k = np.clip(np.searchsorted(xs, tc, side="right") - 1, 0, len(xs) - 2)
    hk = h[k]
    u = np.where(hk > EPSILON, (tc - xs[k]) / np.where(hk > EPSILON, hk, 1.0), 1.0)
    u2, u3 = u * u, u * u * u
    return ((2 * u3 - 3 * u2 + 1) * ys[k] + (u3 - 2 * u2 + u) * hk * m[k]
            + (-2 * u3 + 3 * u2) * ys[k + 1] + (u3 - u2) * hk * m[k + 1])


class LipsDriver(MotionDriver):
    """A viseme: the mouth DOFs blend from the pose found at the start to ``values`` by ready (at least
    :data:`MIN_RAMP` after the start), hold to relax (or to ``hold_until``, when the next viseme starts
    during this one's relax..end) and are handed back for the rest of the unit."""

    def __init__(self, name: str, keys: KeyTimes, values: Mapping[str, float], hold_until: float | None = None,
                 **kw):
        super().__init__(name, keys, PRIORITY["lips"], list(values), **kw)
        self.values = dict(values)
        self.hold_until = hold_until

    def release_time(self) -> float:
        """Relax, or the next viseme's start when that comes between relax and end."""
        relax = self.keys.time("relax") if self.keys.has("relax") else self.keys.end
        if self.hold_until is not None:
            return max(relax, min(self.hold_until, self.keys.end))
        return relax

    def handover(self) -> float:
        return max(self.keys.end - self.release_time(), MIN_RAMP)

    def ramp_end(self) -> float:
        """When the shape is reached (driver time): ready, or :data:`MIN_RAMP` after the unit began."""
        ready = self.keys.time("ready") if self.keys.has("ready") else self.keys.start
        return max(ready, self.begun + MIN_RAMP)

    def on_tick(self, t: np.ndarray) -> None:
        target = {k: np.full(len(t), v) for k, v in self.values.items()}
        self.write_held(blend_in(self, target, t, self.begun, self.ramp_end()))


class CurvesDriver(MotionDriver):
    """Keyframed face channels: each channel's weight (interpolated by :func:`monotone_cubic`) times its
    shape, summed over channels, on the mouth DOFs any channel moves, from start to end."""

    grant_blend = CURVE_BLEND
    release_key = "end"

    def __init__(self, name: str, keys: KeyTimes, channels: Sequence[Channel], duration: float, **kw):
        dofs = [d for d in MOUTH_DOFS if any(d in c.values for c in channels)]
        super().__init__(name, keys, PRIORITY["lips"], dofs, **kw)
        self.channels = list(channels)
        self.duration = float(duration)

    def curve_time(self, t: np.ndarray) -> np.ndarray:
        """Seconds on the curves' own time axis at driver times ``t`` (stretched in proportion when the
        behaviour's planned duration differs from its last key)."""
        span = self.keys.end - self.keys.start
        local = np.asarray(t, dtype=float) - self.keys.start
        if span > EPSILON and abs(span - self.duration) > 1e-9:
            local = local * (self.duration / span)
        return local

    def on_tick(self, t: np.ndarray) -> None:
        local = self.curve_time(t)
        out = {d: np.zeros(len(t)) for d in self.dof_names}
        for c in self.channels:
            w = monotone_cubic(c.times, c.weights, local)
            for d, v in c.values.items():
                out[d] += w * v
        self.write_held(out)


def curves_driver(name: str, keys: KeyTimes, behaviour, lexicon: Lexicon, **kw) -> tuple[CurvesDriver | None, str]:
    """The driver of a curves behaviour (None if none of its channels moves the mouth, as ``lexicon`` has
    their shapes) and a note on the channels left out."""
    channels, notes = curve_channels(behaviour, lexicon)
    note = ("channels without DOFs: " + ", ".join(notes)) if notes else ""
    if not channels:
        return None, (note + "; " if note else "") + "no channel moves this body"
    return CurvesDriver(name, keys, channels, curves_duration(behaviour), **kw), note


# ------------------------------------------------------------------------------------ phonemes to visemes
#: The phoneme-to-viseme table: an IPA phoneme (as espeak-ng names them; length marks and stress left out)
#: -> the viseme of the lexicon that shows it. Consonants by place of articulation (bilabials PBM,
#: labiodentals FV, dentals Th, alveolar stops and nasals D/N, sibilants Z, postalveolars ShCh, velars K,
#: the approximants R, L and W), vowels by openness and rounding (open Aa/Ah/Ao, mid Eh/Oh/Er, close
#: Ih/Iy/Uh/Uw). A diphthong shows the viseme of its first element; ``h`` and the glottal stop take the
#: next phoneme's shape in speech, here the neutral one (Ah). The built-in backend's letter units are
#: read through :data:`LETTER_VISEMES`.
PHONEME_VISEMES: dict[str, str] = {
    "p": "PBM", "b": "PBM", "m": "PBM",
    "f": "FV", "v": "FV",
    "θ": "Th", "ð": "Th",
    "t": "D", "d": "D", "n": "N", "ɾ": "D",
    "s": "Z", "z": "Z",
    "ʃ": "ShCh", "ʒ": "ShCh", "tʃ": "ShCh", "dʒ": "ShCh",
    "k": "K", "ɡ": "K", "g": "K", "ŋ": "K", "x": "K",
    "ɹ": "R", "r": "R", "l": "L", "ɫ": "L", "w": "W", "j": "Iy", "h": "Ah", "ʔ": "Ah",
    "i": "Iy", "ɪ": "Ih", "e": "Eh", "ɛ": "Eh", "æ": "Aa", "a": "Aa", "ɑ": "Aa", "ʌ": "Ah", "ə": "Ah",
    "ɐ": "Ah", "ɜ": "Er", "ɚ": "Er", "ɝ": "Er", "ɒ": "Ao", "ɔ": "Ao", "o": "Oh", "ʊ": "Uh", "u": "Uw",
    "ɵ": "Uh", "y": "Uw",
}
#: The built-in backend's units (letters and letter groups) -> visemes, by the sound the letters spell.
LETTER_VISEMES: dict[str, str] = {
    "c": "K", "q": "K", "j": "ShCh", "sh": "ShCh", "ch": "ShCh", "th": "Th", "ph": "FV", "ng": "K",
    "y": "Iy", "o": "Oh", "u": "Uh", "e": "Eh", "ee": "Iy", "oo": "Uw",
}


def phoneme_viseme(symbol: str) -> str:
    """The viseme of one phoneme (an IPA symbol, or a built-in backend's letter unit); ``_`` for silence and
    Ah (the neutral open mouth) for a symbol neither table knows."""
    s = symbol.strip().replace("ː", "").replace("ˈ", "").replace("ˌ", "")
    if not s:
        return "_"
    for table in (PHONEME_VISEMES, LETTER_VISEMES):
        for key in (s, s.lower()):
            if key in table:
                return table[key]
    for n in (2, 1):  # a diphthong or affricate by its first element
        if s[:n] in PHONEME_VISEMES:
            return PHONEME_VISEMES[s[:n]]
    return "Ah"


@dataclass(frozen=True)
class VisemeRow:
    """One phoneme of a speech as heard, and the viseme that shows it (seconds on the run's axis)."""

    block: str
    behaviour: str
    word: str
    phoneme: str
    viseme: str
    start_s: float
    end_s: float


def speech_visemes(recording) -> list[VisemeRow]:
    """The visemes of every speech of a recording, phoneme by phoneme where and as long as it was heard
    (its playback drift included; a speech stopped early keeps the phonemes that began before the stop)."""
    rows = []
    for heard in recording.speech:
        words = heard.utterance.words
        speed = 1.0 + heard.drift_ppm * 1e-6
        for p in heard.utterance.phonemes:
            a, b = heard.t0 + p.start * speed, heard.t0 + p.end * speed
            if heard.stopped is not None:
                if a >= heard.stopped:
                    continue
                b = min(b, heard.stopped)
            word = words[p.word_index].text if 0 <= p.word_index < len(words) else ""
            rows.append(VisemeRow(heard.block, heard.behaviour, word, p.symbol, phoneme_viseme(p.symbol), a, b))
    return sorted(rows, key=lambda r: r.start_s)


# ------------------------------------------------------------------------------------ the mouth while speaking
#: Dominance of a viseme over the mouth while speaking (co-articulation, Cohen & Massaro's dominance
#: functions): the lips must close for a bilabial and touch the teeth for a labiodental, so those dominate;
#: vowels and the rounded and postalveolar consonants shape the lips less firmly; the tongue consonants
#: leave the lips to their neighbours. Names not listed have :data:`DOMINANCE_DEFAULT`.
DOMINANCE = {"pbm": 2.0, "bmp": 2.0, "fv": 1.5, "f": 1.5, "w": 0.7, "shch": 0.6, "uw": 0.6, "oh": 0.6,
             "d": 0.3, "n": 0.3, "k": 0.3, "l": 0.35, "z": 0.4, "th": 0.35, "_": 0.6}
DOMINANCE_DEFAULT = 0.5
#: How fast a viseme's dominance falls off on either side of its phoneme's middle (s per factor of e).
COARTICULATION = 0.035
#: A gap this long (s) between phonemes (a pause) is silence: the mouth goes towards rest.
PAUSE = 0.08
#: The speaking mouth blends from the pose it finds over this long after the speech's start (s), and back
#: to the pose it hands over to by the end.
SPEECH_BLEND = MIN_RAMP
#: Times of a viseme track computed at once (:func:`viseme_track`).
TRACK_CHUNK = 512
#: How far (s) beyond a time's nearest viseme middle the others still count: 50 decay lengths, e^-50.
REACH = 50 * COARTICULATION


def speech_segments(phonemes: Sequence[tuple[str, float, float]]) -> list[tuple[str, float, float]]:
    """The visemes a speech shows, ``(viseme, start, end)`` in seconds on its timeline: one per phoneme
    (:func:`phoneme_viseme`), and silence ``_`` in every pause of at least :data:`PAUSE` s."""
    out: list[tuple[str, float, float]] = []
    last = None
    for symbol, a, b in phonemes:
        if last is not None and a - last >= PAUSE:
            out.append(("_", last, a))
        name = "_" if symbol.strip().startswith("_") else phoneme_viseme(symbol)
        out.append((name, float(a), float(b)))
        last = float(b) if last is None else max(last, float(b))
    return out


class VisemeTrack:
    """The mouth of one speech while it is spoken: its visemes' middles, dominances and shapes (those of
    ``lexicon``), built once from its phonemes (:func:`speech_segments`), and evaluated at any times with
    :meth:`at`."""

    def __init__(self, phonemes: Sequence[tuple[str, float, float]], lexicon: Lexicon):
        segments = speech_segments(phonemes)
        self.mids = np.array([0.5 * (a + b) for _, a, b in segments])
        self.alphas = np.array([DOMINANCE.get(name.lower(), DOMINANCE_DEFAULT) for name, _, _ in segments])
        shapes = {name: (viseme_shape(name, lexicon) or NEUTRAL).dofs() for name in {name for name, _, _ in segments}}
        self.shapes = np.array([[shapes[name][d] for d in MOUTH_DOFS] for name, _, _ in segments])
        self.ordered = np.sort(self.mids)

    def at(self, u) -> dict[str, np.ndarray]:
        """The mouth DOF values (degrees) at times ``u`` (seconds on the speech's timeline); see
        :func:`viseme_track`."""
        u = np.asarray(u, dtype=float)
        if not len(self.mids) or u.size == 0:
            return {d: np.zeros(u.shape) for d in MOUTH_DOFS}
        flat = u.ravel()
        mids, ordered = self.mids, self.ordered
        result = np.empty((flat.size, len(MOUTH_DOFS)))
        for lo in range(0, flat.size, TRACK_CHUNK):
            part = flat[lo:lo + TRACK_CHUNK]
            k = np.searchsorted(ordered, part)
            reach = REACH + np.minimum(np.abs(part - ordered[np.maximum(k - 1, 0)]),
                                       np.abs(part - ordered[np.minimum(k, len(ordered) - 1)]))
            chosen = np.flatnonzero((mids >= np.min(part - reach)) & (mids <= np.max(part + reach)))
            distance = np.abs(part[None, :] - mids[chosen, None])
            weights = np.where(distance <= reach, self.alphas[chosen, None] * np.exp(-distance / COARTICULATION),
                               0.0)
            # summed over the visemes in their order, one after another from zero (a running sum), so that
            # those left out add exact zeros and a time's sum does not depend on how many times are
            # computed with it
            total = _running_sum(weights)
            share = weights / np.maximum(total, 1e-300)
            result[lo:lo + TRACK_CHUNK] = _running_sum(share[:, :, None] * self.shapes[chosen][:, None, :])
        return {d: result[:, i].reshape(u.shape) for i, d in enumerate(MOUTH_DOFS)}


def _running_sum(terms: np.ndarray) -> np.ndarray:
    """``0 + terms[0] + terms[1] + ...`` along the first axis, added one after another in that order."""
    out = np.zeros(terms.shape[1:])
    for term in terms:
        out += term
    return out


def viseme_track(phonemes: Sequence[tuple[str, float, float]], u, lexicon: Lexicon | None = None
                 ) -> dict[str, np.ndarray]:
    """The mouth DOF values (degrees) at times ``u`` (seconds on the speech's timeline) while the phonemes
    are spoken, with co-articulation: each viseme's shape is weighted by its dominance
    ``alpha * exp(-|u - middle| / COARTICULATION)`` and the shapes are averaged by weight, so each viseme
    shows most at its phoneme's middle and colours its neighbours (rounding comes early, a bilabial
    still closes the lips between two open vowels).

    Each time counts the visemes whose middle lies within :data:`REACH` beyond its nearest middle (the others
    weigh less than e^-50 of the nearest one, below a double's precision), and the times are taken
    :data:`TRACK_CHUNK` at a time: the cost and the memory grow with the speech's length, not with its length
    squared (a 70-minute speech is some 250,000 frames and 50,000 phonemes), and a time's value is the same
    whichever other times it is computed with. A speech evaluated at many times builds its
    :class:`VisemeTrack` once. The shapes are those of ``lexicon`` (default: the built-in one)."""
    return VisemeTrack(phonemes, lexicon if lexicon is not None else Lexicon.builtin()).at(u)


class SpeechMouthDriver(MotionDriver):
    """The mouth while speech plays (start to end): the visemes of its phonemes (:func:`viseme_track`),
    placed on the driver's time by linear time warping between the speech's sync points (``preferred``:
    their times on the speech's own timeline), so the mouth stays with the words wherever its sync points
    went. It blends from the pose it finds over :data:`SPEECH_BLEND` s and back to it by the end. The
    visemes' shapes are those of ``lexicon``."""

    def __init__(self, name: str, keys: KeyTimes, phonemes: Sequence[tuple[str, float, float]],
                 preferred: Sequence[float], lexicon: Lexicon, **kw):
        super().__init__(name, keys, PRIORITY["speech"], list(MOUTH_DOFS), **kw)
        self.release_key = keys.sync_ids[-1]
        self.phonemes = [(str(s), float(a), float(b)) for s, a, b in phonemes]
        pref = np.asarray(preferred, dtype=float)
        if len(pref) != len(keys.times):
            pref = np.asarray(keys.times, dtype=float) - keys.times[0]
        self.preferred = np.maximum.accumulate(pref)
        self.track = VisemeTrack(self.phonemes, lexicon)

    def release_time(self) -> float:
        return self.keys.end

    def speech_time(self, t: np.ndarray) -> np.ndarray:
        """Seconds on the speech's timeline at driver times ``t``."""
        times = np.asarray(self.keys.times, dtype=float)
        if times[-1] - times[0] <= EPSILON:
            return np.asarray(t, dtype=float) - times[0]
        return np.interp(t, times, self.preferred)

    def on_tick(self, t: np.ndarray) -> None:
        t0, t1 = self.keys.start, self.keys.end
        env = np.clip(np.minimum(t - t0, t1 - t) / SPEECH_BLEND, 0, 1)
        track = self.track.at(self.speech_time(t))
        self.write_held({d: self.start_value(d) * (1 - env) + track[d] * env for d in MOUTH_DOFS})
