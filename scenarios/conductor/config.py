"""Pieces and scenario configurations, read from TOML and checked before anything runs.

A *piece* (``pieces/*.toml``) is what the score says: meter, number of bars, tempo, tempo changes and
dynamics markings. A *configuration* (``configs/*.toml``) says which piece is played, by which musicians
(General MIDI instruments, the parameters of their timing model), how the audio is rendered, and how
the conductor works. Every value has a default; a file only names what differs. Anything that cannot
be played (an unknown instrument, a meter without a conducting pattern, a tempo that is not positive,
...) raises :class:`~agentsim.errors.AgentsimError` with one message naming the file and the value.

Piece file::

    title = "Steady in four"
    meter = "4/4"          # 2/4, 3/4 or 4/4 (the conducting patterns)
    bars = 24
    tempo = 120.0          # BPM at bar 1
    music_seed = 3         # the notes (key, chords, patterns) of the generated score
    [[tempo_changes]]      # optional: from bar 13 on 132 BPM, reached over 2 bars (0: at once)
    bar = 13
    bpm = 132.0
    ramp_bars = 2
    [[dynamics]]           # markings pp, p, mp, mf, f, ff from a bar on
    bar = 1
    marking = "mf"

Configuration file: see ``configs/default.toml``, which spells out every key with its default.

Meter, tempo and instruments are the music library's: a piece's time is an
:class:`agentsim.music.tempo.TempoMap` (its tempo changes are :class:`~agentsim.music.tempo.TempoChange`),
instrument names are looked up by :func:`agentsim.music.instruments.gm_program`, and the dynamics
markings are :data:`agentsim.music.score.DYNAMICS_DB`. The files count bars and beats from 1, the music
library from 0.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agentsim.errors import AgentsimError, UsageError
from agentsim.music.instruments import DRUM_CHANNEL, DRUM_KIT, PARTS, default_part, gm_program, program_name
from agentsim.music.score import DYNAMICS_DB
from agentsim.music.tempo import Meter, TempoChange, TempoMap
from scenarios.conductor.names import STRATEGIES

HERE = Path(__file__).resolve().parent
PIECES_DIR = HERE / "pieces"
CONFIGS_DIR = HERE / "configs"
DEFAULT_CONFIG = CONFIGS_DIR / "default.toml"

#: Meters with conducting patterns (beats per bar).
METER_BEATS = (2, 3, 4)


def _fail(where: str, message: str) -> AgentsimError:
    return AgentsimError(f"{where}: {message}")


# ---------------------------------------------------------------------------------------------- pieces
@dataclass(frozen=True)
class Piece:
    """What the score says about time and loudness.

    Beats are numbered from 1 (the first beat of bar 1), as the conductor counts them and as BML refers to
    them (``anticipators:plan:beat17``); bars too. ``tempo_at(n)`` is the score's tempo from beat ``n`` to
    beat ``n + 1``.

    Attributes
    ----------
    title : str
        The piece's title.
    tempo_map : TempoMap
        Meter, tempo at bar 1 and tempo changes (beat ``n`` here is beat ``n - 1`` of the map).
    bars : int
        Number of bars.
    dynamics : tuple of (int, str)
        Dynamics markings (:data:`~agentsim.music.score.DYNAMICS_DB`) from a bar (1-based) on.
    music_seed : int
        Seed of the generated score's notes (:func:`~agentsim.music.score.build_score`).
    source : str
        Where the piece was read from.
    """

    title: str = "untitled"
    tempo_map: TempoMap = field(default_factory=lambda: TempoMap(120.0))
    bars: int = 24
    dynamics: tuple[tuple[int, str], ...] = ((1, "mf"),)
    music_seed: int = 3
    source: str = ""

    @property
    def meter(self) -> Meter:
        """The time signature."""
        return self.tempo_map.meter

    @property
    def tempo(self) -> float:
        """Score tempo (BPM) at bar 1."""
        return self.tempo_map.bpm

    @property
    def beats_per_bar(self) -> int:
        return self.meter.beats_per_bar

    @property
    def n_beats(self) -> int:
        return self.bars * self.beats_per_bar

    def bar_of(self, beat: int) -> int:
        """Bar (1-based) of beat ``beat`` (1-based)."""
        return (beat - 1) // self.beats_per_bar + 1

    def beat_in_bar(self, beat: int) -> int:
        """Position (1-based) of beat ``beat`` in its bar."""
        return (beat - 1) % self.beats_per_bar + 1

    def first_beat(self, bar: int) -> int:
        return (bar - 1) * self.beats_per_bar + 1

    def tempo_at(self, beat: float) -> float:
        """Score tempo (BPM) at beat position ``beat`` (1-based; fractions allowed)."""
        return float(self.tempo_map.tempo(beat - 1))

    def target_bpm(self) -> np.ndarray:
        """Score tempo of every beat 1..n_beats (index 0 is beat 1)."""
        return self.tempo_map.tempo(np.arange(self.n_beats))

    def score_offsets(self) -> np.ndarray:
        """Seconds from beat 1 to every beat 1..n_beats + 1 at the score's tempo."""
        return self.tempo_map.beat_times(self.n_beats + 1)

    def marking_at(self, bar: int) -> str:
        """The dynamics marking in force in bar ``bar``."""
        marking = "mf"
        for b, m in sorted(self.dynamics):
            if b <= bar:
                marking = m
        return marking

    def level_db(self, beat: int) -> float:
        """Level (dB, :data:`~agentsim.music.score.DYNAMICS_DB`) the score asks for at beat ``beat``."""
        return DYNAMICS_DB[self.marking_at(self.bar_of(beat))]


