"""Tests of the ensemble generator: tempo maps, MIDI, FluidSynth rendering and reference beat times."""

from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

from agentsim.errors import AgentsimError, Unavailable
from agentsim.music import rendering
from agentsim.music.ensemble import read_beats, render_ensemble, render_ensemble_full, write_beats
from agentsim.music.events import score_events
from agentsim.music.instruments import HIHAT, KICK, SNARE
from agentsim.music.midi import midi_tick_times, midi_to_events, score_to_midi
from agentsim.music.onsets import beat_onset_offset, energy_onsets, measure_onset_offsets
from agentsim.music.rendering import PUBLISHED, FluidSynthRenderer, render_events, render_midi_file
from agentsim.music.score import build_score
from agentsim.music.tempo import Meter, TempoChange, TempoMap, TempoRamp, TempoStep, make_tempo_map


# ---------------------------------------------------------------------------------------- tempo maps


def test_constant_tempo_beat_times():
    np.testing.assert_allclose(TempoMap(120.0).beat_times(5), [0.0, 0.5, 1.0, 1.5, 2.0])
    np.testing.assert_allclose(make_tempo_map(90, "3/4").beat_times(4), [0.0, 2 / 3, 4 / 3, 2.0])


def test_ramp_beat_times_by_hand():
    # 4/4 at 120 BPM, +10 % over bar 1 (beats 4..8): tempi 120 120 120 120 | 120 123 126 129 | 132 ...
    tm = TempoMap(120.0, Meter(4), ramps=(TempoRamp(start_bar=1, bars=1, change=0.10),))
    intervals = [0.5, 0.5, 0.5, 0.5, 0.5, 60 / 123, 60 / 126, 60 / 129, 60 / 132, 60 / 132]
    expected = np.concatenate([[0.0], np.cumsum(intervals)])
    np.testing.assert_allclose(tm.beat_times(11), expected, rtol=0, atol=1e-12)
    # hand-summed values
    assert tm.beat_times(7)[6] == pytest.approx(2.987804878, abs=1e-8)
    assert tm.beat_times(8)[7] == pytest.approx(3.463995354, abs=1e-8)
    assert tm.beat_times(10)[9] == pytest.approx(4.383657088, abs=1e-8)
    np.testing.assert_allclose(tm.tempo([0, 4, 5, 6, 8, 100]), [120, 120, 123, 126, 132, 132])


def test_step_and_fractional_positions():
    tm = make_tempo_map(100, "2/4", steps=[(1, 1.5)])  # 0.6 s beats, then 0.4 s from bar 1 (beat 2)
    np.testing.assert_allclose(tm.beat_times(5), [0.0, 0.6, 1.2, 1.6, 2.0])
    assert TempoMap(100.0, Meter(2), steps=(TempoStep(1, 1.5),)) == tm
    np.testing.assert_allclose(tm.time_at([0.5, 1.5, 2.25]), [0.3, 0.9, 1.3])


def test_tempo_changes_reach_a_new_tempo():
    # 3/4 at 132 BPM, to 120 BPM over bars 2-3 (counting from 0), then 150 BPM at once from bar 5
    tm = TempoMap(132.0, Meter(3), changes=(TempoChange(5, 150.0), TempoChange(2, 120.0, ramp_bars=2)))
    np.testing.assert_allclose(tm.tempo([0, 5, 6, 7, 8, 9, 12, 14, 15, 20]),
                               [132, 132, 132, 130, 128, 126, 120, 120, 150, 150], rtol=0, atol=1e-12)
    intervals = 60.0 / tm.tempo(np.arange(15))
    np.testing.assert_allclose(tm.beat_times(16), np.concatenate([[0.0], np.cumsum(intervals)]), rtol=0, atol=1e-12)
    with pytest.raises(ValueError):
        TempoChange(1, 0.0)


def test_rubato_is_bounded_smooth_and_seeded():
    base = make_tempo_map(120, "4/4")
    tm = make_tempo_map(120, "4/4", rubato=0.02, seed=3)
    beats = np.arange(400)
    ratio = tm.tempo(beats) / base.tempo(beats)
    assert np.all(np.abs(ratio - 1) <= 0.02 + 1e-12)
    assert np.ptp(ratio) > 0.02  # it does vary
    assert np.max(np.abs(np.diff(ratio))) < 0.02 * np.pi / 8 + 1e-9  # cosine joins between knots 8 beats apart
    again = make_tempo_map(120, "4/4", rubato=0.02, seed=3)
    np.testing.assert_array_equal(again.beat_times(300), tm.beat_times(300))
    # a longer evaluation does not change earlier beats
    np.testing.assert_array_equal(tm.beat_times(1000)[:300], tm.beat_times(300))
    other = make_tempo_map(120, "4/4", rubato=0.02, seed=4)
    assert not np.allclose(other.beat_times(50), tm.beat_times(50))


