"""The body side: strokes land on the stroke feedback, the Arbitrator keeps one writer per DOF, blinks
give way to a stare, BVH files read back, and a seed fixes the poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agentsim.animation import DriverManager, evaluate_poses, write_bvh, write_npz
from agentsim.animation.analysis import head_orientation, measure_strokes
from agentsim.animation.arbitrator import ArbitrationError, Arbitrator
from agentsim.animation.drivers import Driver
from agentsim.realizer import Realizer
from helpers import EXAMPLES

BML_NS = "http://www.bml-initiative.org/bml/bml-1.0"

LONG_BLOCK = f"""<bml xmlns="{BML_NS}" id="long" characterId="agent">
  <speech id="s1"><text>Welcome to the concert hall. <sync id="m1"/>Tonight we play music by Haydn,
    <sync id="m2"/>and the orchestra is ready.</text></speech>
  <gesture id="b1" lexeme="BEAT" mode="RIGHT_HAND" stroke="s1:m1"/>
  <gesture id="b2" lexeme="BEAT" stroke="s1:m2"/>
  <head id="n1" lexeme="NOD" start="2"/>
  <gaze id="gz" target="audience" influence="NECK" start="3" ready="4" relax="8" end="9"/>
  <faceLexeme id="f1" lexeme="RAISE_BROWS" start="5" end="7"/>
  <pointing id="p1" target="violins" start="10" end="13"/>
  <head id="n2" lexeme="SHAKE" start="12" repetition="2"/>
  <posture id="pose1" lexeme="LEAN_FORWARD" start="14" end="20"/>
  <gesture id="g3" lexeme="CHOP" mode="LEFT_HAND" start="16" end="18"/>
  <gazeShift id="gs" target="left" start="21" end="22"/>
  <headDirectionShift id="hs" target="user" start="23" end="24"/>
  <locomotion id="walk" target="bluebox" start="24" end="27"/>
  <gesture id="c1" lexeme="CONDUCT_3_4" start="27" end="28.5"/>
  <faceFacs id="ff" au="26" start="28" end="29"/>
  <wait id="w" start="29" end="30"/>
