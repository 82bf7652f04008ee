"""The simulated user: a person exercising with the trainer, each repetition's key point timed by a noisy
timekeeper drawn towards the trainer's key points.

The person keeps a period of their own that drifts (fatigue slows them), with timekeeper and motor noise
(Vorberg & Wing 1996), pauses once and restarts, and corrects towards the trainer as an ensemble does towards
its conductor (:mod:`scenarios.conductor.ensemble`): the phase by a share ``alpha`` of the asynchrony to the
trainer's nearest key point, the period by a share ``beta`` of the difference to the trainer's period, but
by at most 5 % a repetition and only while the two are together (within a quarter of a period): a trainer far out of step is not
followed. Everything is drawn from a generator seeded by the run's seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenarios.trainer.signal import acceleration

#: Within this share of a period of the trainer's key point the user is with the trainer, and corrects.
TOGETHER = 0.25
#: A trainer's period further than this share from the user's own is not taken up: a person follows a tempo
#: near theirs, not one far from it.
REACH = 0.1
#: The most a person changes their period in one repetition (a share of it).
MAX_CHANGE = 0.05
#: The user's sensor: samples a second (a phone's motion events come at about 60 Hz; 50 keeps runs light).
RATE = 50.0


@dataclass(frozen=True)
class UserModel:
    """One person, as drawn for a seed."""

    start_period: float
    first_key: float
    repetitions: int
    motor_sd: float
    keeper_sd: float
    fatigue: float
    pause_after: int
    pause_seconds: float
    alpha: float
    beta: float

    @classmethod
    def draw(cls, target_period: float, seed: int, repetitions: int = 20) -> "UserModel":
        """A person for ``seed``: 17-25 % off the target tempo (slower or faster), a pause after the 9th to
        12th repetition."""
        rng = np.random.default_rng([seed, 41])
        off = rng.uniform(0.17, 0.25) * (1 if rng.random() < 0.5 else -1)
        return cls(start_period=target_period / (1.0 + off), first_key=float(rng.uniform(1.8, 2.4)),
                   repetitions=repetitions, motor_sd=float(rng.uniform(0.01, 0.018)),
                   keeper_sd=float(rng.uniform(0.006, 0.01)), fatigue=float(rng.uniform(0.001, 0.004)),
                   pause_after=int(rng.integers(9, 13)), pause_seconds=float(rng.uniform(3.0, 4.5)),
                   alpha=float(rng.uniform(0.4, 0.55)), beta=float(rng.uniform(0.5, 0.7)))


class SimulatedUser:
    """The person's key points, decided one repetition ahead, and the signal their phone reports."""

    def __init__(self, model: UserModel, exercise: str, seed: int):
        self.model = model
        self.exercise = exercise
        self.rng = np.random.default_rng([seed, 42])
        self.keys: list[float] = [model.first_key]
        self.period = model.start_period
        self.trainer: list[float] = []  # the trainer's key points as seen
        self.pauses: list[int] = []  # indices (from 0) of the key points that follow a pause
        self.heard_until = 0.0

    def see(self, t: float) -> None:
        """The trainer reached a key point at ``t``."""
        self.trainer.append(t)

    @property
    def done(self) -> bool:
        return len(self.keys) >= self.model.repetitions

    def _decide(self) -> None:
        """The next key point, decided on the way up from the last one."""
        m = self.model
        last = self.keys[-1]
        self.period *= 1.0 + m.fatigue
        seen = [t for t in self.trainer if abs(t - last) < 0.5 * self.period]
        correction = 0.0
        if seen:
            nearest = min(seen, key=lambda t: abs(t - last))
            asynchrony = last - nearest
            if abs(asynchrony) < TOGETHER * self.period:
                correction = -m.alpha * asynchrony
                if len(self.trainer) >= 2:
                    theirs = self.trainer[-1] - self.trainer[-2]
                    if abs(theirs - self.period) < REACH * self.period:
                        change = m.beta * (theirs - self.period)
                        self.period += max(-MAX_CHANGE * self.period, min(MAX_CHANGE * self.period, change))
        self.period += self.rng.normal(0.0, m.keeper_sd)
        interval = self.period + correction + self.rng.normal(0.0, m.motor_sd)
        if len(self.keys) == m.pause_after:
            interval += m.pause_seconds
            self.pauses.append(len(self.keys))
        self.keys.append(last + interval)

    def samples(self, until: float) -> tuple[np.ndarray, np.ndarray]:
        """The sensor's samples after the last ones given, up to ``until``: times and acceleration."""
        while not self.done and self.keys[-1] + 0.2 * self.period <= until:
            self._decide()  # on the way up from a key point, having seen where the trainer was
        first = int(np.floor(self.heard_until * RATE)) + 1
        last = int(np.floor(until * RATE))
        self.heard_until = until
        if last < first:
            return np.zeros(0), np.zeros((0, 3))
        t = np.arange(first, last + 1) / RATE
        return t, acceleration(t, self.keys, self.exercise, self.rng)

    @property
    def end(self) -> float:
        """When the set is over: after the last key point, standing again."""
        return self.keys[-1] + 1.5 if self.done else float("inf")
