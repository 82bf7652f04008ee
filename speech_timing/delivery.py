"""Progress events of a playing utterance and the channel that delivers them late.

World model (all times in seconds):

* Speech time ``s`` is a position in the utterance's own audio timeline (the backend's times).
* Playback requested at ``t_request`` really starts at ``t0 = t_request + latency`` (plus an optional
  unknown start offset, :attr:`DeliveryModel.start_jitter`), and the audio clock drifts: the sound at
  speech time ``s`` is heard at ``t_true(s) = t0 + s * (1 + drift_ppm * 1e-6)``.
* One progress event is produced per word onset, phoneme onset, sentence, mark and at the end, at the
  moment its audio is played (:func:`true_events`).
* The events reach the animation system through a channel (:func:`deliver`) that adds a base delay, a
  non-negative per-event jitter, bursts (the channel stalls and releases the held events together, as
  Chang observed over a network) and loss, and delivers in order (first in, first out).

:func:`delivery_process` replays delivered events as a SimPy process.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator

if TYPE_CHECKING:  # numpy is imported where events are drawn: the models themselves are plain values
    import numpy as np

from speech_timing.backend import Utterance

__all__ = ["EVENT_KINDS", "JITTER_DISTRIBUTIONS", "ProgressEvent", "DeliveryModel", "PLAYBACK", "CONDITIONS",
           "true_events", "deliver", "draw_jitter", "delivery_process"]

#: Kinds of progress events, in the order in which events at the same instant are produced.
EVENT_KINDS = ("sentence", "mark", "word", "phoneme", "end")
_KIND_ORDER = {kind: i for i, kind in enumerate(EVENT_KINDS)}

#: Jitter distributions, all non-negative (an event is never early) and with mean ``jitter``.
JITTER_DISTRIBUTIONS = ("exponential", "gamma", "half-normal")


@dataclass
class ProgressEvent:
    """A progress event of a playing utterance.

    Parameters
    ----------
    kind : {"word", "phoneme", "sentence", "mark", "end"}
        What the event announces.
    index : int
        Index of the word, phoneme, sentence or mark in the utterance (0 for the end).
    speech_time : float
        Speech time (s) of what the event announces.
    true_time : float
        Simulation time (s) at which it is heard, when the event is produced.
    arrival_time : float
        Simulation time (s) at which the event reaches the animation system (NaN until delivered).
    payload : dict
        Details: for a word ``text``, ``char_start``, ``char_end``; for a phoneme ``symbol``,
        ``word_index``, ``in_word`` (position in its word), ``stressed`` and ``char_start`` (of its
        word); for a mark ``name``.
    """

    kind: str
    index: int
    speech_time: float
    true_time: float = math.nan
    arrival_time: float = math.nan
    payload: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in _KIND_ORDER:
            raise ValueError(f"unknown event kind {self.kind!r}; expected one of {EVENT_KINDS}")


@dataclass(frozen=True)
class DeliveryModel:
    """Playback start, audio clock drift and the event channel.

    Parameters
    ----------
    latency : float
        Nominal playback latency (s): audio requested at ``t_request`` starts at ``t_request + latency``.
    drift_ppm : float
        Audio clock drift in parts per million: speech time ``s`` is heard ``s * drift_ppm * 1e-6``
        seconds later than on the simulation clock (negative: earlier).
    delay : float
        Base delay (s) of every event: the fastest possible delivery.
    jitter : float
        Mean (s) of the extra, non-negative per-event delay.
    burst_probability : float
        Probability that an event stalls the channel. The channel then holds it, and every later event
        that would have arrived before the release, and releases them together.
    burst_hold : float
        Longest stall (s); each stall lasts a uniform draw in ``[0, burst_hold]``.
    loss : float
        Probability that an event is lost (never delivered).
    jitter_distribution : {"exponential", "gamma", "half-normal"}
        Shape of the jitter, scaled so that its mean is ``jitter``: exponential with scale ``jitter``
        (mode at zero, a long tail: queueing in a network), gamma with shape 2 and scale
        ``jitter / 2`` (no mass at zero: a few hops of queueing), or the absolute value of a normal
        with standard deviation ``jitter * sqrt(pi / 2)``. All are one-sided, so an event is never
        early; the default exponential is the usual single-queue model of network delay.
    start_jitter : float
        Unknown extra playback latency (s): the real start is ``t_request + latency + u`` with ``u``
        uniform in ``[0, start_jitter]`` (:meth:`draw_start`). Strategies know ``latency`` only.
    """

    latency: float = 0.0
    drift_ppm: float = 0.0
    delay: float = 0.0
    jitter: float = 0.0
    burst_probability: float = 0.0
    burst_hold: float = 0.0
    loss: float = 0.0
    jitter_distribution: str = "exponential"
    start_jitter: float = 0.0

    def __post_init__(self) -> None:
        for name in ("latency", "delay", "jitter", "burst_hold", "start_jitter"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite non-negative number of seconds, not {value!r}")
        for name in ("burst_probability", "loss"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], not {value!r}")
        if not math.isfinite(self.drift_ppm) or abs(self.drift_ppm) >= 1e5:
            raise ValueError(f"drift_ppm must be finite and below 1e5 in magnitude, not {self.drift_ppm!r}")
        if self.jitter_distribution not in JITTER_DISTRIBUTIONS:
            raise ValueError(f"jitter_distribution must be one of {JITTER_DISTRIBUTIONS}, "
                             f"not {self.jitter_distribution!r}")

    def draw_start(self, t_request: float, rng: np.random.Generator) -> float:
        """Real playback start ``t0`` for a request at ``t_request`` (draws one number from ``rng``)."""
        return t_request + self.latency + self.start_jitter * float(rng.uniform())

    def with_(self, **changes: Any) -> "DeliveryModel":
        """A copy with some fields changed."""
        return replace(self, **changes)


#: The playback every named condition shares: nominal latency 80 ms plus an unknown 0 to 40 ms, audio clock
#: drift 500 ppm.
PLAYBACK = {"latency": 0.08, "start_jitter": 0.04, "drift_ppm": 500.0}

#: The delivery conditions of the speech-sync tables, by name: **A** events delayed 50 ms plus exponential
#: jitter of mean 30 ms, with stalls (p = 0.03, held up to 0.25 s); **B** as A with jitter 100 ms; **C**
#: delay 150 ms, jitter 50 ms, stalls and 2 % loss. A is the default wherever a condition is not given.
CONDITIONS: dict[str, DeliveryModel] = {
    "A": DeliveryModel(**PLAYBACK, delay=0.05, jitter=0.03, burst_probability=0.03, burst_hold=0.25),
    "B": DeliveryModel(**PLAYBACK, delay=0.05, jitter=0.10, burst_probability=0.03, burst_hold=0.25),
    "C": DeliveryModel(**PLAYBACK, delay=0.15, jitter=0.05, burst_probability=0.03, burst_hold=0.25, loss=0.02),
}


def true_events(utterance: Utterance, t0: float, drift_ppm: float = 0.0) -> list[ProgressEvent]:
    """The progress events of ``utterance`` played from ``t0``, at the times they are heard.

    Parameters
    ----------
    utterance : Utterance
        The backend's timeline (speech times in seconds).
    t0 : float
        Simulation time at which the audio really starts.
    drift_ppm : float
        Audio clock drift; speech time ``s`` is heard at ``t0 + s * (1 + drift_ppm * 1e-6)``.

    Returns
    -------
    list of ProgressEvent
        One event per word onset, phoneme onset, sentence onset and mark, and one at the end
        (``utterance.duration``), ordered by true time (at equal times: sentence, mark, word, phoneme,
        end); ``arrival_time`` is NaN.
    """
    if not math.isfinite(t0):
        raise ValueError("t0 must be finite")
    scale = 1.0 + drift_ppm * 1e-6
    counts: dict[int, int] = {}
    events: list[ProgressEvent] = []
    char_of = {w.index: w.char_start for w in utterance.words}
    for i, word in enumerate(utterance.words):
        events.append(ProgressEvent("word", i, word.start, payload={
            "text": word.text, "char_start": word.char_start, "char_end": word.char_end}))
    for i, ph in enumerate(utterance.phonemes):
        m = counts.get(ph.word_index, 0)
        counts[ph.word_index] = m + 1
        events.append(ProgressEvent("phoneme", i, ph.start, payload={
            "symbol": ph.symbol, "word_index": ph.word_index, "in_word": m, "stressed": ph.stressed,
            "char_start": char_of.get(ph.word_index, -1)}))
    for i, s in enumerate(utterance.sentences):
        events.append(ProgressEvent("sentence", i, float(s)))
    for i, mark in enumerate(utterance.marks):
        events.append(ProgressEvent("mark", i, mark.time, payload={"name": mark.name}))
    events.append(ProgressEvent("end", 0, utterance.duration))
    for event in events:
        event.true_time = t0 + event.speech_time * scale
    events.sort(key=lambda e: (e.true_time, _KIND_ORDER[e.kind], e.index))
    return events


def draw_jitter(model: DeliveryModel, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` non-negative jitter values (s) with mean ``model.jitter`` (see :class:`DeliveryModel`)."""
    import numpy as np

    if model.jitter_distribution == "exponential":
        return rng.exponential(model.jitter, n) if model.jitter > 0 else np.zeros(n)
    if model.jitter_distribution == "gamma":
        return rng.gamma(2.0, model.jitter / 2.0, n) if model.jitter > 0 else np.zeros(n)
    sigma = model.jitter * math.sqrt(math.pi / 2.0)
    return np.abs(rng.normal(0.0, 1.0, n)) * sigma


