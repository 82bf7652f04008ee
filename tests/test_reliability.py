"""Reliability: nothing a document, an anticipator or a long run does may stop the realizer or lose feedback.

The reproducers of the reliability issue, each ending with the run complete, a warning naming the cause,
and (through the command line) exit status 0 with every feedback of the good files.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from anticipators.metronome import Metronome
from agentsim.bml.parser import MAX_BEHAVIOURS, MAX_DOCUMENT, guess_block_id, parse_document
from agentsim.core.xmltree import MAX_DEPTH
from agentsim.core.block import Block
from agentsim.engines.speech import SpeechConfig
from agentsim.realizer import Realizer
from speech_timing.animator_time import STRATEGIES
from speech_timing.builtin import BuiltinBackend

from helpers import realize

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
ROOT = Path(__file__).resolve().parent.parent
GOOD = f'<bml {NS} id="good"><head id="h" lexeme="NOD"/><gesture id="g" lexeme="BEAT" stroke="1"/></bml>'


def doc(body: str, block_id: str = "b", attrs: str = "") -> str:
    return f'<bml {NS} id="{block_id}" {attrs}>{body}</bml>'


def warnings_of(r) -> list[tuple[str, str, str]]:
    return [(w["id"], w["warningType"], w["description"]) for w in r.warnings]


def completes_good_after(r) -> None:
    """The good block submitted after the bad one ran whole."""
    assert "good:h:end" in r.glob and "good:g:stroke" in r.glob
    assert [b["id"] for b in r.blocks if b["id"].startswith("good:")] == ["good:start", "good:end"]


# ---------------------------------------------------------------------- documents that raised
@pytest.mark.parametrize("bad, cause", [
    (doc('<head id="h" lexeme="NOD"/>', block_id="h\ud800"), "not valid Unicode"),
    ('<?xml version="1.0" encoding="bogus"?>' + doc('<head id="h" lexeme="NOD"/>'), "unknown encoding: bogus"),
    (doc("<required>" * 1000 + '<head id="h" lexeme="NOD"/>' + "</required>" * 1000),
     f"nested more than {MAX_DEPTH} deep"),
    ("<bml" * 16000, "malformed XML"),
], ids=["lone surrogate", "bogus encoding", "deep nesting", "many unclosed bml"])
def test_a_document_that_cannot_be_read_is_refused_and_the_next_one_runs(bad, cause):
    r = realize(bad, GOOD)
    ((target, kind, description),) = warnings_of(r)
    assert kind == "PARSING_FAILURE" and cause in description and description.startswith("block refused")
    completes_good_after(r)


@pytest.mark.parametrize("ref, cause", [
    ("anticipators:metronome:beat" + "9" * 400, "is 427 characters long (at most 256)"),
    ("anticipators:metronome:beat" + "9" * 5000, "is 5027 characters long (at most 256)"),
    ("anticipators:metronome:beat" + "9" * 40, "a number in it has more than 32 digits"),
    ("2+" + "9" * 40, "a number in it has more than 32 digits"),
    ("anticipators:metronome:beat" + "9" * 20, "has no sync point 'beat99999999999999999999'"),
])
def test_huge_numbers_in_a_reference_lose_only_their_behaviour(ref, cause):
    r = realize(doc(f'<gesture id="g" lexeme="BEAT" stroke="{ref}"/><head id="h" lexeme="NOD"/>'), GOOD,
                anticipators=[Metronome()])
    ((target, kind, description),) = warnings_of(r)
    assert target == "b:g" and cause in description
    assert "b:h:end" in r.glob and "b:g:start" not in r.glob
    completes_good_after(r)


def test_a_dtd_attribute_default_is_not_applied():
    text = ('<?xml version="1.0"?><!DOCTYPE bml [<!ATTLIST bml id CDATA "fromdtd">'
            f'<!ATTLIST head stroke CDATA "anticipators:metronome:beat{"9" * 400}">]>'
            f'<bml {NS}><head id="h" lexeme="NOD"/></bml>')
    (strict,) = parse_document(text, strict=True)
    assert strict.error.reason == "the <bml> block has no id"
    (lenient,) = parse_document(text)
    assert lenient.id == "bml1" and lenient.behaviours[0].refs == {}


@pytest.mark.parametrize("strategy", sorted(STRATEGIES))
def test_a_speech_without_words_under_an_animator_time_strategy_plays_as_planned(strategy):
    r = realize(doc('<speech id="s"><text>...</text></speech><head id="h" lexeme="NOD"/>'), GOOD,
                speech=SpeechConfig(strategy=strategy))
    ((target, kind, description),) = warnings_of(r)
    assert target == "b:s" and kind == "IMPOSSIBLE_TO_SCHEDULE"
    assert description == (f"s: the speech has no words, so no progress events for the {strategy!r} strategy to "
                           "follow; it plays as planned")
    assert r.glob["b:s:start"] == 0.0 and "b:s:end" in r.glob and "b:h:end" in r.glob
    completes_good_after(r)


@pytest.mark.parametrize("strategy", ["chang-naive", "skip-70ms", "best"])
def test_an_appended_block_tied_inside_itself_after_a_speech_gets_finite_times(strategy):
    r = realize(doc('<speech id="s"><text>Hello there my friend, how are you today?</text></speech>'),
                doc('<faceLexeme id="f" lexeme="smile"/><gesture id="g" lexeme="BEAT" start="f:end+1"/>', "b2",
                    'composition="APPEND"'), at=[0, 0.5], speech=SpeechConfig(strategy=strategy))
    assert not r.warnings
    assert r.glob["b2:g:start"] == pytest.approx(r.glob["b2:f:end"] + 1.0, abs=1e-9)
    assert [b["id"] for b in r.blocks] == ["b:start", "b:end", "b2:start", "b2:end"]


def test_a_timing_that_is_not_a_number_is_refused_by_the_planner():
    from agentsim.core.engine import Planner
    from agentsim.errors import ScheduleError

    with pytest.raises(ScheduleError, match="not a number"):
        Planner().check_times(None, [0.0, 1.0], [0.0, float("nan")])


@pytest.mark.parametrize("bpm, start", [(100.0, float("nan")), (100.0, float("inf")), (float("inf"), 0.0),
                                        (float("nan"), 0.0)])
def test_a_metronome_with_times_that_are_not_finite_is_refused_when_made(bpm, start):
    with pytest.raises(ValueError, match="finite|positive"):
        Metronome(bpm=bpm, start=start)


# ---------------------------------------------------------------------- silent losses
def test_replace_cutting_a_speech_reports_its_end_and_an_interrupted_warning():
    r = realize(doc('<speech id="s"><text>Hello there my friend, how are you today?</text></speech>'
                    '<head id="later" lexeme="NOD" start="5"/>'),
                doc('<head id="h" lexeme="NOD"/>', "b2", 'composition="REPLACE"'), at=[0, 0.5])
    assert r.glob["b:s:start"] == 0.0 and r.glob["b:s:end"] == 0.5
    assert warnings_of(r) == [("b:s", "INTERRUPTED", "s: its block was replaced by b2; stopped at once"),
                              ("b:later", "INTERRUPTED", "later: its block was replaced by b2; it will not start")]
    assert [b["id"] for b in r.blocks] == ["b:start", "b:end", "b2:start", "b2:end"]
    ends = [f["id"] for f in r.items if f["type"] in ("syncPointProgress", "blockProgress")]
    assert ends.index("b:s:end") < ends.index("b:end")


def test_a_behaviour_tied_to_a_dropped_one_is_dropped_with_its_own_warning():
    r = realize(doc('<gesture id="g" lexeme="BEAT" start="zz:end"/><head id="h" lexeme="NOD" start="g:end+2"/>'
                    '<head id="free" lexeme="SHAKE"/>'))
    assert warnings_of(r) == [
        ("b:g", "IMPOSSIBLE_TO_SCHEDULE", "g: start='zz:end': no behaviour 'zz' in block b; behaviour dropped"),
        ("b:h", "IMPOSSIBLE_TO_SCHEDULE", "h: start='g:end+2': it is tied to g, which was dropped; behaviour dropped")]
    assert "b:h:start" not in r.glob and "b:free:end" in r.glob


def test_chains_of_ties_to_a_dropped_behaviour_all_go():
    r = realize(doc('<head id="c" lexeme="NOD" start="b:end"/><head id="b" lexeme="NOD" start="a:end"/>'
                    '<gesture id="a" lexeme="BEAT" start="nobody:end"/>'))
    assert [w[0] for w in warnings_of(r)] == ["b:a", "b:b", "b:c"]
    assert not r.syncs


def test_an_id_with_a_colon_is_refused_so_feedback_ids_stay_unambiguous():
    r = realize(doc('<head id="h" lexeme="NOD"/>', block_id="a:b"), GOOD)
    ((target, kind, description),) = warnings_of(r)
    assert kind == "PARSING_FAILURE" and "contains ':'" in description
    completes_good_after(r)
    r = realize(doc('<head id="x:y" lexeme="NOD"/><head id="h" lexeme="NOD"/>'))
    ((target, kind, description),) = warnings_of(r)
    assert target == "b" and "behaviour id 'x:y' contains ':'" in description and "b:h:end" in r.glob


@pytest.mark.parametrize("strict", [False, True])
def test_an_xinclude_inside_speech_text_is_said(strict):
    text = doc('<speech id="s"><text>Hello <xi:include xmlns:xi="http://www.w3.org/2001/XInclude" href="x.txt"/> '
               'there</text></speech>')
    r = realize(text, strict=strict)
    assert any("xi:include" in w[2] for w in warnings_of(r)), warnings_of(r)
    assert "b:s:end" in r.glob


# ---------------------------------------------------------------------- limits
def test_a_document_over_the_size_limit_is_refused_before_it_is_parsed():
    big = doc("<x/>" * (MAX_DOCUMENT // 4 + 1))
    r = realize(big, GOOD)
    ((target, kind, description),) = warnings_of(r)
    assert target == "b" and "MB long: at most 8 MB is read" in description
    completes_good_after(r)


def test_behaviours_beyond_the_limit_are_ignored_with_one_warning():
    body = "".join(f'<wait id="w{i}" start="0" end="0.001"/>' for i in range(MAX_BEHAVIOURS + 3))
    (block,) = parse_document(doc(body))
    assert isinstance(block, Block) and len(block.behaviours) == MAX_BEHAVIOURS
    (w,) = block.warnings
    assert f"more than {MAX_BEHAVIOURS} behaviours: w{MAX_BEHAVIOURS} and every behaviour after it" in w.description


def test_guessing_the_id_of_a_malformed_document_stays_linear():
    # every failed try stops at the next tag: 100,000 unclosed tags are one pass
    assert guess_block_id("<bml" * 100_000) == ""
    assert guess_block_id('<bml <bml id="x" ') == "x"


# ---------------------------------------------------------------------- the command line
def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *args], capture_output=True, text=True,
                          timeout=120, cwd=cwd, env=env)


def test_the_command_line_realizes_every_good_file_after_bad_ones(tmp_path):
    bad = {
        "encoding.xml": b'<?xml version="1.0" encoding="bogus"?>' + doc('<head id="h" lexeme="NOD"/>').encode(),
        "deep.xml": doc("<required>" * 1000 + "</required>" * 1000).encode(),
        "number.xml": doc('<gesture id="g" lexeme="BEAT" stroke="anticipators:metronome:beat' + "9" * 5000
                          + '"/>').encode(),
        "binary.xml": bytes(range(256)) * 4,
    }
    for name, data in bad.items():
        (tmp_path / name).write_bytes(data)
    (tmp_path / "good.xml").write_text(GOOD)
    proc = cli("realize", "--tts", "builtin", "--metronome", "120", *bad, "good.xml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    feedback = [json.loads(line) for line in proc.stdout.splitlines()]
    alone = cli("realize", "--tts", "builtin", "--metronome", "120", "good.xml", cwd=tmp_path)
    good = [f for f in feedback if f["id"].startswith("good")]
    assert good == [f for f in map(json.loads, alone.stdout.splitlines())]
    warned = [f["description"] for f in feedback if f["type"] == "warningFeedback"]
    assert len(warned) == len(bad) and all(w for w in warned)


@pytest.mark.parametrize("option", ["--metronome=100,nan", "--metronome=100,inf", "--metronome=inf",
                                    "--anticipator=metronome:m2,start=nan"])
def test_a_metronome_that_is_not_finite_is_left_out_and_the_run_goes_on(tmp_path, option):
    (tmp_path / "good.xml").write_text(GOOD)
    (tmp_path / "beat.xml").write_text(doc('<head id="n" lexeme="NOD" stroke="anticipators:metronome:beat2"/>',
                                           "beat"))
    proc = cli("realize", "--tts", "builtin", option, "good.xml", "beat.xml", cwd=tmp_path)
    assert proc.returncode == 0 and "internal error" not in proc.stderr and "Traceback" not in proc.stderr
    feedback = [json.loads(line) for line in proc.stdout.splitlines()]
    warnings = [f for f in feedback if f["type"] == "warningFeedback"]
    assert warnings[0]["warningType"] == "NO_SUCH_TARGET" and "left out" in warnings[0]["description"]
    assert "finite" in warnings[0]["description"]
    assert any(w["id"] == "beat:n" for w in warnings)  # what was tied to it is dropped, with its own warning
    alone = cli("realize", "--tts", "builtin", "good.xml", cwd=tmp_path)
    good = [line for line in proc.stdout.splitlines() if '"good' in line and "warningFeedback" not in line]
    assert good == [line for line in alone.stdout.splitlines() if "warningFeedback" not in line]


def test_recording_of_a_complete_run_is_kept():
    realizer = Realizer()
    realizer.submit(GOOD)
    realizer.run()
    assert [b.id for b in realizer.recording().blocks] == ["good"]


@pytest.mark.parametrize("fps", ["1e5", "0", "nan"])
def test_a_frame_rate_out_of_bounds_is_a_usage_error_before_the_run(tmp_path, fps):
    (tmp_path / "good.xml").write_text(GOOD)
    proc = cli("realize", "--tts", "builtin", "--fps", fps, "--poses", "out.npz", "good.xml", cwd=tmp_path)
    assert proc.returncode == 2 and "--fps must be positive and at most 1000 frames per second" in proc.stderr
    assert not proc.stdout and not (tmp_path / "out.npz").exists()


def test_many_free_behaviours_end_one_by_one_without_rescanning_the_block():
    body = "".join(f'<wait id="w{i}" start="{i * 0.001:.3f}" end="{i * 0.001 + 0.0005:.4f}"/>' for i in range(5000))
    r = realize(doc(body))
    assert not r.warnings and len(r.syncs) == 10_000
    assert r.blocks[-1]["id"] == "b:end" and r.blocks[-1]["globalTime"] == pytest.approx(4.9995)


def test_marks_are_placed_at_the_word_after_them():
    from speech_timing.backend import SpeechText, Word, mark_times_from_words

    words = [Word(i, f"w{i}", 0.5 * i, 0.5 * i + 0.4, 3 * i, 3 * i + 2) for i in range(4)]
    speech = SpeechText("w0 w1 w2 w3", ((0, "a"), (4, "b"), (6, "c"), (11, "d")))
    marks = mark_times_from_words(speech, words, duration=2.0)
    assert [(m.name, m.time) for m in marks] == [("a", 0.0), ("b", 1.0), ("c", 1.0), ("d", 2.0)]
    backwards = mark_times_from_words(speech, words[::-1], duration=2.0)
    assert [m.time for m in backwards] == [1.5, 1.5, 1.5, 2.0]  # the first word listed at or after the mark


def test_a_path_crossing_is_found_by_binary_search_with_the_same_times():
    from speech_timing.animator_time import Path

    path = Path(0.0, 0.0, 1.0)
    for k in range(1, 2000):
        path.then(float(k), 0.5 if k % 2 else 2.0)
    assert path.crossing(0.5, 0.0) == 0.5
    assert path.crossing(path.at(1234.25), 10.0) == pytest.approx(1234.25, abs=1e-9)
    assert path.crossing(path.at(1999.5), 1999.0) == pytest.approx(1999.5, abs=1e-9)
    assert path.crossing(-1.0, 5.0) == 5.0
    stuck = Path(0.0, 0.0, 1.0).then(1.0, 0.0)
    assert stuck.crossing(2.0, 0.0) == float("inf")


@pytest.mark.parametrize("strategy", sorted(STRATEGIES))
def test_animator_time_never_goes_back_whatever_order_events_come_in(strategy):
    import importlib.util

    import numpy as np

    spec = importlib.util.spec_from_file_location("bench_storm", ROOT / "benchmarks" / "bench_storm.py")
    bench_storm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench_storm)
    backend, utterance, events = bench_storm.storm_events(2000)
    shuffled = np.random.default_rng(3).permutation(len(events))
    for order, instants in ((range(len(events)), 200), (shuffled, 200), (shuffled, 1)):
        result = bench_storm.run_storm(strategy, backend, utterance, events, order, utterance.duration / 2, instants)
        assert result["monotone"]


# ---------------------------------------------------------------------- a flat memory
def test_a_realizer_that_keeps_a_few_blocks_releases_older_ones_with_their_pegs():
    realizer = Realizer(keep=4, anticipators=[Metronome(bpm=120)])
    for i in range(100):
        realizer.submit_at(i * 2.0, doc('<gesture id="g" lexeme="BEAT" stroke="anticipators:metronome:beat'
                                        f'{4 * i + 3}"/><speech id="s"><text>one two</text></speech>', f"b{i}"))
    realizer.run()
    scheduler = realizer.scheduler
    assert len(scheduler.book.all_runs) <= 2 * 4 + 16 and scheduler.book.all_runs[-1].id == "b99"
    assert len(realizer.board.block_pegs) == len(scheduler.book.all_runs)
    assert len(realizer.speech.heard()) <= len(scheduler.book.all_runs)
    assert len(realizer.scheduler.anticipators["metronome"].pegs) < 60  # of 100: the last minute, and a batch
    # every block ran whole: the feedback listeners got everything, the log keeps the latest
    ends = [f for f in realizer.feedback.items if f["type"] == "blockProgress" and f["id"].endswith(":end")]
    assert ends[-1]["id"] == "b99:end" and not realizer.feedback.warnings()


def test_a_released_block_can_no_longer_be_referred_to_but_a_kept_one_can():
    realizer = Realizer(keep=1)
    for i in range(30):
        realizer.submit_at(float(i), doc('<head id="h" lexeme="NOD"/>', f"b{i}"))
    realizer.submit_at(40.0, doc('<head id="late" lexeme="NOD" start="b29:h:end+20"/>'
                                 '<head id="lost" lexeme="NOD" start="b0:h:end"/>', "tail"))
    realizer.run()
    syncs = realizer.feedback.sync_times()
    assert syncs["tail:late:start"] == pytest.approx(syncs["b29:h:end"] + 20.0, abs=1e-9)
    ((w),) = [w for w in realizer.feedback.warnings()]
    assert w["id"] == "tail:lost" and "no sync point b0:h:end in a planned block" in w["description"]


def test_by_default_a_realizer_keeps_the_whole_run_for_its_recording():
    realizer = Realizer()
    for i in range(300):
        realizer.submit_at(float(i), doc('<head id="h" lexeme="NOD"/>', f"b{i}"))
    realizer.run()
    recording = realizer.recording()
    assert len(recording.blocks) == 300 and len(recording.behaviours) == 300


# ---------------------------------------------------------------------- fuzz
@pytest.mark.parametrize("cases", [300, pytest.param(2000, marks=pytest.mark.system)])
def test_mutated_documents_neither_stop_the_realizer_nor_lose_feedback(cases):
    """The profile of ``benchmarks/fuzz_bml.py`` the suite runs, seeded: 300 cases in the default run, 2,000
    in the system run."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("fuzz_bml", ROOT / "benchmarks" / "fuzz_bml.py")
    fuzz_bml = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fuzz_bml)
    report = fuzz_bml.fuzz(cases, seed=17)
    assert report["failures"] == []
    assert report["uncaught_exceptions"] == report["feedback_losses"] == 0
    assert report["cases_that_played_something"] > cases // 2  # most mutations still reach the scheduler


