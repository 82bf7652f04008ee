"""Bad input gets warning feedback naming the block or behaviour and the reason; the rest keeps running."""

from __future__ import annotations

import signal
import time
from contextlib import contextmanager
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import EXAMPLES, realize

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def block(body: str, attrs: str = 'id="bml1"') -> str:
    return f"<bml {NS} {attrs}>{body}</bml>"


def test_unknown_behaviour_type_is_skipped_and_the_rest_runs():
    r = realize(block('<dance id="d1" start="0"/><head id="nod1" lexeme="NOD"/>'))
    (w,) = r.warnings
    assert w["warningType"] == "BEHAVIOR_TYPE_NOT_SUPPORTED" and "<dance>" in w["description"]
    assert "line 1" in w["description"] and r.t("nod1:start") == 0.0


def test_extension_element_in_another_namespace_is_ignored_with_a_warning():
    r = realize(block('<ext:blink xmlns:ext="urn:x" id="b1"/><head id="nod1" lexeme="NOD"/>'))
    (w,) = r.warnings
    assert w["warningType"] == "BEHAVIOR_TYPE_NOT_SUPPORTED" and "ext:blink" in w["description"]
    assert "nod1:end" in r.local


def test_cyclic_constraints_drop_the_behaviour_that_closes_the_circle_and_what_is_tied_to_it():
    r = realize(block('<head id="a" lexeme="NOD" start="b:end"/><head id="b" lexeme="NOD" start="a:end"/>'
                      '<head id="c" lexeme="SHAKE"/>'))
    # b closes the circle; a is tied to b's end, which will never come: it goes too, with its own warning
    assert [(w["id"], w["warningType"]) for w in r.warnings] == [("bml1:b", "IMPOSSIBLE_TO_SCHEDULE"),
                                                               ("bml1:a", "IMPOSSIBLE_TO_SCHEDULE")]
    assert "it is tied to b, which was dropped" in r.warnings[1]["description"]
    assert "c:end" in r.local and "a:start" not in r.local
    assert [b["id"] for b in r.blocks] == ["bml1:start", "bml1:end"]


def test_contradictory_constraints_drop_the_behaviour_they_contradict():
    body = ('<head id="a" lexeme="NOD" start="1"/><head id="b" lexeme="NOD" start="a:start"/>'
            '<constraint><synchronize><sync ref="b:start"/><sync ref="2"/></synchronize></constraint>')
    r = realize(block(body))
    (w,) = r.warnings
    assert w["modifiedBehaviours"] == ["b"] and "contradictory" in w["description"]
    assert r.t("a:start") == 1.0 and "b:start" not in r.local


def test_offset_cycle_within_one_group_is_contradictory():
    body = ('<head id="a" lexeme="NOD"/><head id="b" lexeme="NOD" start="a:start+1"/>'
            '<constraint><synchronize><sync ref="a:start"/><sync ref="b:start"/></synchronize></constraint>')
    r = realize(block(body))
    assert r.dropped() == {"b"} and "contradictory" in r.warnings[0]["description"]


def test_huge_offsets_and_non_numbers_are_refused_per_behaviour():
    r = realize(block('<head id="a" lexeme="NOD" start="1e9"/><head id="b" lexeme="NOD" start="nan"/>'
                      '<head id="c" lexeme="NOD" start="d:start+1e7"/><head id="d" lexeme="NOD"/>'))
    assert r.dropped() == {"a", "b", "c"}
    assert all(w["warningType"] == "PARSING_FAILURE" for w in r.warnings)
    assert any("out of range" in w["description"] for w in r.warnings)
    assert r.t("d:start") == 0.0


def test_billion_laughs_is_refused_fast():
    lol = ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">'
           + "".join(f'<!ENTITY lol{i} "{("&lol" + (str(i - 1) if i > 1 else "") + ";") * 10}">' for i in range(1, 10))
           + f']><bml {NS} id="bml1"><speech id="s"><text>&lol9;</text></speech></bml>')
    started = time.perf_counter()
    r = realize(lol)
    assert time.perf_counter() - started < 1.0
    (w,) = r.warnings
    assert w["warningType"] == "PARSING_FAILURE" and w["id"] == "bml1" and "entity" in w["description"]
    assert not r.blocks


