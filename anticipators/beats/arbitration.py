"""Who sets and moves the beat grid the follower keeps: the two strategies of
:class:`~anticipators.beats.tracking.CausalBeatTracker` (its ``sync`` option).

=======================  ==========================================================================================
class                    what it decides
=======================  ==========================================================================================
``JointFilterGrid``      ``sync="dbn"`` (the tracker ``causal``): a joint tempo-phase filter over the onsets
                         holds the posterior over (beat interval, position in the beat) from the first frame;
                         its grid is set, predicted while it is the better one, and restarts the follower
``CombResync``           ``sync="comb"`` (``causal-comb``, the tracker before the joint filter): the first grid
                         from the autocorrelation tempo and the comb phase; a restart when either keeps
                         disagreeing with the grid
=======================  ==========================================================================================

A strategy is handed the parts it reads and drives (the envelope, the follower, the onset picker) and a
callable giving the tracker's latest tempo estimate; the tracker calls :meth:`hear` after every update of the
envelope, :meth:`sync` after every tempo estimate, and (``JointFilterGrid`` only) :meth:`predict`. Each keeps
its own counters and caches. All times are seconds from the first sample heard.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from anticipators.beats.dbn import BeatPointerFilter, FluxActivation
from anticipators.beats.envelope import EnvelopeSource
from anticipators.beats.follower import BeatFollower
from anticipators.beats.network import NetworkActivation
from anticipators.beats.onsets import OnsetPicker
from anticipators.beats.phase import comb_phase, comb_score
from anticipators.beats.tempo import TempoEstimate

__all__ = ["JointFilterGrid", "CombResync", "PHASE_MARGIN", "restart_grid"]

#: Another phase at the same tempo is taken when the onset strength of its last three beats is this many
#: times that of the grid held (the strength of equal clicks varies by 10 % with their alignment to the
#: frames).
PHASE_MARGIN = 1.3

Estimate = Callable[[], "TempoEstimate | None"]


def restart_grid(follower: BeatFollower, picker: OnsetPicker, envelope: EnvelopeSource, now: float, t_beat: float,
                 period: float, periodicity: float) -> None:
    """Restart the follower on the grid through ``t_beat``, ``period`` apart, from its latest beat that is old
    enough to be timed precisely (``now``: seconds heard), timed on the onset there when one is near."""
    while t_beat > now - 0.06 - envelope.latency:
        t_beat -= period
    fine = picker.onset_near(t_beat)
    if math.isfinite(fine) and abs(fine - t_beat) < 0.04:
        t_beat = fine
    follower.restart(t_beat, period, periodicity=periodicity)


class JointFilterGrid:
    """The joint tempo-phase filter's grid against the follower's (``sync="dbn"``).

    From ``init_frames`` on, the filter's most probable interval and phase (with hysteresis) set the beat
    grid; whenever the follower's grid differs from the filter's (tempo by more than ``agree_tempo``, phase by
    more than ``agree_phase`` of a beat) the filter's grid is predicted, and the follower restarts on it after
    ``patience`` tempo estimates, unless the follower's last three beats hold ``follower_margin`` times the
    onset strength of the filter's (a sudden change the follower found first). While the follower agrees,
    its precisely timed grid is predicted. In silence (the last 2 s without onset strength) the follower
    continues the grid the music left.

    The tracker's options of the same names are documented on
    :class:`~anticipators.beats.tracking.CausalBeatTracker`; ``odf_bias`` is its ``ODF_BIAS``.
    """

    def __init__(self, envelope: EnvelopeSource, follower: BeatFollower, picker: OnsetPicker, estimate: Estimate,
                 *, min_bpm: float, max_bpm: float, odf_bias: float, init_frames: int, dbn_options: dict | None = None,
                 activation_options: dict | None = None, network_options: dict | None = None,
                 use_network: bool = False, network_mix: float = 0.0, patience: int = 1, agree_tempo: float = 0.02,
                 agree_phase: float = 0.05, follower_margin: float = 1.5, hysteresis: float = 2.0):
        self.envelope = envelope
        self.follower = follower
        self.picker = picker
        self.estimate = estimate
        self.fps = envelope.fps
        self.odf_bias = float(odf_bias)
        #: what the filter observes of the envelope, and grids are weighed on (its onset strength if it keeps
        #: no other observation)
        self.observed = getattr(envelope, "observation_values", envelope.values)
        options = {"min_bpm": min_bpm, "max_bpm": max_bpm, "n_tempi": None, "prior_bpm": 100.0,
                   "prior_octaves": 1.0, **(dbn_options or {})}
        #: the joint filter (:class:`~anticipators.beats.dbn.BeatPointerFilter`)
        self.dbn = BeatPointerFilter(self.fps, **options)
        self.activation = FluxActivation(self.fps, **{"scale": 20.0, "floor": 0.01, **(activation_options or {})})
        #: the learned activation (``observation="network"``), or None
        self.network = NetworkActivation(**(network_options or {})) if use_network else None
        self.network_mix = float(network_mix)
        self.init_frames = int(init_frames)
        self.patience = max(int(patience), 1)
        self.agree_tempo = float(agree_tempo)
        self.agree_phase = float(agree_phase)
        self.follower_margin = float(follower_margin)
        self.hysteresis = float(hysteresis)
        #: whether the filter hears onsets to go by (set at every tempo estimate)
        self.active = False
        self._bad = 0
        self._beat_cache = (-1, 0.0, 0.0)
        self._wins_cache: tuple = (None, False)
        self._held: tuple[int, float] | None = None  # interval index and latest beat chosen

    def hear(self) -> None:
        """Step the filter over the frames the envelope gained."""
        envelope, dbn = self.envelope, self.dbn
        if dbn.n_frames < envelope.n_frames:
            a = self.activation(self.observed(dbn.n_frames, envelope.n_frames))
            if self.network is not None:
                learned = self.network(envelope.bands(dbn.n_frames, envelope.n_frames))
                a = learned if self.network_mix <= 0.0 else (1.0 - self.network_mix) * learned + self.network_mix * a
            dbn.step(a)

    def predict(self, now: float, horizon_beats: int) -> np.ndarray:
        """The follower's predictions unless the filter's grid is the better one (:meth:`wins`), then the
        filter's: the next ``horizon_beats`` beats at or after ``now``."""
        follower = self.follower
        if follower.out_of_range:
            return np.zeros(0)  # a pulse faster than the range (fast_pulse_check): no grid
        if not self.active:
            return follower.predict(now, horizon_beats) if follower.locked else np.zeros(0)
        if follower.locked and not self.wins():
            return follower.predict(now, horizon_beats)
        t_beat, period = self.beat()
        k0 = math.ceil((now - t_beat) / period - 1e-9)
        return t_beat + period * np.arange(k0, k0 + int(horizon_beats))

    def sync(self, now: float) -> None:
        """Set or move the beat grid to the filter's most probable tempo and phase (``now``: seconds heard)."""
        follower = self.follower
        self.active = self.hears()
        if not self.active or follower.out_of_range:
            return
        t_dbn, period_dbn = self.beat()
        if not follower.locked:
            self._restart(now, t_dbn, period_dbn)
            return
        if self.wins() and not self.agrees(0.06, 0.2):
            self._bad += 1
        else:
            self._bad = 0
        if self._bad >= self.patience:
            self._bad = 0
            self._restart(now, t_dbn, period_dbn)

    def beat(self) -> tuple[float, float]:
        """The filter's latest beat (s) and period (s): its most probable interval and, within it, its
        most probable position, with hysteresis against the grid chosen before. Another interval is taken
        once it holds ``hysteresis`` times the posterior of the one before; another phase at the same
        interval once the onset strength of its last three beats is clearly higher (two grids as strong,
        such as every other click of a fast pulse, would otherwise take turns, as the posterior of each
        rises at its own beats)."""
        dbn = self.dbn
        if self._beat_cache[0] != dbn.n_frames:
            tempo = dbn.tempo_posterior()
            k = int(np.argmax(tempo))
            held = self._held
            if held is not None and held[0] != k and self.hysteresis * tempo[held[0]] > tempo[k]:
                k = held[0]
            interval = int(dbn.intervals[k])
            a = int(dbn.starts[k])
            position = int(np.argmax(dbn.p[a : a + interval]))
            t, period = self._grid(interval, position)
            if held is not None and held[0] == k:
                t_old = held[1]
                d = ((t - t_old) / period + 0.5) % 1.0 - 0.5
                if abs(d) > 0.1 and self.strength(t, period) <= PHASE_MARGIN * self.strength(t_old, period):
                    t = t_old
            self._held = (k, t)
            self._beat_cache = (dbn.n_frames, t, period)
        return self._beat_cache[1], self._beat_cache[2]

    def _grid(self, interval: int, position: int) -> tuple[float, float]:
        """Latest beat (s) and period (s) of the state ``(interval, position)`` of the filter."""
        frame = int(self.dbn.n_frames - 1 - position)
        # the beat lies in the beat states after the wrap: at the strongest onset among those heard
        count = int(self.dbn.beat_width[int(np.searchsorted(self.dbn.intervals, interval))])
        region = self.envelope.values(frame, min(frame + count, self.dbn.n_frames))
        if region.size > 1:
            frame += int(np.argmax(region))
        return float(self.envelope.frame_time(float(frame))) - self.odf_bias, interval / self.fps

    def hears(self) -> bool:
        """Whether the filter has onsets to go by: the last 2 s hold some onset strength against the
        long-term mean (in silence the grid the music left is continued by the beat follower)."""
        if self.dbn.n_frames < self.init_frames or self.activation.mean <= 0.0:
            return False
        recent = self.envelope.values(self.envelope.n_frames - int(2.0 * self.fps), self.envelope.n_frames)
        return recent.size > 0 and float(recent.mean()) > 0.05 * self.activation.mean

    def agrees(self, tempo: float, phase: float) -> bool:
        """Whether the follower's grid is within ``tempo`` (log ratio) and ``phase`` (periods) of the filter's."""
        t_dbn, period_dbn = self.beat()
        t_latest, period = self.follower.state[0], self.follower.state[1]
        d = ((t_dbn - t_latest) / period + 0.5) % 1.0 - 0.5
        return abs(math.log(period / period_dbn)) < tempo and abs(d) < phase

    def strength(self, t_beat: float, period: float, beats: int = 3) -> float:
        """Mean onset strength at the latest ``beats`` beats heard of the grid through ``t_beat``, ``period`` apart:
        of what the filter observes (with ``far_lag``, the flux mixed with the increase over ``far_lag``
        frames), so that grids are weighed on the evidence the filter chose them by (real recordings F 0.792
        to 0.801 against the frame-to-frame flux)."""
        envelope = self.envelope
        last = envelope.n_frames - 3  # (an onset's strength peaks a frame or two after it)
        lag = period * self.fps
        frame = float(envelope.frame_index(t_beat + self.odf_bias))
        frame += math.floor((last - frame) / lag) * lag  # the grid's latest beat heard
        teeth = np.rint(frame - lag * np.arange(beats)).astype(np.intp)
        a = max(int(teeth[-1]) - 1, envelope.first_kept)
        values = self.observed(a, last + 2)
        if values.size < 3:
            return 0.0
        # the strongest frame within one of each tooth (a peak is one frame wide)
        near = np.maximum(np.maximum(values[:-2], values[1:-1]), values[2:])  # near[i]: frames a+i .. a+i+2
        idx = teeth - a - 1
        idx = idx[(idx >= 0) & (idx < near.size)]
        return float(near[idx].sum() / beats)

    def wins(self) -> bool:
        """Whether the filter's grid is to be followed rather than the follower's: it agrees with it
        (tempo within ``agree_tempo``, phase within ``agree_phase``), or it is not, and the onset strength of
        its last three beats is higher (so a sudden change the follower found before the filter stands)."""
        follower = self.follower
        key = (self.dbn.n_frames, follower.state[0], follower.state[1])
        if self._wins_cache[0] != key:
            if self.agrees(self.agree_tempo, self.agree_phase):
                wins = False
            else:
                t_dbn, period_dbn = self.beat()
                s_dbn = self.strength(t_dbn, period_dbn)
                s_follower = self.strength(*follower.state[:2])
                if abs(math.log(follower.state[1] / period_dbn)) < 0.04:
                    # the same tempo at another phase: only clearly stronger beats move the grid (two
                    # grids as strong, such as every other click of a fast pulse, would take turns)
                    wins = s_dbn > PHASE_MARGIN * s_follower
                else:
                    wins = self.follower_margin * s_dbn > s_follower
            self._wins_cache = (key, wins)
        return self._wins_cache[1]

    def _restart(self, now: float, t_beat: float, period: float) -> None:
        estimate = self.estimate()
        periodicity = estimate.periodicity_at(period * self.fps) if estimate is not None else 0.5
        restart_grid(self.follower, self.picker, self.envelope, now, t_beat, period, periodicity)


