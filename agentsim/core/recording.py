"""The recording of a run: what every behaviour really did, the blocks, the drops and the anticipators' pegs,
as plain values that animation output, plots and scenarios read instead of the scheduler's internals.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Iterator

from agentsim.core.block import Behaviour
from agentsim.core.timed import TimedBehaviour


@dataclass(frozen=True)
class BehaviourRecord:
    """What became of one behaviour of a block.

    Attributes
    ----------
    block, id : str
        Its block's id and its own.
    behaviour : Behaviour
        Its BML: type, attributes, sync references, text.
    sync_ids : tuple of str
        Its sync points, in order.
    times : tuple of float or None
        Global time (s) of each sync point: when it was passed, else when it was last planned to be
        (``None``: never known; ``inf``: waiting for the world when the run stopped).
    passed : tuple of bool
        Which sync points were passed.
    preferred : tuple of float
        Preferred time of each sync point after the start (s), the timing it was planned from.
    state : str
        ``finished``, ``dropped`` (also when its block was cut), ``active`` or ``planned`` (the run
        stopped first).
    stopped : float or None
        When it was dropped or cut (s), if it was.
    order : int
        Planning order: behaviours due at one instant are played in this order.
    peg_groups : tuple of int or None
        Sync points (of any behaviour of the recording) with the same number hang from one time peg.
    tied_to : tuple of str
        The behaviours (``block:behaviour``) whose sync points its BML ties it to.
    interrupted : bool
        Whether an interruption cut it short (its skipped sync points have no time).
    parameters : tuple of (param, start, end, kind, initial, target)
        BMLA parameter changes that applied to it, in the order they started.
    phonemes : tuple of (symbol, start, end)
        A speech's phonemes as spoken, in seconds on its own timeline (the axis of ``preferred``), once it
        started; the mouth shows their visemes. Empty for every other behaviour.
    """

    block: str
    id: str
    behaviour: Behaviour
    sync_ids: tuple[str, ...]
    times: tuple[float | None, ...]
    passed: tuple[bool, ...]
    preferred: tuple[float, ...]
    state: str
    stopped: float | None
    order: int
    peg_groups: tuple[int | None, ...] = ()
    tied_to: tuple[str, ...] = ()
    interrupted: bool = False
    parameters: tuple[tuple[str, float | None, float | None, str, float, float], ...] = ()
    phonemes: tuple[tuple[str, float, float], ...] = ()

    @property
    def type(self) -> str:
        return self.behaviour.type

    @property
    def name(self) -> str:
        """``block:behaviour``."""
        return f"{self.block}:{self.id}"

    @property
    def started(self) -> bool:
        return bool(self.passed) and self.passed[0]

    @property
    def start(self) -> float | None:
        return self.times[0] if self.times else None

    @property
    def end(self) -> float | None:
        return self.times[-1] if self.times else None

    def time(self, sync_id: str) -> float | None:
        """Global time of one sync point (KeyError if it has no such sync point)."""
        if sync_id not in self.sync_ids:
            raise KeyError(sync_id)
        return self.times[self.sync_ids.index(sync_id)]

    def until(self, t: float) -> "BehaviourRecord":
        """This record as seen at time ``t``: later sync points not known yet."""
        return replace(self, times=tuple(x if x is not None and x <= t else None for x in self.times))


@dataclass(frozen=True)
class BlockRecord:
    """One submitted block: its id, how it was composed, what became of it and when."""

    id: str
    character: str
    composition: str
    state: str  # ended, refused, running or pending (the run stopped first)
    start: float | None
    end: float | None


@dataclass(frozen=True)
class DropRecord:
    """A behaviour that was dropped or cut, when (s), and why (a warning type and its description)."""

    block: str
    behaviour: str
    time: float
    warning_type: str
    reason: str


@dataclass(frozen=True)
class Recording:
    """Everything a run did, as values.

    Attributes
    ----------
    behaviours : tuple of BehaviourRecord
        Every behaviour of every accepted block, in submission and document order.
    blocks : tuple of BlockRecord
        Every submitted block that was read, in submission order.
    drops : tuple of DropRecord
        Every behaviour dropped while planning or playing, and every one cut by another block.
    anticipators : dict
        Each anticipator's pegs and their last times: ``{anticipator: {sync: time}}`` (s).
    feedback : tuple of dict
        Every feedback sent, in order.
    speech : tuple
        What the speech engine played: one :class:`~agentsim.engines.speech.HeardSpeech` per speech that
        started, in order.
    audio : tuple
        The sound files played: one :class:`~agentsim.engines.audio.HeardAudio` each, in order.
    now : float
        Simulated time when the recording was made (s).
    lexicon : object
        What the run's lexemes play (its realizer's :class:`~agentsim.animation.lexicon.Lexicon`; None: the
        built-in one), for the poses evaluated from the recording.
    """

    behaviours: tuple[BehaviourRecord, ...]
    blocks: tuple[BlockRecord, ...] = ()
    drops: tuple[DropRecord, ...] = ()
    anticipators: dict[str, dict[str, float | None]] = field(default_factory=dict)
    feedback: tuple[dict[str, Any], ...] = ()
    speech: tuple = ()
    audio: tuple = ()
    now: float = 0.0
    lexicon: object = field(default=None, repr=False, compare=False)

    def __iter__(self) -> Iterator[BehaviourRecord]:
        return iter(self.behaviours)

    def behaviour(self, name: str) -> BehaviourRecord | None:
        """The record of ``block:behaviour``, or None."""
        return next((b for b in self.behaviours if b.name == name), None)

    def sync_times(self) -> dict[str, float]:
        """Global time of every sync point passed, by ``block:behaviour:sync`` id (as fed back)."""
        return {f["id"]: f["globalTime"] for f in self.feedback if f["type"] == "syncPointProgress"}

    def until(self, t: float) -> "Recording":
        """The recording as it stood at time ``t`` (s): behaviours started by then, sync points and
        feedback up to then."""
        behaviours = tuple(b.until(t) for b in self.behaviours if b.start is not None and b.start < t)
        return replace(self, behaviours=behaviours, drops=tuple(d for d in self.drops if d.time <= t),
                       feedback=tuple(f for f in self.feedback if f.get("globalTime", float("inf")) <= t),
                       now=min(self.now, t))


def record_behaviours(timed: Iterable[TimedBehaviour]) -> list[BehaviourRecord]:
    """Records of timed behaviours as they stand now; sync points sharing a time peg get one group number."""
    groups: dict[int, int] = {}
    records = []
    for t in timed:
        times = t.times()
        peg_groups = []
        for key in t.keys:
            if key is None:
                peg_groups.append(None)
            else:
                root = id(key.peg.root())
                peg_groups.append(groups.setdefault(root, len(groups)))
        refs = t.behaviour.refs.values()
        tied = tuple(dict.fromkeys(f"{r.block or t.block_id}:{r.behaviour}" for r in refs
                                   if r.kind == "sync" and r.behaviour is not None))
        times = [None if i in t.skipped else x for i, x in enumerate(times)]
        parameters = tuple((c.param, c.start, c.end, c.kind, c.initial, c.target) for c in t.parameters)
        records.append(BehaviourRecord(
            block=t.block_id, id=t.id, behaviour=t.behaviour, sync_ids=tuple(t.sync_ids),
            times=tuple(times), passed=tuple(p is not None for p in t.passed), preferred=tuple(t.preferred),
            state=t.state, stopped=t.stopped, order=t.order, peg_groups=tuple(peg_groups), tied_to=tied,
            interrupted=t.interrupted, parameters=parameters, phonemes=tuple(getattr(t, "phonemes", ()))))
    return records
