"""Where the conductor puts its strokes: the ``follow``, ``target``, ``lead`` and ``best`` strategies.

Each strategy says what a conducting gesture's ``stroke`` refers to in BML (:meth:`Strategy.stroke`),
when it plans the ictus of a beat (:meth:`Strategy.planned`), and which anticipators of its own the
realizer needs (:attr:`Strategy.anticipators`). The strokes move whenever the pegs they refer to move,
while the plan plays.

``follow``
    ``anticipators:band:beatN``: the ictus on the ensemble's beats as the tracker predicts them.
``target``
    ``anticipators:score:beatN`` of :class:`ScoreBeats`: the score's tempo from the first ictus on
    (placed on the ensemble's predicted beat), whatever the ensemble does.
``lead``
    ``anticipators:band:beatN-0.05``: as Elckerlyc's conductor, in the ensemble's tempo but slightly ahead
    of it while it is too slow (behind it while too fast, on it within ``lead_tolerance``); the offset is
    chosen for each bar when its block is submitted.
``best``
    ``anticipators:plan:beatN`` of :class:`PlannedBeats`: model-predictive control. The anticipator fits
    how the ensemble responds to the ictus (:class:`~scenarios.conductor.planning.ResponseEstimator`)
    from the beats the tracker hears and the strokes that were made, and after every heard beat plans
    the next ictus times that bring the ensemble's tempo to the score's fastest while the projected
    standard deviation of the ensemble's asynchrony stays within ``asynchrony_sd_budget``
    (:class:`~scenarios.conductor.planning.BudgetPlanner`); it moves the pegs of the beats not yet
    conducted to the new plan.
"""

from __future__ import annotations

import re

import numpy as np

from agentsim.core.anticipator import Anticipator
from scenarios.conductor.config import ConductorConfig, Piece
from scenarios.conductor.hearing import Ears
from scenarios.conductor.planning import BudgetPlanner, ResponseEstimator

_BEAT = re.compile(r"^beat(\d{1,9})$")

#: An ictus closer than this to now (s) is not moved any more.
FREEZE = 0.12
#: Ictus planned closer than this (s) to the one before are moved later.
MIN_INTERVAL = 0.25


def score_period(piece: Piece, beat: int) -> float:
    """The score's period (s) from beat ``beat`` to the next (beats past the end keep the last tempo)."""
    return 60.0 / piece.tempo_at(min(max(beat, 1), piece.n_beats))


class Strategy:
    """Where strokes go. Subclasses override :meth:`stroke` and :meth:`planned` (and may add anticipators).

    Parameters
    ----------
    piece : Piece
        The score (its tempo is the target).
    config : ConductorConfig
        Conductor parameters.
    ears : Ears
        The tracker, id ``band``.
    """

    name = "strategy"

    def __init__(self, piece: Piece, config: ConductorConfig, ears: Ears):
        self.piece = piece
        self.config = config
        self.ears = ears
        self.anticipators: list[Anticipator] = []
        self.first_beat: int | None = None
        self.ictus: dict[int, float] = {}

    def start(self, beat: int, time: float) -> None:
        """The conductor starts conducting at beat ``beat``, planned at ``time``."""
        self.first_beat = beat

    def stroke(self, beat: int) -> str:
        """The BML sync reference of beat ``beat``'s stroke (asked once, when its bar is submitted)."""
        return f"anticipators:{self.ears.id}:beat{beat}"

    def planned(self, beat: int) -> float | None:
        """When the ictus of ``beat`` is planned now (None: not known yet)."""
        return self.ears.beat_time(beat)

    def on_ictus(self, beat: int, time: float) -> None:
        """The stroke of ``beat`` happened at ``time``."""
        self.ictus[beat] = time

    def describe(self) -> dict:
        """What the strategy found out, for the metrics."""
        return {}


class Follow(Strategy):
    """The ictus on the ensemble's predicted beats."""

    name = "follow"


class ScoreBeats(Anticipator):
    """Beats at the score's tempo from an anchor: peg ``beatN`` at ``anchor_time`` plus the score's time
    from ``anchor_beat`` to ``N`` (unknown before :meth:`anchor`)."""

    def __init__(self, anticipator_id: str, piece: Piece):
        super().__init__(anticipator_id)
        self.piece = piece
        self.offsets = piece.score_offsets()
        self.anchor_beat: int | None = None
        self.anchor_time: float | None = None

    def anchor(self, beat: int, time: float) -> None:
        self.anchor_beat, self.anchor_time = int(beat), float(time)
        for sync_id, peg in self.pegs.items():
            peg.set(self.beat_time(int(sync_id[4:])))

    def beat_time(self, beat: int) -> float | None:
        if self.anchor_beat is None:
            return None
        last = self.offsets.size - 1
        def off(n):
            k = min(max(n - 1, 0), last)
            return self.offsets[k] + max(n - 1 - last, 0) * (self.offsets[-1] - self.offsets[-2])
        return self.anchor_time + off(beat) - off(self.anchor_beat)

    def make_peg(self, sync_id: str):
        m = _BEAT.match(sync_id)
        if not m or int(m.group(1)) < 1:
            return False
        return self.beat_time(int(m.group(1)))