def deliver(events: Iterable[ProgressEvent], model: DeliveryModel,
            rng: np.random.Generator) -> list[ProgressEvent]:
    """Send ``events`` through the channel; return the delivered ones with their arrival times.

    Parameters
    ----------
    events : iterable of ProgressEvent
        Events with ``true_time`` set (e.g. from :func:`true_events`), in the order they are sent.
    model : DeliveryModel
        The channel.
    rng : numpy.random.Generator
        The only source of randomness. Exactly ``4 * len(events)`` numbers are drawn, in blocks
        (jitter, stall decisions, stall lengths, losses), so the same seed gives the same arrivals
        whatever the parameters.

    Returns
    -------
    list of ProgressEvent
        Copies of the delivered events (lost ones removed) in arrival order, with ``arrival_time``
        set. Arrival times are non-decreasing and never earlier than ``true_time + delay``.

    Notes
    -----
    Event ``i`` would arrive at ``true_time + delay + jitter_i``. With probability
    ``burst_probability`` it stalls the channel until ``that time + U(0, burst_hold)``; every event
    that would arrive during a stall arrives at its end. A lost event neither arrives nor holds others.
    Finally the channel is first in, first out: no event overtakes an earlier one.
    """
    import numpy as np

    events = list(events)
    n = len(events)
    jitter = draw_jitter(model, rng, n)
    stall = rng.uniform(size=n) < model.burst_probability
    hold = rng.uniform(size=n) * model.burst_hold
    lost = rng.uniform(size=n) < model.loss
    true = np.array([e.true_time for e in events], dtype=float)
    if n and not np.all(np.isfinite(true)):
        raise ValueError("every event needs a finite true_time")
    raw = true + model.delay + jitter
    delivered: list[ProgressEvent] = []
    release = -math.inf  # end of the current stall
    last = -math.inf
    for i, event in enumerate(events):
        if lost[i]:
            continue
        arrival = raw[i]
        if arrival < release:
            arrival = release
        elif stall[i]:
            release = arrival + hold[i]
            arrival = release
        arrival = max(arrival, last)
        last = arrival
        delivered.append(replace(event, payload=dict(event.payload), arrival_time=float(arrival)))
    return delivered


def delivery_process(env: Any, events: Iterable[ProgressEvent],
                     on_event: Callable[[ProgressEvent, float], None]) -> Iterator[Any]:
    """SimPy process that hands each delivered event to ``on_event(event, now)`` at its arrival time.

    Parameters
    ----------
    env : simpy.Environment
        The simulation.
    events : iterable of ProgressEvent
        Delivered events (from :func:`deliver`), in arrival order.
    on_event : callable
        Called as ``on_event(event, env.now)``; events arriving together are handed over one by one,
        in order, at the same simulation time.

    Examples
    --------
    >>> env.process(delivery_process(env, delivered, strategy.on_event))  # doctest: +SKIP
    """
    for event in events:
        wait = event.arrival_time - env.now
        if wait > 0:
            yield env.timeout(wait)
        on_event(event, env.now)
