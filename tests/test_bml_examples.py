"""Every bundled BML 1.0 example parses (or is refused) and meets the "Required timing" of its header.

Where a header comment is stale and contradicts its own document, the document wins; the table says so.
"""

from __future__ import annotations

import re

import pytest

from helpers import realize
from agentsim.core.block import BEHAVIOUR_TYPES

# Relations over block-relative sync times: "a = b = 3", "a < 10", "a:end+1 >= b:start".
EXPECTED: dict[str, list[str]] = {
    "after.xml": ["beat1:stroke+2 >= speech1:sync4", "nod1:stroke >= speech1:sync4", "no warnings"],
    "after2.xml": ["beat1:stroke+2 >= speech1:sync4+1", "nod1:stroke >= speech1:sync4+1", "no warnings"],
    "after_required.xml": ["beat1:stroke+2 >= speech1:sync4", "nod1:stroke >= speech1:sync4", "no warnings"],
    "afterunify.xml": ["beat1:stroke+2 >= speech1:sync4", "nod1:stroke >= speech1:sync4",
                       "beat1:end+5 >= speech1:sync4", "nod1:end+6 >= speech1:sync4", "no warnings"],
    "afterunify_offset.xml": ["beat1:stroke+2 >= speech1:sync4", "nod1:stroke >= speech1:sync4",
                              "beat1:end >= speech1:sync4+5", "nod1:end+1 >= speech1:sync4+5", "no warnings"],
    # Header says "beat1:stroke > speech1:sync4 + 2": stale, the document has <before>.
    "before.xml": ["beat1:stroke+2 <= speech1:sync4", "nod1:stroke <= speech1:sync4", "beat1:start = 0",
                   "no warnings"],
    "empty.xml": ["no warnings"],
    "testabs.xml": ["nod1:start = g1:start = speech1:start = 1", "no warnings"],
    # Header says beat1:end = 5: stale, the document says end="7".
    "testbeatandnod.xml": ["beat1:start = 3", "beat1:end = 7", "beat1:strokeEnd = nod1:start", "no warnings"],
    # The second comment calls this timing invalid; the header requires it and the document asks it.
    "testbeatreadytimed.xml": ["beat1:start = 1", "beat1:ready = 2", "no warnings"],
    "testgazereadytimed.xml": ["gaze1:ready = 3", "gaze1:end = 10", "no warnings"],
    "testgazeshift.xml": ["shift1:start = 0", "shift1:end = 3", "no warnings"],
    # lexeme "Y" is none BML knows: it plays as a nod, and the reader says so
    "testhead_selftimed.xml": ["shake1:start = 0", "shake1:end = 1", "warning mentions Y (shake1)"],
    "testinvalidxml.xml": ["refused"],
    "testinvalidxml2.xml": ["dropped speech1", "nod1:start = 0"],
    "testnod.xml": ["nod1:start = 0", "no warnings"],
    # Header says nod1:end = 3: stale, its own constraints say nod2:start = 3.
    "testnod2x_absolute.xml": ["nod1:start = 1", "nod2:start = 3", "no warnings"],
    # Header swaps start and end; its constraints and the document say start 0, end 2.
    "testnod_absolute.xml": ["nod1:start = 0", "nod1:end = 2", "no warnings"],
    "testnod_invalidtime.xml": ["dropped nod1"],
    "testnod_offset.xml": ["nod1:start = 0", "nod2:start = 2", "no warnings"],
    "testnod_unknownattributes.xml": ["nod1:start = 0", "warning CUSTOM_ATTRIBUTE_NOT_SUPPORTED"],
    "testnodandbeat.xml": ["nod1:start = 3", "nod1:end = 5", "nod1:stroke = beat1:start", "no warnings"],
    "testnodandbeat_switchedorder.xml": ["nod1:start = 3", "nod1:end = 5", "nod1:stroke = beat1:start",
                                         "no warnings"],
    "testnods.xml": ["nod1:start = 1", "tilt1:start = nod1:end+1", "nod1:end > nod1:start", "no warnings"],
    "testoffset.xml": ["g1:start = 4", "g2:end = 4", "g2:start = 3", "h1:start = g1:end", "h1:start > 4",
                       "no warnings"],
    "testoffset2.xml": ["g1:start = 4", "g2:end = 5", "g2:start = 3", "h1:start = g1:end", "h1:start > 4",
                        "no warnings"],
    "testoffset3.xml": ["g1:start = 4", "g2:end = 5", "g2:start = 3", "h1:start = g1:end", "h1:start > 4",
                        "gaze1:start = 1", "gaze1:end = g1:end+3", "gaze1:end > 7", "no warnings"],
    "testoffsetchain.xml": ["h1:start = 4", "h2:start = 6", "h3:start = 8", "h4:start = 10", "no warnings"],
    # Header says "h2:end = h1:end": stale, the document ties h2:start to h1:end.
    "testoffsetchainneg.xml": ["speech1:start = 0", "h1:start = speech1:s1", "h1:start > 0",
                               "h2:start = h1:end", "h3:start = h2:end", "h4:start = h3:end", "no warnings"],
    # Header says h2:end = 6: stale, the document says h2:start = h3:start-2 = 6.
    "testoffsetchainreversed.xml": ["h1:start = 4", "h2:start = 6", "h3:start = 8", "h4:start = 10",
                                    "no warnings"],
    # Header says "gaze1:ready = speech1:ready" (speech has no ready): the document ties speech1:start.
    "testoffsetgaze.xml": ["gaze1:start = 2", "speech1:start = gaze1:ready", "speech1:start > 2", "no warnings"],
    "testoffsetgaze2.xml": ["gaze1:start = 2", "speech1:start = gaze1:ready", "speech1:start > 2",
                            "no warnings"],
    "testpostureshift.xml": ["shift1:start = 0", "shift1:end = 3", "no warnings"],
    "testrequiredbeh.xml": ["h1:start = 4", "h2:start = 6", "h3:start = 8", "h4:start = 10", "no warnings"],
    "testspeech3x.xml": ["speech10:start = 4", "speech11:start = speech10:end+4",
                         "speech12:start = speech11:end+4", "no warnings"],
    "testspeech_2linked.xml": ["speech1:start = 0", "speech1:end = speech2:start", "no warnings"],
    "testspeech_endtimed.xml": ["speech1:end = 5", "no warnings"],
    "testspeech_endtimed2.xml": ["dropped speech1"],
    "testspeech_gesturestart.xml": ["g1:start = 0", "g1:stroke = speech1:this", "no warnings"],
    "testspeech_invalidtime.xml": ["dropped speech1"],
    "testspeech_invalidtimesync.xml": ["dropped speech1"],
    "testspeech_invalidtimesync2.xml": ["dropped speech1"],
    "testspeech_nodtimedtosync.xml": ["speech1:start = 6", "speech1:syncstart1 = nod1:start", "nod1:end = 9",
                                      "no warnings"],
    "testspeech_nodtimedtosync_capitalization.xml": [
        "speech1WithCapitalizedStuff:start = 6",
        "speech1WithCapitalizedStuff:syncStart_1 = nod1WithCapitalizedStuff:start",
        "nod1WithCapitalizedStuff:end = 9", "no warnings"],
    "testspeech_nodtimedtosyncinverseorder.xml": ["speech1:start = 6", "speech1:syncstart1 = nod1:start",
                                                  "nod1:end = 9", "no warnings"],
    "testspeech_nodtimedtosyncoffset.xml": ["speech1:start = 6", "speech1:syncstart1+1 = nod1:start",
                                            "nod1:end = 9", "no warnings"],
    "testspeech_syncatstart.xml": ["welkom:start = 0", "welkom:deicticheart1 >= 0", "no warnings"],
    "testspeech_syncatstartandtobeat.xml": ["welkom:start = 0", "g1:start = welkom:deicticheart1",
                                            "g1:end = welkom:deicticheart1+2", "no warnings"],
    "testspeech_synctimed.xml": ["speech1:s1 = 10", "speech1:start < 10", "no warnings"],
    "testspeech_synctimed2x.xml": ["speech1:s1 = 10", "speech1:start < 10", "speech2:s1 = 20",
                                   "speech2:start < 20", "no warnings"],
    "testspeech_synctimed2x_required.xml": ["speech1:s1 = 10", "speech1:start < 10", "speech2:s1 = 20",
                                            "speech2:start < 20", "no warnings"],
    "testspeech_unknownbehavior.xml": ["dropped welkom", "warning mentions unknownbeh"],
    # Header asks nod1:start = speech1:unknown, but speech1 has no such sync point: nod1 is dropped.
    "testspeech_unknownsync.xml": ["dropped nod1", "warning mentions unknown", "speech1:start = 0"],
    "testspeechandnod_synctimed.xml": ["speech1:s1 = 10", "speech1:start = nod1:start", "speech1:start < 10",
                                       "speech1:end > 10", "no warnings"],
    "testspeechgestures.xml": ["g1:start = welkom:deicticheart1 = transleft:end-1 = 1", "g1:end = 3",
                               "g1:end = welkom:deicticheart1+2", "relaxleft:start = 3.5", "relaxleft:end = 5.8",
                               "transleft:start = 0", "no warnings"],
    "testspeechrel_offsets.xml": ["speech1:start = 4", "speech2:start = speech1:end+5",
                                  "nod2:start = speech1:start-2", "nod2:end = speech2:end+3", "no warnings"],
    "testtimeshift.xml": ["speech1:start = nod1:end", "nod1:start = 0", "no warnings"],
    # Header says w1:stroke (a wait has none): the document ties w1:end to speech1:end.
    "waitdoublesync.xml": ["w1:start = speech1:start = 0", "w1:end = speech1:end = speech2:start",
                           "no warnings"],
}