# ---------------------------------------------------------------------- outputs that cannot half-exist
def test_a_file_is_written_whole_or_not_at_all(tmp_path):
    from agentsim.written import written
    from agentsim.media.files import write_text

    target = tmp_path / "feedback.jsonl"
    write_text(target, "old\n")
    with pytest.raises(OSError, match="No space left"):
        with written(target) as tmp:
            tmp.write_text("half of it")
            raise OSError(28, "No space left on device")
    assert target.read_text() == "old\n" and sorted(p.name for p in tmp_path.iterdir()) == ["feedback.jsonl"]
    write_text(target, "new\n")
    assert target.read_text() == "new\n" and len(list(tmp_path.iterdir())) == 1


def test_the_bvh_and_csv_writers_leave_the_old_file_when_writing_fails(tmp_path, monkeypatch):
    import numpy as np

    from agentsim.animation import evaluate_poses, write_bvh
    from agentsim.media.tables import write_csv

    realizer = Realizer()
    realizer.submit(doc('<head id="h" lexeme="NOD"/>'))
    realizer.run()
    stream = evaluate_poses(realizer.recording(), fps=30)
    bvh, table = tmp_path / "run.bvh", tmp_path / "rows.csv"
    bvh.write_text("old\n")
    table.write_text("old\n")

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savetxt", full)
    with pytest.raises(OSError, match="No space left"):
        write_bvh(bvh, stream)

    class Row(dict):
        def get(self, *args):
            raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        write_csv(table, [Row(a=1)], columns=["a"])
    assert bvh.read_text() == "old\n" and table.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rows.csv", "run.bvh"]