def test_meter_parse_and_validation():
    assert Meter.parse("3/4") == Meter(3, 4)
    assert Meter.parse(2) == Meter(2, 4)
    with pytest.raises(ValueError):
        TempoMap(0.0)
    with pytest.raises(ValueError):
        build_score(TempoMap(120.0), 2, parts=("kazoo",))


# ------------------------------------------------------------------------------------------ scores


def test_score_drum_pattern_marks_beats():
    tm = make_tempo_map(120, "3/4")
    sc = build_score(tm, 2, seed=1)
    drums = [n for n in sc.notes if n.part == "drums"]
    kicks = sorted(n.start for n in drums if n.key == KICK)
    snares = sorted(n.start for n in drums if n.key == SNARE)
    hats = sorted(n.start for n in drums if n.key == HIHAT)
    assert kicks == [0, 3]
    assert snares == [1, 2, 4, 5]
    assert hats == [i * 0.5 for i in range(12)]
    assert all(n.channel == 9 for n in drums)
    assert {n.part for n in sc.notes} == {"drums", "bass", "piano", "strings"}


def test_midi_file_follows_tempo_map(tmp_path):
    tm = make_tempo_map(112, "4/4", ramp=(1, 2, 0.1), rubato=0.02, seed=2)
    sc = build_score(tm, 6, seed=2)
    path = tmp_path / "piece.mid"
    score_to_midi(sc, path)
    events = midi_to_events(path)
    hat_on = np.array([e.time for e in events if e.kind == "note_on" and e.channel == 9 and e.data1 == HIHAT])
    on_beats = hat_on[::2]  # hi-hat on every eighth: even ones are the beats
    np.testing.assert_allclose(on_beats, sc.beat_times(), atol=1e-4)
    direct = score_events(sc)
    assert len([e for e in direct if e.kind == "note_on"]) == len([e for e in events if e.kind == "note_on"])
    beat_ticks = np.arange(sc.n_beats) * 960
    np.testing.assert_allclose(midi_tick_times(path, beat_ticks), sc.beat_times(), atol=1e-5)
    np.testing.assert_allclose(midi_tick_times(path, beat_ticks), on_beats, atol=1e-9)


# ---------------------------------------------------------------------------------------- rendering


@pytest.fixture(scope="module")
def ensemble():
    return render_ensemble_full(
        118, "4/4", 12, ramp=(2, 16, 0.10), rubato=0.02, seed=11, sample_rate=22050
    )


def test_rendered_onsets_at_reference_beats(ensemble):
    r = ensemble
    # the drum transients dominate a first-difference signal; find each beat's energy onset there
    onsets = energy_onsets(np.diff(r.audio, prepend=0.0), r.sample_rate, r.beat_times)
    err = onsets - r.beat_times
    assert np.all(np.isfinite(err))
    assert np.median(np.abs(err)) < 0.001
    assert np.percentile(np.abs(err), 90) < 0.002
    assert 0.0005 < r.onset_offset < 0.005


def test_rendered_onsets_at_reference_beats_44k():
    r = render_ensemble_full(126, "3/4", 8, rubato=0.02, seed=12, sample_rate=44100)
    onsets = energy_onsets(np.diff(r.audio, prepend=0.0), r.sample_rate, r.beat_times)
    err = onsets - r.beat_times
    assert np.max(np.abs(err)) < 0.002
    # without the offset correction every beat would be late by about the offset
    err_uncorrected = onsets - (r.beat_times - r.onset_offset)
    assert np.median(err_uncorrected) == pytest.approx(r.onset_offset, abs=0.0005)


def test_measured_onset_offsets_are_small_and_ordered():
    m = measure_onset_offsets(22050)
    assert 0.0 < m["kick+hihat"] < 0.005
    assert 0.0 < m["snare+hihat"] < 0.005
    assert m["hihat"] < 0.002
    assert m["strings"] > m["piano"]  # slow strings have a soft attack
    assert beat_onset_offset(22050) == pytest.approx(0.5 * (m["kick+hihat"] + m["snare+hihat"]))


