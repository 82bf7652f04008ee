"""BML as Greta, SmartBody, the Virtual Human Toolkit, EMBR and the drafts write it: the corpus in
``tests/dialects`` realized leniently, with what each document must realize, report and time."""

from __future__ import annotations

from pathlib import Path

import pytest

from agentsim.bml.parser import Refused, parse_document
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend
from speech_timing.espeak import EspeakBackend

CORPUS = Path(__file__).resolve().parent / "dialects"
EXACT = 1e-9
PUNCTUATION = ".,!?;:"

# For each document: the behaviours whose end must be reported (block:behaviour), phrases the adaptations
# must contain, the other warnings (type, phrase) exactly, relations between sync times (global seconds;
# a bare number is seconds after the block's start) and the word each speech sync point must land on.
CASES: dict[str, dict] = {
    "greta/fml_apml.xml": {
        "realized": ["bml1:s1", "bml1:b1_0", "bml1:b1_0_2", "bml1:f1", "bml1:t1"],
        "adapted": ["envelope <fml-apml>", "named bml1", "<lexeme> child", "<torso>", "'b1_0' renamed 'b1_0_2'",
                    "<tm id>", "<pitchaccent>", "<boundary>"],
        "warnings": [("BEHAVIOR_TYPE_NOT_SUPPORTED", "<fml> part of <fml-apml>")],
        "times": ["bml1:b1_0:start = bml1:s1:tm2", "bml1:b1_0:end = bml1:s1:tm3+0.5",
                  "bml1:b1_0_2:start = bml1:s1:tm4", "bml1:b1_0_2:end = bml1:s1:tm5", "bml1:f1:end = 1.5",
                  "bml1:t1:start = 0.5", "bml1:t1:end = 2"],
        "words": {"bml1:s1:tm1": "Good", "bml1:s1:tm2": "evening,", "bml1:s1:tm3": "café",
                  "bml1:s1:tm4": "owner", "bml1:s1:tm5": "and"},
    },
    "greta/early_gesture.xml": {
        # the offer's preparation before ready="0" (0.4 s preferred, stretched as 0.6 -> 0.872 between ready
        # and relax) would start it 0.581 s before the block: the block plays that much later
        "realized": ["bml1:p1_0", "bml1:h1", "bml1:s1"],
        "adapted": ["mindmakers.org", "composition 'blend'", "characterId", "times before the block start"],
        "times": ["bml1:p1_0:start = 0", "bml1:p1_0:ready = bml1:s1:start = 0.58133333",
                  "bml1:p1_0:relax = bml1:p1_0:ready+0.872", "bml1:h1:start = bml1:s1:start-0.2",
                  "bml1:h1:end = bml1:s1:start+0.6"],
        "words": {"bml1:s1:tm1": "Welcome", "bml1:s1:tm2": "back."},
        "character": "Greta",
    },
    "greta/semaine.xml": {
        "realized": ["bml1:s1", "bml1:ges1", "bml1:face1", "bml1:h1"],
        "adapted": ["document type declaration", "text= attribute", "merged into the first",
                    "stroke= smaller than start=", "end= smaller than start=", "affect=joy' read as the expression SMILE"],
        # Greta's expressivity parameters are kept on the gesture, and said to be ignored
        "warnings": [("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", "attribute 'expressivityspc' of ges1"),
                     ("CUSTOM_ATTRIBUTE_NOT_SUPPORTED", "attribute 'expressivitytmp' of ges1"),
                     ("BEHAVIOR_TYPE_NOT_SUPPORTED", "<lip>")],
        "times": ["bml1:ges1:start = 1", "bml1:ges1:end = 2.08", "bml1:h1:start = 2", "bml1:h1:stroke = 2.3",
                  "bml1:h1:end = 2.8", "bml1:face1:start = 0.5", "bml1:face1:end = 3.24"],
        "attributes": {"ges1": {"lexeme": "BEAT", "expressivityspc": "-0.1", "expressivitytmp": "0.4"},
                       "face1": {"lexeme": "SMILE"}},
    },
    "smartbody/act_marks.xml": {
        "realized": ["bml1:sp1", "bml1:animation1", "bml1:animation2", "bml1:head1", "bml1:face1", "bml1:face2",
                     "bml1:gaze1", "bml1:event1", "bml1:event2"],
        "adapted": ["envelope <act>", "'doctor'", "<mark name>", "<animation> clips",
                    "sync point ready of <faceFacs> read as attackPeak", "sp1:ready read as sp1:start",
                    "sp1:relax read as sp1:end", "sbm:joint-range", "<event>"],
        "warnings": [("BEHAVIOR_TYPE_NOT_SUPPORTED", "<turn> in <act>"),
                     ("BEHAVIOR_TYPE_NOT_SUPPORTED", "<sbm:reach>: SmartBody's reaching")],
        "times": ["bml1:animation1:stroke = bml1:sp1:T0", "bml1:animation2:stroke = bml1:sp1:T4",
                  "bml1:head1:ready = bml1:sp1:T2", "bml1:head1:relax = bml1:sp1:T3",
                  "bml1:face1:attackPeak = bml1:sp1:T0", "bml1:face1:relax = bml1:sp1:T1",
                  "bml1:face2:relax = bml1:sp1:T7", "bml1:gaze1:ready = bml1:sp1:T0",
                  "bml1:event1:start = bml1:event1:end = bml1:sp1:start",
                  "bml1:event2:start = bml1:event2:end = bml1:sp1:end"],
        "words": {"bml1:sp1:T0": "I", "bml1:sp1:T2": "am", "bml1:sp1:T4": "your", "bml1:sp1:T6": "doctor."},
        "attributes": {"animation1": {"lexeme": "OFFER"}, "animation2": {"lexeme": "BEAT"},
                       "gaze1": {"influence": "NECK"}, "head1": {"lexeme": "NOD", "repetition": "1"}},
        "character": "doctor",
    },
    "smartbody/lipsync.bml": {
        "realized": ["bml1:sp1", *(f"bml1:lips{i}" for i in range(1, 7)), "bml1:curves1"],
        "adapted": ["NVBG's placeholders", "carry times (from a recording)", "<lips viseme>", "<curves>"],
        "times": ["bml1:lips2:start = bml1:lips1:end = 0.05", "bml1:lips3:ready = 0.17", "bml1:lips6:end = 0.72",
                  "bml1:curves1:start = bml1:sp1:start = 0", "bml1:curves1:end = 0.6"],
        "words": {"bml1:sp1:T0": "hello", "bml1:sp1:T2": "there"},
        "attributes": {"lips3": {"viseme": "L", "articulation": "0.8"},
                       "curves1": {}},
    },
    "vht/cerebella.xml": {
        "realized": ["bml1:sp1", "bml1:face1", "bml1:face2", "bml1:toss1", "bml1:head1", "bml1:gaze1",
                     "bml1:gesture1"],
        "adapted": ["'ChrRachel'", "read as <faceFacs>", "offsetDirection", "offsetAngle",
                    "played as a nod: TOSS (toss1)"],
        "warnings": [("BEHAVIOR_TYPE_NOT_SUPPORTED", "<fml> part of <act>")],
        "times": ["bml1:face1:start = bml1:sp1:T0", "bml1:face1:end = bml1:sp1:T1",
                  "bml1:face2:start = bml1:sp1:T4", "bml1:head1:start = bml1:sp1:T4",
                  "bml1:head1:end = bml1:sp1:T7+0.3", "bml1:gesture1:stroke = bml1:sp1:T4",
                  "bml1:gaze1:start = bml1:sp1:T2"],
        "words": {"bml1:sp1:T0": "Nice", "bml1:sp1:T4": "see", "bml1:sp1:T6": "you."},
        "attributes": {"gaze1": {"offsetDirection": "UPLEFT", "offsetAngle": "10", "influence": "EYES"},
                       "head1": {"lexeme": "SHAKE", "repetition": "2"}, "face1": {"au": "26"}},
        "character": "ChrRachel",
    },
    "embr/numeric_syncs.bml": {
        "realized": ["bml1:s", "bml1:g1", "bml1:n1", "bml1:f1"],
        "adapted": ["named bml1", "stroke_start read as strokeStart", "stroke_end read as strokeEnd",
                    "read as <head>", "per-behaviour agent=", "'happy' read as the expression SMILE",
                    "played as a generic gesture: cup_2H (g1)"],
        "times": ["bml1:g1:strokeStart = bml1:s:1", "bml1:g1:strokeEnd = bml1:s:2+0.5",
                  "bml1:n1:strokeEnd = bml1:s:finish", "bml1:f1:attackPeak = bml1:s:0", "bml1:f1:relax = bml1:s:2"],
        "words": {"bml1:s:0": "Thanks", "bml1:s:1": "to", "bml1:s:2": "you,", "bml1:s:finish": "really."},
        "character": "Amber",
    },
    "embr/upper_case.bml": {
        "realized": ["b1:s2", "b1:g1"],
        "adapted": ["another case", "wait= of a speech read as its start"],
        "times": ["b1:s2:start = 1", "b1:g1:strokeStart = b1:s2:1"],
        "words": {"b1:s2:1": "there."},
        "character": "Alfonse",
    },
    "drafts/draft1.xml": {
        "realized": ["bml1:speech1", "bml1:nod1", "bml1:g1", "bml1:gaze1", "bml1:face1"],
        "adapted": ["rotation= read as the lexeme", "hand= read as mode", "modality= read as the gaze influence",
                    "read as <faceFacs>"],
        "times": ["bml1:speech1:start = 1", "bml1:nod1:start = bml1:speech1:syncstart1",
                  "bml1:g1:stroke = bml1:speech1:syncstart1", "bml1:gaze1:start = 0", "bml1:gaze1:end = 4",
                  "bml1:face1:start = 2"],
        "words": {"bml1:speech1:syncstart1": "what"},
        "attributes": {"nod1": {"lexeme": "SHAKE"}, "g1": {"lexeme": "BEAT", "mode": "LEFT_HAND"},
                       "gaze1": {"influence": "NECK"}},
    },
    "drafts/vienna.xml": {
        "realized": ["bml1:welkom", "bml1:nod1", "bml1:point1", "bml1:torso1"],
        "adapted": ["read as <pointing>", "torso1", "<tm id>", "speech without <text>"],
        "times": ["bml1:nod1:start = 0", "bml1:nod1:end = 1", "bml1:point1:start = bml1:welkom:deicticheart1"],
        "words": {"bml1:welkom:deicticheart1": "gentlemen!"},
    },
    "ssml/in_text.xml": {
        "realized": ["b4:s4", "b4:g1", "b4:h1"],
        "adapted": ["<emphasis>", "<prosody>", "<break>", "<say-as>", "<sub alias>", "<mark name>"],
        "times": ["b4:g1:stroke = b4:s4:s1", "b4:h1:stroke = b4:s4:m2"],
        "words": {"b4:s4:s1": "now,", "b4:s4:m2": "please."},
        "spoken": "That is really very good. Call ABC at World Wide Web Consortium now, please.",
    },
    "ssml/speak.xml": {
        "realized": ["b5:sp1", "b5:g1"],
        "adapted": ["SSML speech", "<s>", "<p>", "<break>"],
        "times": ["b5:g1:stroke = b5:sp1:b"],
        "words": {"b5:sp1:a": "sentence.", "b5:sp1:b": "one."},
        "spoken": "First sentence. Second one.",
    },
    "mixed/several_blocks.xml": {
        "realized": ["first:h1", "bml1:s1", "bml2:gesture1", "bml2:gesture2"],
        "adapted": ["3 <bml> blocks in one document", "named bml2", "gesture1, gesture2"],
        "times": ["bml2:gesture2:start = bml2:gesture1:end", "bml2:gesture1:start = bml1:s1:end"],
    },
}