def _number(table: dict, key: str, where: str, default, kind=float, positive: bool = False,
            minimum: float | None = None, maximum: float | None = None):
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, f"{key} must be a number, got {value!r}")
    if kind is int:
        if isinstance(value, float) and not value.is_integer():
            raise _fail(where, f"{key} must be a whole number, got {value!r}")
        value = int(value)
    else:
        value = float(value)
    if not math.isfinite(value):
        raise _fail(where, f"{key} must be finite, got {value!r}")
    if positive and not value > 0:
        raise _fail(where, f"{key} must be > 0, got {value!r}")
    if minimum is not None and value < minimum:
        raise _fail(where, f"{key} must be >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise _fail(where, f"{key} must be <= {maximum}, got {value!r}")
    return value


def _check_keys(table: dict, allowed, where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise _fail(where, f"unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(allowed))}")


def parse_meter(text, where: str = "piece") -> tuple[int, int]:
    """``"4/4"`` -> (4, 4), the beats per bar and beat unit of a :class:`~agentsim.music.tempo.Meter`;
    AgentsimError for anything that is not 2/4, 3/4 or 4/4 (or x/2, x/8)."""
    num, sep, den = str(text).strip().partition("/")
    try:
        beats, unit = int(num), int(den if sep else 4)
    except ValueError:
        raise _fail(where, f"meter {text!r} is not a time signature like 4/4") from None
    if beats < 1 or unit < 1 or unit & (unit - 1):
        raise _fail(where, f"meter {text!r} is impossible: beats per bar must be >= 1 and the beat unit "
                           "a power of two")
    if beats not in METER_BEATS or unit not in (2, 4, 8):
        raise _fail(where, f"meter {text!r} has no conducting pattern: use 2/4, 3/4 or 4/4")
    return beats, unit


def piece_from_dict(data: dict, where: str = "piece") -> Piece:
    """Check a piece table and make a :class:`Piece`."""
    _check_keys(data, ("title", "meter", "bars", "tempo", "tempo_changes", "dynamics", "music_seed"), where)
    meter = parse_meter(data.get("meter", "4/4"), where)
    bars = _number(data, "bars", where, 24, int, minimum=1, maximum=2000)
    tempo = _number(data, "tempo", where, 120.0, positive=True)
    if not 30 <= tempo <= 240:
        raise _fail(where, f"tempo {tempo:g} BPM is outside the conductable range 30..240 BPM")
    changes = []
    for i, ch in enumerate(data.get("tempo_changes", [])):
        w = f"{where}: tempo_changes[{i}]"
        if not isinstance(ch, dict):
            raise _fail(w, "must be a table with bar and bpm")
        _check_keys(ch, ("bar", "bpm", "ramp_bars"), w)
        for key in ("bar", "bpm"):
            if key not in ch:
                raise _fail(w, f"needs {key}")
        bar = _number(ch, "bar", w, None, int, minimum=1, maximum=bars)
        bpm = _number(ch, "bpm", w, None, positive=True)
        if not 30 <= bpm <= 240:
            raise _fail(w, f"bpm {bpm:g} is outside the conductable range 30..240 BPM")
        changes.append(TempoChange(bar - 1, bpm, _number(ch, "ramp_bars", w, 0.0, minimum=0.0)))
    dynamics = []
    for i, d in enumerate(data.get("dynamics", [{"bar": 1, "marking": "mf"}])):
        w = f"{where}: dynamics[{i}]"
        if not isinstance(d, dict):
            raise _fail(w, "must be a table with bar and marking")
        _check_keys(d, ("bar", "marking"), w)
        bar = _number(d, "bar", w, 1, int, minimum=1, maximum=bars)
        marking = str(d.get("marking", "")).lower()
        if marking not in DYNAMICS_DB:
            raise _fail(w, f"unknown dynamics marking {d.get('marking')!r}; use one of {', '.join(DYNAMICS_DB)}")
        dynamics.append((bar, marking))
    return Piece(title=str(data.get("title", "untitled")),
                 tempo_map=TempoMap(tempo, Meter(*meter), changes=tuple(changes)),
                 bars=bars, dynamics=tuple(sorted(dynamics)) or ((1, "mf"),),
                 music_seed=_number(data, "music_seed", where, 3, int, minimum=0), source=where)


def _read_toml(path: Path) -> dict:
    if path.is_dir():
        raise AgentsimError(f"{path} is a folder, not a configuration file")
    if not path.is_file():
        raise AgentsimError(f"no such file: {path}")
    try:
        from agentsim.core.inputs import read_limited

        return tomllib.loads(read_limited(path).decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise AgentsimError(f"{path}: not UTF-8 text (byte {exc.start}: {exc.reason}); TOML files are UTF-8") from None
    except OSError as exc:
        raise AgentsimError(f"cannot read {path}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise AgentsimError(f"{path}: not valid TOML ({exc})") from None


def find_piece(name: str, relative_to: Path | None = None) -> Path:
    """Path of a piece given as a shipped name (``steady_4_4``) or a file path."""
    candidates = []
    p = Path(name)
    if relative_to is not None and not p.is_absolute():
        candidates.append(relative_to / p)
    candidates += [p, PIECES_DIR / p, PIECES_DIR / f"{name}.toml"]
    for c in candidates:
        if c.is_file():
            return c
    shipped = ", ".join(sorted(q.stem for q in PIECES_DIR.glob("*.toml")))
    raise AgentsimError(f"no piece {name!r} (a file, or one of the shipped pieces: {shipped})")


def load_piece(name: str, relative_to: Path | None = None) -> Piece:
    """Read and check a piece (a shipped name or a TOML file)."""
    path = find_piece(name, relative_to)
    return piece_from_dict(_read_toml(path), str(path))


# ---------------------------------------------------------------------------------------------- musicians
@dataclass(frozen=True)
class ModelParams:
    """Timing model of one musician: a timekeeper with linear phase and period correction.

    Musician ``i`` plays beat ``n + 1`` at ``t(n+1) = k(n+1) + m(n+1)``, where the timekeeper runs
    ``k(n+1) = k(n) + T(n) + e(n) - sum_j alpha_j A_j(n)`` and the period follows
    ``T(n+1) = T(n) - sum_j beta_j A_j(n) + drag (T_c - T(n))`` (Vorberg & Wing 1996; Mates 1994;
    Repp & Keller 2004). ``A_j(n) = t_i(n) - t_j(n)`` is the asynchrony to partner ``j`` (the
    conductor's ictus as seen, or another musician as heard), ``e`` timekeeper noise, ``m`` motor
    delay noise and ``T_c`` the musician's comfortable period. Asynchronies of half a period or more
    are not corrected (such a beat cannot be told from the next or the previous one).

    Attributes
    ----------
    alpha_conductor : float
        Phase correction toward the conductor's ictus (per beat). 0.25: within the 0.1-0.3 that
        Wing et al. (2014) estimated for each partner of a string quartet.
    beta_conductor : float
        Period correction toward the conductor. Small: period correction is much weaker than phase
        correction and mostly follows lasting tempo changes (Repp 2005; Repp & Keller 2004, about 0.1).
    alpha_partner : float
        Phase correction toward each other musician. 0.1 per partner (Wing et al. 2014: 0.1-0.3; the
        sum over three partners stays below the 0.5-0.6 where correction becomes unstable with noise).
    beta_partner : float
        Period correction toward each other musician (0: Wing et al. 2014 needed none).
    timekeeper_sd : float
        Standard deviation (s) of the timekeeper intervals: 12 ms (Vorberg & Wing 1996: 10-20 ms at
        periods of 0.4-0.6 s; Wing et al. 2014 similar for professional players).
    motor_sd : float
        Standard deviation (s) of the motor delays: 5 ms (Vorberg & Wing 1996; Repp 2005).
    ictus_sd : float
        Standard deviation (s) with which the conductor's ictus is seen: 10 ms. Musicians time the
        ictus from the downward acceleration of the stroke (Luck & Sloboda 2009), so they see it coming
        and perceive it on time despite the visual delay, but less precisely than a sound.
    drag : float
        Per-beat pull of the period back toward the comfortable period (the tendency to drag): 0.03.
        Not from the literature: it makes an ensemble that has been led to a faster tempo drift back
        without guidance, by about 3 % of the difference per beat.
    decide_fraction : float
        When the next onset is committed: this fraction of a period after the musician's own onset
        (0.6). Information seen or heard later only counts for the beat after.
    """

    alpha_conductor: float = 0.25
    beta_conductor: float = 0.1
    alpha_partner: float = 0.1
    beta_partner: float = 0.0
    timekeeper_sd: float = 0.012
    motor_sd: float = 0.005
    ictus_sd: float = 0.010
    drag: float = 0.03
    decide_fraction: float = 0.6


_MODEL_LIMITS = {"alpha_conductor": (0.0, 1.0), "beta_conductor": (0.0, 1.0), "alpha_partner": (0.0, 1.0),
                 "beta_partner": (0.0, 1.0), "timekeeper_sd": (0.0, 0.2), "motor_sd": (0.0, 0.1),
                 "ictus_sd": (0.0, 0.2), "drag": (0.0, 1.0), "decide_fraction": (0.3, 0.9)}


def _model_from(table: dict, base: ModelParams, where: str) -> ModelParams:
    values = {}
    for f in dataclasses.fields(ModelParams):
        if f.name in table:
            lo, hi = _MODEL_LIMITS[f.name]
            values[f.name] = _number(table, f.name, where, None, minimum=lo, maximum=hi)
    return dataclasses.replace(base, **values)


@dataclass(frozen=True)
class MusicianConfig:
    """One musician: a name, a General MIDI instrument on its own MIDI channel, the line of the score it
    plays and its timing model."""

    name: str
    program: int  # General MIDI program; DRUM_KIT (-1) for the percussion kit
    channel: int
    part: str
    model: ModelParams = field(default_factory=ModelParams)

    @property
    def instrument(self) -> str:
        return program_name(self.program)


def instrument_program(name, where: str) -> int:
    """General MIDI program of an instrument name or number (-1: the percussion kit), or AgentsimError."""
    try:
        return gm_program(name)
    except ValueError as exc:
        raise _fail(where, str(exc)) from None


# ---------------------------------------------------------------------------------------------- scenario
@dataclass(frozen=True)
class EnsembleConfig:
    """The simulated ensemble.

    Attributes
    ----------
    start_bpm : float
        Tempo the ensemble starts at (the default scenario: 108 BPM, 10 % below the score's 120).
    comfortable_bpm : float or None
        Tempo each musician drifts back to (the drag's pull); by default ``start_bpm``.
    comfortable_spread : float
        Relative standard deviation of the musicians' comfortable tempi around it (0.5 %).
    start_time : float
        When the ensemble plays beat 1 (s); the conductor cued it and numbers beats from there.
    visual_delay : float
        Seconds after an ictus (or any gesture's stroke) until a musician has seen it: 0.1 s (visual
        processing and reaction; the ictus itself is perceived on time, see ``ModelParams.ictus_sd``).
    loudness_db : float
        How much louder (positive) or softer (negative) than marked the ensemble plays: -6 dB.
    louder_step_db : float
        How much louder the musicians play after seeing a "play louder" gesture (up to the marked level).
    musicians : tuple of MusicianConfig
    """

    start_bpm: float = 108.0
    comfortable_bpm: float | None = None
    comfortable_spread: float = 0.005
    start_time: float = 0.5
    visual_delay: float = 0.1
    loudness_db: float = -6.0
    louder_step_db: float = 3.0
    musicians: tuple[MusicianConfig, ...] = ()


@dataclass(frozen=True)
class AudioConfig:
    """How the ensemble is rendered: FluidSynth at ``sample_rate`` with the General MIDI ``soundfont``,
    in blocks of ``block_seconds`` that the conductor hears as the simulation advances."""

    sample_rate: int = 22050
    gain: float = 0.3
    block_seconds: float = 0.02
    reverb: bool = False
    soundfont: str = ""


@dataclass(frozen=True)
class ConductorConfig:
    """How the conductor works.

    Attributes
    ----------
    strategy : str
        ``follow``, ``target``, ``lead`` or ``best``.
    lead_seconds : float
        How far ahead of (or behind) the predicted beats ``lead`` conducts while the ensemble is too slow
        (too fast).
    lead_tolerance : float
        Relative tempo error within which ``lead`` just follows.
    join_confidence : float
        Tracker confidence at which the conductor starts conducting (at the next bar it can prepare).
    prepare_seconds : float
        The first ictus comes at least this long after the conductor decides to join.
    horizon_seconds : float
        Conducting BML is submitted bar by bar, each bar once its first beat is planned within this time.
    asynchrony_sd_budget : float
        ``best``: the standard deviation of the ensemble's asynchrony to the ictus it may cause (s).
    horizon_beats : int
        ``best``: beats planned ahead.
    louder_threshold_db : float
        A "play louder" gesture when the ensemble is this much softer than the score asks.
    louder_every_bars : int
        At most one "play louder" gesture per this many bars.
    stop_confidence : float
        Below this tracker confidence the ensemble is not heard to keep a beat...
    stop_after_seconds : float
        ... and after this long without, the conductor stops the piece.
    fps : float
        Frame rate of the written motion (BVH).
    tracker_observation_sd : float
        Standard deviation (s) the beat tracker expects of a beat's onset around a smooth beat. Its
        default (1.5 ms) suits mechanically exact renders; players' onsets scatter by 10-20 ms
        (Wing et al. 2014), and a tracker expecting that keeps more beats in its gate.
    tracker_process_sd : tuple of float
        The tracker's per-beat process noise (s) of beat time, period and period change; a little more than
        its default, because a conducted ensemble changes tempo within a few beats.
    """

    strategy: str = "best"
    lead_seconds: float = 0.05
    lead_tolerance: float = 0.01
    join_confidence: float = 0.5
    prepare_seconds: float = 1.0
    horizon_seconds: float = 2.0
    asynchrony_sd_budget: float = 0.040
    horizon_beats: int = 8
    louder_threshold_db: float = 3.0
    louder_every_bars: int = 2
    stop_confidence: float = 0.3
    stop_after_seconds: float = 3.0
    fps: float = 30.0
    tracker_observation_sd: float = 0.015
    tracker_process_sd: tuple[float, float, float] = (0.003, 0.004, 0.002)

    def tracker_options(self) -> dict:
        """Keyword arguments for the causal beat tracker."""
        return {"observation_noise": self.tracker_observation_sd, "process_noise": tuple(self.tracker_process_sd)}


@dataclass(frozen=True)
class ScenarioConfig:
    """Everything one run needs: the piece, the ensemble, the audio and the conductor."""

    piece: Piece
    ensemble: EnsembleConfig
    audio: AudioConfig
    conductor: ConductorConfig
    source: str = ""


def default_musicians(model: ModelParams) -> tuple[MusicianConfig, ...]:
    """Drums, finger bass, piano and slow strings, each on its own channel."""
    return (MusicianConfig("drums", DRUM_KIT, DRUM_CHANNEL, "drums", model),
            MusicianConfig("bass", 33, 1, "bass", model),
            MusicianConfig("piano", 0, 0, "piano", model),
            MusicianConfig("strings", 49, 2, "strings", model))


def config_from_dict(data: dict, where: str = "config", base_dir: Path | None = None) -> ScenarioConfig:
    """Check a configuration table and make a :class:`ScenarioConfig`."""
    _check_keys(data, ("piece", "ensemble", "audio", "conductor"), where)
    piece_spec = data.get("piece", "steady_4_4")
    if isinstance(piece_spec, dict):
        piece = piece_from_dict(piece_spec, f"{where}: [piece]")
    else:
        try:
            piece = load_piece(str(piece_spec), base_dir)
        except AgentsimError as exc:
            raise _fail(where, str(exc)) from None

    ens = data.get("ensemble", {})
    w = f"{where}: [ensemble]"
    if not isinstance(ens, dict):
        raise _fail(w, "must be a table")
    _check_keys(ens, ("start_bpm", "comfortable_bpm", "comfortable_spread", "start_time", "visual_delay",
                      "loudness_db", "louder_step_db", "model", "musicians"), w)
    start_bpm = _number(ens, "start_bpm", w, 108.0, positive=True)
    if not 30 <= start_bpm <= 240:
        raise _fail(w, f"start_bpm {start_bpm:g} is outside 30..240 BPM")
    comfortable = ens.get("comfortable_bpm")
    if comfortable is not None:
        comfortable = _number(ens, "comfortable_bpm", w, None, positive=True)
        if not 30 <= comfortable <= 240:
            raise _fail(w, f"comfortable_bpm {comfortable:g} is outside 30..240 BPM")
    model_table = ens.get("model", {})
    if not isinstance(model_table, dict):
        raise _fail(w, "model must be a table")
    _check_keys(model_table, [f.name for f in dataclasses.fields(ModelParams)], f"{w} model")
    model = _model_from(model_table, ModelParams(), f"{w} model")
    musicians = []
    specs = ens.get("musicians")
    if specs is None:
        musicians = list(default_musicians(model))
    else:
        if not isinstance(specs, list) or not specs:
            raise _fail(w, "musicians must be a non-empty list of [[ensemble.musicians]] tables")
        free = [c for c in range(16) if c != DRUM_CHANNEL]
        for i, spec in enumerate(specs):
            mw = f"{w} musicians[{i}]"
            if not isinstance(spec, dict):
                raise _fail(mw, "must be a table")
            allowed = ["name", "instrument", "part"] + [f.name for f in dataclasses.fields(ModelParams)]
            _check_keys(spec, allowed, mw)
            if "instrument" not in spec:
                raise _fail(mw, "needs an instrument")
            program = instrument_program(spec["instrument"], mw)
            part = str(spec.get("part", default_part(program))).lower()
            if part not in PARTS:
                raise _fail(mw, f"unknown part {part!r}; use one of {', '.join(PARTS)}")
            if (program < 0) != (part == "drums"):
                raise _fail(mw, "the drum part needs the drum kit (instrument = \"drums\") and the drum kit "
                                "can only play the drum part")
            if program < 0:
                channel = DRUM_CHANNEL
            else:
                if not free:
                    raise _fail(mw, "too many melodic instruments: at most 15 (one MIDI channel each)")
                channel = free.pop(0)
            name = str(spec.get("name", f"{part}{i + 1}"))
            musicians.append(MusicianConfig(name, program, channel, part, _model_from(spec, model, mw)))
        names = [m.name for m in musicians]
        if len(set(names)) != len(names):
            raise _fail(w, f"musician names must differ: {names}")
        if sum(m.program < 0 for m in musicians) > 1:
            raise _fail(w, "only one drum kit (General MIDI has one percussion channel)")
    ensemble = EnsembleConfig(
        start_bpm=start_bpm, comfortable_bpm=comfortable,
        comfortable_spread=_number(ens, "comfortable_spread", w, 0.005, minimum=0.0, maximum=0.1),
        start_time=_number(ens, "start_time", w, 0.5, minimum=0.1, maximum=10.0),
        visual_delay=_number(ens, "visual_delay", w, 0.1, minimum=0.0, maximum=0.3),
        loudness_db=_number(ens, "loudness_db", w, -6.0, minimum=-30.0, maximum=10.0),
        louder_step_db=_number(ens, "louder_step_db", w, 3.0, minimum=0.0, maximum=20.0),
        musicians=tuple(musicians))

    aud = data.get("audio", {})
    w = f"{where}: [audio]"
    if not isinstance(aud, dict):
        raise _fail(w, "must be a table")
    _check_keys(aud, ("sample_rate", "gain", "block_seconds", "reverb", "soundfont"), w)
    sample_rate = _number(aud, "sample_rate", w, 22050, int, minimum=8000, maximum=96000)
    block = _number(aud, "block_seconds", w, 0.02, minimum=0.005, maximum=0.1)
    audio = AudioConfig(sample_rate=sample_rate, gain=_number(aud, "gain", w, 0.3, positive=True, maximum=5.0),
                        block_seconds=block, reverb=bool(aud.get("reverb", False)),
                        soundfont=str(aud.get("soundfont", "")))
    if audio.soundfont and not Path(audio.soundfont).is_file():
        raise _fail(w, f"soundfont {audio.soundfont!r} not found")

    con = data.get("conductor", {})
    w = f"{where}: [conductor]"
    if not isinstance(con, dict):
        raise _fail(w, "must be a table")
    _check_keys(con, [f.name for f in dataclasses.fields(ConductorConfig)], w)
    strategy = str(con.get("strategy", "best"))
    if strategy not in STRATEGIES:
        raise _fail(w, f"unknown strategy {strategy!r}; use one of {', '.join(STRATEGIES)}")
    conductor = ConductorConfig(
        strategy=strategy,
        lead_seconds=_number(con, "lead_seconds", w, 0.05, minimum=0.0, maximum=0.2),
        lead_tolerance=_number(con, "lead_tolerance", w, 0.01, minimum=0.0, maximum=0.2),
        join_confidence=_number(con, "join_confidence", w, 0.5, minimum=0.0, maximum=1.0),
        prepare_seconds=_number(con, "prepare_seconds", w, 1.0, minimum=0.7, maximum=5.0),
        horizon_seconds=_number(con, "horizon_seconds", w, 2.0, minimum=1.0, maximum=10.0),
        asynchrony_sd_budget=_number(con, "asynchrony_sd_budget", w, 0.040, positive=True, maximum=0.2),
        horizon_beats=_number(con, "horizon_beats", w, 8, int, minimum=2, maximum=32),
        louder_threshold_db=_number(con, "louder_threshold_db", w, 3.0, positive=True),
        louder_every_bars=_number(con, "louder_every_bars", w, 2, int, minimum=1),
        stop_confidence=_number(con, "stop_confidence", w, 0.3, minimum=0.0, maximum=1.0),
        stop_after_seconds=_number(con, "stop_after_seconds", w, 3.0, positive=True),
        fps=_number(con, "fps", w, 30.0, positive=True, maximum=240.0),
        tracker_observation_sd=_number(con, "tracker_observation_sd", w, 0.015, positive=True, maximum=0.1),
        tracker_process_sd=_triple(con, "tracker_process_sd", w, (0.003, 0.004, 0.002)))
    return ScenarioConfig(piece, ensemble, audio, conductor, where)


def _triple(table: dict, key: str, where: str, default) -> tuple[float, float, float]:
    value = table.get(key, list(default))
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v <= 0.1 for v in value)):
        raise _fail(where, f"{key} must be three numbers in (0, 0.1], got {value!r}")
    return tuple(float(v) for v in value)


def config_names() -> list[str]:
    """The short names of the shipped configurations (``--config NAME``), sorted."""
    return sorted(p.stem for p in CONFIGS_DIR.glob("*.toml"))


def find_config(name: str | Path) -> Path:
    """A configuration file by its path, or a shipped one by its short name (``waltz_3_4``, or
    ``waltz_3_4.toml``) when no file of that name is where the command runs."""
    path = Path(name)
    if path.exists() or len(path.parts) != 1:
        return path
    shipped = CONFIGS_DIR / (path.name if path.suffix == ".toml" else f"{path.name}.toml")
    if shipped.is_file():
        return shipped
    raise UsageError(f"no configuration file or shipped configuration named {str(name)!r} "
                        f"(shipped: {', '.join(config_names())}; 'agentsim run conductor --list-configs')")


def load_config(path: str | Path | None = None, overrides: dict | None = None,
                described: str = "") -> ScenarioConfig:
    """Read and check a configuration file (the default scenario when ``path`` is None).

    ``overrides`` replaces keys of its tables before anything is checked, as the command line's knobs do:
    ``{"piece": {"tempo": 132, "meter": "3/4", "bars": 16}, "ensemble": {"start_bpm": 100},
    "conductor": {"fps": 60}}``; a piece named by the file is read first, so that only those keys change,
    and fewer ``bars`` drop the piece's markings past its new end. ``described`` says where they came from
    in error messages (``--meter 5/4``).
    """
    path = find_config(path) if path is not None else DEFAULT_CONFIG
    data = _read_toml(path)
    base_dir = path.resolve().parent
    for table, values in (overrides or {}).items():
        values = {k: v for k, v in values.items() if v is not None}
        if not values:
            continue
        current = data.get(table, "steady_4_4" if table == "piece" else {})
        if table == "piece" and not isinstance(current, dict):
            try:
                current = _read_toml(find_piece(str(current), base_dir))
            except AgentsimError as exc:
                raise _fail(str(path), str(exc)) from None
        if table == "piece" and "bars" in values:
            for key in ("dynamics", "tempo_changes"):
                if isinstance(current.get(key), list):
                    current = {**current, key: [m for m in current[key]
                                                if not isinstance(m, dict) or m.get("bar", 1) <= values["bars"]]}
        data = {**data, table: {**current, **values}}
    where = f"{path} with {described}" if described else str(path)
    return config_from_dict(data, where, base_dir)