def test_render_ensemble_shape_and_reference(ensemble, tmp_path):
    r = ensemble
    assert r.audio.dtype == np.float32 and r.audio.ndim == 1
    assert np.max(np.abs(r.audio)) == pytest.approx(0.89, abs=1e-3)
    assert len(r.beat_times) == 48
    ideal = r.lead_in + r.score.beat_times() + r.onset_offset
    # reference = note-on aligned to FluidSynth's 64-sample blocks + onset offset
    assert np.max(np.abs(r.beat_times - ideal)) <= 32 / 22050 + 1e-9
    assert np.all(np.diff(r.beat_times) > 0)
    assert r.audio.size / r.sample_rate == pytest.approx(r.lead_in + r.score.tempo_map.time_at(48) + 1.0, abs=1e-3)


def test_same_seed_same_audio():
    a1, sr1, b1 = render_ensemble(130, "3/4", 3, rubato=0.02, seed=5, sample_rate=22050)
    a2, sr2, b2 = render_ensemble(130, "3/4", 3, rubato=0.02, seed=5, sample_rate=22050)
    a3, _, b3 = render_ensemble(130, "3/4", 3, rubato=0.02, seed=6, sample_rate=22050)
    assert sr1 == sr2 == 22050
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(b1, b2)
    assert not np.array_equal(b1, b3)


def test_block_renderer_matches_whole_render():
    sc = build_score(make_tempo_map(125, "4/4", rubato=0.02, seed=1), 3, seed=1)
    events = score_events(sc, offset=0.3)
    whole = render_events(events, 6.0, 22050)
    rng = np.random.default_rng(0)
    blocks = []
    with FluidSynthRenderer(22050) as r:
        pending = sorted(events, key=lambda e: e.time)
        t = 0.0
        while t < 6.0:
            t = min(6.0, t + float(rng.uniform(0.002, 0.15)))
            # notes are decided as the simulation advances: schedule those due soon
            while pending and pending[0].time < t + 0.05:
                r.schedule(pending.pop(0))
            block = r.render_until(t)
            assert block.dtype == np.float32
            blocks.append(block)
        assert r.time == pytest.approx(6.0)
    np.testing.assert_array_equal(np.concatenate(blocks), whole)



@pytest.mark.parametrize("apart", [False, True], ids=["thread", "process"])
def test_rendering_ahead_gives_the_same_samples_and_counts_a_broken_promise(apart):
    from agentsim.music.process import RenderingProcess

    sc = build_score(make_tempo_map(125, "4/4", rubato=0.02, seed=1), 3, seed=1)
    events = sorted(score_events(sc, offset=0.3), key=lambda e: e.time)
    whole = render_events(events, 6.0, 22050)
    rng = np.random.default_rng(0)
    blocks, lead = [], 0.4
    with (RenderingProcess if apart else FluidSynthRenderer)(22050) as r:
        pending = list(events)
        t = 0.0
        while t < 6.0:
            t = min(6.0, t + float(rng.uniform(0.002, 0.05)))
            while pending and pending[0].time < t + lead:
                r.schedule(pending.pop(0))
            blocks.append(r.render_until(t))
            # every event before t + lead is queued: a thread (a process) may render up to there while we go on
            r.render_ahead(t + lead if not pending else min(t + lead, pending[0].time))
        assert r.time == pytest.approx(6.0) and r.broken_promises == 0
        if apart:
            child = r._process
        else:  # it rendered ahead
            assert any(th.name.startswith("fluidsynth") for th in threading.enumerate())
        r.render_ahead(7.0)
        r.note(6.5, 0, 60, 100, 0.2)  # both events are within what was promised quiet: counted
        assert r.broken_promises == 2
    np.testing.assert_array_equal(np.concatenate(blocks), whole)
    if apart:  # the child has ended
        assert not child.is_alive() and child.exitcode == 0


def test_a_caller_waits_for_the_start_of_a_stretch_rendered_ahead_not_for_the_whole_stretch():
    sc = build_score(make_tempo_map(125, "4/4", seed=1), 2, seed=1)
    events = sorted(score_events(sc, offset=0.1), key=lambda e: e.time)
    whole = render_events(events, 2.0, 22050)
    go = threading.Event()
    with FluidSynthRenderer(22050) as r:
        render = r._render

        def held(n, out):  # the rendering thread stops after its first stretch until it is let go
            render(n, out)
            if threading.current_thread().name.startswith("fluidsynth") and r._pos > PUBLISHED:
                assert go.wait(30)

        r._render = held
        r.schedule(events)
        r.render_ahead(2.0)
        first = r.render_until(PUBLISHED / 22050)  # handed out while the thread still holds the rest
        assert len(first) == PUBLISHED and not r._jobs[0].done()
        go.set()
        rest = r.render_until(2.0)
    np.testing.assert_array_equal(np.concatenate([first, rest]), whole)