#: Documents whose every behaviour BML 1.0 can read too, with the attributes it does not know ignored.
QUIETLY_DEFAULT = {"drafts/draft1.xml"}


class Run:
    """A document realized on its own (leniently unless told), with its feedback indexed."""

    def __init__(self, name: str, tts=None, strict: bool = False):
        self.realizer = Realizer(tts=tts, strict=strict)
        path = CORPUS / name
        self.realizer.submit(path.read_bytes(), source=str(path))
        self.realizer.run()
        items = self.realizer.feedback.items
        self.sync = {f["id"]: f["globalTime"] for f in items if f["type"] == "syncPointProgress"}
        self.blocks = {f["id"]: f["globalTime"] for f in items if f["type"] == "blockProgress"}
        self.warnings = self.realizer.feedback.warnings()
        self.items = items

    def time(self, term: str) -> float:
        term = term.strip()
        sign = max(term.rfind("+"), term.rfind("-"))
        offset = 0.0
        if sign > 0 and ":" in term[:sign]:
            term, offset = term[:sign], float(term[sign:])
        if ":" not in term:
            return float(term) + min(t for k, t in self.blocks.items() if k.endswith(":start"))
        assert term in self.sync, f"no feedback for {term}"
        return self.sync[term] + offset

    def word_at(self, sync_id: str) -> str:
        """The word of the speech that is heard at the sync point's time."""
        block, behaviour, _ = sync_id.split(":")
        heard = next(h for h in self.realizer.recording().speech if (h.block, h.behaviour) == (block, behaviour))
        t = self.sync[sync_id]
        word = next(w.text for w in heard.utterance.words if abs(heard.t0 + w.start - t) <= EXACT)
        return word.strip(PUNCTUATION)  # the built-in backend's words leave punctuation out, espeak-ng's keep it