class Target(Strategy):
    """The score's tempo regardless of the ensemble, from the first ictus on the ensemble's predicted beat."""

    name = "target"

    def __init__(self, piece, config, ears):
        super().__init__(piece, config, ears)
        self.score = ScoreBeats("score", piece)
        self.anticipators = [self.score]

    def start(self, beat, time):
        super().start(beat, time)
        self.score.anchor(beat, time)
        self.ears.on_block(self._reanchor)

    def _reanchor(self) -> None:
        """Until the first ictus, it stays on the tracker's latest prediction of the ensemble's beat."""
        beat = self.first_beat
        if beat in self.ictus:
            return
        t = self.ears.beat_time(beat)
        now = self.ears.env.now
        anchored = self.score.anchor_time
        if t is not None and t > now + FREEZE and anchored > now + FREEZE and abs(t - anchored) > 1e-6:
            self.score.anchor(beat, t)

    def stroke(self, beat):
        return f"anticipators:score:beat{beat}"

    def planned(self, beat):
        return self.score.beat_time(beat)


class Lead(Strategy):
    """Elckerlyc's conductor: in the ensemble's tempo, ``lead_seconds`` ahead of it while it is too slow."""

    name = "lead"

    def __init__(self, piece, config, ears):
        super().__init__(piece, config, ears)
        self.offsets: dict[int, float] = {}

    def tracked_bpm(self) -> float | None:
        up = self.ears.upcoming
        if len(up) >= 2:
            return 60.0 * (len(up) - 1) / (up[-1] - up[0])
        bpm = self.ears.tracker.tempo_bpm
        return float(bpm) if np.isfinite(bpm) else None

    def offset_for(self, beat: int) -> float:
        bpm = self.tracked_bpm()
        if bpm is None:
            return 0.0
        target = self.piece.tempo_at(beat)
        error = bpm / target - 1.0
        if error < -self.config.lead_tolerance:
            return -self.config.lead_seconds
        if error > self.config.lead_tolerance:
            return self.config.lead_seconds
        return 0.0

    def stroke(self, beat):
        bar = self.piece.bar_of(beat)
        if bar not in self.offsets:
            self.offsets[bar] = self.offset_for(beat)
        off = self.offsets[bar]
        ref = f"anticipators:{self.ears.id}:beat{beat}"
        return ref if off == 0 else f"{ref}{off:+.3f}"

    def planned(self, beat):
        t = self.ears.beat_time(beat)
        if t is None:
            return None
        return t + self.offsets.get(self.piece.bar_of(beat), self.offset_for(beat))

    def describe(self):
        return {"lead_offsets_s": {str(k): v for k, v in sorted(self.offsets.items())}}


class PlannedBeats(Anticipator):
    """Pegs ``beat1``, ``beat2``, ... at the ictus times a :class:`Best` strategy plans (moved on re-planning)."""

    def __init__(self, anticipator_id: str, strategy: "Best"):
        super().__init__(anticipator_id)
        self.strategy = strategy

    def make_peg(self, sync_id: str):
        m = _BEAT.match(sync_id)
        if not m or int(m.group(1)) < 1:
            return False
        return self.strategy.planned(int(m.group(1)))

    def refresh(self, now: float) -> None:
        """Move the pegs of beats not yet conducted (and not about to be) to the current plan."""
        for sync_id, peg in self.pegs.items():
            beat = int(sync_id[4:])
            if beat in self.strategy.ictus:
                continue
            t = self.strategy.planned(beat)
            if t is None or peg.time is None or peg.time < now + FREEZE:
                continue
            peg.set(max(t, now + FREEZE))


