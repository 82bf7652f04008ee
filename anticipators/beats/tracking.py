"""Causal audio beat tracking that predicts upcoming beats, and the registry of beat trackers.

:class:`CausalBeatTracker` hears audio block by block and, using only the audio heard so far,
predicts the times of the next beats, so that a virtual performer can act on a beat before it sounds.
It combines the parts of this package:

    1. Onset strength from an envelope source (:mod:`anticipators.beats.envelope`; by default
       :class:`~anticipators.beats.envelope.SpectralFluxEnvelope`, causal log-mel spectral flux, hop 10 ms).
    2. Tempo, every 0.25 s (:mod:`anticipators.beats.tempo`): autocorrelation of the last 6 s of onset
       strength, candidate periods between ``60 / max_bpm`` and ``60 / min_bpm`` scored over four
       multiples with a log-normal preference for ``prior_bpm``. Optionally (``fast_pulse_check``) a
       pulse faster than ``max_bpm`` that is as periodic as the best candidate marks the tempo as out of
       range (smoothed over estimates).
    3. Phase at start and on resynchronisation (:mod:`anticipators.beats.phase`): a comb at the estimated
       period over the last 4 s of onset strength (recent beats weighted most) gives the latest beat.
    4. Beat filter (:mod:`anticipators.beats.follower`): a Kalman filter over beats fed, once the audio
       around an expected beat has been heard, by the salient onset there, timed on the waveform
       (:mod:`anticipators.beats.onsets`); it follows ramps and rubato, switches to a sudden tempo or
       phase change that two onsets agree on, and rates its confidence.
    5. Tempo and phase (``sync="dbn"``, the default, tracker ``causal``): a joint tempo-phase filter
       (:class:`~anticipators.beats.dbn.BeatPointerFilter`, a beat-pointer network filtered forward over
       onset strength turned into a beat activation; the onset strength it observes is the flux mixed with
       the increase over 4 frames, ``far_lag``) holds the posterior over (beat interval, position
       in the beat) from the first frame. From 1 s on its most probable interval and phase (with
       hysteresis) set the beat grid; whenever the follower's grid differs from the filter's (tempo by
       more than 2 %, phase by more than 5 % of a beat) the filter's grid is predicted, and the follower
       restarts on it, unless the follower's last three beats hold ``follower_margin`` times the onset
       strength of the filter's (a sudden change the follower found first). While the follower agrees,
       its precisely timed grid is predicted. In silence (the last 2 s without onset strength) the
       follower continues the grid the music left.
    6. Resynchronisation (``sync="comb"``, tracker ``causal-comb``, the tracker before the joint filter):
       if the autocorrelation persistently prefers another period while the grid misses its beats (or,
       over 2 s, another metrical level), or the comb persistently prefers another phase, the filter
       restarts from them; the first grid is set after ``init_seconds``.

Prediction
    :meth:`CausalBeatTracker.predict` extrapolates the filter state: about one beat period ahead of
    the latest observed beat at any time. The observation of a beat completes ``0.2 * period``
    (at most 100 ms) plus about 34 ms after it, so the next beat is predicted at least 200 ms ahead
    from its predecessor's onset alone for periods above about 0.29 s (tempi up to about 200 BPM). While
    the joint filter's grid is followed (``sync="dbn"``, it and the follower disagree), the predictions
    are the filter's latest beat plus whole periods, asked for after every block.

Baselines
    :class:`~anticipators.beats.baselines.IOIBaselineTracker` and
    :func:`~anticipators.beats.baselines.librosa_offline_beats` live in :mod:`anticipators.beats.baselines`;
    :func:`make_tracker` and :data:`TRACKER_NAMES` name them all. They, and
    :class:`~anticipators.beats.envelope.SpectralFluxEnvelope`, can still be imported from here.

Measured (``benchmarks/bench_beats.py``; FluidSynth ensembles of drums, bass, piano and strings,
100-140 BPM, 4/4 and 3/4, +10 % ramp over 16 bars, +-2 % rubato, predictions 200 ms ahead scored after
8 s): F-measure 1.0, mean absolute error 2.2 ms at 22.05 kHz and 1.5 ms at 44.1 kHz, mean signed error
within +-0.3 ms, real-time factor 0.0027 at 22.05 kHz and 0.0030 at 44.1 kHz in CPU time on one core of a
busy machine (load 2.8-3.6; :meth:`CausalBeatTracker.track`, as ``track_file`` runs it), of which the joint
filter's forward step is about 0.0005. ``benchmarks/bench_beats_real.py`` (real recordings and ASAP
renders, committed 200 ms ahead): F 0.801 and 0.351 (``causal-comb``: 0.725 and 0.285; ``causal-net``, the
learned activation of :mod:`anticipators.beats.network` as the joint filter's observation: 0.457 and 0.309).

All times are seconds from the first sample heard.
"""

