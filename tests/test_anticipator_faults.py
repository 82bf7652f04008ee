"""Fault injection into anticipators: whatever one does wrong loses only that anticipator or that peg, with a
warning, and the rest of the run goes on."""

from __future__ import annotations

import math

import pytest

from agentsim.core.anticipator import Anticipator
from agentsim.core.reporter import Reporter

from helpers import realize

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


class Faulty(Anticipator):
    """Beats at 1, 2, 3, ... s; ``fault`` says what goes wrong, and when (simulated s)."""

    def __init__(self, fault: str, at: float = 0.5, value: float = math.nan):
        super().__init__("faulty")
        self.kind, self.at, self.value = fault, at, value

    def make_peg(self, sync_id: str):
        if not sync_id.startswith("beat"):
            return False
        n = int(sync_id[4:])
        if self.kind == "make_peg raises" and n == 2:
            raise RuntimeError("the model is not loaded")
        if self.kind == "make_peg not finite" and n == 2:
            return self.value
        return float(n)

    def run(self):
        return self._perceive()

    def _perceive(self):
        yield self.env.timeout(self.at)
        if self.kind == "process raises":
            raise ZeroDivisionError("division by zero")
        if self.kind == "moves not finite":
            self.move("beat2", self.value)
        if self.kind == "moves into the past":
            self.move("beat2", self.env.now - 0.25)
        if self.kind == "storm":
            for _ in range(1000):
                self.move("beat2", math.nan)
        yield self.env.timeout(10.0)


def block(*beats: int) -> str:
    gestures = "".join(f'<gesture id="g{n}" lexeme="BEAT" mode="{"LEFT_HAND" if n % 2 else "RIGHT_HAND"}" '
                       f'stroke="anticipators:faulty:beat{n}"/>' for n in beats)
    return f'<bml {NS} id="b">{gestures}<head id="h" lexeme="NOD"/></bml>'


def run(fault: str, **kwargs):
    return realize(block(1, 2, 3), anticipators=[Faulty(fault, **kwargs)])


def test_an_exception_in_the_process_stops_only_the_anticipator():
    r = run("process raises")
    ((target, kind, description),) = [(w["id"], w["warningType"], w["description"]) for w in r.warnings]
    assert target == "anticipators:faulty" and kind == "IMPOSSIBLE_TO_SCHEDULE"
    assert description == ("anticipator 'faulty' stopped: its process raised ZeroDivisionError: division by zero; "
                           "its pegs keep their last predictions")
    # the pegs keep their predictions: every stroke is on its beat, and the block ends
    assert [r.glob[f"b:g{n}:stroke"] for n in (1, 2, 3)] == [1.0, 2.0, 3.0]
    assert [b["id"] for b in r.blocks] == ["b:start", "b:end"]


def test_an_exception_in_make_peg_loses_that_peg():
    r = run("make_peg raises")
    ((target, kind, description),) = [(w["id"], w["warningType"], w["description"]) for w in r.warnings]
    assert target == "b:g2" and "anticipator 'faulty' failed to predict 'beat2': RuntimeError: the model is not " \
                                "loaded" in description
    assert r.glob["b:g1:stroke"] == 1.0 and r.glob["b:g3:stroke"] == 3.0 and "b:g2:start" not in r.glob


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_prediction_that_is_not_finite_loses_that_peg(value):
    r = run("make_peg not finite", value=value)
    ((target, kind, description),) = [(w["id"], w["warningType"], w["description"]) for w in r.warnings]
    assert target == "b:g2" and f"predicted {value!r} for 'beat2': times must be finite" in description
    assert r.glob["b:g1:stroke"] == 1.0 and r.glob["b:g3:stroke"] == 3.0


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_move_to_a_time_that_is_not_finite_is_refused_and_the_peg_keeps_its_time(value):
    r = run("moves not finite", value=value)
    ((target, kind, description),) = [(w["id"], w["warningType"], w["description"]) for w in r.warnings]
    assert target == "anticipators:faulty:beat2" and kind == "IMPOSSIBLE_TO_SCHEDULE"
    assert description == f"anticipators:faulty:beat2 moved to {value!r}; move refused (times must be finite)"
    assert [r.glob[f"b:g{n}:stroke"] for n in (1, 2, 3)] == [1.0, 2.0, 3.0]
    assert [b["id"] for b in r.blocks] == ["b:start", "b:end"]


def test_a_move_of_a_peg_still_to_come_into_the_past_is_refused():
    r = run("moves into the past", at=1.75)
    ((target, kind, description),) = [(w["id"], w["warningType"], w["description"]) for w in r.warnings]
    assert target == "anticipators:faulty:beat2"
    assert description == ("anticipators:faulty:beat2 moved from 2 s into the past (1.5 s, now 1.75 s); move "
                           "refused")
    # the gesture already under way keeps its timing: no stroke of zero duration at once
    assert r.glob["b:g2:stroke"] == 2.0 and r.glob["b:g2:start"] < 1.75 < r.glob["b:g2:stroke"]


def test_a_storm_of_faults_is_reported_a_bounded_number_of_times():
    r = run("storm")
    faults = [w for w in r.warnings if w["id"] == "anticipators:faulty:beat2"]
    assert len(faults) == Reporter.MAX_FAULT_WARNINGS
    assert faults[-1]["description"].endswith("(further faults of anticipator 'faulty' are not reported)")
    assert [r.glob[f"b:g{n}:stroke"] for n in (1, 2, 3)] == [1.0, 2.0, 3.0]


def test_a_peg_that_has_passed_may_still_be_corrected():
    class Corrects(Faulty):
        def _perceive(self):
            yield self.env.timeout(2.5)
            self.move("beat1", 1.01)  # beat 1 was heard a little later than predicted: history, no fault
            yield self.env.timeout(1.0)

    r = realize(block(1, 2), anticipators=[Corrects("none")])
    assert not r.warnings and r.realizer.scheduler.anticipators["faulty"].pegs["beat1"].time == 1.01