@pytest.mark.parametrize("name", sorted(CASES))
def test_dialect_document_is_realized(name):
    case = CASES[name]
    run = Run(name)
    ends = {k.rsplit(":", 1)[0] for k in run.sync if k.endswith(":end")}
    missing = [b for b in case["realized"] if b not in ends]
    assert not missing, (missing, run.warnings)
    # exactly the behaviours asked for are realized
    assert ends == set(case["realized"])
    # what was adapted is said once per block, first
    adaptations = [a for w in run.warnings if w["warningType"] == "NONSTANDARD_BML" for a in w["adaptations"]]
    for phrase in case["adapted"]:
        assert any(phrase in a for a in adaptations), (phrase, adaptations)
    blocks = {f["id"].rsplit(":", 1)[0] for f in run.items if f["type"] == "blockProgress"}
    nonstandard = [w["id"] for w in run.warnings if w["warningType"] == "NONSTANDARD_BML"]
    assert sorted(nonstandard) == sorted(blocks)
    others = [(w["warningType"], w["description"]) for w in run.warnings if w["warningType"] != "NONSTANDARD_BML"]
    assert len(others) == len(case.get("warnings", [])), others
    for (kind, phrase), (got_kind, description) in zip(case.get("warnings", []), others):
        assert kind == got_kind and phrase in description, (kind, phrase, got_kind, description)
    for relation in case["times"]:
        values = [run.time(term) for term in relation.split("=")]
        assert max(values) - min(values) <= 1e-6, (relation, values)
    for sync_id, word in case.get("words", {}).items():
        assert run.word_at(sync_id) == word.strip(PUNCTUATION), sync_id
    if "character" in case:
        assert {f["characterId"] for f in run.items if f["type"] == "blockProgress"} == {case["character"]}
    block = next(b for b in parse_document((CORPUS / name).read_bytes()) if not isinstance(b, Refused))
    for behaviour, attributes in case.get("attributes", {}).items():
        found = block.behaviour(behaviour)
        assert found is not None and all(found.attributes.get(k) == v for k, v in attributes.items()), (
            behaviour, found.attributes if found else None)