def test_external_entity_is_refused(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("top secret")
    doc = (f'<?xml version="1.0"?><!DOCTYPE bml [<!ENTITY x SYSTEM "file://{secret}">]>'
           + block('<speech id="s"><text>&x;</text></speech>'))
    r = realize(doc)
    assert r.warnings[0]["warningType"] == "PARSING_FAILURE" and not r.blocks
    assert all("top secret" not in str(f) for f in r.items)


def test_required_behaviour_that_cannot_run_refuses_the_block():
    body = ('<required><head id="a" lexeme="NOD" start="2" end="0"/></required>'
            '<head id="b" lexeme="NOD" start="1"/>')
    r = realize(block(body))
    assert not r.blocks and not r.syncs
    assert any("block refused" in w["description"] for w in r.warnings)


def test_required_constraint_that_cannot_hold_refuses_the_block():
    body = ('<head id="a" lexeme="NOD" start="1"/><head id="b" lexeme="NOD" start="3"/>'
            '<required><constraint><synchronize><sync ref="a:start"/><sync ref="b:start"/></synchronize>'
            '</constraint></required>')
    r = realize(block(body))
    assert not r.blocks and any("required constraint" in w["description"] for w in r.warnings)


def test_duplicate_ids_and_missing_ids_are_reported():
    doc = block('<head id="a" lexeme="NOD"/><head id="a" lexeme="SHAKE" start="3"/><head lexeme="NOD"/>')
    strict = realize(doc, strict=True)
    kinds = [(w["warningType"], w["description"][:20]) for w in strict.warnings]
    assert len(kinds) == 2 and all(k == "PARSING_FAILURE" for k, _ in kinds)
    assert strict.t("a:start") == 0.0 and strict.t("a:end") < 3 and "a_2:start" not in strict.local
    # leniently, the second "a" is renamed and the head without id named: all three play, and one warning says so
    lenient = realize(doc)
    (w,) = lenient.warnings
    assert w["warningType"] == "NONSTANDARD_BML" and len(w["adaptations"]) == 2
    assert "'a' renamed 'a_2'" in w["adaptations"][0] and w["adaptations"][1].endswith("number: head1")
    assert lenient.t("a:start") == 0.0 and lenient.t("a_2:start") == 3.0 and lenient.t("head1:start") == 0.0


def test_reference_to_an_unknown_block_or_anticipator():
    r = realize(block('<head id="a" lexeme="NOD" start="bml9:x:end"/>'
                      '<head id="b" lexeme="NOD" start="anticipators:nobody:beat1"/><head id="c" lexeme="NOD"/>'))
    assert r.dropped() == {"a", "b"}
    text = " ".join(w["description"] for w in r.warnings)
    assert "bml9:x:end" in text and "no anticipator 'nobody'" in text


def test_cross_block_reference_ties_to_the_other_block():
    first = block('<speech id="s1"><text>One two <sync id="m"/>three.</text></speech>')
    second = block('<head id="n" lexeme="NOD" stroke="bml1:s1:m"/>', 'id="bml2"')
    r = realize(first, second)
    assert r.glob["bml2:n:stroke"] == r.glob["bml1:s1:m"] and not r.warnings


def test_duplicate_block_id_while_running_is_refused():
    doc = block('<head id="a" lexeme="NOD" start="1"/>')
    r = realize(doc, doc, at=[0, 0.5])
    assert [w["warningType"] for w in r.warnings] == ["PARSING_FAILURE"]
    assert [b["id"] for b in r.blocks] == ["bml1:start", "bml1:end"]


def test_not_bml_and_bad_composition():
    r = realize("<html/>", block("", 'id="b2" composition="SOMETIMES"'), "")
    assert [w["warningType"] for w in r.warnings] == ["PARSING_FAILURE"] * 3
    assert "expected a <bml> element" in r.warnings[0]["description"]
    assert "composition" in r.warnings[1]["description"] and r.warnings[1]["id"] == "b2"


# ---------------------------------------------------------------- property: never raises, never hangs
ASAP = Path(__file__).parent / "bml-examples-asap"
SOURCES = (sorted(EXAMPLES.glob("*.xml")) + sorted((Path(__file__).parent / "bml").glob("*.xml"))
           + sorted((ASAP / "asap").rglob("*.xml")) + sorted((ASAP / "bmlt").glob("*.xml"))
           + sorted((Path(__file__).parent / "dialects").rglob("*.[xb]ml")))
TOKENS = ["<", ">", "/>", '"', ":", "+", "-", "-1e9", "1e30", "0", "-3", "start=\"a:b\"", 'end="speech1:end-99"',
          '<sync id="s9"/>', "&amp;", "&lol;", "<!ENTITY x 'y'>", 'composition="APPEND"', 'composition="REPLACE"',
          'id=""', "</bml>", "<bml>", "<head id=\"n9\" lexeme=\"NOD\" start=\"n9:end\"/>",
          '<constraint><after ref="speech1:end"><sync ref="nod1:start"/></after></constraint>',
          '<required>', '</required>', "anticipators:metronome:beat2", "\u00e9\u4e2d", "\x00", "]]>",
          # BMLA: blocks and behaviours that act on other blocks, which the mixed documents share ids with
          ' xmlns:bmla="http://www.asap-project.org/bmla" bmla:interrupt="bml1"', ' bmla:preplan="true"',
          ' bmla:onStart="bml2 bml3"', ' bmla:chunkAfter="bml1"', ' bmla:appendAfter="bml2"',
          ' bmla:prependBefore="bml1"', ' composition="APPEND-AFTER(bml1,bml2)"', ' composition="CHUNK-AFTER(bml3)"',
          '<bmla:interrupt id="i9" target="bml1" include="speech1"/>', '<bmla:activate id="a9" target="bml2"/>',
          '<bmla:parametervaluechange id="p9" target="bml1:speech1" paramId="volume">'
          '<bmla:trajectory type="linear" initialValue="0" targetValue="100"/></bmla:parametervaluechange>',
          # other realizers' BML: envelopes, marks, draft attributes, their own behaviours
          "<act>", "</act>", "<fml-apml>", '<participant id="p" role="actor"/>', '<tm id="tm9"/>',
          '<mark name="T9"/>', 'type="NOD"', 'stroke_start="s1:tm1"', 'start="-0.5"', 'end="0.1"',
          '<lips viseme="Aa" start="0.1" ready="0.1" relax="0.2" end="0.2"/>', '<animation name="Beat"/>',
          '<event stroke="sp1:relax"/>', "<emphasis>", "</emphasis>", '<break time="9s"/>',
          '<curves><curve name="open" num_keys="2">0 0 0 0 1 1 0 0</curve></curves>', "<BML>"]


@contextmanager
def deadline(seconds: int):
    def boom(*_):
        raise TimeoutError("the realizer hung")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@st.composite
def mutated(draw):
    text = draw(st.sampled_from(SOURCES)).read_text()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(text)))
        j = draw(st.integers(i, min(len(text), i + 40)))
        op = draw(st.sampled_from(["delete", "insert", "replace", "duplicate"]))
        if op == "delete":
            text = text[:i] + text[j:]
        elif op == "duplicate":
            text = text[:j] + text[i:j] + text[j:]
        else:
            token = draw(st.sampled_from(TOKENS) | st.text(max_size=6))
            text = text[:i] + token + (text[i:] if op == "insert" else text[j:])
    return text


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(docs=st.lists(mutated(), min_size=1, max_size=3), gap=st.floats(0, 3))
def test_mutated_examples_never_raise_or_hang(docs, gap):
    from anticipators.metronome import Metronome

    with deadline(20):
        r = realize(*docs, at=[i * gap for i in range(len(docs))], anticipators=[Metronome(bpm=100)])
    seen: dict[str, set[str]] = {}  # a block id may be used again once its block has ended
    for f in r.items:
        if f["type"] == "blockProgress" and f["id"].endswith(":start"):
            seen[f["id"].rsplit(":", 1)[0]] = set()
        elif f["type"] == "syncPointProgress":
            block_id, rest = f["id"].split(":", 1)
            assert rest not in seen[block_id]
            seen[block_id].add(rest)
    starts = [b["id"] for b in r.blocks if b["id"].endswith(":start")]
    ends = [b["id"] for b in r.blocks if b["id"].endswith(":end")]
    assert sorted(starts) == sorted(s.replace(":end", ":start") for s in ends)
    for w in r.warnings:
        assert w["description"]