</bml>"""


def realize(*documents, at=None) -> Realizer:
    r = Realizer()
    for t, doc in zip(at or [0.0] * len(documents), documents):
        r.submit_at(t, doc)
    r.run()
    return r


def example_files() -> list[Path]:
    files = sorted(EXAMPLES.glob("*.xml"))
    assert files, f"the BML examples are expected in {EXAMPLES}"
    return files


@pytest.fixture(scope="module")
def long_realizer() -> Realizer:
    r = realize(LONG_BLOCK)
    assert not r.feedback.warnings(), r.feedback.warnings()
    return r


# --------------------------------------------------------------------------------------------- strokes
def _ictus_of_gesture(stream, side: str, t0: float, t1: float) -> float:
    """Frame time of the wrist's lowest point between strokeStart and strokeEnd (computed here from the
    world positions of the evaluated poses, independently of the analysis module)."""
    y = stream.position(f"{side}_wrist")[:, 1]
    idx = np.nonzero((stream.times >= t0 - 1e-9) & (stream.times <= t1 + 1e-9))[0]
    k = idx[np.argmin(y[idx])]
    # the vertical velocity turns from down to up there
    assert y[k - 1] > y[k] <= y[k + 1]
    return float(stream.times[k])


@pytest.mark.parametrize("fps", [60.0, 120.0])
@pytest.mark.parametrize("path", example_files(), ids=lambda p: p.name)
def test_stroke_feedback_is_where_the_motion_has_its_stroke(path: Path, fps: float):
    r = Realizer()
    r.submit(path.read_bytes())
    r.run()
    syncs = r.feedback.sync_times()
    expected = {k for k in syncs if k.endswith(":stroke")}
    stream = evaluate_poses(r, fps=fps)
    measured = measure_strokes(stream, syncs)
    seen = {f"{m.block}:{m.behaviour}:stroke" for m in measured}
    assert seen == expected  # every gesture, head and pointing stroke is measured
    for m in measured:
        assert m.intact, (path.name, m)  # no other behaviour took the DOFs during the stroke
        assert abs(m.error) <= 1.0 / fps + 1e-9, (path.name, m)
        if m.type == "gesture":
            u = stream.unit(m.behaviour, m.block)
            t = _ictus_of_gesture(stream, m.side, u["keys"]["strokeStart"], u["keys"]["strokeEnd"])
            assert abs(t - syncs[f"{m.block}:{m.behaviour}:stroke"]) <= 1.0 / fps + 1e-9


def test_nod_bottom_and_beat_ictus_on_a_sync_timed_example():
    r = realize((EXAMPLES / "testbeatandnod.xml").read_bytes())
    syncs = r.feedback.sync_times()
    stream = evaluate_poses(r, fps=60)
    pitch, _, _ = head_orientation(stream)
    t_nod = syncs["bml1:nod1:stroke"]
    near = (stream.times > t_nod - 0.15) & (stream.times < t_nod + 0.15)
    lowest = stream.times[near][np.argmax(pitch[near])]
    assert abs(lowest - t_nod) <= 1 / 60
    assert pitch[near].max() > 8.0  # a visible nod (degrees down)
    t_beat = syncs["bml1:beat1:stroke"]
    assert abs(_ictus_of_gesture(stream, "r", syncs["bml1:beat1:strokeStart"], syncs["bml1:beat1:strokeEnd"])
               - t_beat) <= 1 / 60


# --------------------------------------------------------------------------------------------- priority
def _writer_names(stream_or_manager, values_writers, dof: str, times: np.ndarray, t0: float, t1: float):
    manager = stream_or_manager
    names = manager.driver_names()
    col = manager.body.dof(dof)
    _, writers = values_writers
    sel = (times >= t0) & (times < t1)
    return {names.get(int(w)) for w in writers[sel, col]}


def test_a_nod_during_a_head_turn_takes_the_neck_and_hands_it_back():
    m = DriverManager(seed=1)
    turn = m.execute("headtowards", at=0.5, object="violins", approach=0.5, hold=3.0, retract=0.5)
    nod = m.execute("nod", at=1.5, amt=0.4, duration=1.0)
    times = np.arange(0, 300) / 60.0
    out = m.evaluate(times)
    nod_release = nod.release_time()
    # the turn lost the pitch DOFs when the nod started and got them back when the nod let go
    assert (1.5, "loss", ("vc4.pitch", "skullbase.pitch")) in turn.log
    assert (nod_release, "regain", ("vc4.pitch", "skullbase.pitch")) in turn.log
    assert _writer_names(m, out, "skullbase.pitch", times, 1.5, nod_release) == {nod.name}
    assert _writer_names(m, out, "skullbase.pitch", times, nod_release, 4.0) == {turn.name}
    assert _writer_names(m, out, "skullbase.pitch", times, 0.5, 1.5) == {turn.name}
    # the yaw stayed with the turn all along: the head kept facing the violins while nodding
    assert _writer_names(m, out, "skullbase.yaw", times, 0.5, 4.0) == {turn.name}
    values = out[0]
    yaw = values[:, m.body.dof("skullbase.yaw")] + values[:, m.body.dof("vc4.yaw")]
    during = (times > 1.5) & (times < nod_release)
    assert yaw[during].min() > 20.0  # the violins are to the left


def test_a_bml_nod_during_a_gaze_rides_on_the_gaze():
    bml = f"""<bml xmlns="{BML_NS}" id="b">
      <gaze id="look" target="violins" influence="NECK" start="0.5" ready="1.2" relax="4" end="4.5"/>
      <head id="nod" lexeme="NOD" start="2"/>
    </bml>"""
    r = realize(bml)
    stream = evaluate_poses(r, fps=60)
    syncs = r.feedback.sync_times()
    names = stream.driver_names
    col = stream.channels.index("skullbase.pitch")
    ycol = stream.channels.index("skullbase.yaw")
    t = stream.times
    during = (t >= syncs["b:nod:start"]) & (t < syncs["b:nod:relax"])
    after = (t >= syncs["b:nod:end"] + 0.05) & (t < syncs["b:look:relax"])
    assert {names[int(w)] for w in stream.writers[during, col]} == {"b:nod"}
    assert {names[int(w)] for w in stream.writers[during, ycol]} == {"b:look"}
    assert {names[int(w)] for w in stream.writers[after, col]} == {"b:look"}
    gaze = stream.manager.drivers[[d.name for d in stream.manager.drivers].index("b:look")]
    assert any(e == "loss" for _, e, _ in gaze.log) and any(e == "regain" for _, e, _ in gaze.log)


def test_a_blink_is_suppressed_while_a_stronger_driver_holds_the_eyelids():
    m = DriverManager(seed=3)
    m.blink.mean_interval = 0.8  # plenty of blinks
    stare = m.execute("eyelids", at=2.0, amount=0.0, approach=0.05, duration=5.0)
    times = np.arange(0, 10 * 60) / 60.0
    values, writers = m.evaluate(times)
    t_end = stare.keys.end
    executed, suppressed = m.blink.executed, m.blink.suppressed
    assert len(executed) > 3 and len(suppressed) > 3
    assert np.all((suppressed >= 2.0) & (suppressed < t_end))
    assert not np.any((executed >= 2.0) & (executed < t_end))
    lid = m.body.dof("l_eyelid.pitch")
    held = (times >= 2.0) & (times < t_end)
    assert set(writers[held, lid]) == {stare.uid}
    assert np.all(values[(times >= 2.1) & (times < t_end), lid] == 0.0)  # eyes wide open, no closure
    # outside the stare every blink closes the eyes
    for a in executed[executed < times[-1] - 0.2]:
        k = np.searchsorted(times, a + m.blink.close)
        assert values[k, lid] > 50.0
    assert (2.0, "loss", ("l_eyelid.pitch", "r_eyelid.pitch")) in m.blink.log
    assert (t_end, "regain", ("l_eyelid.pitch", "r_eyelid.pitch")) in m.blink.log


class _Rogue(Driver):
    def __init__(self, dof: str, twice: bool = False, other: str | None = None):
        super().__init__("rogue", 50, [dof])
        self.twice, self.other = twice, other

    def on_tick(self, t):
        self.write(self.dof_names[0], 1.0)
        if self.twice:
            self.write(self.dof_names[0], 2.0)
        if self.other:
            self.write(self.other, 3.0)


def test_a_dof_never_gets_two_writers():
    m = DriverManager(seed=0)
    m.add(_Rogue("skullbase.pitch", twice=True))
    with pytest.raises(ArbitrationError, match="twice"):
        m.evaluate(np.arange(10) / 60)
    m = DriverManager(seed=0)
    m.add(_Rogue("skullbase.pitch", other="skullbase.yaw"))
    with pytest.raises(ArbitrationError, match="holds"):
        m.evaluate(np.arange(10) / 60)


def test_every_value_of_a_long_block_has_at_most_one_writer(long_realizer, monkeypatch):
    seen: dict[tuple[int, int], int] = {}
    original = Arbitrator.write

    def counting(self, driver, d, values):
        key = (self._segment, d)
        seen[key] = seen.get(key, 0) + 1
        assert self.owner[d] is driver
        return original(self, driver, d, values)

    monkeypatch.setattr(Arbitrator, "write", counting)
    stream = evaluate_poses(long_realizer, fps=60, duration=30)
    assert seen and max(seen.values()) == 1
    assert set(np.unique(stream.writers)) <= set(stream.driver_names) | {-1}


def test_poses_told_a_stretch_at_a_time_are_the_frames_of_the_finished_stream(long_realizer):
    from agentsim.animation.output import PROGRESS_FRAMES

    told = []

    def progress(body, times, values):
        told.append((len(times), times.copy(), values.copy()))
        assert body.n_dofs == values.shape[1] and len(times) == len(values)

    stream = evaluate_poses(long_realizer, fps=60, duration=30.0, progress=progress)
    plain = evaluate_poses(long_realizer, fps=60, duration=30.0)
    counts = [n for n, _, _ in told]
    # the frames made so far from the first, each time at least PROGRESS_FRAMES more (the frames before a
    # segment of the animation are final once it begins); the last time, all of them
    assert counts[-1] == stream.n_frames and len(counts) >= stream.n_frames // (4 * PROGRESS_FRAMES)
    assert all(b - a >= PROGRESS_FRAMES for a, b in zip([0, *counts[:-2]], counts[:-1])), counts
    for n, times, values in told:
        np.testing.assert_array_equal(times, stream.times[:n])
        np.testing.assert_array_equal(values, stream.values[:n])
    for name in ("values", "writers", "positions", "times"):
        np.testing.assert_array_equal(getattr(stream, name), getattr(plain, name))


# --------------------------------------------------------------------------------------------- files
def test_bvh_of_a_30_second_block_reads_back_with_an_independent_reader(long_realizer, tmp_path):
    bvhio = pytest.importorskip("bvhio")
    stream = evaluate_poses(long_realizer, fps=60, duration=30.0)
    assert stream.n_frames == 30 * 60 + 1
    path = write_bvh(tmp_path / "long.bvh", stream)
    container = bvhio.readAsBvh(str(path))
    assert container.FrameCount == stream.n_frames
    assert container.FrameTime == pytest.approx(1 / 60, abs=1e-7)
    joints = []

    def walk(j):
        joints.append(j)
        for c in j.Children:
            walk(c)

    walk(container.Root)
    assert [j.Name for j in joints] == [j.name for j in stream.body.joints]
    assert list(container.Root.Channels) == ["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation",
                                             "Yrotation"]
    assert all(list(j.Channels) == ["Zrotation", "Xrotation", "Yrotation"] for j in joints[1:])
    assert sum(len(j.Channels) for j in joints) == len(stream.channels)
    # the numbers survive
    assert len(container.Root.Keyframes) == stream.n_frames
    k = 660
    root_pos = np.asarray(container.Root.Keyframes[k].Position)
    assert root_pos == pytest.approx(stream.values[k, :3], abs=1e-4)
    # the reader's own forward kinematics (its reading of the ZXY Euler channels) puts the joints where
    # ours does
    hierarchy = bvhio.readAsHierarchy(str(path))
    by_name = {j.Name: j for j, *_ in hierarchy.layout()}
    for k in (0, 660, 1014, 1660):
        hierarchy.loadPose(k)
        for name in ("r_wrist", "l_wrist", "skullbase", "l_eyeball", "l_ankle"):
            assert np.asarray(by_name[name].PositionWorld) == pytest.approx(stream.position(name)[k], abs=1e-4)


def test_npz_holds_angles_times_and_channel_names(long_realizer, tmp_path):
    stream = evaluate_poses(long_realizer, fps=30, duration=5.0)
    path = write_npz(tmp_path / "poses.npz", stream)
    data = np.load(path)
    assert data["values"].shape == (stream.n_frames, len(stream.channels))
    assert list(data["channels"]) == stream.channels
    assert np.array_equal(data["times"], stream.times)
    assert data["positions"].shape == (stream.n_frames, len(stream.joints), 3)
    assert float(data["fps"]) == 30.0


def test_the_recording_or_its_behaviour_records_play_like_the_realizer(long_realizer):
    recording = long_realizer.recording()
    a = evaluate_poses(long_realizer, fps=30, duration=10)
    b = evaluate_poses(list(recording.behaviours), fps=30, duration=10)
    c = evaluate_poses(recording, fps=30, duration=10)
    assert np.array_equal(a.values, b.values) and np.array_equal(a.values, c.values)
    assert a.units and a.units == c.units


def test_the_same_seed_gives_the_same_poses(long_realizer):
    a = evaluate_poses(long_realizer, fps=60, seed=7, duration=12)
    b = evaluate_poses(long_realizer, fps=60, seed=7, duration=12)
    c = evaluate_poses(long_realizer, fps=60, seed=8, duration=12)
    assert np.array_equal(a.values, b.values)
    assert np.array_equal(a.positions, b.positions)
    assert not np.array_equal(a.values, c.values)


def test_poses_evaluated_into_files_a_window_at_a_time_are_the_poses_evaluated_in_memory(long_realizer, tmp_path,
                                                                                         monkeypatch):
    """Evaluated into files with a window of 50 frames (many hand-overs, and segments longer than the
    window), the poses, their writers and positions, the BVH and the measured strokes are those of the
    stream evaluated in memory; the windows, rows and frames read back are the arrays'."""
    import agentsim.animation.output as output

    whole = evaluate_poses(long_realizer, fps=60, seed=3, duration=20)
    monkeypatch.setattr(output, "FK_ROWS", 50)
    stored = evaluate_poses(long_realizer, fps=60, seed=3, duration=20, folder=tmp_path / "poses")
    assert stored.files is not None and sorted(p.name for p in (tmp_path / "poses").iterdir()) == [
        "positions.npy", "values.npy", "writers.npy"]

    def named(stream, writers):  # driver uids count on from manager to manager: compare their names
        return np.vectorize(lambda uid: stream.driver_names.get(int(uid), ""))(writers)

    for name in ("values", "writers", "positions"):
        same = (lambda a, b: np.array_equal(named(stored, a), named(whole, b))) if name == "writers" else \
            np.array_equal
        assert same(getattr(stored, name), getattr(whole, name)), name
        blocks = list(stored.windows(name, rows=333))
        assert [a for a, _ in blocks] == list(range(0, whole.n_frames, 333))
        assert same(np.concatenate([b for _, b in blocks]), getattr(whole, name))
        assert same(stored.rows(name, 100, 250), getattr(whole, name)[100:250])
    frames = np.array([3, 4, 90, 700, whole.n_frames - 1])
    assert np.array_equal(stored.take("values", frames), whole.values[frames])
    assert np.array_equal(stored.position("r_wrist", frames), whole.position("r_wrist", frames))
    assert np.array_equal(stored.tracked("r_wrist"), whole.position("r_wrist"))
    assert np.array_equal(stored.tracked("r_elbow"), whole.position("r_elbow"))
    assert np.array_equal(stored.tracked("l_knee"), whole.position("l_knee"))  # not tracked: from the angles
    assert [np.array_equal(a, b) for a, b in zip(head_orientation(stored), head_orientation(whole))] == [True] * 3
    assert repr([m.as_dict() for m in measure_strokes(stored)]) == repr([m.as_dict() for m in measure_strokes(whole)])
    write_bvh(tmp_path / "a.bvh", whole)
    write_bvh(tmp_path / "b.bvh", stored)
    assert (tmp_path / "a.bvh").read_bytes() == (tmp_path / "b.bvh").read_bytes()


def test_a_manager_hands_its_frames_to_a_sink_in_order_and_keeps_none(long_realizer):
    """With a sink, the frames come in order, in windows of at least the window's size (but the last), and
    are the frames evaluate returns without one; nothing is returned."""
    from agentsim.animation.behaviours import build_drivers

    def manager():
        m = DriverManager(seed=5)
        build_drivers(m, list(long_realizer.recording().behaviours), None)
        return m

    times = np.arange(600) / 60.0
    values, writers = manager().evaluate(times)
    got = []
    assert manager().evaluate(times, sink=lambda a, v, w: got.append((a, v.copy(), w.copy())), window=64) is None
    assert [a for a, _, _ in got] == list(np.cumsum([0] + [len(v) for _, v, _ in got[:-1]]))
    assert all(len(v) >= 64 for _, v, _ in got[:-1]) and len(got) > 3
    assert np.array_equal(np.concatenate([v for _, v, _ in got]), values)
    assert np.array_equal(np.concatenate([w for _, _, w in got]) >= 0, writers >= 0)
