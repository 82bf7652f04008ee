"""The trainer: its repetitions as postures whose key points are pegged to predictions of the user's, counting
on the user's key points, and remarks fitted between repetitions.

Strategies, as the conductor's: ``follow`` pegs the trainer's key points to the repetition anticipator's
predictions of the user's (``anticipators:reps:repN``); ``lead`` pegs them to its own plan
(``anticipators:trainer:keyN``): the user's predicted key point, moved ahead of it (for a user slower than the
target; behind for one faster) by up to 0.18 periods, in proportion to how far the user's tempo is from the
target (the whole of it from 10 % off): the user, drawn towards the trainer's key points, shortens (or
lengthens) each interval and takes the new tempo up, as an ensemble follows a conductor who leads it;
``fixed`` keeps the target tempo from the user's third repetition on and ignores them (the baseline). Each
count word is pegged so that its stressed syllable falls on the user's predicted key point, whatever the
strategy; a remark is pegged to end a little before the next count, so that it moves with the tempo and never
cuts a count, and is said only when it fits.
"""

from __future__ import annotations

import re

from agentsim.core.anticipator import PAST_TOLERANCE, Anticipator

NUMBERS = ("zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen fifteen "
           "sixteen seventeen eighteen nineteen twenty").split()
#: Posture lexeme, the sync point that is the key point, and each sync point's place in periods from it.
MOVES = {
    "squat": ("SQUAT", "ready", {"start": -0.4, "ready": 0.0, "relax": 0.01, "end": 0.4}),
    "jumping-jack": ("JUMPING_JACK", "end", {"start": -0.85, "ready": -0.55, "relax": -0.45, "end": 0.0}),
    "arm-raise": ("ARM_RAISE", "end", {"start": -0.85, "ready": -0.55, "relax": -0.45, "end": 0.0}),
}
#: What the trainer says after a repetition: (repetition, or a negative count from the last), the words (a
#: shorter way of saying it after a ``|``, for a gap too short for the first).
REMARKS = {
    "squat": ((5, "keep your back straight|back straight"), (9, "you are doing great|great"), (-3, "three more"), (-0, "well done")),
    "jumping-jack": ((5, "arms all the way up|arms up"), (9, "you are doing great|great"), (-3, "three more"),
                     (-0, "well done")),
    "arm-raise": ((5, "arms all the way up|arms up"), (9, "you are doing great|great"), (-3, "three more"),
                  (-0, "well done")),
}
#: Silence kept between a remark and the next count, seconds.
MARGIN = 0.25
#: How soon after it is submitted a hurried move starts (s; its sync points are written to the millisecond).
SOON = 0.02
#: How far (in periods) ``lead``'s key points are at most ahead of (or behind) the user's predicted ones, and
#: from how far off the target tempo (a share) they are that far.
LEAD_AHEAD, LEAD_FULL = 0.18, 0.1
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
_KEY = re.compile(r"^key(\d{1,9})$")


def number(n: int) -> str:
    """The count word for ``n``."""
    return NUMBERS[n] if 0 <= n < len(NUMBERS) else str(n)


class Plan(Anticipator):
    """The trainer's own key points (``keyN``) for ``lead`` (N: the user's repetition it goes with) and
    ``fixed`` (N: its own repetitions, from the user's third on)."""

    def __init__(self, anticipator_id: str, strategy: str, reps, target_period: float):
        super().__init__(anticipator_id)
        self.strategy, self.reps, self.target = strategy, reps, target_period
        self.keys: dict[int, float] = {}
        self.first: int | None = None

    def make_peg(self, sync_id: str):
        match = _KEY.match(sync_id)
        if not match:
            return False
        return self.keys.get(int(match.group(1)))

    def update(self, now: float, last: int) -> None:
        """Plan the key points up to the ``last``-th and move the pegs."""
        tracker = self.reps.tracker
        if tracker.period is None:
            return
        if self.first is None:
            self.first = max(3, len(tracker.repetitions) + 1)
        for n in range(self.first, last + 1):
            if n in self.keys and self.keys[n] <= now:
                continue  # passed: kept
            before = self.keys.get(n - 1)
            if self.strategy == "fixed":
                self.keys[n] = tracker.key_point(n) if before is None else before + self.target
                continue
            predicted = tracker.key_point(n)
            user = tracker.period
            off = max(-1.0, min(1.0, (user / self.target - 1.0) / LEAD_FULL))  # > 0: the user is slower
            self.keys[n] = predicted - LEAD_AHEAD * off * user
        for sync_id, peg in self.pegs.items():
            time = self.make_peg(sync_id)
            if time is None or time == peg.time:
                continue
            if peg.time is not None and peg.time >= now - PAST_TOLERANCE and time < now - PAST_TOLERANCE:
                continue
            peg.set(time)