def test_warnings_carry_line_and_column():
    doc = f'<bml {NS} id="bml1">\n  <head id="a" lexeme="NOD"/>\n    <head id="b" lexeme="NOD" start="zz:end"/>\n</bml>'
    (w,) = realize(doc).warnings
    assert (w["line"], w["column"]) == (3, 5) and w["id"] == "bml1:b"
    (w,) = realize(f'<bml {NS} id="bml1">\n<head id="a">\n</bml>').warnings
    assert (w["line"], w["column"]) == (3, 3) and w["warningType"] == "PARSING_FAILURE"


def test_impossible_ordering_within_one_tied_cluster_is_reported_once():
    body = ('<speech id="s"><text>One <sync id="m"/>two three.</text></speech>'
            '<gesture id="g" lexeme="BEAT" stroke="s:m"/>'
            '<constraint><before ref="s:start"><sync ref="g:end"/></before></constraint>')
    r = realize(block(body))
    assert len(r.warnings) == 1 and r.dropped() == {"g"}
    assert r.t("s:start") == 0.0 and "cannot be before" in r.warnings[0]["description"]


def test_ids_with_a_colon_are_refused_because_feedback_ids_join_ids_with_colons():
    bml = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="{block}">'
           '<gesture id="{beh}" lexeme="BEAT"/><head id="h" lexeme="NOD"/>'
           '<speech id="s"><text>one <sync id="a:b"/>two</text></speech></bml>')
    r = realize(bml.format(block="a:b", beh="g"))
    assert [w["warningType"] for w in r.warnings] == ["PARSING_FAILURE"] and "contains ':'" in r.warnings[0]["description"]
    assert not r.syncs and not r.blocks
    r = realize(bml.format(block="b", beh="x:y"))
    assert sorted(w["description"].split(" (line")[0] for w in r.warnings) == [
        "behaviour id 'x:y' contains ':', which feedback ids use to join block, behaviour and sync ids; "
        "behaviour ignored", "speech s: sync id 'a:b' contains ':' and is ignored"]
    assert {f["id"] for f in r.syncs} == {"b:h:" + s for s in ("start", "ready", "strokeStart", "stroke",
                                                                "strokeEnd", "relax", "end")} | {"b:s:start", "b:s:end"}