def test_a_full_disk_for_the_feedback_is_one_clear_line(tmp_path):
    (tmp_path / "good.xml").write_text(GOOD)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "realize", "--tts", "builtin", "good.xml"],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=120, cwd=tmp_path, env=env)
    lines = [line for line in proc.stderr.splitlines() if not line.startswith("speech:")]
    assert proc.returncode == 1 and lines == ["agentsim: cannot go on: No space left on device"]


def test_a_closed_standard_output_is_one_clear_line(tmp_path):
    (tmp_path / "good.xml").write_text(GOOD)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(f"'{sys.executable}' -m agentsim.cli realize --tts builtin good.xml >&-", shell=True,
                          stderr=subprocess.PIPE, text=True, timeout=120, cwd=tmp_path, env=env)
    lines = [line for line in proc.stderr.splitlines() if not line.startswith("speech:")]
    assert proc.returncode == 2
    assert lines == ["agentsim: standard output is closed: there is nowhere to write the feedback"]


@pytest.mark.parametrize("where", ["file/poses.npz", "file/deeper/poses.npz"])
def test_an_output_that_cannot_be_written_is_said_before_the_run(tmp_path, where):
    (tmp_path / "good.xml").write_text(GOOD)
    (tmp_path / "file").write_text("a file, not a folder")
    proc = cli("realize", "--tts", "builtin", "--poses", where, "good.xml", cwd=tmp_path)
    assert proc.returncode == 2 and not proc.stdout  # nothing ran
    assert proc.stderr.splitlines()[-1] == (f"agentsim: cannot write {where}: a file is in the way of its folder "
                                            f"{where.rsplit('/', 1)[0]}")