def test_a_renderer_process_ends_when_its_parent_has_gone():
    from agentsim.music.process import RenderingProcess

    r = RenderingProcess(22050)
    r.render_until(0.1)
    r._connection.close()  # as the parent's end closes when the parent dies, killed before it could say so
    r._process.join(timeout=30)
    assert r._process.exitcode == 0


def test_a_renderer_process_that_cannot_load_its_soundfont_says_so_where_samples_are_asked_for(tmp_path):
    from agentsim.errors import Unavailable
    from agentsim.music.process import RenderingProcess, renderer

    bad = tmp_path / "not-a-soundfont.sf2"
    bad.write_bytes(b"RIFF nothing of a soundfont")
    with RenderingProcess(22050, bad) as r:
        with pytest.raises(Unavailable, match="could not load the soundfont"):
            r.render_until(0.1)
    with pytest.raises(Unavailable, match="soundfont not found"):  # a missing file: at once, in this process
        renderer(22050, tmp_path / "missing.sf2")


def test_a_renderer_is_forked_only_from_a_process_with_no_other_thread(monkeypatch):
    from agentsim.music.process import RenderingProcess, renderer

    held = threading.Event()
    other = threading.Thread(target=held.wait, args=(30,))
    other.start()
    try:
        with renderer(22050) as r:  # another thread: rendered here, on a thread of its own
            assert isinstance(r, FluidSynthRenderer)
    finally:
        held.set()
        other.join()
    monkeypatch.setattr(threading, "active_count", lambda: 1)  # (as the command line has it)
    with renderer(22050) as r:
        assert isinstance(r, RenderingProcess)


def test_event_sample_is_block_aligned():
    with FluidSynthRenderer(44100) as r:
        assert r.event_sample(1.0) % 64 == 0
        assert abs(r.event_sample(1.0) - 44100) <= 32


def test_write_and_read_beats(tmp_path, ensemble):
    path = tmp_path / "beats.txt"
    write_beats(path, ensemble.beat_times)
    lines = path.read_text().splitlines()
    assert len(lines) == len(ensemble.beat_times)
    np.testing.assert_allclose(read_beats(path), ensemble.beat_times, atol=1e-6)


def test_fluidsynth_command_line_render(tmp_path):
    sc = build_score(make_tempo_map(120, "4/4"), 2, parts=("drums",), seed=0)
    mid = tmp_path / "drums.mid"
    score_to_midi(sc, mid)
    audio, sr = render_midi_file(mid, tmp_path / "drums.wav", sample_rate=22050)
    assert sr == 22050 and audio.dtype == np.float32
    onsets = energy_onsets(np.diff(audio, prepend=0.0), sr, sc.beat_times()[1:])
    # the command line player lands within a 64-sample block plus the instrument offset
    assert np.all((onsets - sc.beat_times()[1:] > -0.001) & (onsets - sc.beat_times()[1:] < 0.008))


# ------------------------------------------------------------------------------------------- errors


def test_missing_soundfont_says_how_to_install(tmp_path):
    with pytest.raises(Unavailable, match="apt-get install fluidsynth fluid-soundfont-gm"):
        render_ensemble(120, "4/4", 1, soundfont=tmp_path / "missing.sf2")
    with pytest.raises(Unavailable, match="apt-get install fluidsynth fluid-soundfont-gm"):
        FluidSynthRenderer(22050, soundfont=tmp_path / "missing.sf2")


def test_missing_fluidsynth_library_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "fluidsynth", None)  # makes `import fluidsynth` fail
    with pytest.raises(Unavailable, match="apt-get install fluidsynth fluid-soundfont-gm"):
        FluidSynthRenderer(22050)


def test_missing_fluidsynth_program_says_how_to_install(monkeypatch, tmp_path):
    monkeypatch.setattr(rendering.shutil, "which", lambda name: None)
    with pytest.raises(Unavailable, match="apt-get install fluidsynth fluid-soundfont-gm"):
        render_midi_file(tmp_path / "x.mid")
    assert issubclass(Unavailable, AgentsimError)  # the one root the command line reports
