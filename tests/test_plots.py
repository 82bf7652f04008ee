"""The pictures, read through their artists rather than their pixels: the words under the speech row at
their onsets and legible, windows of the timeline, a long run as an overview plus windows, the tempo plot's
recovery marker and asynchrony, the command line's window options, and no "None" or "nan" in any text."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from agentsim.animation.pictures import plot_timelines, start_timelines
from agentsim.animation.timeline import (heard_words, layout_words, overview_figure, run_duration, time_windows,
                                         timeline_figure, window_path)
from agentsim.realizer import Realizer
from scenarios.conductor.metrics import (asynchrony, asynchrony_series, beats_to_recover, local_tempo,
                                                  recovery_phrase, tempo_figure)

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
SENTENCE = ("Once upon a time a keeper lived on the hill and every night he climbed the stairs to light the lamp "
            "for the boats that came home late across the water")


def realize(*blocks, at=None):
    realizer = Realizer()
    for t, doc in zip(at or [0.0] * len(blocks), blocks):
        realizer.submit_at(t, doc)
    realizer.run()
    return realizer.recording()


def texts(fig) -> list[str]:
    """Every piece of text of a figure: titles, labels, tick labels, legends, annotations."""
    return [t.get_text() for t in fig.findobj(Text) if t.get_text()]


def says_none_or_nan(fig) -> list[str]:
    return [t for t in texts(fig) if re.search(r"\bNone\b|\bnan\b", t, re.IGNORECASE)]


def drawn_words(fig) -> list[tuple[str, float]]:
    return [(t.get_text(), t.get_position()[0]) for t in fig.findobj(Text) if t.get_gid() == "word"]


def note(fig) -> str:
    (found,) = [t.get_text() for t in fig.findobj(Text) if t.get_gid() == "word-note"]
    return found


def row_labels(fig) -> list[str]:
    return [t.get_text() for t in fig.axes[0].get_yticklabels()]


def bars(fig, gid: str) -> list[tuple[float, float, float, float]]:
    """The bars (left, bottom, right, top in data units) of the collections of the first axes with ``gid``:
    one path each."""
    out = []
    for c in fig.axes[0].collections:
        if c.get_gid() == gid:
            for path in c.get_paths():
                (x0, y0), (x1, y1) = path.vertices.min(axis=0), path.vertices.max(axis=0)
                out.append((x0, y0, x1, y1))
    return out


@pytest.fixture(scope="module")
def talk():
    """A speech heard 0.25 s late on a clock that drifts by 5000 ppm (exaggerated so that it shows), and
    three beat gestures, the last one well after the others."""
    recording = realize(f'<bml {NS} id="b"><speech id="s"><text>{SENTENCE}</text></speech>'
                        '<gesture id="g1" lexeme="BEAT" start="0.5"/><gesture id="g2" lexeme="BEAT" start="3"/>'
                        '<gesture id="g3" lexeme="BEAT" start="14"/></bml>')
    (speech,) = recording.speech
    return replace(recording, speech=(replace(speech, t0=speech.t0 + 0.25, drift_ppm=5000.0),))


def expected_words(recording, start=-math.inf, end=math.inf, stop=math.inf):
    (s,) = recording.speech
    onsets = [(w.text, s.t0 + w.start * (1 + s.drift_ppm * 1e-6)) for w in s.utterance.words]
    return [(text, t) for text, t in onsets if start <= t < end and t < stop]


# ------------------------------------------------------------------------------------------- the words
def test_the_words_under_the_speech_are_the_utterances_at_their_onsets(talk):
    want = expected_words(talk, 1.0, 6.0)
    assert len(want) > 10
    assert [(w.text, w.onset) for w in heard_words(talk, 1.0, 6.0)] == want
    fig = timeline_figure(talk, width=40.0, start=1.0, end=6.0)  # wide enough for every label
    assert _same(drawn_words(fig), want)
    assert note(fig) == f"words: all {len(want)} labelled at their onsets"
    # the labels hang under the speech row (its row's bars are above every word)
    (speech_bar,) = {bottom for _, bottom, _, _ in bars(fig, "behaviour:b:s")}
    assert all(t.get_position()[1] < speech_bar for t in fig.findobj(Text) if t.get_gid() == "word")


def _same(drawn, want) -> bool:
    assert [d[0] for d in drawn] == [w[0] for w in want]
    assert np.allclose([d[1] for d in drawn], [w[1] for w in want], rtol=0, atol=1e-12)
    return True


def test_words_that_would_overlap_are_left_out_and_the_note_says_how_many(talk):
    fig = timeline_figure(talk, width=6.0)  # the whole sentence in a few inches: not every label fits
    want = expected_words(talk)
    drawn = drawn_words(fig)
    assert 0 < len(drawn) < len(want) and set(drawn) <= set(want)
    left_out = len(want) - len(drawn)
    assert note(fig).startswith(f"words: {len(drawn)} of {len(want)} labelled at their onsets")
    assert f"; {left_out} left out where they would overlap at this width" in note(fig)
    # no two labels drawn touch: same line means disjoint extents
    renderer = fig.canvas.get_renderer()
    boxes = [(t.get_position()[1], t.get_window_extent(renderer)) for t in fig.findobj(Text) if t.get_gid() == "word"]
    for i, (y, a) in enumerate(boxes):
        for z, b in boxes[i + 1:]:
            assert y != z or a.x1 < b.x0 or b.x1 < a.x0


def test_layout_puts_a_word_on_the_first_free_line_and_skips_it_when_none_is():
    from agentsim.animation.timeline import HeardWord

    words = [HeardWord("b:s", "word", t, t + 0.1) for t in (0.0, 0.01, 0.02, 0.03, 5.0)]
    placed, skipped = layout_words(words, 0.0, 10.0, inches=10.0, lines=3)
    assert [(w.onset, line) for w, line in placed] == [(0.0, 0), (0.01, 1), (0.02, 2), (5.0, 0)]
    assert [w.onset for w in skipped] == [0.03]


def test_an_interrupted_speech_has_no_words_after_its_stop(talk):
    (speech,) = talk.speech
    stop = 3.0
    cut = replace(talk, speech=(replace(speech, stopped=stop),))
    want = expected_words(cut, stop=stop)
    assert 0 < len(want) < len(expected_words(talk))
    assert [(w.text, w.onset) for w in heard_words(cut)] == want
    assert all(w.end <= stop for w in heard_words(cut))
    assert _same(drawn_words(timeline_figure(cut, width=60.0)), want)


def test_a_speech_cut_by_another_block_has_no_words_after_the_cut():
    recording = realize(f'<bml {NS} id="one"><speech id="s"><text>{SENTENCE}</text></speech></bml>',
                        f'<bml {NS} id="two" composition="REPLACE"><head id="n" lexeme="NOD"/></bml>', at=[0.0, 2.0])
    assert recording.behaviour("one:s").stopped == 2.0
    words = heard_words(recording)
    assert words and max(w.onset for w in words) < 2.0
    assert len(words) == len(expected_words(recording, stop=2.0))


# ------------------------------------------------------------------------------------------- windows
def test_a_window_leaves_out_the_behaviours_outside_it(talk):
    start = talk.behaviour("b:s").end - 1.0  # the last second of the speech, and g3
    assert talk.behaviour("b:g2").end < start < talk.behaviour("b:g3").start
    fig = timeline_figure(talk, start=start, end=16.0)
    rows = row_labels(fig)
    assert "b:g3 (gesture BEAT)" in rows and "b:s (speech)" in rows
    assert not [r for r in rows if r.startswith(("b:g1", "b:g2"))]
    drawn = {c.get_gid() for c in fig.axes[0].collections if c.get_gid()}
    assert drawn == {"behaviour:b:g3", "behaviour:b:s"}
    assert fig.axes[0].get_xlim() == (start, 16.0)
    assert {w for w, _ in drawn_words(fig)} == {w for w, _ in expected_words(talk, start, 16.0)}
    # the whole run has a row for each
    whole = row_labels(timeline_figure(talk))
    assert {r.split(" ")[0] for r in whole} >= {"b:s", "b:g1", "b:g2", "b:g3"}
    with pytest.raises(ValueError):
        timeline_figure(talk, start=5.0, end=5.0)


def long_run(seconds: float = 95.0):
    """Beat gestures every 2.5 s for ``seconds``: one row each."""
    gestures = "".join(f'<gesture id="g{i}" lexeme="BEAT" start="{2.5 * i}"/>' for i in range(int(seconds / 2.5)))
    return realize(f'<bml {NS} id="long">{gestures}</bml>')


def test_a_long_run_writes_an_overview_and_one_file_per_window(tmp_path):
    from PIL import Image

    recording = long_run()
    duration = run_duration(recording)
    assert duration > 90
    stale = tmp_path / "timeline_0300-0330s.png"  # left by an earlier, longer run
    stale.write_bytes(b"old")
    keep = tmp_path / "timeline_notes.png"
    keep.write_bytes(b"mine")
    written = plot_timelines(recording, tmp_path, window=30.0)
    n = math.ceil(duration / 30.0)
    assert n == len(time_windows(duration, 30.0)) == 4
    assert [p.name for p in written] == ["timeline.png"] + [f"timeline_{30 * k:04d}-{30 * k + 30:04d}s.png"
                                                             for k in range(n)]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in written)
    assert not stale.exists() and keep.exists()
    assert sorted(p.name for p in tmp_path.glob("timeline*.png")) == sorted([p.name for p in written] + [keep.name])
    for p in written:  # none is the unreadable strip of a whole run
        assert Image.open(p).size[1] < 2200
    # a short run (or a long one under a higher threshold) is one picture
    assert plot_timelines(recording, tmp_path / "one.png", threshold=200.0) == [tmp_path / "one.png"]
    assert window_path(tmp_path / "t.png", 12.5, 25.0).name == "t_0012.5-0025s.png"


def test_the_overview_has_a_row_per_type_and_a_tick_per_stroke():
    recording = long_run()
    fig = overview_figure(recording, title="long", window=30.0)
    assert row_labels(fig) == ["gesture (38, 38 strokes)"]
    (strokes,) = [c for c in fig.axes[0].collections if c.get_gid() == "overview-stroke"]
    stroke_times = sorted(b.time("stroke") for b in recording.behaviours)
    assert sorted(seg[0][0] for seg in strokes.get_segments()) == pytest.approx(stroke_times)
    spans = np.array(sorted((b.start, b.end) for b in recording.behaviours))
    drawn = np.array(sorted((x0, x1) for x0, _, x1, _ in bars(fig, "overview:gesture")))
    assert drawn.shape == (38, 2) and np.allclose(drawn, spans, rtol=0, atol=1e-9)  # a bar per gesture
    assert says_none_or_nan(fig) == []


def test_the_bars_are_a_collection_per_row_not_an_artist_per_bar():
    recording = long_run()
    fig = timeline_figure(recording, start=0.0, end=40.0)
    ax = fig.axes[0]
    rows = [r for r in row_labels(fig) if r != "feedback"]
    phases = {r.name: len(r.times) - 1 for r in recording.behaviours if r.start < 40.0}
    assert len(rows) == len(phases) > 10
    assert len(ax.patches) == 0  # no Rectangle per bar
    collections = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert sorted(c.get_gid() for c in collections) == sorted(f"behaviour:{name}" for name in phases)
    assert {c.get_gid(): len(c.get_paths()) for c in collections} == {f"behaviour:{n}": k for n, k in phases.items()}
    # the texts of the axes: a label per stroke, the block's name and the word note, no more
    strokes = [t for t in ax.texts if t.get_text() == "stroke"]
    names = [t for t in ax.texts if t.get_gid() == "block-name"]
    assert len(strokes) == len(phases) and len(names) == 1  # the block's start
    assert len(ax.texts) == len(strokes) + len(names) + 1  # and the (empty) word note
    overview = overview_figure(recording, window=30.0)
    assert len(overview.axes[0].patches) == 0 and len(bars(overview, "overview:gesture")) == 38
    assert [c.get_gid() for c in overview.axes[0].collections if isinstance(c, PolyCollection)] == ["overview:gesture"]


def test_windows_drawn_by_worker_processes_are_the_files_drawn_here(tmp_path, monkeypatch):
    from agentsim.animation import pictures

    monkeypatch.setattr(pictures, "_cores", lambda: 2)  # side by side even where this process has one core
    recording = long_run(40.0)  # an overview and three windows
    here = plot_timelines(recording, tmp_path / "here", window=15.0, threshold=15.0, width=8.0, workers=1)
    with start_timelines(recording, tmp_path / "workers", window=15.0, threshold=15.0, width=8.0, workers=2) as drawing:
        assert drawing.workers == 2
        there = drawing.result()
    assert drawing.workers == 2  # none of them fell back to this process
    assert [p.name for p in here] == [p.name for p in there] == [
        "timeline.png", "timeline_0000-0015s.png", "timeline_0015-0030s.png", "timeline_0030-0045s.png"]
    for a, b in zip(here, there):  # byte for byte: the same size, the same labels
        assert a.read_bytes() == b.read_bytes(), a.name


def test_windows_whose_poses_come_later_begin_when_theirs_have_come_and_are_the_same_files(tmp_path, monkeypatch):
    from agentsim.animation import evaluate_poses, pictures
    from agentsim.animation.timeline import PosePanel

    monkeypatch.setattr(pictures, "_cores", lambda: 2)
    recording = long_run(40.0)  # an overview and three windows
    stream = evaluate_poses(recording, fps=30, seed=0)
    here = plot_timelines(recording, tmp_path / "here", stream=stream, window=15.0, threshold=15.0, width=8.0,
                          workers=1)
    windows = ["timeline_0000-0015s.png", "timeline_0015-0030s.png", "timeline_0030-0045s.png"]
    with start_timelines(recording, tmp_path / "later", window=15.0, threshold=15.0, width=8.0, workers=2,
                         poses_later=True) as drawing:
        waiting = lambda: [p.name for p in drawing.waiting]  # noqa: E731
        assert waiting() == windows  # the overview shows no poses: begun at once
        with pytest.raises(RuntimeError, match="poses_until"):
            drawing.result()
        progress = drawing.follow()
        upto = int(np.searchsorted(stream.times, 15.5, side="right"))  # a window shows its poses 0.5 s beyond it
        progress(stream.body, stream.times[:upto], stream.values[:upto])
        assert waiting() == windows
        progress(stream.body, stream.times[:upto + 1], stream.values[:upto + 1])
        assert waiting() == windows[1:]
        upto = int(np.searchsorted(stream.times, 40.0))
        progress(stream.body, stream.times[:upto], stream.values[:upto])
        assert waiting() == windows[2:]
        drawing.poses_until(PosePanel.of(stream), complete=True)
        assert waiting() == []
        later = drawing.result()
    assert drawing.workers == 2
    assert [p.name for p in here] == [p.name for p in later] == ["timeline.png", *windows]
    for a, b in zip(here, later):  # byte for byte
        assert a.read_bytes() == b.read_bytes(), a.name


# ------------------------------------------------------------------------------------------- tempo
def ramp():
    """An ensemble at 108 BPM for 8 beats that reaches 120 BPM, conducted from beat 5."""
    periods = np.r_[np.full(8, 60 / 108), np.linspace(60 / 108, 0.5, 8), np.full(40, 0.5)]
    beats = np.cumsum(np.r_[1.0, periods])
    target = np.full(beats.size, 120.0)
    first_index = 4
    ictus = {b + 1: float(beats[b] - 0.02) for b in range(first_index, beats.size)}
    rng = np.random.default_rng(3)
    onsets = beats[None, :] + rng.normal(0.0, 0.01, (3, beats.size))
    onsets[1, 20] = np.nan  # one musician misses a beat
    return beats, local_tempo(beats), target, ictus, first_index, onsets


def test_the_tempo_plot_marks_the_recovery_and_draws_the_asynchrony():
    beats, tempo, target, ictus, first_index, onsets = ramp()
    recovered = beats_to_recover(tempo, target, first_index)
    assert recovered is not None and recovered > 0
    title = f"ramp ({recovery_phrase(recovered)})"
    fig = tempo_figure(beats, tempo, target, ictus, title, first_index=first_index, onsets=onsets)
    (line,) = [a for a in fig.axes[0].lines if a.get_gid() == "recovery"]
    assert set(line.get_xdata()) == {beats[first_index + recovered]}
    (label,) = [t.get_text() for t in fig.findobj(Text) if t.get_gid() == "recovery-label"]
    assert f"from beat {first_index + recovered + 1} on" in label and f"({recovered} beats after" in label
    (mean,) = [a for a in fig.axes[1].lines if a.get_gid() == "asynchrony"]
    conducted = sorted(ictus)
    want = [np.nanmean(onsets[:, b - 1] - ictus[b]) * 1000.0 for b in conducted]
    assert np.allclose(mean.get_xdata(), [ictus[b] for b in conducted])
    assert np.allclose(mean.get_ydata(), want)
    series = asynchrony_series(onsets, ictus)
    assert np.nanmean(series["musicians"]) == pytest.approx(asynchrony(onsets, ictus)["mean"], abs=0.005)
    assert np.isnan(series["musicians"][1, conducted.index(21)])
    assert says_none_or_nan(fig) == []


def test_a_run_that_never_recovers_says_so_and_has_no_marker():
    beats, _, target, ictus, first_index, onsets = ramp()
    dragging = np.full(beats.size, 110.0)
    assert beats_to_recover(dragging, target, first_index) is None
    title = f"drag ({recovery_phrase(None)})"
    fig = tempo_figure(beats, dragging, target, ictus, title, first_index=first_index, onsets=onsets)
    assert not [a for a in fig.axes[0].lines if a.get_gid() == "recovery"]
    assert fig.axes[0].get_title() == "drag (did not recover to within 2 %)"
    assert says_none_or_nan(fig) == []
    assert recovery_phrase(1) == "recovered in 1 beat" and recovery_phrase(0) == "recovered in 0 beats"


def test_the_conductors_tempo_figure_of_a_run_that_falls_apart():
    from scenarios.conductor.config import config_from_dict
    from scenarios.conductor.scenario import collect_metrics, run_tempo_figure, simulate

    from helpers import FALLS_APART

    config = config_from_dict(FALLS_APART)
    run = simulate(config, "best", 1)
    metrics = collect_metrics(run)
    assert metrics["beats_to_recover"] is None and metrics["stopped"]
    fig = run_tempo_figure(run, metrics)
    assert fig.axes[0].get_title() == "short: best, seed 1 (did not recover to within 2 %)"
    assert says_none_or_nan(fig) == []
    (mean,) = [a for a in fig.axes[1].lines if a.get_gid() == "asynchrony"]
    assert len(mean.get_xdata()) > 0
    # no speech in this run: the timeline says nothing of words, and nothing is None or nan
    recording = run.realizer.recording()
    assert recording.speech == ()
    for fig in (timeline_figure(recording), timeline_figure(recording, start=5.0, end=10.0),
                overview_figure(recording, window=15.0)):
        assert says_none_or_nan(fig) == []
        assert not [t for t in fig.findobj(Text) if t.get_gid() == "word" or (t.get_gid() == "word-note"
                                                                              and t.get_text())]


def test_no_text_says_none_or_nan_for_speech_without_gestures_and_a_dropped_behaviour():
    recording = realize(f'<bml {NS} id="one"><speech id="s"><text>{SENTENCE}</text></speech>'
                        '<gesture id="g" lexeme="BEAT" start="4"/></bml>',
                        f'<bml {NS} id="two" composition="REPLACE"><head id="n" lexeme="NOD"/></bml>', at=[0.0, 2.0])
    for fig in (timeline_figure(recording), timeline_figure(recording, start=1.0, end=3.0), overview_figure(recording)):
        assert says_none_or_nan(fig) == []


# ------------------------------------------------------------------------------------------- the command line
def cli(*argv):
    return subprocess.run([sys.executable, "-m", "agentsim.cli", *argv], capture_output=True, timeout=120)


@pytest.mark.parametrize("options, message", [
    (["--from", "3", "--to", "1"], "--to (1 s) must come after --from (3 s)"),
    (["--from", "2", "--to", "2"], "--to (2 s) must come after --from (2 s)"),
    (["--from", "-1"], "--from must be a non-negative number of seconds, got -1"),
    (["--to", "nan"], "--to must be a non-negative number of seconds, got nan"),
    (["--to", "soon"], "--to expects seconds, got 'soon'"),
    (["--from", "100"], "--from 100 s is after the end of the run"),
])
def test_bad_windows_are_one_line_usage_errors(tmp_path, options, message):
    doc = tmp_path / "speech.xml"
    doc.write_text(f'<bml {NS} id="b"><speech id="s"><text>Hello world.</text></speech></bml>')
    proc = cli("plot", "timeline", str(doc), *options, "--out", str(tmp_path / "t.png"))
    err = proc.stderr.decode()
    assert proc.returncode == 2 and err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "t.png").exists()


def test_the_command_line_draws_a_window(tmp_path):
    from PIL import Image

    doc = tmp_path / "talk.xml"
    doc.write_text(f'<bml {NS} id="b"><speech id="s"><text>{SENTENCE}</text></speech>'
                   '<gesture id="g1" lexeme="BEAT" start="0.5"/><gesture id="g3" lexeme="BEAT" start="6"/></bml>')
    whole, part = tmp_path / "whole.png", tmp_path / "part.png"
    assert cli("plot", "timeline", str(doc), "--out", str(whole)).returncode == 0
    proc = cli("plot", "timeline", str(doc), "--from", "5", "--to", "8", "--out", str(part))
    assert proc.returncode == 0, proc.stderr
    # one row fewer (g1 is outside the window): a shorter picture of the same width
    (w0, h0), (w1, h1) = Image.open(whole).size, Image.open(part).size
    assert w0 == w1 and h1 < h0


def boxes_of(fig, artists):
    renderer = fig.canvas.get_renderer()
    return [a.get_window_extent(renderer) for a in artists]


def overlapping(boxes, names) -> list[tuple[str, str]]:
    return [(names[i], names[j]) for i in range(len(boxes)) for j in range(i + 1, len(boxes))
            if boxes[i].overlaps(boxes[j])]


def test_no_label_of_the_conductors_timelines_overlaps_another_or_leaves_the_picture(tmp_path, monkeypatch):
    """A conductor run through the command line: the lane labels on the left of every timeline picture, the
    block names at the top of its lines (bar4:end and bar6:start 0.1 s apart) and the stroke labels, as the
    renderer lays them out in the files written."""
    from agentsim.animation import pictures, timeline
    from agentsim.cli import main

    figures = []
    monkeypatch.setattr(pictures, "WORKERS", 1)  # every picture drawn in this process, where it is kept
    for name in ("timeline_figure", "overview_figure"):
        def keep(*args, _make=getattr(timeline, name), **kwargs):
            figures.append(_make(*args, **kwargs))
            return figures[-1]
        monkeypatch.setattr(timeline, name, keep)  # plot_timeline draws with it
        if hasattr(pictures, name):
            monkeypatch.setattr(pictures, name, keep)  # and the overview is drawn here
    assert main(["run", "conductor", "--bars", "8", "--out", str(tmp_path)]) == 0
    assert len(figures) == 3 and (tmp_path / "timeline_0000-0015s.png").is_file()
    import json

    feedback = [json.loads(line) for line in (tmp_path / "feedback.jsonl").read_text().splitlines()]
    starts_and_ends = sorted(f["globalTime"] for f in feedback if f["type"] == "blockProgress")
    # two blocks end and start within 0.12 s of each other (bar4:end and bar6:start, in the first window)
    assert any(b - a < 0.12 and b < 15.0 for a, b in zip(starts_and_ends, starts_and_ends[1:]))
    for fig in figures:
        ax = fig.axes[0]
        page = fig.bbox
        lanes = [t for t in ax.get_yticklabels() if t.get_text()]
        lane_boxes = boxes_of(fig, lanes)
        assert len(lanes) >= 2
        assert overlapping(lane_boxes, [t.get_text() for t in lanes]) == []
        assert all(page.x0 <= b.x0 and b.x1 <= page.x1 and page.y0 <= b.y0 and b.y1 <= page.y1 for b in lane_boxes)
        names = [t for t in ax.texts if t.get_rotation() == 90]  # the block names (gid "block-name")
        strokes = [t for t in ax.texts if t.get_text() == "stroke"]
        if fig.axes[0].get_title(loc="left").endswith("(strokes as ticks; the detail is drawn per 15 s window)"):
            assert not names  # the overview
            continue
        assert names and strokes
        name_boxes = boxes_of(fig, names)
        assert overlapping(name_boxes, [t.get_text() for t in names]) == []
        axis = ax.get_window_extent(fig.canvas.get_renderer())
        assert all(axis.x0 <= b.x0 and b.x1 <= axis.x1 + 0.5 and b.y1 <= axis.y1 for b in name_boxes)
        bar_boxes = [Bbox(ax.transData.transform([(x0, y0), (x1, y1)])) for c in ax.collections
                     if (c.get_gid() or "").startswith("behaviour:") for x0, y0, x1, y1 in bars(fig, c.get_gid())]
        assert bar_boxes and not ax.patches
        others = boxes_of(fig, strokes) + bar_boxes
        assert not [t.get_text() for t, b in zip(names, name_boxes) if any(b.overlaps(o) for o in others)]
