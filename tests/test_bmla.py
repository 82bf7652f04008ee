"""Continuous interaction (BMLA, BMLT): AsapRealizer's own test documents realized with the timings its tests
assert, exactly (to 1e-9 s where two times come from different sums), with no warnings and one start and end
per block; and what an interruption does."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import soundfile

from agentsim.animation.units import NOD
from agentsim.realizer import Realizer

ASAP = Path(__file__).resolve().parent / "bml-examples-asap"
NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'


class Run:
    """Feedback of ``agentsim realize`` on some AsapRealizer documents, indexed for assertions."""

    def __init__(self, *files: str, at: str | None = None, cwd: Path = ASAP):
        command = [sys.executable, "-m", "agentsim.cli", "realize", *files] + (["--at", at] if at else [])
        proc = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        self.items = [json.loads(line) for line in proc.stdout.splitlines()]
        self.sync = {f["id"]: f["globalTime"] for f in self.items if f["type"] == "syncPointProgress"}
        self.block = {f["id"]: f["globalTime"] for f in self.items if f["type"] == "blockProgress"}
        self.warnings = [f for f in self.items if f["type"] == "warningFeedback"]
        #: ids of the feedback that says ``"status": "INTERRUPTED"``
        self.interrupted = [f["id"] for f in self.items if f.get("status") == "INTERRUPTED"]

    def check(self, blocks: list[str]) -> None:
        """No warnings (as AsapRealizer's tests assert: an interruption that was asked for is not a fault), no
        feedback twice, one start and one end per block, the end after the start."""
        assert self.warnings == []
        ids = Counter(f["id"] for f in self.items if f["type"] != "predictionFeedback")
        assert [k for k, n in ids.items() if n > 1] == []
        assert sorted(self.block) == sorted([f"{b}:start" for b in blocks] + [f"{b}:end" for b in blocks])
        for b in blocks:
            assert self.block[f"{b}:start"] <= self.block[f"{b}:end"]
        order = [f["id"] for f in self.items if f["type"] == "syncPointProgress"]
        for b in blocks:  # every sync point of a block comes between its start and end
            for sync, t in self.sync.items():
                if sync.startswith(f"{b}:"):
                    assert self.block[f"{b}:start"] <= t <= self.block[f"{b}:end"], sync
        assert len(order) == len(set(order))

    def predictions(self, block: str) -> list[dict]:
        return [f for f in self.items if f["type"] == "predictionFeedback" and f["id"] == block]


def test_activate_starts_the_preplanned_speech_when_the_nod_ends():
    r = Run("asap/activate/testpreplannedspeech1.xml", "asap/activate/testactivate.xml")
    r.check(["bml1", "bml2"])
    assert r.sync["bml1:speech1:start"] == r.sync["bml2:nod1:end"] == r.block["bml1:start"]
    assert r.sync["bml2:nod1:end"] == pytest.approx(0.65, abs=1e-12)  # a shake: 0.65 s
    # planned and predicted at once, started only when activated
    first = r.predictions("bml1")[0]
    assert first["globalTime"] == 0.0 and first["behaviours"][0]["id"] == "speech1"


def test_append_after_waits_for_the_named_blocks_only():
    r = Run(*(f"asap/appendafter/{n}.xml" for n in ("testspeech1", "testspeech2", "testspeech3",
                                                     "testnodappendafter")))
    r.check(["bml1", "bml2", "bml3", "bml4"])
    assert r.block["bml2:start"] == r.block["bml1:end"] > 0
    assert r.block["bml3:start"] == r.block["bml2:end"]
    assert r.block["bml4:start"] == max(r.block["bml1:end"], r.block["bml2:end"]) < r.block["bml3:end"]


def test_an_interrupting_block_starts_exactly_when_the_interrupted_block_ends():
    r = Run("asap/interruptblock/testlongspeechandnod.xml", "asap/interruptblock/testinterruptbml1.xml", at="0,1")
    r.check(["bml1", "bml2"])
    # at 1 s the speech stops and the nod (stretched from 0 to 10) retracts: its preferred retraction
    retraction = NOD.keys[-1] - NOD.keys[5]
    assert r.sync["bml1:speech1:end"] == 1.0 == r.sync["bml1:nod1:relax"]
    assert r.sync["bml1:nod1:end"] == pytest.approx(1.0 + retraction, abs=1e-12)
    assert r.block["bml2:start"] == r.block["bml1:end"] == r.sync["bml1:nod1:end"]
    # the interruption was asked for: the ends of what it cut and of the block say so, as feedback
    assert r.interrupted == ["bml1:speech1:end", "bml1:nod1:end", "bml1:end"]
    # at the same instant, nothing has started yet: nothing of bml1 is played
    r = Run("asap/interruptblock/testlongspeechandnod.xml", "asap/interruptblock/testinterruptbml1.xml")
    r.check(["bml1", "bml2"])
    assert r.block["bml2:start"] == r.block["bml1:end"] == 0.0 and not r.sync
    assert r.interrupted == ["bml1:end"]


def test_an_interrupt_behaviour_stops_the_speech_and_retracts_the_nod_at_its_start():
    r = Run("asap/interrupt/testlongspeechandnod.xml", "asap/interrupt/testspeechinterrupt.xml", at="0,0.5")
    r.check(["bml1", "bml2"])
    assert r.sync["bml2:i1:start"] == 2.5 == r.sync["bml1:speech1:end"] == r.sync["bml1:nod1:relax"]
    assert r.sync["bml2:speech1:start"] == 2.5
    assert r.block["bml1:end"] == r.sync["bml1:nod1:end"] == pytest.approx(2.5 + NOD.keys[-1] - NOD.keys[5])
    # the nod's stroke, planned for later, never came
    assert "bml1:nod1:stroke" not in r.sync
    assert r.interrupted == ["bml1:speech1:end", "bml1:nod1:end", "bml1:end"]


def test_interrupting_some_behaviours_and_activating_at_a_sync_point():
    r = Run("asap/interruptbehavior/testlongspeechandnod.xml", "asap/interruptbehavior/testinterruptionspeech.xml",
            "asap/interruptbehavior/testspeechinterrupt.xml")
    r.check(["bml1", "bml2", "bml3"])
    s1 = r.sync["bml1:speech1:s1"]
    assert s1 > 1.0 and r.block["bml3:start"] == s1 == r.sync["bml1:speech1:end"] == r.sync["bml2:i2:start"]
    # the nod tied to s1 was interrupted (i1: all of bml1 but the speech) before it started: it is gone, with
    # no feedback of its own and no warning (it was not required), and the prediction says so
    assert not [k for k in r.sync if k.startswith("bml1:nod1")]
    gone = [b for p in r.predictions("bml1") for b in p["behaviours"] if b.get("status") == "removed"]
    assert [b["id"] for b in gone] == ["nod1"]
    assert r.interrupted == ["bml1:speech1:end", "bml1:end"]


def test_interrupting_the_same_documents_again_after_a_replace_gives_the_same_times():
    files = ["asap/interruptbehavior/testlongspeechandnod.xml", "asap/interruptbehavior/testinterruptionspeech.xml",
             "asap/interruptbehavior/testspeechinterrupt.xml"]
    once = Run(*files)
    replace = ASAP / "asap" / "interruptbehavior" / "replace.xml"
    replace.write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="bmlrep" composition="REPLACE"/>')
    try:
        twice = Run(*files, str(replace.relative_to(ASAP)), *files, at="0,0,0,20,20,20,20")
    finally:
        replace.unlink()
    assert twice.warnings == []
    # the second time round, the same behaviours are interrupted at the same times (20 s later)
    cut = [(f["id"], f["globalTime"]) for f in twice.items if f.get("status") == "INTERRUPTED"]
    first = [(i, t) for i, t in cut if t < 20]
    again = [(i, t - 20) for i, t in cut if t >= 20]
    assert [i for i, _ in first] == ["bml1:speech1:end", "bml1:end"] == [i for i, _ in again]
    assert [t for _, t in again] == pytest.approx([t for _, t in first], abs=1e-9)
    second = [f for f in twice.items if f["type"] == "syncPointProgress" and f["globalTime"] >= 20]
    assert {f["id"]: f["globalTime"] - 20 for f in second} == pytest.approx(once.sync, abs=1e-9)


def test_preplanned_block_started_by_the_block_that_interrupts():
    r = Run("asap/preplan/testspeech1.xml", "asap/preplan/testspeechinterrupt.xml", "asap/preplan/testnod.xml",
            at="0,0,3")
    r.check(["bml1", "bml2", "bml3"])
    assert r.sync["bml1:speech1:end"] == 3.0 == r.block["bml1:end"] == r.block["bml3:start"] == r.block["bml2:start"]
    assert r.sync["bml2:speech1:start"] == 3.0
    assert r.interrupted == ["bml1:speech1:end", "bml1:end"]


def test_chunks_follow_one_another_and_coarticulate():
    r = Run("asap/chunking/firstchunk.xml", "asap/chunking/secondchunk.xml")
    r.check(["bml1", "bml2"])
    # the second chunk starts when the first subsides: its gesture relaxes as the next one starts
    assert r.sync["bml1:g1:relax"] == r.block["bml2:start"] == pytest.approx(r.sync["bml2:g1:start"], abs=1e-9)
    # the mark after the last word is where that word ends; the speech ends after its final pause
    assert r.sync["bml1:g1:stroke"] == r.sync["bml1:speech1:chunk"] <= r.sync["bml1:speech1:end"]
    # different hands: the first gesture retracts on its own while the second prepares (a beat: 0.3 s)
    assert r.sync["bml1:g1:end"] == pytest.approx(r.sync["bml1:g1:relax"] + 0.3, abs=1e-12)
    # on the same hand its retraction is skipped: relax = end = the next gesture's start
    r = Run("asap/chunkingconflictres/firstchunk.xml", "asap/chunkingconflictres/secondchunk.xml")
    r.check(["bml1", "bml2"])
    assert r.sync["bml1:g1:relax"] == r.sync["bml1:g1:end"] == r.block["bml2:start"]
    assert r.sync["bml2:g1:start"] == pytest.approx(r.block["bml2:start"], abs=1e-9)
    assert r.sync["bml1:g1:relax"] - r.sync["bml1:g1:stroke"] == pytest.approx(0.2, abs=1e-12)  # unhurried


def test_parameter_value_change_spans_the_speech_it_is_tied_to():
    r = Run("asap/parametervaluechange/speechandnod.xml", "asap/parametervaluechange/volumechange.xml")
    r.check(["bml1", "bml2"])
    assert r.sync["bml2:pvc1:start"] == r.sync["bml1:speech1:start"]
    assert r.sync["bml2:pvc1:end"] == r.sync["bml1:speech1:end"]
    r = Run("asap/parametervaluechange.xml")
    r.check(["bml1"])
    assert r.sync["bml1:pvc1:start"] == r.sync["bml1:speech1:start"] == 0.0
    assert r.sync["bml1:pvc1:end"] == r.sync["bml1:speech1:end"] == r.sync["bml1:speech2:start"]


def test_volume_change_is_recorded_on_the_speech_as_heard():
    realizer = Realizer()
    realizer.submit((ASAP / "asap" / "parametervaluechange.xml").read_text())
    realizer.run()
    recording = realizer.recording()
    speech = recording.speech[0]
    end = recording.sync_times()["bml1:speech1:end"]
    assert speech.gain(0.0) == 0.0 and speech.gain(end / 2) == pytest.approx(0.5) and speech.gain(end) == 1.0
    (change,) = recording.behaviour("bml1:speech1").parameters
    assert change == ("volume", 0.0, end, "linear", 0.0, 100.0)


def test_a_sound_file_lasts_as_long_as_the_file(tmp_path):
    folder = tmp_path / "bmlt"
    shutil.copytree(ASAP / "bmlt", folder)
    (folder / "audio").mkdir()
    rate, seconds = 22050, 0.8
    soundfile.write(folder / "audio" / "audience.wav", 0.1 * np.sin(np.arange(int(rate * seconds)) * 0.05), rate)
    r = Run("bmlt/bmltaudio.xml", cwd=tmp_path)  # found beside the document, not in the working directory
    r.check(["bml1"])
    assert r.sync["bml1:audio1:start"] == 0.0 and r.sync["bml1:audio1:end"] == pytest.approx(seconds, abs=1e-9)
    missing = Run(str(ASAP / "bmlt" / "bmltaudio.xml"), cwd=tmp_path / "bmlt" / "audio")
    (warning,) = missing.warnings
    assert warning["id"] == "bml1:audio1" and "audience.wav" in warning["description"]
    assert missing.block == {"bml1:start": 0.0, "bml1:end": 0.0}


def test_a_transition_moves_into_the_next_behaviour():
    r = Run("bmlt/transition.xml")
    r.check(["bml1"])
    assert (r.sync["bml1:transition1:start"], r.sync["bml1:transition1:end"]) == (0.0, 1.0) == (0.0,
                                                                                              r.sync["bml1:nod1:start"])