_TERM = re.compile(r"^\s*(?:(?P<num>-?\d+(?:\.\d+)?)|(?P<sync>[\w.]+:[\w.]+)(?P<off>[+-]\d+(?:\.\d+)?)?)\s*$")
EXACT = 1e-9


def value(result, term: str) -> float:
    match = _TERM.match(term)
    assert match, f"bad term {term!r}"
    if match.group("num") is not None:
        return float(match.group("num"))
    name = match.group("sync")
    assert name in result.local, f"no feedback for {name}: {sorted(result.local)}"
    return result.t(name) + float(match.group("off") or 0)


def check(result, rule: str) -> None:
    if rule == "no warnings":
        assert not result.warnings, result.warnings
    elif rule == "refused":
        assert len(result.warnings) == 1 and result.warnings[0]["warningType"] == "PARSING_FAILURE"
        assert "line" in result.warnings[0]["description"] and "column" in result.warnings[0]["description"]
        assert not result.blocks and not result.syncs
    elif rule.startswith("dropped "):
        beh = rule.split()[1]
        assert beh in result.dropped(), result.warnings
        assert not any(k.startswith(f"{beh}:") for k in result.local)
        assert [b["id"].split(":")[1] for b in result.blocks] == ["start", "end"]
    elif rule.startswith("warning mentions "):
        word = rule.split()[2]
        assert any(word in w["description"] for w in result.warnings), result.warnings
    elif rule.startswith("warning "):
        assert any(w["warningType"] == rule.split()[1] for w in result.warnings), result.warnings
    else:
        for op in (">=", "<=", "=", "<", ">"):
            if op in rule:
                terms = [value(result, t) for t in rule.split(op)]
                break
        for a, b in zip(terms, terms[1:]):
            {"=": lambda: abs(a - b) <= EXACT, "<": lambda: a < b, ">": lambda: a > b,
             "<=": lambda: a <= b + EXACT, ">=": lambda: a >= b - EXACT}[op]() or pytest.fail(
                f"{rule}: {a!r} vs {b!r}")