@pytest.mark.parametrize("name", [n for n in sorted(CASES) if "spoken" in CASES[n]])
def test_every_word_of_the_text_is_spoken_by_espeak(name):
    """No word vanishes in SSML markup: the real engine's word events are the words of the text."""
    run = Run(name, tts=EspeakBackend())
    (heard,) = run.realizer.recording().speech
    assert [w.text.strip(PUNCTUATION) for w in heard.utterance.words] == [
        w.strip(PUNCTUATION) for w in CASES[name]["spoken"].split()]
    for sync_id, word in CASES[name]["words"].items():
        assert run.word_at(sync_id) == word.strip(PUNCTUATION)


def test_ssml_prosody_reaches_the_speech_engine():
    (block,) = parse_document((CORPUS / "ssml/in_text.xml").read_bytes())
    speech = block.behaviour("s4")
    spans = {(kind, speech.text[a:b] if kind != "break" else speech.text[a:a + 4]): dict(attrs)
             for kind, a, b, attrs in speech.prosody}
    assert spans == {("emphasis", "really"): {"level": "strong"},
                     ("prosody", "very good"): {"rate": "slow", "volume": "loud"},
                     ("break", " Cal"): {"time": "300ms"}, ("say-as", "ABC"): {"interpret-as": "characters"}}
    # the built-in backend pauses 300 ms at the break: every word after it is later by exactly that much
    plain = Realizer(tts=BuiltinBackend())
    plain.submit(f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="p"><speech id="s"><text>{speech.text}'
                 '</text></speech></bml>')
    plain.run()
    marked = Run("ssml/in_text.xml", tts=BuiltinBackend())
    words = {h.block: h.utterance.words for h in (*plain.recording().speech, *marked.realizer.recording().speech)}
    call = [w.text for w in words["p"]].index("Call")
    assert words["b4"][call].start - words["p"][call].start == pytest.approx(
        words["b4"][call - 1].end - words["p"][call - 1].end + 0.3, abs=EXACT)