from __future__ import annotations

import math

import numpy as np

from anticipators.beats.baselines import AubioTracker, IOIBaselineTracker, librosa_offline_beats
from anticipators.beats.dbn import BeatPointerFilter, FluxActivation
from anticipators.beats.envelope import EnvelopeSource, SpectralFluxEnvelope, mono_samples
from anticipators.beats.follower import BeatFollower
from anticipators.beats.network import BandFluxEnvelope, NetworkActivation
from anticipators.beats.onsets import WAVEFORM_AFTER, OnsetPicker
from anticipators.beats.phase import comb_phase, comb_score
from anticipators.beats.tempo import TempoEstimate, TempoEstimator

__all__ = [
    "SpectralFluxEnvelope",
    "CausalBeatTracker",
    "IOIBaselineTracker",
    "AubioTracker",
    "librosa_offline_beats",
    "make_tracker",
    "TRACKER_NAMES",
]


class CausalBeatTracker:
    """Causal beat tracker predicting upcoming beat times from audio heard block by block.

    Parameters
    ----------
    sample_rate : int
        Sample rate of the audio blocks in Hz (any rate from 4 kHz; frame sizes follow it).
    min_bpm, max_bpm : float
        Range of beat tempi considered.
    prior_bpm : float
        Centre of the log-normal tempo preference that decides between metrical levels.
    prior_octaves : float
        Width (standard deviation in octaves) of the tempo preference.
    tempo_window : float
        Seconds of onset strength used for tempo estimation.
    tempo_interval : float
        Seconds between tempo estimates.
    init_seconds : float
        Audio needed before the first beat grid is set.
    confidence_threshold : float
        Below this confidence, :meth:`predict` keeps using the last confident state. 0 by default: the
        predictions always follow the current state and are committed however unsure (on the real
        recordings of ``benchmarks/bench_beats_real.py`` a stale confident grid, and silence while
        unsure, cost more than an unsure grid: F 0.61 with 0.4, 0.65 with 0).
    onset_bias : float, optional
        Seconds subtracted from precise onset times; :attr:`ONSET_BIAS` (0) by default. Against the
        reference beats of :func:`agentsim.music.ensemble.render_ensemble` the timing rule finds
        onsets 0.1 ms early at 44.1 kHz and 0.7 ms early at 22.05 kHz, so no correction is applied.
    process_noise : (float, float, float)
        Standard deviations (s) of the filter's per-beat changes of beat time, period and period change.
    observation_noise : float
        Standard deviation (s) of a precisely timed onset; 8 ms is used when only the onset-strength
        peak is available.
    fast_pulse_check : bool
        Whether a pulse faster than ``max_bpm`` as periodic as the best candidate marks the tempo as out of
        range (no confidence, no grid). Off by default: eighth-note hi-hats trip it on steady pop, disco and
        hip-hop, whose beat the tracker has right (real recordings: 4 silent clips with it, none without;
        F 0.65 to 0.73).
    sync : {"dbn", "comb"}
        How the beat grid is set and moved: by the joint tempo-phase filter (``"dbn"``, the default; the
        tracker ``causal``) or by autocorrelation tempo and comb phase (``"comb"``, ``causal-comb``).
    dbn_options : dict, optional
        Keyword arguments for :class:`~anticipators.beats.dbn.BeatPointerFilter` (by default the tempo
        range of the tracker, every whole interval in frames, a preference for 100 BPM one octave wide).
    activation_options : dict, optional
        Keyword arguments for :class:`~anticipators.beats.dbn.FluxActivation` (scale 20, floor 0.01).
    dbn_init_seconds : float
        Audio heard before the joint filter's grid is used (with ``fast_pulse_check``, at least
        ``init_seconds``). 1 s: the filter's grid is unsure so early, but an unsure grid finds the first
        beats sooner than none (real recordings: median time to 4 correct beats 5.64 s with 1.5 s, 5.12 s
        with 1 s, 5.17 s with 0.5 s; 0.5 s also delays the conductor's recovery past its bar).
    dbn_patience : int
        Tempo estimates (every ``tempo_interval``) on which the filter's grid must be the better one before
        the follower restarts on it.
    dbn_predict : bool
        Whether predictions are the filter's grid while it and the follower disagree (True), or always the
        follower's, the filter only restarting it (False; real recordings F 0.711 against 0.744 when the
        choice was made).
    agree_tempo, agree_phase : float
        The follower agrees with the filter within this log tempo ratio and this fraction of a beat.
    follower_margin : float
        A follower's grid at another tempo than the filter's is kept while the onset strength of its last
        three beats is at least this many times that of the filter's (a sudden change found first).
    dbn_hysteresis : float
        The filter's chosen interval changes once another holds this many times its posterior.
    observation : {"flux", "network"}
        What the joint filter observes: the onset strength turned into an activation (``"flux"``,
        :class:`~anticipators.beats.dbn.FluxActivation`) or the learned causal beat activation
        (``"network"``, :class:`~anticipators.beats.network.NetworkActivation`, the tracker ``causal-net``;
        the envelope must keep the flux per band, as :class:`~anticipators.beats.network.BandFluxEnvelope`
        does, the default then).
    network_options : dict, optional
        Keyword arguments for :class:`~anticipators.beats.network.NetworkActivation` (floor 0.01).
    network_mix : float
        With the network observation, the weight of the flux activation mixed into it (0: the network alone).
    far_lag, far_weight : int, float
        What the joint filter observes (the default envelope's ``far_lag`` and ``far_weight``, see
        :class:`~anticipators.beats.envelope.SpectralFluxEnvelope`): the frame-to-frame flux mixed with
        weight 0.3 with the flux over 4 frames (40 ms), which counts onsets that rise over several frames.
        The grids' onset strength that decides between the filter's and the follower's grid, and between
        phases, is measured on it too. Measured on ``benchmarks/bench_beats_real.py``: real recordings F
        0.769 to 0.801, ASAP renders 0.329 to 0.351 (AMLt 0.245 to 0.302); ``far_lag`` 0 observes the flux
        alone. An envelope without ``observation_values`` is observed through its onset strength.
    envelope : anticipators.beats.envelope.EnvelopeSource, optional
        The onset-envelope front end the blocks are fed to (for instance an
        :class:`~anticipators.beats.envelope.ArrayEnvelope` of hand-made onset strength); its sample rate
        must be ``sample_rate``. By default a :class:`~anticipators.beats.envelope.SpectralFluxEnvelope`
        keeping ``max(12, tempo_window + 4)`` seconds.

    Attributes
    ----------
    envelope : anticipators.beats.envelope.EnvelopeSource
        The onset-envelope front end.
    tempo : anticipators.beats.tempo.TempoEstimator
        The tempo estimator.
    picker : anticipators.beats.onsets.OnsetPicker
        Picks and times the onsets the beat filter observes.
    follower : anticipators.beats.follower.BeatFollower
        The beat filter.
    time : float
        Seconds of audio heard.
    tempo_bpm : float
        Current tempo estimate in BPM (NaN before the first estimate).
    confidence : float
        Confidence in the current predictions, in [0, 1].
    locked : bool
        Whether a beat grid has been set.
    beats_observed : list of float
        Recent onset times (s) the filter accepted as beats (at most 64 are kept).
    """

    #: Default ``onset_bias`` (seconds).
    ONSET_BIAS = 0.0
    #: Interpolated onset-strength peaks come this much after energy onsets (seconds; measured on
    #: FluidSynth renders, about 2-3 ms); used when the waveform timing is not available.
    ODF_BIAS = 0.003
    #: Coarse (onset-strength peak) timing's standard deviation (seconds).
    COARSE_NOISE = 0.008
    #: Another phase at the same tempo is taken when the onset strength of its last three beats is this
    #: many times that of the grid held (the strength of equal clicks varies by 10 % with their alignment
    #: to the frames).
    PHASE_MARGIN = 1.3

    def __init__(
        self,
        sample_rate: int,
        min_bpm: float = 60.0,
        max_bpm: float = 200.0,
        *,
        prior_bpm: float = 120.0,
        prior_octaves: float = 1.0,
        tempo_window: float = 6.0,
        tempo_interval: float = 0.25,
        init_seconds: float = 3.0,
        confidence_threshold: float = 0.0,
        onset_bias: float | None = None,
        process_noise: tuple[float, float, float] = (0.002, 0.002, 0.001),
        observation_noise: float = 0.0015,
        envelope: EnvelopeSource | None = None,
        fast_pulse_check: bool = False,
        sync: str = "dbn",
        dbn_options: dict | None = None,
        activation_options: dict | None = None,
        dbn_init_seconds: float = 1.0,
        dbn_patience: int = 1,
        dbn_predict: bool = True,
        agree_tempo: float = 0.02,
        agree_phase: float = 0.05,
        follower_margin: float = 1.5,
        dbn_hysteresis: float = 2.0,
        observation: str = "flux",
        network_options: dict | None = None,
        network_mix: float = 0.0,
        far_lag: int = 4,
        far_weight: float = 0.3,
    ) -> None:
        if observation not in ("flux", "network"):
            raise ValueError(f"observation must be 'flux' or 'network', not {observation!r}")
        if sync not in ("dbn", "comb"):
            raise ValueError(f"sync must be 'dbn' or 'comb', not {sync!r}")
        self.sync = sync
        if not 0 < min_bpm < max_bpm:
            raise ValueError("need 0 < min_bpm < max_bpm")
        self.sample_rate = int(sample_rate)
        self.min_bpm = float(min_bpm)
        self.max_bpm = float(max_bpm)
        self.prior_bpm = float(prior_bpm)
        self.prior_octaves = float(prior_octaves)
        self.fast_pulse_check = bool(fast_pulse_check)
        use_network = observation == "network" and sync == "dbn"
        if envelope is None:
            make = BandFluxEnvelope if use_network else SpectralFluxEnvelope
            envelope = make(self.sample_rate, keep_seconds=max(12.0, tempo_window + 4.0),
                            far_lag=far_lag if sync == "dbn" else 0, far_weight=far_weight)
        elif use_network and not hasattr(envelope, "bands"):
            raise ValueError("the network observation needs an envelope that keeps the flux per band (BandFluxEnvelope)")
        elif int(envelope.sample_rate) != self.sample_rate:
            raise ValueError(f"the envelope's sample rate {envelope.sample_rate} is not {self.sample_rate}")
        self.envelope = envelope
        #: what the joint filter observes of the envelope, and grids are weighed on (its onset strength if it
        #: keeps no other observation)
        self._observed = getattr(envelope, "observation_values", envelope.values)
        fps = envelope.fps
        self._fps = fps
        self.tempo = TempoEstimator(fps, self.min_bpm, self.max_bpm, prior_bpm=self.prior_bpm,
                                    prior_octaves=self.prior_octaves)
        self._tempo_frames = int(round(tempo_window * fps))
        self._tempo_every = max(int(round(tempo_interval * fps)), 1)
        self._init_frames = int(round(init_seconds * fps))
        self.picker = OnsetPicker(envelope, peak_bias=self.ODF_BIAS,
                                  onset_bias=self.ONSET_BIAS if onset_bias is None else float(onset_bias))
        # seconds after the end of an onset search window until its frames and audio are complete
        ready_delay = max(envelope.latency + 2.0 / fps, WAVEFORM_AFTER) + 0.002
        self.follower = BeatFollower(self.picker.pick, self.min_bpm, self.max_bpm, ready_delay=ready_delay,
                                     confidence_threshold=confidence_threshold, process_noise=process_noise,
                                     observation_noise=observation_noise, coarse_noise=self.COARSE_NOISE)
        self._tempo_every_samples = self._tempo_every * envelope.hop
        self._next_tempo_sample = self._tempo_every_samples
        self._due_sample = self._tempo_every_samples  # next sample count at which work is needed
        # tempo state
        self._estimate: TempoEstimate | None = None  # latest tempo estimate
        self._fast_level = 0.0  # moving average of finding a pulse faster than max_bpm
        # resynchronisation state
        self._period_bad = 0
        self._phase_bad = 0
        # the joint tempo-phase filter (sync="dbn")
        self.dbn: BeatPointerFilter | None = None
        if sync == "dbn":
            options = {"min_bpm": self.min_bpm, "max_bpm": self.max_bpm, "n_tempi": None, "prior_bpm": 100.0,
                       "prior_octaves": 1.0, **(dbn_options or {})}
            self.dbn = BeatPointerFilter(fps, **options)
            self.activation = FluxActivation(fps, **{"scale": 20.0, "floor": 0.01, **(activation_options or {})})
            #: the learned activation (observation="network"), or None
            self.network = NetworkActivation(**(network_options or {})) if use_network else None
            self.network_mix = float(network_mix)
            # with the fast-pulse flag on, the grid waits for init_seconds, as the flag needs some estimates
            start = max(dbn_init_seconds, init_seconds) if self.fast_pulse_check else dbn_init_seconds
            self._dbn_init_frames = int(round(start * fps))
            self._dbn_patience = max(int(dbn_patience), 1)
            self._dbn_bad = 0
            self._dbn_cache = (-1, 0.0, 0.0)
            self._dbn_active = False
            self._wins_cache = (None, False)
            self._dbn_held: tuple[int, float] | None = None  # interval index and latest beat chosen
        self.dbn_predict = bool(dbn_predict) and self.dbn is not None
        self.agree_tempo = float(agree_tempo)
        self.agree_phase = float(agree_phase)
        self.follower_margin = float(follower_margin)
        self.dbn_hysteresis = float(dbn_hysteresis)

    # ------------------------------------------------------------------ public API

    @property
    def time(self) -> float:
        """Seconds of audio heard so far."""
        return self.envelope.n_samples / self.sample_rate

    @property
    def locked(self) -> bool:
        """Whether a beat grid has been set."""
        return self.follower.locked

    @property
    def confidence(self) -> float:
        """Confidence in the current predictions, in [0, 1]."""
        return self.follower.confidence

    @property
    def tempo_bpm(self) -> float:
        """Tempo of the beat grid in BPM (NaN before the first grid)."""
        return self.follower.tempo_bpm

    @property
    def beats_observed(self) -> list[float]:
        """Recent onset times (s) the filter accepted as beats (at most 64 are kept)."""
        return self.follower.beats_observed

    @property
    def confidence_threshold(self) -> float:
        """Below this confidence, :meth:`predict` keeps using the last confident state (0: never)."""
        return self.follower.confidence_threshold

    @confidence_threshold.setter
    def confidence_threshold(self, value: float) -> None:
        self.follower.confidence_threshold = float(value)

    @property
    def onset_bias(self) -> float:
        """Seconds subtracted from precise onset times."""
        return self.picker.onset_bias

    @onset_bias.setter
    def onset_bias(self, value: float) -> None:
        self.picker.onset_bias = float(value)

    def process(self, block) -> None:
        """Hear the next block of audio (mono float samples at ``sample_rate``; NaNs count as silence).

        The samples are buffered; onset strength, tempo and beat updates are computed when the next
        tempo estimate or beat observation falls due, so small blocks cost little.
        """
        self._hear(mono_samples(block))

    def _hear(self, x: np.ndarray) -> None:
        """:meth:`process` of samples already mono float32 and finite."""
        envelope = self.envelope
        if envelope.n_samples + x.size < self._due_sample:
            envelope.append(x)  # nothing falls due within this block
            return
        pos = 0
        while pos < x.size:
            take = min(x.size - pos, max(self._due_sample - envelope.n_samples, 1))
            envelope.append(x[pos : pos + take])
            pos += take
            if envelope.n_samples >= self._due_sample:
                self._work()

    def predict(self, horizon_beats: int = 4) -> np.ndarray:
        """Predicted times of the next ``horizon_beats`` beats at or after :attr:`time`.

        While :attr:`confidence` is below ``confidence_threshold`` (0 by default: never) the predictions
        continue the last state the tracker was confident in (if any).

        Parameters
        ----------
        horizon_beats : int
            Number of upcoming beats to predict.

        Returns
        -------
        numpy.ndarray
            Increasing beat times in seconds, all ``>= time``; empty before the first beat grid.
        """
        if self.dbn_predict:
            return self._predict_dbn(self.time, horizon_beats)
        return self.follower.predict(self.envelope.n_samples / self.sample_rate, horizon_beats)  # at self.time

    def _predict_dbn(self, now: float, horizon_beats: int) -> np.ndarray:
        """The beat follower's predictions unless the joint filter's grid is the better one
        (:meth:`_dbn_wins`), then the filter's."""
        follower = self.follower
        if follower.out_of_range:
            return np.zeros(0)  # a pulse faster than the range (fast_pulse_check): no grid
        if not self._dbn_active:
            return follower.predict(now, horizon_beats) if follower.locked else np.zeros(0)
        if follower.locked and not self._dbn_wins():
            return follower.predict(now, horizon_beats)
        t_beat, period = self._dbn_beat()
        k0 = math.ceil((now - t_beat) / period - 1e-9)
        return t_beat + period * np.arange(k0, k0 + int(horizon_beats))

    def track(self, audio, block_size: int = 512, horizon_beats: int = 4) -> list[dict]:
        """Hear ``audio`` block by block, predicting after each block, and return the predictions that changed.

        The same as calling :meth:`process` with each block of ``block_size`` samples and then
        :meth:`predict`, keeping each prediction that differs from the one before: after a block within
        which nothing falls due, the predictions are asked for only once they may have changed (the
        beat follower says until when they hold).

        Parameters
        ----------
        audio : array_like
            Mono samples at ``sample_rate`` (NaNs count as silence).
        block_size : int
            Samples per block.
        horizon_beats : int
            Beats predicted after each block.

        Returns
        -------
        list of dict
            ``{"t": time, "beats": [...]}`` after each block whose predictions differ from the previous
            ones (the first block's always), ``time`` being :attr:`time` after that block.
        """
        x = mono_samples(audio)
        envelope = self.envelope
        follower = self.follower
        size = max(int(block_size), 1)
        sample_rate = self.sample_rate
        updates: list[dict] = []
        last = None
        until = -math.inf
        a, total = 0, x.size
        while a < total:
            # the blocks from here within which nothing falls due and after which the predictions still
            # hold are only heard: their samples go to the envelope as one stretch
            due, b = self._due_sample, a
            heard = envelope.n_samples + size  # once the block from b is heard
            while b + size < total and heard < due and heard / sample_rate <= until:
                b += size
                heard += size
            if b > a:
                envelope.append(x[a:b])
                a = b
            block = x[a : a + size]
            quiet = envelope.n_samples + block.size < self._due_sample  # nothing falls due within it
            self._hear(block)
            a += size
            now = envelope.n_samples / sample_rate
            if quiet and now <= until:
                continue  # the same predictions as after the block before
            if self.dbn_predict:
                beats, until = self._predict_dbn(now, horizon_beats), now
            else:
                beats, until = follower.predict_until(now, horizon_beats)
            beats = beats.tolist()
            if beats != last:
                updates.append({"t": now, "beats": beats})
                last = beats
        return updates

    # ------------------------------------------------------------------ internals

    def _work(self) -> None:
        """Bring onset strength up to date, then estimate tempo and advance the beat filter as due."""
        envelope = self.envelope
        follower = self.follower
        envelope.update()
        dbn = self.dbn
        if dbn is not None and dbn.n_frames < envelope.n_frames:
            a = self.activation(self._observed(dbn.n_frames, envelope.n_frames))
            if self.network is not None:
                learned = self.network(envelope.bands(dbn.n_frames, envelope.n_frames))
                a = learned if self.network_mix <= 0.0 else (1.0 - self.network_mix) * learned + self.network_mix * a
            dbn.step(a)
        if envelope.n_samples >= self._next_tempo_sample:
            self._next_tempo_sample = envelope.n_samples + self._tempo_every_samples
            self._estimate_tempo()
            if dbn is not None:
                self._dbn_sync()
            elif not follower.locked:
                self._try_init()
            else:
                self._check_sync()
        if follower.locked:
            follower.advance(self.time)
        due = self._next_tempo_sample
        if follower.locked:
            due = min(due, int(math.ceil(follower.observe_time() * self.sample_rate)))
        self._due_sample = max(due, envelope.n_samples + 1)

    def _recent(self, seconds: float) -> tuple[np.ndarray, int]:
        """Onset strength of the last ``seconds`` (at most what is kept) and its first absolute frame."""
        envelope = self.envelope
        start = max(envelope.n_frames - int(seconds * self._fps), envelope.first_kept)
        return envelope.values(start, envelope.n_frames), start

    def _estimate_tempo(self) -> None:
        """Autocorrelation tempo estimate over the recent onset strength; updates the follower's inputs."""
        envelope = self.envelope
        follower = self.follower
        strength = envelope.values(envelope.n_frames - self._tempo_frames, envelope.n_frames)
        self.picker.recent_mean = float(np.add.reduce(strength) / strength.size) if strength.size else 0.0
        estimate = self.tempo.estimate(strength)
        self._estimate = estimate
        if estimate is None:
            follower.periodicity = 0.0
            follower.update_confidence()
            return
        self._fast_level = 0.7 * self._fast_level + 0.3 * float(estimate.fast_pulse and self.fast_pulse_check)
        if follower.out_of_range:
            follower.out_of_range = self._fast_level > 0.5
        else:
            follower.out_of_range = self._fast_level > 0.6
        lag = follower.state[1] * self._fps if follower.locked else estimate.lag
        follower.periodicity = estimate.periodicity_at(lag)
        follower.update_confidence()

    def _comb(self, lag: float) -> tuple[float, float]:
        """Latest beat time (s) and its comb score over the last 4 s at a period of ``lag`` frames."""
        strength, start = self._recent(4.0)
        phase = comb_phase(strength, lag, start)
        return float(self.envelope.frame_time(phase.frame)), phase.score

    def _comb_score_at(self, lag: float, t_beat: float) -> float:
        """Comb score over the last 4 s of the grid through ``t_beat`` seconds, ``lag`` frames apart."""
        strength, start = self._recent(4.0)
        return comb_score(strength, lag, float(self.envelope.frame_index(t_beat)), start)

    def _try_init(self) -> None:
        estimate = self._estimate
        if self.envelope.n_frames < self._init_frames or estimate is None or self.follower.out_of_range:
            return
        if self.follower.periodicity < 0.1:
            return
        self._restart(estimate.lag)

    def _restart(self, lag: float, keep_period: float | None = None) -> None:
        """Set a new beat grid from the comb phase at period ``lag`` (frames)."""
        t_beat, _ = self._comb(lag)
        period = keep_period if keep_period is not None else lag / self._fps
        # use the latest beat that is old enough to be timed precisely
        while t_beat > self.time - 0.06 - self.envelope.latency:
            t_beat -= period
        fine = self.picker.onset_near(t_beat)
        if math.isfinite(fine) and abs(fine - t_beat) < 0.04:
            t_beat = fine
        self._period_bad = 0
        self._phase_bad = 0
        self.follower.restart(t_beat, period, periodicity=self._estimate.periodicity_at(lag))

    def _dbn_beat(self) -> tuple[float, float]:
        """The joint filter's latest beat (s) and period (s): its most probable interval and, within it, its
        most probable position, with hysteresis against the grid chosen before. Another interval is taken
        once it holds ``dbn_hysteresis`` times the posterior of the one before; another phase at the same
        interval once the onset strength of its last three beats is clearly higher (two grids as strong,
        such as every other click of a fast pulse, would otherwise take turns, as the posterior of each
        rises at its own beats)."""
        dbn = self.dbn
        if self._dbn_cache[0] != dbn.n_frames:
            tempo = dbn.tempo_posterior()
            k = int(np.argmax(tempo))
            held = self._dbn_held
            if held is not None and held[0] != k and self.dbn_hysteresis * tempo[held[0]] > tempo[k]:
                k = held[0]
            interval = int(dbn.intervals[k])
            a = int(dbn.starts[k])
            position = int(np.argmax(dbn.p[a : a + interval]))
            t, period = self._dbn_grid(interval, position)
            if held is not None and held[0] == k:
                t_old = held[1]
                d = ((t - t_old) / period + 0.5) % 1.0 - 0.5
                if abs(d) > 0.1 and self._grid_strength(t, period) <= self.PHASE_MARGIN * self._grid_strength(t_old, period):
                    t = t_old
            self._dbn_held = (k, t)
            self._dbn_cache = (dbn.n_frames, t, period)
        return self._dbn_cache[1], self._dbn_cache[2]

    def _dbn_grid(self, interval: int, position: int) -> tuple[float, float]:
        """Latest beat (s) and period (s) of the state ``(interval, position)`` of the joint filter."""
        frame = int(self.dbn.n_frames - 1 - position)
        # the beat lies in the beat states after the wrap: at the strongest onset among those heard
        count = int(self.dbn.beat_width[int(np.searchsorted(self.dbn.intervals, interval))])
        region = self.envelope.values(frame, min(frame + count, self.dbn.n_frames))
        if region.size > 1:
            frame += int(np.argmax(region))
        return float(self.envelope.frame_time(float(frame))) - self.ODF_BIAS, interval / self._fps

    def _dbn_hears(self) -> bool:
        """Whether the joint filter has onsets to go by: the last 2 s hold some onset strength against the
        long-term mean (in silence the grid the music left is continued by the beat follower)."""
        if self.dbn.n_frames < self._dbn_init_frames or self.activation.mean <= 0.0:
            return False
        recent = self.envelope.values(self.envelope.n_frames - int(2.0 * self._fps), self.envelope.n_frames)
        return recent.size > 0 and float(recent.mean()) > 0.05 * self.activation.mean

    def _dbn_sync(self) -> None:
        """Set or move the beat grid to the joint filter's most probable tempo and phase."""
        follower = self.follower
        self._dbn_active = self._dbn_hears()
        if not self._dbn_active or follower.out_of_range:
            return
        t_dbn, period_dbn = self._dbn_beat()
        if not follower.locked:
            self._restart_at(t_dbn, period_dbn)
            return
        if self._dbn_wins() and not self._agrees(0.06, 0.2):
            self._dbn_bad += 1
        else:
            self._dbn_bad = 0
        if self._dbn_bad >= self._dbn_patience:
            self._dbn_bad = 0
            self._restart_at(t_dbn, period_dbn)

    def _agrees(self, tempo: float, phase: float) -> bool:
        """Whether the follower's grid is within ``tempo`` (log ratio) and ``phase`` (periods) of the filter's."""
        t_dbn, period_dbn = self._dbn_beat()
        t_latest, period = self.follower.state[0], self.follower.state[1]
        d = ((t_dbn - t_latest) / period + 0.5) % 1.0 - 0.5
        return abs(math.log(period / period_dbn)) < tempo and abs(d) < phase

    def _grid_strength(self, t_beat: float, period: float, beats: int = 3) -> float:
        """Mean onset strength at the latest ``beats`` beats heard of the grid through ``t_beat``, ``period`` apart:
        of what the joint filter observes (with ``far_lag``, the flux mixed with the increase over ``far_lag``
        frames), so that grids are weighed on the evidence the filter chose them by (real recordings F 0.792
        to 0.801 against the frame-to-frame flux)."""
        envelope = self.envelope
        last = envelope.n_frames - 3  # (an onset's strength peaks a frame or two after it)
        lag = period * self._fps
        frame = float(envelope.frame_index(t_beat + self.ODF_BIAS))
        frame += math.floor((last - frame) / lag) * lag  # the grid's latest beat heard
        teeth = np.rint(frame - lag * np.arange(beats)).astype(np.intp)
        a = max(int(teeth[-1]) - 1, envelope.first_kept)
        values = self._observed(a, last + 2)
        if values.size < 3:
            return 0.0
        # the strongest frame within one of each tooth (a peak is one frame wide)
        near = np.maximum(np.maximum(values[:-2], values[1:-1]), values[2:])  # near[i]: frames a+i .. a+i+2
        idx = teeth - a - 1
        idx = idx[(idx >= 0) & (idx < near.size)]
        return float(near[idx].sum() / beats)

    def _dbn_wins(self) -> bool:
        """Whether the joint filter's grid is to be followed rather than the follower's: it agrees with it
        (tempo within ``agree_tempo``, phase within ``agree_phase``), or it is not, and the onset strength of
        its last three beats is higher (so a sudden change the follower found before the filter stands)."""
        key = (self.dbn.n_frames, self.follower.state[0], self.follower.state[1])
        if self._wins_cache[0] != key:
            if self._agrees(self.agree_tempo, self.agree_phase):
                wins = False
            else:
                t_dbn, period_dbn = self._dbn_beat()
                s_dbn = self._grid_strength(t_dbn, period_dbn)
                s_follower = self._grid_strength(*self.follower.state[:2])
                if abs(math.log(self.follower.state[1] / period_dbn)) < 0.04:
                    # the same tempo at another phase: only clearly stronger beats move the grid (two
                    # grids as strong, such as every other click of a fast pulse, would take turns)
                    wins = s_dbn > self.PHASE_MARGIN * s_follower
                else:
                    wins = self.follower_margin * s_dbn > s_follower
            self._wins_cache = (key, wins)
        return self._wins_cache[1]

    def _restart_at(self, t_beat: float, period: float) -> None:
        """Set a new beat grid through ``t_beat`` seconds, ``period`` seconds apart."""
        while t_beat > self.time - 0.06 - self.envelope.latency:
            t_beat -= period
        fine = self.picker.onset_near(t_beat)
        if math.isfinite(fine) and abs(fine - t_beat) < 0.04:
            t_beat = fine
        lag = period * self._fps
        periodicity = self._estimate.periodicity_at(lag) if self._estimate is not None else 0.5
        self.follower.restart(t_beat, period, periodicity=periodicity)

    def _check_sync(self) -> None:
        """Restart the grid when the autocorrelation or the comb persistently disagree with it."""
        estimate = self._estimate
        follower = self.follower
        if estimate is None or follower.out_of_range:
            self._period_bad = self._phase_bad = 0
            return
        t_latest, period = follower.state[0], follower.state[1]
        lag_k = period * self._fps
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
            self._restart(estimate.lag)
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
            self._restart(lag_k, keep_period=period)