def test_every_example_has_expectations(examples):
    assert sorted(p.name for p in examples.glob("*.xml")) == sorted(EXPECTED)


@pytest.mark.parametrize("strict", [True, False], ids=["strict", "lenient"])
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_timing(examples, name, strict):
    result = realize((examples / name).read_bytes(), strict=strict)
    for rule in EXPECTED[name]:
        check(result, rule)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_lenient_reader_reads_bml_1_0_as_the_strict_one_does(examples, name):
    """On BML 1.0 the lenient reader adapts nothing: the feedback is the strict reader's, item for item."""
    strict = realize((examples / name).read_bytes(), strict=True)
    lenient = realize((examples / name).read_bytes())
    assert lenient.items == strict.items


@pytest.mark.parametrize("strict", [True, False], ids=["strict", "lenient"])
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_feedback_is_well_formed(examples, name, strict):
    """Each sync point once, in its default order, block end after every sync, time = global - block start."""
    result = realize((examples / name).read_bytes(), strict=strict)
    ids = [f["id"] for f in result.syncs]
    assert len(ids) == len(set(ids))
    if not result.blocks:
        return
    start, end = result.blocks[0], result.blocks[-1]
    assert start["id"].endswith(":start") and end["id"].endswith(":end")
    assert all(start["globalTime"] <= f["globalTime"] <= end["globalTime"] for f in result.syncs)
    assert result.items.index(end) > max((result.items.index(f) for f in result.syncs), default=-1)
    for f in result.syncs:
        assert f["time"] == pytest.approx(f["globalTime"] - start["globalTime"], abs=1e-12)
    by_behaviour: dict[str, list[str]] = {}
    for f in result.syncs:
        _, beh, sync = f["id"].split(":")
        by_behaviour.setdefault(beh, []).append(sync)
    block = result.realizer.scheduler.book.all_runs[0].block
    for beh, syncs in by_behaviour.items():
        declared = block.behaviour(beh).sync_ids
        assert syncs == declared, f"{beh}: {syncs} != {declared}"
        default = [s for s in BEHAVIOUR_TYPES[block.behaviour(beh).type].syncs]
        assert [s for s in syncs if s in default] == default