class Trainer:
    """Submits the trainer's moves (``repN`` blocks) and a count word for each of the user's repetitions from
    the third on (``countN``), and its remarks (``remarkN``)."""

    def __init__(self, realizer, reps, plan: Plan | None, exercise: str, repetitions: int, spoken):
        self.realizer, self.reps, self.plan = realizer, reps, plan
        self.exercise = exercise
        self.repetitions = repetitions
        self.spoken = spoken  # text -> (its stressed syllable's onset, its duration), seconds
        self.moved = 2  # the last move planned
        self.count_planned = 2  # the last count planned
        self.remarked: set[int] = set()
        self.pending: list[str] = []  # remarks due that have not fitted yet
        self.remarks: list[tuple[int, str]] = []  # (after repetition, words) said
        self.skipped: list[tuple[int, str]] = []  # remarks that did not fit
        lexeme, self.key_sync, self.places = MOVES[exercise]
        self.lexeme = lexeme
        self.key_points: dict[int, float] = {}  # move -> the trainer's key point as it played
        self.counted: dict[int, float] = {}  # repetition -> when its count word started
        self.recounted: list[int] = []  # repetitions counted again after a pause
        realizer.feedback.listen(self.see)

    def see(self, feedback) -> None:
        if feedback.get("type") != "syncPointProgress":
            return
        block, _, rest = str(feedback.get("id", "")).partition(":")
        if rest == f"move:{self.key_sync}" and block.startswith("rep"):
            self.key_points[int(block[3:])] = float(feedback["globalTime"])
        elif rest == "count:start" and block.startswith("count"):
            self.counted[int(block[5:])] = float(feedback["globalTime"])

    def key_ref(self, n: int) -> str:
        return f"anticipators:trainer:key{n}" if self.plan is not None else f"anticipators:reps:rep{n}"

    def step(self, now: float) -> None:
        """After each update of the anticipator: plan what is due."""
        tracker = self.reps.tracker
        found = len(tracker.repetitions)
        period = tracker.period
        if period is None:
            return
        last = min(self.repetitions, found + 2)
        fixed = self.plan is not None and self.plan.strategy == "fixed"
        if fixed:  # its own moves at the target tempo, planned two periods ahead
            self.plan.update(now, self.moved + 1)
            while self.moved < self.repetitions and self.plan.keys.get(self.moved + 1, now) < now + 2 * self.plan.target:
                self.moved += 1
                self.submit_move(self.moved, self.plan.target, now)
                self.plan.update(now, self.moved + 1)
        else:
            if self.plan is not None:
                self.plan.update(now, last)
            while self.moved < last:
                self.moved += 1
                self.submit_move(self.moved, period, now)
        while self.count_planned < last:
            self.count_planned += 1
            self.submit_count(self.count_planned)
        # a count that went to a repetition that did not come (the person paused) is said again on the one that
        # did: as soon as the tracker senses the person slowing into its bottom (a count said once the
        # repetition is found comes a third of a second and more after it, late for a quick tempo), or else
        # once it is found
        restart = tracker.restart
        for n, at in ((found + 1, restart), (found, tracker.repetitions[-1])):
            started = self.counted.get(n)
            if 3 <= n <= self.repetitions and n not in self.recounted and at is not None and started is not None \
                    and started < at - 0.5 * period:
                self.recounted.append(n)
                self.realizer.submit(f'<bml {NS} id="recount{n}"><speech id="count" start="0.02">'
                                     f'<text>{number(n)}</text></speech></bml>')
        if found >= 3 and found not in self.remarked:
            self.remarked.add(found)
            self.remark(found, now)

    def submit_move(self, n: int, period: float, now: float) -> None:
        """The ``n``-th move, its sync points ``period`` s apart as :data:`MOVES` places them; a move whose start
        would already have passed (the first, when the user's second repetition is found late in a quick tempo)
        is hurried into its key point from now."""
        key = self.key_ref(n)
        at = self.plan.keys.get(n) if self.plan is not None else self.reps.tracker.key_point(n)
        before = -min(self.places.values()) * period  # how long the move takes before its key point
        room = (at - now - SOON) if at is not None else before
        hurry = min(1.0, room / before) if before > 0 and room > 0 else 1.0
        syncs = " ".join(f'{name}="{key}{self.places[name] * period * (hurry if self.places[name] < 0 else 1):+.3f}"'
                         for name in self.places)
        self.realizer.submit(f'<bml {NS} id="rep{n}"><posture id="move" lexeme="{self.lexeme}" {syncs}/></bml>')

    def submit_count(self, n: int) -> None:
        word = number(n)
        self.realizer.submit(f'<bml {NS} id="count{n}"><speech id="count" start="anticipators:reps:rep{n}-'
                             f'{self.spoken[word][0]:.3f}"><text>{word}</text></speech></bml>')

    def remark(self, n: int, now: float) -> None:
        """After repetition ``n`` (just found): a remark due, if one fits before the next count (one that does
        not waits for the next gap, but for "three more", which is true only once)."""
        due = [words for at, words in REMARKS[self.exercise] if at == n or (at <= 0 and n == self.repetitions + at)]
        self.pending = [w for w in self.pending if w != "three more"] + due
        if not self.pending:
            return
        if n >= self.repetitions:  # after the last: the last remark, as nothing follows
            words = self.pending[-1].split("|")[0]
            self.pending = []
            self.realizer.submit(f'<bml {NS} id="remark{n}"><speech id="say" start="0.3">'
                                 f'<text>{words}</text></speech></bml>')
            self.remarks.append((n, words))
            return
        tracker = self.reps.tracker
        upcoming = number(n + 1)
        next_key = tracker.key_point(n + 1)
        free_from = max(now + 0.05, tracker.key_point(n) + self.spoken[number(n)][1] + 0.1)
        for remark in list(self.pending):
            for words in remark.split("|"):
                lead = self.spoken[upcoming][0] + MARGIN + self.spoken[words][1]
                if free_from <= next_key - lead:
                    self.pending.remove(remark)
                    self.realizer.submit(f'<bml {NS} id="remark{n}"><speech id="say" start="anticipators:reps:'
                                         f'rep{n + 1}-{lead:.3f}"><text>{words}</text></speech></bml>')
                    self.remarks.append((n, words))
                    return
        self.skipped.append((n, self.pending[0].split("|")[0]))