TRACKER_NAMES = ("causal", "causal-net", "causal-comb", "baseline", "aubio", "librosa_offline")
"""Tracker names accepted by :func:`anticipators.beats.evaluation.track_file` (all but the last also by
:func:`make_tracker`; ``"aubio"`` needs the optional aubio package; ``"librosa_offline"`` needs the
whole audio at once)."""


def make_tracker(name: str, sample_rate: int, **kwargs):
    """Make a causal tracker by name: ``"causal"`` (:class:`CausalBeatTracker`), ``"causal-net"`` (the same,
    ``observation="network"``), ``"causal-comb"`` (``sync="comb"``), ``"baseline"``
    (:class:`~anticipators.beats.baselines.IOIBaselineTracker`) or ``"aubio"``
    (:class:`~anticipators.beats.baselines.AubioTracker`; ImportError without aubio)."""
    if name == "causal":
        return CausalBeatTracker(sample_rate, **kwargs)
    if name == "causal-net":
        return CausalBeatTracker(sample_rate, **{"observation": "network", **kwargs})
    if name == "causal-comb":
        return CausalBeatTracker(sample_rate, **{"sync": "comb", **kwargs})
    if name == "baseline":
        return IOIBaselineTracker(sample_rate, **kwargs)
    if name == "aubio":
        return AubioTracker(sample_rate, **kwargs)
    raise ValueError(f"unknown causal tracker {name!r}; choose from {', '.join(TRACKER_NAMES[:-1])}")