def test_greta_pitch_accents_and_boundaries_become_emphasis_and_pauses():
    (block,) = parse_document((CORPUS / "greta/fml_apml.xml").read_bytes())
    speech = block.behaviour("s1")
    assert speech.text == "Good evening, café owner and friends."
    (emphasis,) = [p for p in speech.prosody if p[0] == "emphasis"]
    (pause,) = [p for p in speech.prosody if p[0] == "break"]
    assert speech.text[emphasis[1]:emphasis[2]].strip() == "evening,"
    assert speech.text[pause[1]:].startswith("and friends")


def test_several_blocks_start_in_order_and_append_waits_for_both():
    run = Run("mixed/several_blocks.xml")
    starts = [f["id"] for f in run.items if f["type"] == "blockProgress" and f["id"].endswith(":start")]
    assert starts == ["first:start", "bml1:start", "bml2:start"]
    assert run.blocks["bml2:start"] == max(run.blocks["first:end"], run.blocks["bml1:end"])


def test_older_bmlt_control_reads_as_bmla():
    realizer = Realizer()
    realizer.submit('<bml id="bml1"><speech id="s0"><text>First part.</text></speech></bml>')
    realizer.submit((CORPUS / "drafts/bmlt_control.xml").read_bytes())
    realizer.run()
    blocks = {f["id"]: f["globalTime"] for f in realizer.feedback.items if f["type"] == "blockProgress"}
    assert blocks["bml2:start"] == blocks["bml1:end"]
    assert [w["warningType"] for w in realizer.feedback.warnings()] == ["NONSTANDARD_BML"]
    heard = next(h for h in realizer.recording().speech if h.block == "bml2")
    ((start, end, kind, initial, target),) = heard.volume
    syncs = realizer.feedback.sync_times()
    assert (start, end, kind, initial, target) == (syncs["bml2:speech1:start"], syncs["bml2:speech1:end"],
                                                   "linear", 100.0, 50.0)


