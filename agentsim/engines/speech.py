"""The speech engine: speech behaviours timed by a text-to-speech backend, played rigidly.

The planner asks the backend for the utterance's timeline (words, marks, duration) or, with
``timing="linear"``, only Chang's linear characters-to-time model; a speech behaviour's sync points are
its start, the ``<sync>`` marks in its text and its end, at those times. Speech is not stretched:
constraints that would stretch it make it invalid.

Once speech starts, its timing belongs to the audio. Without a :class:`SpeechConfig` strategy the audio
plays exactly as planned and the speech's pegs are detached from whatever they were tied to. With one,
the audio really starts after a playback latency, its clock drifts, and its progress events reach the
realizer late, scattered and in bursts (:mod:`speech_timing.delivery`); an animator-time strategy
(:mod:`speech_timing.animator_time`) turns them into ``t_A``, and every sync point of the speech, with
everything tied to it, is passed when ``t_A`` reaches its planned speech time.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

from agentsim.core.block import Behaviour
from agentsim.core.engine import Engine, EngineContext, Planner
from agentsim.errors import ScheduleError
from agentsim.core.pegboard import ComputedPeg, OffsetPeg, TimeCache
from agentsim.core.interruption import set_key_time
from agentsim.core.timed import KeyRef, TimedBehaviour, parameter_at
from speech_timing.backend import Prosody, SpeechText, TTSBackend, Utterance

#: Speech keys may be off their rigid spacing by this much (seconds) before the speech is invalid.
RIGID_TOLERANCE = 1e-6


@dataclass
class SpeechConfig:
    """How speech meets the animation: what the planner knows and how progress events arrive.

    Parameters
    ----------
    strategy : str or None
        Animator-time strategy (a key of ``speech_timing.animator_time.STRATEGIES``); None plays the
        audio exactly as planned, with no latency and no events.
    delivery : DeliveryModel
        Playback latency, audio clock drift and the progress-event channel.
    timing : {"tts", "linear"}
        What the planner knows in advance: the backend's own timeline, or only the linear model.
    linear_model : LinearModel, optional
        Chang's linear model; calibrated on the bundled texts when needed and not given.
    seed : int
        Seed of the random generator of the first speech (later speeches use seed + 1, + 2, ...).
    trace_frame : float or None
        If set, ``t_A`` is sampled every this many seconds while speech plays (for snap and stall metrics).
    """

    strategy: str | None = None
    delivery: object = None
    timing: str = "tts"
    linear_model: object = None
    seed: int = 0
    trace_frame: float | None = None

    def __post_init__(self) -> None:
        if self.timing not in ("tts", "linear"):
            raise ValueError(f"timing must be 'tts' or 'linear', not {self.timing!r}")
        if self.strategy is not None:
            from speech_timing.animator_time import check_strategy
            from speech_timing.delivery import DeliveryModel

            check_strategy(self.strategy)
            if self.delivery is None:
                self.delivery = DeliveryModel()


def speech_text(behaviour: Behaviour, rate: float = 1.0) -> SpeechText:
    """What a backend is asked to speak for a speech behaviour: its text, sync marks and prosody spans,
    at ``rate`` times the backend's own rate."""
    prosody = tuple(Prosody(kind, start, end, tuple((str(name), str(value)) for name, value in
                                                    (attrs.items() if isinstance(attrs, dict) else attrs)))
                    for kind, start, end, attrs in behaviour.prosody)
    return SpeechText(behaviour.text, tuple(behaviour.marks), rate, prosody)