class CombResync:
    """The grid from autocorrelation tempo and comb phase (``sync="comb"``).

    The first grid is set after ``init_frames`` from the tempo estimate's period and the comb's latest beat.
    Then, if the autocorrelation persistently prefers another period while the grid misses its beats (or,
    over 2 s, another metrical level), or the comb persistently prefers another phase, the follower restarts
    from them.
    """

    def __init__(self, envelope: EnvelopeSource, follower: BeatFollower, picker: OnsetPicker, estimate: Estimate,
                 *, init_frames: int):
        self.envelope = envelope
        self.follower = follower
        self.picker = picker
        self.estimate = estimate
        self.fps = envelope.fps
        self.init_frames = int(init_frames)
        self.active = False  # (no filter of its own to predict from)
        self._period_bad = 0
        self._phase_bad = 0

    def hear(self) -> None:
        """Nothing to step: the comb reads the envelope when it is asked."""

    def sync(self, now: float) -> None:
        """Set the first grid, or restart the grid that the tempo or the comb keeps disagreeing with."""
        if not self.follower.locked:
            self._try_init(now)
        else:
            self._check(now)

    def _recent(self, seconds: float) -> tuple[np.ndarray, int]:
        """Onset strength of the last ``seconds`` (at most what is kept) and its first absolute frame."""
        envelope = self.envelope
        start = max(envelope.n_frames - int(seconds * self.fps), envelope.first_kept)
        return envelope.values(start, envelope.n_frames), start

    def _comb(self, lag: float) -> tuple[float, float]:
        """Latest beat time (s) and its comb score over the last 4 s at a period of ``lag`` frames."""
        strength, start = self._recent(4.0)
        phase = comb_phase(strength, lag, start)
        return float(self.envelope.frame_time(phase.frame)), phase.score

    def _comb_score_at(self, lag: float, t_beat: float) -> float:
        """Comb score over the last 4 s of the grid through ``t_beat`` seconds, ``lag`` frames apart."""
        strength, start = self._recent(4.0)
        return comb_score(strength, lag, float(self.envelope.frame_index(t_beat)), start)

    def _try_init(self, now: float) -> None:
        estimate = self.estimate()
        if self.envelope.n_frames < self.init_frames or estimate is None or self.follower.out_of_range:
            return
        if self.follower.periodicity < 0.1:
            return
        self._restart(now, estimate.lag)

    def _restart(self, now: float, lag: float, keep_period: float | None = None) -> None:
        """Set a new beat grid from the comb phase at period ``lag`` (frames)."""
        t_beat, _ = self._comb(lag)
        period = keep_period if keep_period is not None else lag / self.fps
        self._period_bad = 0
        self._phase_bad = 0
        restart_grid(self.follower, self.picker, self.envelope, now, t_beat, period,
                     self.estimate().periodicity_at(lag))

    def _check(self, now: float) -> None:
        """Restart the grid when the autocorrelation or the comb persistently disagree with it."""
        estimate = self.estimate()
        follower = self.follower
        if estimate is None or follower.out_of_range:
            self._period_bad = self._phase_bad = 0
            return
        t_latest, period = follower.state[0], follower.state[1]
        lag_k = period * self.fps
        ratio = estimate.lag / lag_k
        # another metrical level (x2, x3, /2, /3) needs stronger and longer evidence than a new tempo
        other_level = any(abs(math.log(ratio * m)) < 0.06 for m in (0.5, 1 / 3, 2.0, 3.0))
        need_ratio, need_count = (0.7, 8) if other_level else (0.8, 4)
        # a grid that keeps finding its beats is only moved to another metrical level; a tempo the
        # autocorrelation prefers otherwise may just lag behind a tempo change
        if (
            estimate.score_at(lag_k) < need_ratio * estimate.score
            and abs(math.log(ratio)) > 0.04
            and (other_level or follower.hit_rate < 0.7)
        ):
            self._period_bad += 1
        else:
            self._period_bad = 0
        if self._period_bad >= need_count:
            self._restart(now, estimate.lag)
            return
        t_best, s_best = self._comb(lag_k)
        # phase of the grid relative to the comb's beat
        d = ((t_best - t_latest) / period + 0.5) % 1.0 - 0.5
        if abs(d) > 0.15:
            s_grid = self._comb_score_at(lag_k, t_best - d * period)
            if s_grid < 0.7 * s_best:
                self._phase_bad += 1
            else:
                self._phase_bad = 0
        else:
            self._phase_bad = 0
        if self._phase_bad >= 4:
            self._restart(now, lag_k, keep_period=period)