def test_an_unknown_encoding_is_refused_in_both_readers():
    doc = '<?xml version="1.0" encoding="TF-8"?><bml id="b1"><head id="h" lexeme="NOD"/></bml>'
    for strict in (True, False):
        r = realize(doc, strict=strict)
        (w,) = r.warnings
        assert w["warningType"] == "PARSING_FAILURE" and "TF-8" in w["description"] and not r.blocks


def test_the_usual_references_are_read_quickly_as_the_pattern_reads_them():
    """The references of the usual form are read with string methods where they plainly are of it, and every
    text comes out as the general pattern reads it: the same reference, or None for the full reader to read (or
    refuse); the lenient reader keeps a reference's spelling as it is where one like it was kept."""
    import numpy as np

    from agentsim.bml.parser import _matched_ref, _plain_ref
    from agentsim.bml.spelling import AS_WRITTEN, References, respell

    texts = ["g1:stroke", "g1:end+0.5", "g1:end-2.", "b1:g1:start", "g1:end+.5", "g1:end+1.2.3", "g1:end+1-2",
             "g1:end+1e3", "é1:start", "g1:strokeé", "g1:end+²", "g1:end+١", "1g:start", "g1:1", "g1 :start",
             "g1:start ", "g1:end+ 1", ":start", "g1:", "g1:end+", "g1:end-0", "g1:end+99999999", "g1:end+1000000.5",
             "_:_", "a_1:b_2-0.5", "g1:end+0001", "g1:start\n", "g1\n:start", "class:def", "g1:end--1", "g1:end++1",
             "g1:end+1:2", "a" * 30 + ":b", "anticipators:beat:b1"]
    rng = np.random.default_rng(5)
    alphabet = list("ab_1.:+- \n\u00e9\u00b2")
    texts += ["".join(rng.choice(alphabet, int(rng.integers(1, 12)))) for _ in range(3000)]
    for text in texts + texts[::-1]:  # (and again, each tail read before: as the first time)
        assert _plain_ref(text) == _matched_ref(text), text
    assert _plain_ref("g1:end-2.") == ("sync", -2.0, None, "g1", "end", None, "g1:end-2.")
    spellings = ["b1:end", "b2:end", "b1:stroke_start", "b2:stroke_start", " b3:end", "b3:end ", "b1:ready",
                 "b2:ready", "b1:relax+1", "a:b+c:end", "a:b+c:d+", "x\ny:end", "b4:end\n"]
    spellings += ["".join(rng.choice(list("b1:end_rStR+-. \n"), int(rng.integers(1, 14)))) for _ in range(3000)]
    references = References()
    for value in spellings:
        assert references.once(value) == respell(value), repr(value)
        assert references.kept(value) is (respell(value) is AS_WRITTEN), repr(value)