class SpeechPlanner(Planner):
    """Times speech with a :class:`~speech_timing.backend.TTSBackend` (or the linear model)."""

    behaviour_types = ("speech",)
    rigid = True

    def __init__(self, backend: TTSBackend, config: SpeechConfig | None = None):
        super().__init__()
        self.backend = backend
        self.config = config or SpeechConfig()
        self._utterances: dict[int, Utterance] = {}
        self._plans: dict[int, object] = {}
        self.speaking: set[int] = set()  # behaviours timed by their audio now, not by the plan

    def utterance(self, behaviour: Behaviour) -> Utterance:
        """The backend's utterance of a speech behaviour (its text, marks and prosody), made once."""
        key = id(behaviour)
        utt = self._utterances.get(key)
        if utt is None:
            utt = self.backend.synthesize(speech_text(behaviour))
            self._utterances[key] = utt
        return utt

    def set_utterance(self, behaviour: Behaviour, utterance: Utterance) -> None:
        """Speak ``behaviour`` as ``utterance`` from now on (it was synthesised again, at another rate)."""
        self._utterances[id(behaviour)] = utterance

    def linear_model(self):
        if self.config.linear_model is None:
            from speech_timing.linear_model import default_linear_model

            self.config.linear_model = default_linear_model(self.backend)
        return self.config.linear_model

    def linear_plan(self, behaviour: Behaviour):
        """The speech plan made from the linear model alone (``timing="linear"``).

        The linear model knows the text only: the behaviour's prosody spans are ignored here (see
        :func:`~speech_timing.linear_model.plan_from_linear`).
        """
        key = id(behaviour)
        if key not in self._plans:
            from speech_timing.linear_model import plan_from_linear

            self._plans[key] = plan_from_linear(behaviour.text, self.linear_model())
        return self._plans[key]

    def preferred(self, behaviour: Behaviour) -> list[float]:
        if self.config.timing == "linear":
            plan = self.linear_plan(behaviour)
            chars, onsets = list(plan.word_chars), list(plan.word_onsets)
            marks = {}
            for offset, name in behaviour.marks:
                k = next((i for i, c in enumerate(chars) if c >= offset), None)
                marks[name] = float(onsets[k]) if k is not None else float(plan.duration)
            return [0.0] + [marks[s] for s in behaviour.sync_ids[1:-1]] + [float(plan.duration)]
        utt = self.utterance(behaviour)
        marks = {m.name: m.time for m in utt.marks}
        return [0.0] + [marks[s] for s in behaviour.sync_ids[1:-1]] + [utt.duration]

    def check_times(self, behaviour, preferred, times) -> None:
        super().check_times(behaviour, preferred, times)
        if id(behaviour) in self.speaking:
            return
        for p, t in zip(preferred, times):
            if abs((t - times[0]) - p) > RIGID_TOLERANCE:
                raise ScheduleError("speech cannot be stretched or skewed to meet its constraints")

    def judges(self, timed: TimedBehaviour) -> bool:
        # once speaking it follows its audio: its sync points come in order, when they are heard
        return id(timed.behaviour) not in self.speaking and super().judges(timed)

    def remove(self, timed: TimedBehaviour) -> None:
        super().remove(timed)
        for store in (self._utterances, self._plans):
            store.pop(id(timed.behaviour), None)
        self.speaking.discard(id(timed.behaviour))


class SpeechTimePeg(ComputedPeg):
    """A peg at speech time ``s`` of an utterance being played: its time is when animator time reaches s."""

    __slots__ = ("playback", "s")

    def __init__(self, playback: "Playback", s: float, name: str = "", cache: TimeCache | None = None):
        super().__init__(None, name=name, cache=cache)
        self.playback = playback
        self.s = s

    def compute(self) -> float | None:
        return self.playback.crossing(self.s)


@dataclass
class Playback:
    """One utterance playing: the truth (start, drift), its delivered events, and the strategy's t_A."""

    env: object
    timed: TimedBehaviour
    utterance: Utterance
    plan: object
    strategy: object
    t_request: float
    t0: float
    drift_ppm: float
    delivered: list
    finished: bool = False
    history: list = field(default_factory=list)  # (clock time, t_A) breakpoints of t_A up to the last event
    history_max: list = field(default_factory=list)  # running maximum of t_A along the history
    dependants: object = None  # what the scheduler says hangs from the speech's pegs
    trace: list = field(default_factory=list)

    @property
    def scale(self) -> float:
        return 1.0 + self.drift_ppm * 1e-6

    def true_time(self, s_true: float) -> float:
        """Clock time at which true speech time ``s_true`` is heard."""
        return self.t0 + s_true * self.scale

    @property
    def t_end(self) -> float:
        return self.true_time(self.utterance.duration)

    def record(self, now: float) -> None:
        """Keep how t_A went since the last event, before the next event changes its future."""
        last = self.history[-1][0] if self.history else None
        path = self.strategy.path
        times = path.times
        points = [] if last is None else times[bisect.bisect_right(times, last):bisect.bisect_left(times, now)]
        for t in points + [now]:
            p = path.at(t)
            self.history.append((t, p))
            self.history_max.append(max(p, self.history_max[-1]) if self.history_max else p)

    def crossing(self, s: float) -> float:
        """When t_A reached (or, as far as is known now, will reach) speech time ``s``.

        A time already passed stays where it was passed; only the future moves with new events.
        """
        now = self.env.now
        if self.history_max and s <= self.history_max[-1]:
            k = bisect.bisect_left(self.history_max, s)
            if k == 0:
                return self.history[0][0]
            (t0, p0), (t1, p1) = self.history[k - 1], self.history[k]
            return t1 if p1 <= p0 else t0 + (s - p0) / (p1 - p0) * (t1 - t0)
        since = self.history[-1][0] if self.history else now
        t = self.strategy.crossing(s, since)
        if math.isinf(t) and self.finished:
            return now  # every event is in: what t_A has not reached by now, it never will
        return t


