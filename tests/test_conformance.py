"""A BML 1.0 conformance run of the kind BMLRealizerTester performs, through the realizer and the CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import realize

BML = Path(__file__).parent / "bml"
GESTURE = ["start", "ready", "strokeStart", "stroke", "strokeEnd", "relax", "end"]


def cli(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *args], input=stdin, capture_output=True,
                          timeout=120)


def lines(proc: subprocess.CompletedProcess) -> list[dict]:
    return [json.loads(line) for line in proc.stdout.decode().splitlines()]


def syncs_of(feedback: list[dict], block: str, behaviour: str) -> list[str]:
    prefix = f"{block}:{behaviour}:"
    return [f["id"][len(prefix):] for f in feedback if f["type"] == "syncPointProgress" and f["id"].startswith(prefix)]


def test_gaze_overlap_gives_one_warning_and_keeps_one_gaze():
    r = realize((BML / "gazeoverlap.xml").read_text())
    assert len(r.warnings) == 1
    assert r.warnings[0]["modifiedBehaviours"] == ["gaze2"]
    assert r.warnings[0]["warningType"] == "IMPOSSIBLE_TO_SCHEDULE"
    assert syncs_of(r.items, "bml1", "gaze1") == ["start", "ready", "relax", "end"]
    assert syncs_of(r.items, "bml1", "gaze2") == []
    assert r.t("gaze1:start") == 1.0 and r.t("gaze1:end") == 10.0
    assert [b["id"] for b in r.blocks] == ["bml1:start", "bml1:end"]


def test_block_without_id_is_refused_with_one_warning():
    r = realize((BML / "noid.xml").read_text(), strict=True)
    assert len(r.warnings) == 1 and r.warnings[0]["warningType"] == "PARSING_FAILURE"
    assert "line 1, column 1" in r.warnings[0]["description"]
    assert not r.blocks and not r.syncs


def test_the_lenient_reader_names_a_block_without_id_and_says_so():
    r = realize((BML / "noid.xml").read_text())
    (w,) = r.warnings
    assert w["warningType"] == "NONSTANDARD_BML" and w["adaptations"] == ["block without id: named bml1"]
    assert [b["id"] for b in r.blocks] == ["bml1:start", "bml1:end"] and r.syncs


def test_append_starts_at_the_previous_block_end():
    r = realize((BML / "speech.xml").read_text(), (BML / "speechappend.xml").read_text())
    blocks = {b["id"]: b["globalTime"] for b in r.blocks}
    assert [b["id"] for b in r.blocks] == ["bml1:start", "bml1:end", "bml2:start", "bml2:end"]
    assert blocks["bml2:start"] == blocks["bml1:end"] == r.glob["bml1:speech1:end"]
    assert blocks["bml1:end"] > blocks["bml1:start"] and blocks["bml2:end"] > blocks["bml2:start"]
    assert r.glob["bml2:speech1:start"] == blocks["bml2:start"]
    assert r.glob["bml2:nod1:stroke"] == r.glob["bml2:speech1:end"]
    assert not r.warnings


def test_replace_ends_the_earlier_block_now():
    r = realize((BML / "longspeechandnod.xml").read_text(), (BML / "replace.xml").read_text(), at=[0, 0.7])
    blocks = [(b["id"], b["globalTime"]) for b in r.blocks]
    assert blocks[:3] == [("bml1:start", 0.0), ("bml1:end", 0.7), ("bml3:start", 0.7)]
    assert blocks[3][0] == "bml3:end"
    assert all(f["globalTime"] <= 0.7 for f in r.syncs if f["id"].startswith("bml1:"))
    # the speech cut short gets its end at the cut, and an INTERRUPTED warning
    assert r.glob["bml1:speech1:end"] == 0.7
    cut = [(w["id"], w["warningType"], w["globalTime"]) for w in r.warnings]
    assert ("bml1:speech1", "INTERRUPTED", 0.7) in cut and all(kind == "INTERRUPTED" for _, kind, _ in cut)
    assert syncs_of(r.items, "bml3", "nod1") == GESTURE


def test_append_and_replace_and_resubmission():
    speech, append, replace = ((BML / n).read_text() for n in ("speech.xml", "speechappend.xml", "replace.xml"))
    r = realize(speech, append, replace, speech, append, at=[0, 0, 3.0, 3.0, 3.0])
    starts = [b["id"] for b in r.blocks if b["id"].endswith(":start")]
    ends = [b["id"] for b in r.blocks if b["id"].endswith(":end")]
    assert starts == ["bml1:start", "bml2:start", "bml3:start", "bml1:start", "bml2:start"]
    assert ends == ["bml1:end", "bml2:end", "bml3:end", "bml1:end", "bml2:end"]
    # what the REPLACE cut is said, nothing else
    assert {(w["id"], w["warningType"]) for w in r.warnings} == {("bml2:speech1", "INTERRUPTED"),
                                                                  ("bml2:nod1", "INTERRUPTED")}


def test_replace_of_a_block_not_yet_started_still_reports_start_and_end():
    speech, append, replace = ((BML / n).read_text() for n in ("speech.xml", "speechappend.xml", "replace.xml"))
    r = realize(speech, append, replace, at=[0, 0, 0.5])
    assert [(b["id"], b["globalTime"]) for b in r.blocks][:5] == [
        ("bml1:start", 0.0), ("bml1:end", 0.5), ("bml2:start", 0.5), ("bml2:end", 0.5), ("bml3:start", 0.5)]
    assert not any(f["id"].startswith("bml2:") for f in r.syncs)


def test_pointing_face_and_posture_keep_their_default_sync_order():
    r = realize((BML / "point.xml").read_text())
    assert syncs_of(r.items, "bml1", "point1") == GESTURE
    assert syncs_of(r.items, "bml1", "face1") == ["start", "attackPeak", "relax", "end"]
    assert syncs_of(r.items, "bml1", "pose1") == ["start", "ready", "relax", "end"]
    assert (r.t("point1:start"), r.t("point1:end"), r.t("face1:start"), r.t("pose1:start")) == (1, 10, 2, 0)
    assert not r.warnings


def test_feedback_is_sent_at_the_simulated_time_it_names():
    from agentsim.realizer import Realizer

    realizer = Realizer()
    stamps = []
    realizer.feedback.listen(lambda f: stamps.append((f, realizer.env.now)))
    realizer.submit((BML / "point.xml").read_text())
    realizer.run()
    timed = [(f, now) for f, now in stamps if f["type"] in ("syncPointProgress", "blockProgress")]
    assert len(timed) == 17
    for f, now in timed:
        assert f["globalTime"] == pytest.approx(now, abs=1e-9)
    assert [now for _, now in timed] == sorted(now for _, now in timed)


def test_cli_prints_json_lines_with_bml_names(tmp_path):
    proc = cli("realize", str(BML / "speech.xml"), str(BML / "speechappend.xml"))
    assert proc.returncode == 0, proc.stderr
    out = lines(proc)
    assert {f["type"] for f in out} == {"predictionFeedback", "blockProgress", "syncPointProgress"}
    start = next(f for f in out if f["id"] == "bml1:start")
    assert start == {"type": "blockProgress", "id": "bml1:start", "globalTime": 0.0, "characterId": "agent"}
    sync = next(f for f in out if f["id"] == "bml2:speech1:start")
    assert set(sync) == {"type", "id", "time", "globalTime", "characterId"} and sync["time"] == 0.0
    ids = [f["id"] for f in out if f["type"] != "predictionFeedback"]
    assert len(ids) == len(set(ids))


def test_cli_at_times_and_until(tmp_path):
    proc = cli("realize", str(BML / "longspeechandnod.xml"), str(BML / "replace.xml"), "--at", "0,0.7")
    blocks = [(f["id"], f["globalTime"]) for f in lines(proc) if f["type"] == "blockProgress"]
    assert blocks[:3] == [("bml1:start", 0.0), ("bml1:end", 0.7), ("bml3:start", 0.7)]
    proc = cli("realize", str(BML / "longspeechandnod.xml"), "--until", "0.5")
    out = lines(proc)
    assert max(f.get("globalTime", 0) for f in out) <= 0.5 and not any(f["id"] == "bml1:end" for f in out)


def test_cli_malformed_input_is_feedback_and_usage_errors_exit_nonzero(tmp_path, examples):
    proc = cli("realize", str(examples / "testinvalidxml.xml"))
    assert proc.returncode == 0
    (warning,) = lines(proc)
    assert warning["warningType"] == "PARSING_FAILURE" and warning["id"] == "bml1"
    assert "line 26, column 3" in warning["description"]
    missing = cli("realize", str(tmp_path / "nope.xml"))
    assert missing.returncode == 2 and b"no such file" in missing.stderr and not missing.stdout
    assert b"Traceback" not in missing.stderr
    bad_at = cli("realize", str(BML / "speech.xml"), "--at", "1,2")
    assert bad_at.returncode == 2 and b"--at gives 2 times for 1 files" in bad_at.stderr


def test_cli_reads_standard_input():
    proc = cli("realize", "-", stdin=(BML / "speech.xml").read_bytes())
    assert proc.returncode == 0 and any(f["id"] == "bml1:end" for f in lines(proc))


def test_cli_writes_bvh_poses_and_timeline(tmp_path):
    import bvhio
    import numpy as np

    bvh, npz, png = tmp_path / "out.bvh", tmp_path / "out.npz", tmp_path / "timeline.png"
    proc = cli("realize", str(BML / "point.xml"), "--bvh", str(bvh), "--poses", str(npz), "--fps", "30")
    assert proc.returncode == 0, proc.stderr
    end = next(f["globalTime"] for f in lines(proc) if f["id"] == "bml1:end")
    root = bvhio.readAsHierarchy(str(bvh))
    assert len(root.Keyframes) == len(np.load(npz)["times"]) >= int(end * 30)
    assert cli("plot", "timeline", str(BML / "point.xml"), "--out", str(png)).returncode == 0
    assert png.stat().st_size > 20_000
    assert cli("realize", str(BML / "point.xml"), "--bvh", str(bvh), "--fps", "0").returncode == 2


def test_a_reader_that_goes_away_ends_the_command_quietly(tmp_path):
    doc = tmp_path / "long.xml"
    doc.write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b">' + "".join(
        f'<gesture id="g{i}" lexeme="BEAT" start="{i}"/>' for i in range(400)) + "</bml>")
    proc = subprocess.Popen([sys.executable, "-m", "agentsim.cli", "realize", str(doc)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()  # like `| head -1`
    _, err = proc.communicate(timeout=60)
    assert json.loads(first)["type"] == "predictionFeedback"
    assert proc.returncode == 0 and err.decode().splitlines() == ["speech: espeak-ng (voice en, 175 words per minute)"]


NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def test_a_gesture_whose_preparation_would_start_before_its_block_is_shortened_to_fit():
    # bml2 starts at 1 s; its beat's stroke is tied to 1.2 s (bml1's end less 0.8): its 0.45 s from start to
    # stroke would begin at 0.75, before its block; it begins at 1.0, its stroke kept, its phases scaled
    first = f'<bml {NS} id="bml1"><wait id="w" start="0" end="2"/></bml>'
    later = f'<bml {NS} id="bml2"><gesture id="g" lexeme="BEAT" stroke="bml1:w:end-{{}}"/></bml>'
    r = realize(first, later.format(0.8), at=[0.0, 1.0])
    assert r.warnings == []
    times = {s: r.glob[f"bml2:g:{s}"] for s in GESTURE}
    scale = 0.2 / 0.45  # the part before the stroke: 0.2 s where 0.45 s were preferred
    assert times == pytest.approx({"start": 1.0, "ready": 1.0 + 0.30 * scale, "strokeStart": 1.0 + 0.32 * scale,
                                   "stroke": 1.2, "strokeEnd": 1.3, "relax": 1.4, "end": 1.7}, abs=1e-12)
    assert r.glob["bml2:g:start"] == r.blocks[1]["globalTime"] == 1.0
    # down to a third of it (0.15 s); at 0.1 s it is refused, and says why
    r = realize(first, later.format(0.85), at=[0.0, 1.0])
    assert r.warnings == [] and r.glob["bml2:g:stroke"] == pytest.approx(1.15, abs=1e-12)
    assert r.glob["bml2:g:start"] == 1.0
    r = realize(first, later.format(0.9), at=[0.0, 1.0])
    (warning,) = r.warnings
    assert (warning["id"], warning["warningType"]) == ("bml2:g", "IMPOSSIBLE_TO_SCHEDULE")
    assert warning["description"] == ("g: it would start 0.350 s before the block start, and its preparation "
                                      "(0.450 s to its stroke) cannot be shortened below 0.150 s to fit (0.100 s "
                                      "are left); behaviour dropped")
    assert not [s for s in r.glob if s.startswith("bml2:g:")]