@pytest.mark.parametrize("name", ["mixed/malformed_envelope.xml", "mixed/entity_in_envelope.xml"])
def test_an_envelope_does_not_make_malformed_xml_a_success(name):
    run = Run(name)
    (warning,) = run.warnings
    assert warning["warningType"] == "PARSING_FAILURE" and "line" in warning
    assert not run.blocks and not run.sync


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_strict_reader_adapts_nothing(name):
    """Strictly, nothing of another dialect is adapted: no NONSTANDARD_BML, and what BML 1.0 lacks is
    refused or dropped with its warning."""
    strict = Run(name, strict=True)
    assert not [w for w in strict.warnings if w["warningType"] == "NONSTANDARD_BML"]
    lenient_ends = {k for k in Run(name).sync if k.endswith(":end")}
    strict_ends = {k for k in strict.sync if k.endswith(":end")}
    if name in QUIETLY_DEFAULT:
        # BML 1.0 ignores attributes it does not define: strictly, the draft's rotation=, type= and hand=
        # change nothing, and the behaviours play as their defaults (a nod, a beat, ...)
        assert strict_ends == lenient_ends
    else:
        assert strict_ends < lenient_ends and strict.warnings  # what is lost is said


def test_an_adaptation_names_the_behaviours_it_touched_and_the_prediction_what_they_became():
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit('<bml id="b1"><head id="h1" rotation="SHAKE"/><head id="h2" lexeme="NOD" start="1"/>'
                    '<gesture id="g1" lexeme="nod" start="2"/><gesture id="g2" lexeme="BEAT" start="3"/></bml>')
    realizer.run()
    (warning,) = realizer.feedback.warnings()
    assert (warning["id"], warning["warningType"]) == ("b1", "NONSTANDARD_BML")
    assert warning["adaptations"] == ["draft attribute rotation= read as the lexeme of the head movement",
                                      "<gesture lexeme='nod'> (a head movement written as a gesture) read as <head>"]
    assert warning["modifiedBehaviours"] == ["h1", "g1"]  # h2 and g2 were BML 1.0 as written
    (prediction,) = realizer.feedback.of_type("predictionFeedback")
    became = {b["id"]: (b["type"], b["lexeme"], round(b["globalEnd"], 9)) for b in prediction["behaviours"]}
    # a shake lasts 0.65 s, a nod 0.55 s, a beat 0.95 s
    assert became == {"h1": ("head", "SHAKE", 0.65), "h2": ("head", "NOD", 1.55), "g1": ("head", "NOD", 2.55),
                      "g2": ("gesture", "BEAT", 3.95)}
    assert realizer.feedback.sync_times()["b1:h1:end"] == 0.65


def test_the_dialect_tables_are_data_checked_when_read():
    from agentsim.bml import dialect_tables
    from agentsim.errors import AgentsimError

    text = dialect_tables.TABLES_PATH.read_text(encoding="utf-8")
    tables = dialect_tables.read_tables(text)
    assert tables["EXPRESSIONS"]["joy"] == "SMILE" and tables["SYNC_ALIASES"]["speech"]["relax"] == "end"
    assert tables["CLIP_WORDS"][:2] == (("beat", "BEAT"), ("chop", "CHOP"))  # tried in the file's order
    with pytest.raises(AgentsimError, match=r"every \[\[clip_words\]\] needs word and lexeme"):
        dialect_tables.read_tables(text.replace('word = "chop"', 'wrd = "chop"'))
    with pytest.raises(AgentsimError, match="saccade_directions must name 8 directions"):
        dialect_tables.read_tables(text.replace('"DOWN", "DOWNLEFT"]', '"DOWN"]'))
    with pytest.raises(AgentsimError, match=r"\[expressions\] must map names to non-empty strings"):
        dialect_tables.read_tables(text.replace('joy = "SMILE"', 'joy = 3'))
    with pytest.raises(AgentsimError, match=r"missing tables \['compositions'\]"):
        dialect_tables.read_tables(text.replace("compositions = { blend = \"MERGE\" }", ""))