def test_an_output_folder_that_is_missing_is_made(tmp_path):
    (tmp_path / "good.xml").write_text(GOOD)
    proc = cli("realize", "--tts", "builtin", "--poses", "missing/poses.npz", "good.xml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "missing" / "poses.npz").stat().st_size > 0


def test_a_conductor_output_folder_under_a_file_is_said_before_the_run(tmp_path):
    (tmp_path / "file").write_text("a file, not a folder")
    proc = cli("run", "conductor", "--out", "file/out", cwd=tmp_path)
    assert proc.returncode == 2 and "internal error" not in proc.stderr
    assert proc.stderr.splitlines()[-1] == ("agentsim: cannot make the output folder file/out: a file is in the way on "
                                            "its path")


@pytest.mark.parametrize("kind", ["folder", "latin-1"])
def test_a_conductor_configuration_that_is_a_folder_or_not_utf8_is_one_clear_line(tmp_path, kind):
    config = tmp_path / "config.toml"
    if kind == "folder":
        config.mkdir()
    else:
        config.write_bytes('title = "caf\xe9"\n'.encode("latin-1"))
    proc = cli("run", "conductor", "--config", str(config), "--out", "out", cwd=tmp_path)
    assert proc.returncode == 1 and "internal error" not in proc.stderr and "no such file" not in proc.stderr
    message = "is a folder, not a configuration file" if kind == "folder" else "not UTF-8 text (byte 12"
    assert message in proc.stderr.splitlines()[-1] and not (tmp_path / "out").exists()


def test_a_speech_over_the_word_limit_is_ignored_with_a_warning():
    from agentsim.bml.parser import MAX_WORDS

    r = realize(doc(f'<speech id="s"><text>{"word " * (MAX_WORDS + 1)}</text></speech><head id="h" lexeme="NOD"/>'))
    ((target, kind, description),) = warnings_of(r)
    assert target == "b:s" and f"has {MAX_WORDS + 1} words (at most {MAX_WORDS}" in description
    assert "b:h:end" in r.glob


def test_an_empty_alsa_configuration_is_one_clear_line_not_an_abort(tmp_path):
    (tmp_path / "empty.conf").write_text("")
    env = dict(os.environ, PYTHONPATH=str(ROOT), ALSA_CONFIG_PATH=str(tmp_path / "empty.conf"))
    proc = subprocess.run([sys.executable, "-m", "agentsim.cli", "anticipate", "beats", "--input", "default",
                           "--seconds", "1"], capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert proc.returncode == 1
    assert proc.stderr.splitlines()[-1].startswith(f"agentsim: the ALSA configuration (ALSA_CONFIG_PATH="
                                                   f"{tmp_path / 'empty.conf'}) is missing or empty")


@pytest.mark.parametrize("strict", [False, True], ids=["lenient", "strict"])
def test_a_dtd_attribute_default_is_ignored_with_one_warning(strict):
    text = ('<?xml version="1.0"?>\n<!DOCTYPE bml [<!ATTLIST gesture lexeme CDATA "POINT">'
            '<!ATTLIST gesture stroke CDATA "5">]>\n'
            f'<bml {NS} id="b"><gesture id="g" start="1"/><gesture id="w" lexeme="BEAT"/></bml>')
    r = realize(text, strict=strict)
    assert warnings_of(r) == [("b", "CUSTOM_ATTRIBUTE_NOT_SUPPORTED", "attribute defaults declared in the document "
                               "type declaration ignored (gesture lexeme='POINT', gesture stroke='5'): every element "
                               "has only the attributes written in it")]
    # g has no lexeme (it is not made a POINT, nor a BEAT by the document: it plays the default beat) and
    # no stroke at 5 s: its own start and its preferred timing
    (prediction,) = r.realizer.feedback.of_type("predictionFeedback")
    g = next(b for b in prediction["behaviours"] if b["id"] == "g")
    assert "lexeme" not in g and r.realizer.scheduler.book.find("b").block.behaviour("g").attributes.get("lexeme") is None
    assert (r.glob["b:g:start"], r.glob["b:g:stroke"], r.glob["b:g:end"]) == pytest.approx((1.0, 1.45, 1.95),
                                                                                          abs=1e-12)
    assert r.glob["b:w:stroke"] == 0.45


@pytest.mark.parametrize("value, kind, problem, end", [
    ("1000000", "IMPOSSIBLE_TO_SCHEDULE", "repetition='1000000' is more than the 100 repetitions played; clamped to "
     "100", 0.55 + 99 * 0.3),
    ("inf", "PARSING_FAILURE", "repetition='inf' is not a finite number; played once", 0.55),
    ("nan", "PARSING_FAILURE", "repetition='nan' is not a finite number; played once", 0.55),
    ("-1", "PARSING_FAILURE", "repetition='-1' is less than 1; played once", 0.55),
    ("abc", "PARSING_FAILURE", "repetition='abc' is not a number; played once", 0.55),
    ("2.5", "PARSING_FAILURE", "repetition='2.5' is not a whole number; 2 repetitions played", 0.55 + 0.3),
    ("3", None, None, 0.55 + 2 * 0.3),
])
def test_a_repetition_out_of_range_is_clamped_or_refused_with_a_warning_that_says_why(value, kind, problem, end):
    # a nod lasts 0.55 s; each repetition after the first adds its 0.3 s of nodding (strokeStart to strokeEnd)
    r = realize(doc(f'<head id="h" lexeme="NOD" repetition="{value}"/>'), GOOD)
    column = len(doc("")) - len("</bml>") + 1  # where the <head> starts
    expected = [] if kind is None else [("b:h", kind, f"h: {problem} (line 1, column {column})")]
    assert warnings_of(r) == expected
    assert r.glob["b:h:end"] == pytest.approx(end, abs=1e-9)
    completes_good_after(r)


def test_twelve_thousand_marks_in_one_speech_each_come_at_the_word_after_it():
    # (its speed, linear in the marks, is benchmarks/bench_speech_marks.py's)
    n = 12000
    words = "the quick brown fox jumps over a lazy dog and then".split()
    text = " ".join(f'{words[i % 11]}{"." if i % 11 == 10 else ""} <sync id="m{i}"/>' for i in range(n))
    r = realize(doc(f'<speech id="s"><text>{text}</text></speech>'), tts=BuiltinBackend())
    assert r.warnings == []
    (heard,) = r.realizer.recording().speech
    spoken = heard.utterance.words
    assert len(spoken) == n
    order = [f["id"] for f in r.syncs]
    assert order == ["b:s:start"] + [f"b:s:m{i}" for i in range(n)] + ["b:s:end"]
    # a mark between two words comes where the next word starts; the last one after the last word
    assert [r.glob[f"b:s:m{i}"] for i in range(n - 1)] == [w.start for w in spoken[1:]]
    assert spoken[-1].end <= r.glob[f"b:s:m{n - 1}"] <= r.glob["b:s:end"] == heard.utterance.duration


def every_offset(raw: str) -> tuple[str, list[int]]:
    """Where each offset of ``raw`` goes when its runs of white space are collapsed, offset by offset (the map
    :func:`normalize_space` once made whole): the reference it is checked against."""
    pieces, positions, length, done = [], [], 0, 0
    for start, end in [m.span() for m in __import__("re").finditer(r"\s+", raw)]:
        if start > done:
            pieces.append(raw[done:start])
            positions.extend(range(length, length + start - done))
            length += start - done
        if start > 0:
            positions.append(length)
            pieces.append(" ")
            length += 1
            positions.extend([length] * (end - start - 1))
        else:
            positions.extend([length] * end)
        done = end
    if len(raw) > done:
        pieces.append(raw[done:])
        positions.extend(range(length, length + len(raw) - done))
    positions.append(len("".join(pieces)))
    return "".join(pieces).rstrip(), positions


def test_collapsing_white_space_maps_the_offsets_asked_for_as_a_whole_map_would():
    import numpy as np

    from agentsim.bml.speech_text import normalize_space

    rng = np.random.default_rng(25)
    alphabet = list("ab c\t\n\u00a0\u2028\u3000\x1c\x85xyz")
    for n in [0, 1, 2, 3, 5, 8, 13, 40, 200] * 20:
        raw = "".join(rng.choice(alphabet, size=n)) if n else ""
        text, whole = every_offset(raw)
        asked = list(range(len(raw) + 1))
        got_text, mapped = normalize_space(raw, rng.permutation(asked + asked).tolist())
        assert got_text == text and mapped == dict(enumerate(whole)), repr(raw)


def test_reading_a_speech_of_megabytes_weighs_a_few_times_its_text():
    """A speech's marks are placed without a map of every character (36 bytes a character: a 4 MB message to
    the live service had cost 170 MB to read, 9 MB now)."""
    import tracemalloc

    text = " ".join(["lighthouse"] * 95_000)  # 1 MB
    document = doc(f'<speech id="s"><text>{text[:500_000]}<sync id="m"/>{text[500_000:]}</text></speech>')
    tracemalloc.start()
    try:
        (block,) = parse_document(document)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    (speech,) = block.behaviours
    assert speech.marks == [(500_000, "m")] and speech.text.startswith("lighthouse lighthouse")
    assert peak < 20 * len(document), peak / len(document)  # (14 times; 53 with the map of every character)


def test_a_document_read_and_let_go_is_freed_without_waiting_for_a_collection():
    """The XML reader and its expat parser refer to each other; the tree read is not left hanging from them, so
    a document is freed as soon as it is let go (a live service had held dozens of 4 MB documents until the
    collector ran, some 400 MB)."""
    import gc
    import tracemalloc

    document = doc(f'<speech id="s"><text>{"lighthouse " * 100_000}</text></speech>')  # 1 MB
    was_enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    tracemalloc.start()
    try:
        for _ in range(5):
            (block,) = parse_document(document)
            assert len(block.behaviours[0].text) == 1_099_999
            del block
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
        if was_enabled:
            gc.enable()
    # (1% of one document's size is held, the reader's own small cycles; ten documents' worth were before)
    assert held < len(document) / 10, held / len(document)
