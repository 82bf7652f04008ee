"""The conductor: conducting BML bar by bar, a "play louder" gesture when needed, and stopping the piece.

The conductor listens until its tracker is confident of the ensemble's beat, then joins at the next bar
it can prepare for. Each bar is one BML block of conducting gestures (``CONDUCT_4_4_1`` ..
``CONDUCT_4_4_4``, the beat's place in the pattern in the lexeme) on the right hand, submitted once the
bar's first ictus is planned within ``horizon_seconds``; each gesture's stroke refers to the strategy's
anticipator peg of its beat, so it is re-timed while it plays. Short blocks keep plans short: what a
strategy decides later only concerns bars not yet submitted, or moves pegs.

At every downbeat it compares the loudness of the bar it just heard with what the score's marking asks
(a reference from a sound check of the score at its marked dynamics): when the ensemble is more than
``louder_threshold_db`` too soft it adds a left-hand ``LOUDER`` gesture with raised brows. When the
tracker has not been confident for ``stop_after_seconds`` the ensemble has fallen apart: a ``REPLACE``
block with a two-handed ``STOP`` gesture ends the conducting, and the piece.
"""

from __future__ import annotations

import re

from scenarios.conductor.config import ConductorConfig, Piece
from scenarios.conductor.hearing import Ears
from scenarios.conductor.strategies import Strategy

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
_STROKE = re.compile(r"^[^:]+:b(\d+):stroke$")

#: How big the conducting pattern is at each dynamics marking (the gesture's ``amount``).
AMOUNT = {"pp": 0.6, "p": 0.75, "mp": 0.9, "mf": 1.0, "f": 1.15, "ff": 1.3}