@dataclass(frozen=True)
class HeardSpeech:
    """One speech as a listener of the run heard it.

    Attributes
    ----------
    block, behaviour : str
        Its block's id and its own.
    utterance : Utterance
        What the backend made of its text (its timeline and, if the backend makes sound, its audio).
    t_request : float
        When its audio was asked for (global s): the speech's start.
    t0 : float
        When its first sample was heard (global s): later by the playback latency under a strategy.
    drift_ppm : float
        Its audio clock's drift: speech time ``s`` is heard at ``t0 + s * (1 + drift_ppm * 1e-6)``.
    strategy : str or None
        The animator-time strategy its sync points followed (None: they kept the plan).
    delivered : tuple of ProgressEvent
        Its progress events as they reached the realizer (empty without a strategy).
    trace : tuple of (float, float)
        ``(clock time, t_A)`` samples while it played, if asked for (:attr:`SpeechConfig.trace_frame`).
    plan : SpeechPlan or None
        What the strategy was told in advance.
    stopped : float or None
        When an interruption stopped it (global s), if one did.
    volume : tuple of (start, end, kind, initial, target)
        Its BMLA volume changes (percent), in the order they started; see :meth:`gain`.
    """

    block: str
    behaviour: str
    utterance: Utterance
    t_request: float
    t0: float
    drift_ppm: float = 0.0
    strategy: str | None = None
    delivered: tuple = ()
    trace: tuple = ()
    plan: object = None
    stopped: float | None = None
    volume: tuple = ()

    @property
    def scale(self) -> float:
        return 1.0 + self.drift_ppm * 1e-6

    def true_time(self, s: float) -> float:
        """Global time at which speech time ``s`` (s from the utterance's start) was heard."""
        return self.t0 + s * self.scale

    def gain(self, t: float) -> float:
        """The loudness factor at global time ``t`` (1 as synthesised; BMLA volume changes are percent)."""
        value = 100.0
        for start, end, kind, initial, target in self.volume:
            if start is not None and t >= start:
                linear = kind == "linear" and end is not None and end > start and t < end
                value = initial + (target - initial) * (t - start) / (end - start) if linear else target
        return value / 100.0


