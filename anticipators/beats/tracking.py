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

    Steps 5 and 6 are the two strategies of :mod:`anticipators.beats.arbitration` (``JointFilterGrid`` and
    ``CombResync``), the tracker's :attr:`~CausalBeatTracker.grid`.

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

from anticipators.beats.arbitration import PHASE_MARGIN, CombResync, JointFilterGrid
from anticipators.beats.baselines import AubioTracker, IOIBaselineTracker, librosa_offline_beats
from anticipators.beats.dbn import BeatPointerFilter
from anticipators.beats.envelope import EnvelopeSource, SpectralFluxEnvelope, mono_samples
from anticipators.beats.follower import BeatFollower
from anticipators.beats.network import BandFluxEnvelope
from anticipators.beats.onsets import WAVEFORM_AFTER, OnsetPicker
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
    #: See :data:`anticipators.beats.arbitration.PHASE_MARGIN`.
    PHASE_MARGIN = PHASE_MARGIN

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
        # who sets and moves the grid (anticipators.beats.arbitration)
        self.grid: JointFilterGrid | CombResync
        if sync == "dbn":
            # with the fast-pulse flag on, the grid waits for init_seconds, as the flag needs some estimates
            start = max(dbn_init_seconds, init_seconds) if self.fast_pulse_check else dbn_init_seconds
            self.grid = JointFilterGrid(
                envelope, self.follower, self.picker, self._latest_estimate, min_bpm=self.min_bpm,
                max_bpm=self.max_bpm, odf_bias=self.ODF_BIAS, init_frames=int(round(start * fps)),
                dbn_options=dbn_options, activation_options=activation_options, network_options=network_options,
                use_network=use_network, network_mix=network_mix, patience=dbn_patience, agree_tempo=agree_tempo,
                agree_phase=agree_phase, follower_margin=follower_margin, hysteresis=dbn_hysteresis)
        else:
            self.grid = CombResync(envelope, self.follower, self.picker, self._latest_estimate,
                                   init_frames=self._init_frames)
        self.dbn_predict = bool(dbn_predict) and sync == "dbn"

    # ------------------------------------------------------------------ public API

    @property
    def time(self) -> float:
        """Seconds of audio heard so far."""
        return self.envelope.n_samples / self.sample_rate

    @property
    def dbn(self) -> BeatPointerFilter | None:
        """The joint tempo-phase filter (``sync="dbn"``), or None."""
        return getattr(self.grid, "dbn", None)

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
            return self.grid.predict(self.time, horizon_beats)
        return self.follower.predict(self.envelope.n_samples / self.sample_rate, horizon_beats)  # at self.time

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
                beats, until = self.grid.predict(now, horizon_beats), now
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
        self.grid.hear()
        if envelope.n_samples >= self._next_tempo_sample:
            self._next_tempo_sample = envelope.n_samples + self._tempo_every_samples
            self._estimate_tempo()
            self.grid.sync(self.time)
        if follower.locked:
            follower.advance(self.time)
        due = self._next_tempo_sample
        if follower.locked:
            due = min(due, int(math.ceil(follower.observe_time() * self.sample_rate)))
        self._due_sample = max(due, envelope.n_samples + 1)

    def _latest_estimate(self) -> TempoEstimate | None:
        """The latest tempo estimate (None before the first, or in silence)."""
        return self._estimate

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