class Conductor:
    """Plans and submits the conducting of a piece on a realizer, listening through ``ears``.

    Parameters
    ----------
    realizer : Realizer
        Where the BML goes; its feedback must reach :meth:`see`.
    ears : Ears
        The tracker (its pegs are ``anticipators:band:...``).
    strategy : Strategy
        Where the strokes go.
    piece : Piece
        The score.
    config : ConductorConfig
        Conductor parameters.
    reference_db : dict, optional
        Marking -> expected RMS level (dBFS) of the ensemble; no loudness checks without it.
    downbeats_known : bool
        Whether the tracker's beat numbers are the score's (simulation: the conductor cued beat 1). If not
        (live), the conductor joins at any beat and counts bars from there.
    """

    def __init__(self, realizer, ears: Ears, strategy: Strategy, piece: Piece, config: ConductorConfig,
                 reference_db: dict[str, float] | None = None, downbeats_known: bool = True):
        self.realizer = realizer
        self.env = realizer.env
        self.ears = ears
        self.strategy = strategy
        self.piece = piece
        self.config = config
        self.reference_db = reference_db
        self.downbeats_known = downbeats_known
        self.first_beat: int | None = None
        self.join_time: float | None = None
        self.ictus: dict[int, float] = {}
        self.submitted_bars: list[int] = []
        self.louder: list[dict] = []
        self.levels: list[dict] = []
        self.stopped_at: float | None = None
        self.finished = self.env.event()
        self._louder_bar = -10**9
        self._phase = 0
        self.process = self.env.process(self._conduct())

    # ------------------------------------------------------------------ feedback
    def see(self, feedback: dict) -> None:
        """Record the strokes of conducting gestures (the ictus) and tell the strategy."""
        if feedback.get("type") != "syncPointProgress":
            return
        m = _STROKE.match(feedback["id"])
        if m:
            beat = int(m.group(1))
            self.ictus[beat] = float(feedback["globalTime"])
            self.strategy.on_ictus(beat, float(feedback["globalTime"]))
            if self.position(beat) == 1:
                self._downbeat(beat)

    # ------------------------------------------------------------------ bars
    def position(self, beat: int) -> int:
        """Place (1-based) of ``beat`` in its bar as conducted."""
        return (beat - 1 - self._phase) % self.piece.beats_per_bar + 1

    def bar_of(self, beat: int) -> int:
        return (beat - 1 - self._phase) // self.piece.beats_per_bar + 1

    def bar_beats(self, bar: int) -> list[int]:
        first = (bar - 1) * self.piece.beats_per_bar + 1 + self._phase
        beats = range(max(first, self.first_beat), first + self.piece.beats_per_bar)
        return [b for b in beats if b <= self.piece.n_beats]

    def bar_bml(self, bar: int) -> str:
        bpb, unit = self.piece.meter.beats_per_bar, self.piece.meter.beat_unit
        marking = self.piece.marking_at(min(max(bar, 1), self.piece.bars))
        amount = AMOUNT.get(marking, 1.0)
        gestures = "".join(
            f'<gesture id="b{n}" lexeme="CONDUCT_{bpb}_{unit}_{self.position(n)}" mode="RIGHT_HAND" '
            f'amount="{amount:g}" stroke="{self.strategy.stroke(n)}"/>' for n in self.bar_beats(bar))
        return f'<bml {NS} id="bar{bar}" characterId="conductor" composition="MERGE">{gestures}</bml>'

    # ------------------------------------------------------------------ the process
    def _join(self):
        env = self.env
        cfg = self.config
        while True:
            if self.ears.confidence >= cfg.join_confidence and len(self.ears.upcoming) >= 2:
                for beat in sorted(self.ears.beats):
                    t = self.ears.beats[beat]
                    if t < env.now + cfg.prepare_seconds:
                        continue
                    if self.downbeats_known and self.piece.beat_in_bar(beat) != 1:
                        continue
                    if beat > self.piece.n_beats - self.piece.beats_per_bar:
                        return None
                    return beat, t
            yield env.timeout(0.05)

    def _conduct(self):
        env = self.env
        cfg = self.config
        joined = yield from self._join()
        if joined is None:
            self.finished.succeed()
            return
        beat, t = joined
        self.first_beat = beat
        self.join_time = env.now
        if not self.downbeats_known:
            self._phase = (beat - 1) % self.piece.beats_per_bar
        self.strategy.start(beat, t)
        bar = self.bar_of(beat)
        last_bar = self.bar_of(self.piece.n_beats)
        low_since = None
        while True:
            while bar <= last_bar:
                beats = self.bar_beats(bar)
                if not beats:
                    bar += 1
                    continue
                planned = self.strategy.planned(beats[0])
                if planned is None or planned > env.now + cfg.horizon_seconds:
                    break
                self.realizer.submit(self.bar_bml(bar), source=f"bar {bar}")
                self.submitted_bars.append(bar)
                bar += 1
            last_ictus = max(self.ictus) if self.ictus else 0
            if last_ictus >= self.piece.n_beats:
                break
            if self.ears.confidence < cfg.stop_confidence:
                low_since = env.now if low_since is None else low_since
                if env.now - low_since >= cfg.stop_after_seconds:
                    self.stop()
                    break
            else:
                low_since = None
            yield env.timeout(0.05)
        self.finished.succeed()

    # ------------------------------------------------------------------ loudness and stopping
    def _downbeat(self, beat: int) -> None:
        bar = self.bar_of(beat)
        prev = beat - self.piece.beats_per_bar
        if self.reference_db is None or prev not in self.ictus or self.stopped_at is not None:
            return
        heard = self.ears.level_db(self.ictus[prev], self.ictus[beat])
        marking = self.piece.marking_at(min(max(bar - 1, 1), self.piece.bars))
        expected = self.reference_db.get(marking)
        if expected is None:
            return
        self.levels.append({"bar": bar - 1, "heard_db": round(heard, 2), "expected_db": round(expected, 2),
                            "marking": marking})
        too_soft = heard < expected - self.config.louder_threshold_db
        if too_soft and bar - self._louder_bar >= self.config.louder_every_bars and beat < self.piece.n_beats - 2:
            self._louder_bar = bar
            k = len(self.louder) + 1
            doc = (f'<bml {NS} id="louder{k}" characterId="conductor" composition="MERGE">'
                   f'<gesture id="louder{k}" lexeme="LOUDER" mode="LEFT_HAND" amount="1.2"/>'
                   f'<faceLexeme id="brows{k}" lexeme="RAISE_BROWS" start="louder{k}:start" end="louder{k}:end"/>'
                   '</bml>')
            self.realizer.submit(doc, source="play louder")
            self.louder.append({"time": self.env.now, "bar": bar, "heard_db": round(heard, 2),
                                "expected_db": round(expected, 2)})

    def stop(self) -> None:
        """Stop the piece: end all conducting (REPLACE) with a two-handed STOP gesture."""
        if self.stopped_at is not None:
            return
        self.stopped_at = self.env.now
        doc = (f'<bml {NS} id="stop" characterId="conductor" composition="REPLACE">'
               '<gesture id="stop" lexeme="STOP" mode="BOTH_HANDS" amount="1.3"/>'
               '<head id="stopshake" lexeme="SHAKE" start="stop:start"/></bml>')
        self.realizer.submit(doc, source="stop")