class SpeechEngine(Engine):
    """Plays speech behaviours; with a strategy, their sync points follow the audio through animator time."""

    name = "speech"
    #: After a progress event, the behaviours tied to the speech that start within this many seconds are
    #: re-timed (the rest when they come nearer): it covers how far t_A can move a behaviour earlier
    #: between events.
    HORIZON = 3.0

    def __init__(self, context: EngineContext, backend: TTSBackend, config: SpeechConfig | None = None):
        super().__init__(context, SpeechPlanner(backend, config))
        self.config = self.planner.config
        self.playbacks: list[Playback] = []  # the speeches that played under a strategy, in order
        #: every speech that started, in order: the behaviour, its utterance, when it started, its playback
        self._started: list[tuple[TimedBehaviour, Utterance, float, Playback | None]] = []
        self._stopped: dict[int, float] = {}
        #: who hears the speech as it plays (a live loudspeaker): ``sound_started(heard)`` when a speech
        #: starts (its HeardSpeech), ``sound_stopped(block, behaviour, at)`` when an interruption cuts it
        self.listeners: list = []

    def sync_passed(self, timed: TimedBehaviour, index: int, time: float) -> None:
        if index == 0:
            self.apply_rate(timed, time)
            if self.config.strategy is not None and not self.followable(timed):
                self.context.blocks.warn(f"{timed.block_id}:{timed.id}", "IMPOSSIBLE_TO_SCHEDULE",
                                         f"{timed.id}: the speech has no words, so no progress events for the "
                                         f"{self.config.strategy!r} strategy to follow; it plays as planned",
                                         [timed.id])
                self.take_timing(timed, time)
                self._started.append((timed, self.planner.utterance(timed.behaviour), time, None))
            elif self.config.strategy is None:
                self.take_timing(timed, time)
                self._started.append((timed, self.planner.utterance(timed.behaviour), time, None))
            else:
                self.play(timed, time)
                playback = self.playbacks[-1]
                self._started.append((timed, playback.utterance, time, playback))
            timed.phonemes = tuple((p.symbol, p.start, p.end) for p in self._started[-1][1].phonemes)
            if self.listeners:
                heard = self.heard_one(*self._started[-1])
                for listener in self.listeners:
                    listener.sound_started(heard)
        super().sync_passed(timed, index, time)

    def forget(self, block_ids: set[str]) -> None:
        self._started = [s for s in self._started if s[0].block_id not in block_ids]
        self.playbacks = [p for p in self.playbacks if p.timed.block_id not in block_ids]
        kept = {id(s[0]) for s in self._started}
        self._stopped = {k: v for k, v in self._stopped.items() if k in kept}

    def followable(self, timed: TimedBehaviour) -> bool:
        """Whether an animator-time strategy can follow the speech: it has words to make progress events."""
        if self.config.timing == "linear":
            return True  # planned from its text's words (a speech without any was not planned)
        return bool(self.planner.utterance(timed.behaviour).words)

    def stopped(self, timed: TimedBehaviour, now: float) -> None:
        """An interruption stopped the speech at ``now``: its audio ends there, its events stop."""
        self._stopped[id(timed)] = now
        for playback in self.playbacks:
            if playback.timed is timed:
                playback.finished = True
        for listener in self.listeners:
            listener.sound_stopped(timed.block_id, timed.id, now)

    def apply_rate(self, timed: TimedBehaviour, start: float) -> None:
        """A BMLA rate change in effect when the speech starts: speak it at that rate (the backend speaks a
        whole utterance at one rate), and move its sync points to the new timeline."""
        rate = parameter_at(timed, "rate", start, 1.0)
        if rate == 1.0 or self.config.timing != "tts":
            return
        if not rate > 0:
            self.context.blocks.warn(f"{timed.block_id}:{timed.id}", "IMPOSSIBLE_TO_SCHEDULE",
                                     f"{timed.id}: speech rate {rate:g} is not positive; spoken at its own rate",
                                     [timed.id])
            return
        behaviour = timed.behaviour
        utterance = self.planner.backend.synthesize(speech_text(behaviour, rate))
        self.planner.set_utterance(behaviour, utterance)
        marks = {m.name: m.time for m in utterance.marks}
        timed.preferred = [0.0] + [marks[s] for s in timed.sync_ids[1:-1]] + [utterance.duration]
        if self.config.strategy is None:
            for i in range(1, len(timed.sync_ids)):
                set_key_time(timed, i, start + timed.preferred[i])
            self.context.pegs_moved()

    def heard(self) -> list[HeardSpeech]:
        """Every speech that started so far, as it was heard."""
        return [self.heard_one(*started) for started in self._started]

    def heard_one(self, timed: TimedBehaviour, utterance: Utterance, start: float,
                  playback: Playback | None) -> HeardSpeech:
        """One started speech as it was heard (so far)."""
        volume = tuple((c.start, c.end, c.kind, c.initial, c.target) for c in timed.parameters
                       if c.param == "volume")
        stopped = self._stopped.get(id(timed))
        if playback is None:
            return HeardSpeech(timed.block_id, timed.id, utterance, start, start, stopped=stopped, volume=volume)
        return HeardSpeech(timed.block_id, timed.id, utterance, playback.t_request, playback.t0, playback.drift_ppm,
                           self.config.strategy, tuple(playback.delivered), tuple(playback.trace), playback.plan,
                           stopped, volume)

    def take_timing(self, timed: TimedBehaviour, start: float) -> None:
        """From its start on, the speech runs on its own audio timeline: detach its pegs from whatever
        they were tied to (an anticipator, another block), keeping their times. Behaviours sharing those
        pegs now follow the speech."""
        block_peg = timed.run.block_peg
        with self.context.board.quiet():
            for peg in set(timed.own_pegs()):
                peg.freeze(block_peg)
        timed.owns = [t and not f for t, f in zip(timed.tied, timed.fixed)]

    def play(self, timed: TimedBehaviour, t_request: float) -> None:
        """Start the audio and hand the speech's timing to the animator-time strategy."""
        from speech_timing.animator_time import make_strategy
        from speech_timing.delivery import deliver, true_events
        from speech_timing.linear_model import plan_from_utterance

        config, planner = self.config, self.planner
        delivery = config.delivery
        utt = planner.utterance(timed.behaviour)
        known = dict(delay=delivery.delay, latency=delivery.latency, t_request=t_request)
        if config.timing == "linear":
            from speech_timing.linear_model import plan_from_linear

            plan = plan_from_linear(timed.behaviour.text, planner.linear_model(), **known)
        else:
            model = planner.linear_model() if config.strategy == "linear-model" else None
            plan = plan_from_utterance(utt, linear_model=model, **known)
        import numpy as np  # only where speech is played: planning does without it

        rng = np.random.default_rng(config.seed + len(self.playbacks))
        t0 = delivery.draw_start(t_request, rng)
        delivered = deliver(true_events(utt, t0, delivery.drift_ppm), delivery, rng)
        strategy = make_strategy(config.strategy)
        strategy.reset(plan, t_request)
        playback = Playback(self.env, timed, utt, plan, strategy, t_request, t0, delivery.drift_ppm, delivered)
        playback.record(t_request)
        self.playbacks.append(playback)
        planner.speaking.add(id(timed.behaviour))
        # Tie the speech's sync points, and every peg shared with them, to animator time.
        speech_pegs = [SpeechTimePeg(playback, p, name=f"{timed.block_id}:{timed.id}:{s}",
                                     cache=self.context.board.cache)
                       for p, s in zip(timed.preferred, timed.sync_ids)]
        # (A peg held by a time given from outside, a number or an anticipator, keeps that time: what shares
        # it with the speech's start is tied to the number, not to the audio.)
        with self.context.board.quiet():
            for i, key in enumerate(timed.keys):
                if key is not None and timed.tied[i] and not timed.fixed[i] and isinstance(key.peg, OffsetPeg):
                    key.peg.rebase(speech_pegs[i], -key.offset)
                    timed.owns[i] = True  # what shares the peg follows the speech now
            timed.keys = [KeyRef(peg, 0.0) for peg in speech_pegs]
        planned_start = timed.planned_start if timed.planned_start is not None else t_request
        playback.dependants = self.context.dependants_of(
            speech_pegs, planned_now=lambda: planned_start + strategy.position(self.env.now))
        self.context.pegs_moved(playback.dependants)  # the speech now runs on t_A: everything tied to it moved
        self.env.process(self._deliver(playback))
        if config.trace_frame:
            self.env.process(self._trace(playback, config.trace_frame))

    def _deliver(self, playback: Playback):
        env = self.env
        events = playback.delivered
        i = 0
        while i < len(events):
            if events[i].arrival_time > env.now:
                yield env.timeout(events[i].arrival_time - env.now)
            if playback.finished:  # interrupted: nothing it says matters any more
                return
            playback.record(env.now)
            before = playback.strategy.path
            # every event that arrives at this instant, then one look at what they changed (a burst of
            # events at one instant costs the re-timing once)
            first = i
            while i < len(events) and events[i].arrival_time <= env.now:
                playback.strategy.on_event(events[i], env.now)
                i += 1
            if i - first > 1:  # where the events of this instant took t_A (it may have snapped)
                playback.record(env.now)
            if playback.strategy.path is not before:  # the events changed the future of t_A
                self.context.pegs_moved(playback.dependants, horizon=self.HORIZON)
        # After the last event and the longest it could have been held, t_A learns nothing more.
        last = max([playback.t_end] + [e.arrival_time for e in playback.delivered])
        if last > env.now:
            yield env.timeout(last - env.now)
        playback.record(env.now)
        playback.finished = True
        self.context.pegs_moved(playback.dependants)  # what t_A has not reached, it never will: it passes now

    def _trace(self, playback: Playback, frame: float):
        env = self.env
        k = math.ceil((playback.t0 - env.now) / frame) if playback.t0 > env.now else 0
        t = env.now + k * frame
        while t <= playback.t_end:
            if t > env.now:
                yield env.timeout(t - env.now)
            playback.trace.append((t, playback.strategy.position(t)))
            t += frame