class Best(Strategy):
    """Model-predictive control of the ensemble's tempo with an online model of its response."""

    name = "best"

    def __init__(self, piece, config, ears):
        super().__init__(piece, config, ears)
        self.anticipator = PlannedBeats("plan", self)
        self.anticipators = [self.anticipator]
        self.estimator = ResponseEstimator()
        self.planner = BudgetPlanner(config.asynchrony_sd_budget)
        self.plan: dict[int, float] = {}
        self.past_asynchrony: dict[int, float] = {}
        self.history: list[dict] = []
        ears.on_beat(self.heard)
        ears.on_block(self.tick)

    # ------------------------------------------------------------------ hearing
    def heard(self, beat: int, time: float) -> None:
        """A beat onset heard by the tracker: bring the model up to it, then re-plan.

        Once the model runs, the onset is numbered by the model's own predictions (the nearest of the
        next beats), not by the tracker, whose numbering can slip by a beat when it loses and finds the
        beat again; an onset far from every prediction is left out.
        """
        est = self.estimator
        if not est.ready:
            period = 60.0 / self.ears.tracker.tempo_bpm if np.isfinite(self.ears.tracker.tempo_bpm) else 0.5
            est.start(beat, time, period)
        else:
            beat = self._number(time)
            if beat is None or beat <= est.beat:
                return
            while est.beat < beat:
                est.advance(self._ictus_of(est.beat))
            est.update(time)
        if beat in self.ictus:
            self.past_asynchrony[beat] = time - self.ictus[beat]
        if self.first_beat is not None:
            self.replan()

    def _predicted(self, ahead: int) -> list[float]:
        """The model's expected times of the next ``ahead`` beats after its current one."""
        est = self.estimator
        w = est.weights()
        e, t = est.x[:, 0].copy(), est.x[:, 1].copy()
        out = []
        for k in range(ahead):
            c = self._ictus_of(est.beat + k)
            asy = 0.0 if c is None else e - c
            e, t = e + t - est.a * asy, t + est.x[:, 2] - est.g * asy
            out.append(float(w @ e))
        return out

    def _number(self, time: float) -> int | None:
        est = self.estimator
        predicted = np.asarray(self._predicted(3))
        period = float(est.weights() @ est.x[:, 1])
        k = int(np.argmin(np.abs(predicted - time)))
        if abs(predicted[k] - time) > 0.35 * period:
            return None
        return est.beat + 1 + k

    def tick(self) -> None:
        """After every block: if a beat was not heard in time, advance the model without it."""
        est = self.estimator
        if not est.ready or self.first_beat is None:
            return
        now = self.ears.now
        w = est.weights()
        c = self._ictus_of(est.beat)
        e, t = est.x[:, 0], est.x[:, 1]
        nxt = e + t - (0.0 if c is None else est.a * (e - c))
        period = float(w @ t)
        # the tracker has judged a beat about min(0.2 period, 0.1) + 0.035 s after it
        if now > float(w @ nxt) + min(0.2 * period, 0.1) + 0.09:
            est.advance(self._ictus_of(est.beat))
            self.replan()

    def _ictus_of(self, beat: int) -> float | None:
        if self.first_beat is None or beat < self.first_beat:
            return None
        if beat in self.ictus:
            return self.ictus[beat]
        return self.plan.get(beat)

    # ------------------------------------------------------------------ planning
    def start(self, beat, time):
        super().start(beat, time)
        self.plan = {beat: time}
        self.replan()

    def replan(self) -> None:
        est = self.estimator
        if not est.ready or self.first_beat is None:
            return
        now = self.ears.env.now if self.ears.env is not None else self.ears.now
        beat0 = est.beat
        fixed: dict[int, float] = {}
        b = beat0
        while True:
            t = self._ictus_of(b)
            if b >= self.first_beat and (b in self.ictus or (t is not None and t < now + FREEZE)):
                fixed[b] = t
                b += 1
                continue
            if b < self.first_beat:
                b += 1
                continue
            break
        first_free = max(b, self.first_beat)
        last = min(first_free + self.config.horizon_beats - 1, self.piece.n_beats)
        if first_free > last:
            return
        free = list(range(first_free, last + 1))
        top = est.top()
        weights = est.weights()[top]
        conducted = [n for n in self.past_asynchrony]
        past = [self.past_asynchrony[n] for n in sorted(conducted)]
        plan = self.planner.plan(
            past, self.piece.n_beats - last, x0=est.x[top], a=est.a[top], g=est.g[top], weights=weights,
            beat0=beat0, fixed=fixed, free=free, conducted_from=self.first_beat,
            target_period=lambda n: score_period(self.piece, n), previous_ictus=self._ictus_of(beat0 - 1))
        times = np.asarray(plan.ictus, float)
        # keep the conductor's beats in order and playable
        previous = max([t for t in fixed.values() if t is not None], default=None)
        for i in range(times.size):
            lo = now + FREEZE
            if previous is not None:
                lo = max(lo, previous + MIN_INTERVAL)
            times[i] = max(times[i], lo)
            previous = times[i]
        for n, t in zip(free, times):
            self.plan[n] = float(t)
        e = est.estimate()
        self.history.append({"t": now, "beat": beat0, "a": e["a"], "g": e["g"], "period": e["period"],
                             "weight": plan.weight, "asynchrony_ms": [round(1000 * x, 1) for x in plan.asynchrony]})
        self.anticipator.refresh(now)

    def stroke(self, beat):
        return f"anticipators:{self.anticipator.id}:beat{beat}"

    def planned(self, beat):
        if beat in self.ictus:
            return self.ictus[beat]
        if beat in self.plan:
            return self.plan[beat]
        if self.plan:
            last = max(self.plan)
            if beat > last:
                t = self.plan[last]
                for n in range(last, beat):
                    t += score_period(self.piece, n)
                return t
        return self.ears.beat_time(beat)

    def describe(self):
        if not self.estimator.ready:
            return {}
        e = self.estimator.estimate()
        return {"estimated_phase_correction": round(e["a"], 3), "estimated_period_correction": round(e["g"], 3),
                "plans": len(self.history)}


STRATEGY_CLASSES = {"follow": Follow, "target": Target, "lead": Lead, "best": Best}


def make_strategy(name: str, piece: Piece, config: ConductorConfig, ears: Ears) -> Strategy:
    """The strategy called ``name``."""
    return STRATEGY_CLASSES[name](piece, config, ears)
