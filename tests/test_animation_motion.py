"""Motion units in detail: the skeleton and its kinematics, squeezed and stretched gestures, coarticulation,
conducting to a metronome, pointing, gaze, master/slave drivers, animator time and motor functions."""

from __future__ import annotations

import numpy as np
import pytest

from agentsim.animation import DriverManager, TimeSource, evaluate_poses, plot_timeline
from agentsim.animation.analysis import lowest, measure_strokes, pointing_arrival
from agentsim.animation.body import Body, euler_matrix, matrix_euler
from agentsim.animation.drivers import PRIORITY, Driver, SlaveDriver
from agentsim.animation.head import GazeDriver
from agentsim.animation.motion import KeyTimes, ReplacementGroup
from agentsim.realizer import Realizer

BML_NS = "http://www.bml-initiative.org/bml/bml-1.0"


def realize(bml: str, anticipators=()) -> Realizer:
    r = Realizer(anticipators=anticipators)
    r.submit(bml)
    r.run()
    assert not r.feedback.warnings(), r.feedback.warnings()
    return r


def block(body: str, bid: str = "b") -> str:
    return f'<bml xmlns="{BML_NS}" id="{bid}">{body}</bml>'


# --------------------------------------------------------------------------------------------- body
def test_dofs_are_named_and_channels_are_in_bvh_order():
    body = Body()
    assert body.channels[:6] == [("HumanoidRoot", c) for c in
                                 ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")]
    assert body.channels[body.dof("r_shoulder.yaw")] == ("r_shoulder", "Yrotation")
    assert body.channels[body.dof("skullbase.pitch")] == ("skullbase", "Xrotation")
    for joint in ("HumanoidRoot", "sacroiliac", "vl5", "vt10", "vc4", "skullbase", "l_eyeball", "r_eyelid",
                  "l_sternoclavicular", "r_shoulder", "l_elbow", "r_wrist", "l_fingers"):
        assert joint in body.joint
    with pytest.raises(KeyError, match="skullbase.pitch"):
        body.dof("head.nod")


def test_euler_angles_round_trip_through_matrices_even_at_gimbal_lock():
    rng = np.random.default_rng(0)
    roll, pitch, yaw = rng.uniform(-180, 180, 500), rng.uniform(-90, 90, 500), rng.uniform(-180, 180, 500)
    pitch[:50] = 90.0
    m = euler_matrix(roll, pitch, yaw)
    assert np.allclose(euler_matrix(*matrix_euler(m)), m, atol=1e-12)


def test_arm_ik_puts_the_wrist_on_the_target_and_fk_agrees():
    body = Body()
    rng = np.random.default_rng(1)
    for side in "lr":
        p = rng.uniform(-0.5, 0.5, (3000, 3))
        d = np.linalg.norm(p, axis=1)
        p = p[(d > 0.1) & (d < 0.54)]
        angles = body.arm_ik(side, p)
        assert np.allclose(body.arm_fk(side, angles), p, atol=1e-12)
        assert np.all(angles[f"{side}_elbow.pitch"] <= 0) and np.all(angles[f"{side}_elbow.pitch"] >= -160)
        # full forward kinematics from a pose built from the angles lands in the same place
        pose = np.tile(body.rest_pose(), (len(p), 1))
        for name, v in angles.items():
            pose[:, body.dof(name)] = v
        pose[:, body.dof(f"{side}_elbow.yaw")] = 0.0
        rot, shoulder = body.parent_frame(pose, f"{side}_shoulder")
        wrist = body.forward_kinematics(pose, [f"{side}_wrist"])[f"{side}_wrist"][1]
        assert np.allclose(np.einsum("nji,nj->ni", rot, wrist - shoulder), p, atol=1e-12)


def test_rest_pose_stands_on_the_ground():
    body = Body()
    fk = body.forward_kinematics(body.rest_pose()[None])
    eye = fk["l_eyeball"][1][0]
    assert 1.6 < eye[1] < 1.7 and eye[0] > 0  # +X is the character's left
    assert fk["r_wrist"][1][0][1] < fk["r_elbow"][1][0][1] < fk["r_shoulder"][1][0][1]


# --------------------------------------------------------------------------------------------- gestures
def _wrist(stream, side="r"):
    return stream.position(f"{side}_wrist")[:, 1]


@pytest.mark.parametrize("timing", [
    'start="1" stroke="1.15"',                                   # fast: squeezed preparation
    'start="1" strokeStart="1" stroke="1.2"',                    # no time to prepare at all
    'start="1" ready="1.3" strokeStart="2.6" stroke="2.8"',      # slow: long pre-stroke hold
    'start="1" stroke="1.5" strokeEnd="1.7" relax="3.5" end="3.8"',  # long post-stroke hold
])
def test_squeezed_and_stretched_beats_keep_the_ictus_on_the_stroke(timing):
    r = realize(block(f'<gesture id="g" lexeme="BEAT" mode="RIGHT_HAND" {timing}/>'))
    syncs = r.feedback.sync_times()
    for fps in (60, 120):
        stream = evaluate_poses(r, fps=fps)
        (m,) = measure_strokes(stream, syncs)
        assert abs(m.error) <= 1 / fps + 1e-9


def test_a_long_pre_stroke_hold_holds_the_hand_still():
    r = realize(block('<gesture id="g" lexeme="BEAT" mode="RIGHT_HAND" start="1" ready="1.4" '
                      'strokeStart="3" stroke="3.15"/>'))
    stream = evaluate_poses(r, fps=60)
    hold = (stream.times > 1.45) & (stream.times < 2.95)
    wrist = stream.position("r_wrist")[hold]
    assert np.ptp(wrist[:, 1]) < 0.01  # only breathing and sway move it
    assert wrist[:, 1].mean() > _wrist(stream)[0] + 0.15  # and it is up, ready to beat


def test_coarticulated_beats_on_one_hand_skip_the_retraction_between_them():
    r = realize(block('<gesture id="g1" lexeme="BEAT" mode="RIGHT_HAND" start="1" stroke="1.5" end="2.6"/>'
                      '<gesture id="g2" lexeme="BEAT" mode="RIGHT_HAND" start="1.8" stroke="2.3" end="3"/>'))
    syncs = r.feedback.sync_times()
    stream = evaluate_poses(r, fps=60)
    for m in measure_strokes(stream, syncs):
        assert abs(m.error) <= 1 / 60
    between = (stream.times > syncs["b:g1:stroke"]) & (stream.times < syncs["b:g2:stroke"])
    rest = _wrist(stream)[0]
    assert _wrist(stream)[between].min() > rest + 0.1  # the hand stayed up
    assert "coarticulated" in stream.unit("g2")["note"]


def test_gestures_without_a_mode_take_the_free_hand():
    r = realize(block('<gesture id="g1" lexeme="BEAT" mode="RIGHT_HAND" start="1" end="3"/>'
                      '<gesture id="g2" lexeme="BEAT" start="0.5" end="2.5"/>'))
    stream = evaluate_poses(r, fps=60)
    assert stream.unit("g1")["sides"] == ["r"] and stream.unit("g2")["sides"] == ["l"]
    both = realize(block('<gesture id="g" lexeme="OFFER" mode="BOTH_HANDS" start="1" end="2.5"/>'))
    s2 = evaluate_poses(both, fps=60)
    assert s2.unit("g")["sides"] == ["l", "r"]
    for m in measure_strokes(s2, both.feedback.sync_times()):
        assert abs(m.error) <= 1 / 60


def test_conducting_4_4_follows_the_metronome_through_a_tempo_change():
    from anticipators.metronome import Metronome

    metronome = Metronome("metronome", bpm=100, start=1.0)
    gestures = "".join(f'<gesture id="c{k}" lexeme="CONDUCT_4_4" mode="RIGHT_HAND" '
                       f'stroke="anticipators:metronome:beat{k}"/>' for k in range(1, 13))
    r = Realizer(anticipators=[metronome])
    r.submit(block(gestures))

    def faster():
        yield r.env.timeout(3.0)
        metronome.set_tempo(132)

    r.env.process(faster())
    r.run()
    syncs = r.feedback.sync_times()
    strokes = [syncs[f"b:c{k}:stroke"] for k in range(1, 13)]
    assert np.diff(strokes)[-1] == pytest.approx(60 / 132, abs=1e-6)
    for fps in (60, 120):
        stream = evaluate_poses(r, fps=fps)
        measured = measure_strokes(stream, syncs)
        assert len(measured) == 12
        assert max(abs(m.error) for m in measured) <= 1 / fps + 1e-9
    # the pattern: beat 2 inwards (to the character's left for the right hand), beat 3 outwards
    x = stream.position("r_wrist")[:, 0]
    at = {k: x[np.argmin(np.abs(stream.times - strokes[k - 1]))] for k in range(1, 5)}
    assert at[2] > at[1] > at[3]
    assert [stream.unit(f"c{k}")["note"].split()[-3] for k in range(1, 6)] == ["1", "2", "3", "4", "1"]


def test_pointing_reaches_the_target_at_the_stroke():
    r = realize(block('<pointing id="p" target="bluebox" start="1" end="4"/>'
                      '<pointing id="q" target="-0.1 1.2 0.35" mode="RIGHT_HAND" start="5" end="8"/>'))
    syncs = r.feedback.sync_times()
    stream = evaluate_poses(r, fps=60)
    assert stream.unit("p")["sides"] == ["l"]  # the blue box is on the left
    for m in measure_strokes(stream, syncs):
        assert abs(m.error) <= 1 / 60
    # a target within reach gets the wrist on it
    k = np.searchsorted(stream.times, syncs["b:q:stroke"] + 0.1)
    assert np.linalg.norm(stream.position("r_wrist")[k] - [-0.1, 1.2, 0.35]) < 1e-9
    # unknown targets fall back to a point ahead
    r2 = realize(block('<pointing id="p" target="nowhere" start="1" end="4"/>'))
    s2 = evaluate_poses(r2, fps=60)
    t = pointing_arrival(s2, s2.unit("p")["sides"][0], s2.unit("p")["target"], 1.0, 4.0)
    assert abs(t - r2.feedback.sync_times()["b:p:stroke"]) <= 1 / 60


def test_gaze_eyes_and_neck_reach_the_target_at_ready():
    r = realize(block('<gaze id="g" target="violins" influence="NECK" start="1" ready="1.6" relax="3" end="3.5"/>'))
    syncs = r.feedback.sync_times()
    stream = evaluate_poses(r, fps=60)
    target = np.array(stream.unit("g")["target"])
    eye = stream.position("l_eyeball")
    look = stream.forward("l_eyeball")
    to = target - eye
    off = np.degrees(np.arccos(np.clip(np.sum(look * to, 1) / np.linalg.norm(to, axis=1), -1, 1)))
    t = stream.times
    on = (t >= syncs["b:g:ready"] - 1e-9) & (t < syncs["b:g:relax"])
    assert off[on].max() < 1e-4
    assert off[(t > 1.0) & (t < syncs["b:g:ready"] - 0.05)].min() > 0.5
    first_on = t[np.argmax(off < 1e-4)]
    assert abs(first_on - syncs["b:g:ready"]) <= 1 / 60
    yaw = stream.channel("skullbase.yaw") + stream.channel("vc4.yaw")
    assert yaw[on].min() > 10.0  # the neck turned too


def test_replacement_group_keeps_only_the_latest_gaze():
    m = DriverManager(seed=0)
    group = ReplacementGroup("gaze")
    syncs = ("start", "ready", "relax", "end")
    a = m.add(GazeDriver("a", KeyTimes(syncs, [0.5, 1.0, 5.0, 5.5], [0, 0.3, 1.8, 2.1]),
                         m.scene.point("violins"), group=group))
    b = m.add(GazeDriver("b", KeyTimes(syncs, [2.0, 2.5, 3.0, 3.5], [0, 0.3, 1.8, 2.1]),
                         m.scene.point("cellos"), group=group))
    times = np.arange(0, 6 * 60) / 60
    values, writers = m.evaluate(times)
    col = m.body.dof("l_eyeball.yaw")
    assert a.stopped and not b.stopped
    after_b = (times > 3.6) & (times < 5.0)  # a does not come back: it was replaced
    assert a.uid not in set(writers[after_b, col]) and b.uid not in set(writers[after_b, col])
    assert set(writers[(times >= 2.0) & (times < 3.0), col]) == {b.eyes.uid}


class _Master(Driver):
    def __init__(self):
        super().__init__("master", PRIORITY["behaviour"], ["l_eyeball.pitch"])
        self.losses = []

    def on_tick(self, t):
        self.write("l_eyeball.pitch", 10.0 * np.sin(t))

    def on_dof_loss(self, dofs, t):
        self.losses.append((t, tuple(self.body.dof_names[d] for d in dofs)))


class _Usurper(Driver):
    def __init__(self):
        super().__init__("usurper", PRIORITY["command"], ["l_eyelid.pitch"])

    def setup(self):
        self.request(at=1.0)
        self.release(at=2.0)

    def on_tick(self, t):
        self.write("l_eyelid.pitch", 40.0)


def test_a_slave_follows_its_master_and_its_losses_reach_the_master():
    m = DriverManager(seed=0, background=False)
    master = m.add(_Master())
    slave = m.add(SlaveDriver("lid", master, {"l_eyelid.pitch": ("l_eyeball.pitch", 0.8, 0.0)}))
    m.add(_Usurper())
    assert slave.priority == master.priority
    times = np.arange(0, 180) / 60
    values, _ = m.evaluate(times)
    eye, lid = values[:, m.body.dof("l_eyeball.pitch")], values[:, m.body.dof("l_eyelid.pitch")]
    free = times < 1.0
    assert np.allclose(lid[free], 0.8 * eye[free])
    assert np.all(lid[(times >= 1.0) & (times < 2.0)] == 40.0)
    assert master.losses == [(1.0, ("l_eyelid.pitch",))]
    assert (2.0, "regain", ("l_eyelid.pitch",)) in slave.log


def test_eyelids_follow_the_eyes_down_between_blinks():
    m = DriverManager(seed=2)
    m.blink.turn(False, at=0.0)
    m.execute("saccade", at=1.0, target="down", hold=1.0)
    times = np.arange(0, 150) / 60
    values, _ = m.evaluate(times)
    eye, lid = values[:, m.body.dof("l_eyeball.pitch")], values[:, m.body.dof("l_eyelid.pitch")]
    k = np.searchsorted(times, 1.5)
    assert eye[k] > 15 and lid[k] == pytest.approx(0.8 * eye[k])
    assert len(m.blink.executed) == 0


def test_animator_time_moves_speech_pegged_strokes():
    bml = block('<speech id="s"><text>Hello there, <sync id="m"/>everybody in the hall.</text></speech>'
                '<gesture id="g" lexeme="BEAT" mode="RIGHT_HAND" stroke="s:m"/>')
    r = realize(bml)
    stroke = r.feedback.sync_times()["b:g:stroke"]
    late = TimeSource([0.0, 100.0], [-0.2, 99.8])  # the speech is 0.2 s behind the clock
    stream = evaluate_poses(r, fps=120, animator_time=late)
    keys = stream.unit("g")["keys"]
    t, _ = lowest(stream.times, stream.position("r_wrist")[:, 1], keys["strokeStart"] + 0.2, keys["strokeEnd"] + 0.2)
    assert t - stroke == pytest.approx(0.2, abs=1 / 120)
    on_clock = evaluate_poses(r, fps=120)
    (m,) = measure_strokes(on_clock, r.feedback.sync_times())
    assert abs(m.error) <= 1 / 120
    shifted = TimeSource.from_function(lambda x: x - 0.2)
    assert shifted(np.array([1.0, 2.0])) == pytest.approx([0.8, 1.8])
    assert shifted.inverse(1.0) == pytest.approx(1.2)
    again = evaluate_poses(r, fps=120, animator_time=shifted)
    assert np.allclose(again.values, stream.values)
    naive = TimeSource.from_events([0.0, 1.0, 2.5], [0.0, 1.0, 2.0], naive=True)
    assert naive(np.array([0.5, 1.5, 2.2, 2.5])) == pytest.approx([0.5, 1.5, 2.0, 2.0])


def test_motor_functions_have_names_and_defaults():
    m = DriverManager(seed=0)
    interface = m.interface()
    for name in ("beat", "point", "nod", "shake", "eyetrack", "gaze track", "saccade", "handshape", "keyframe",
                 "blinkreflex", "eyeblink", "breathing"):
        assert name in interface
    assert interface["nod"] == {"amt": 0.3, "duration": 1.0, "repeat": 1}
    with pytest.raises(KeyError):
        m.execute("juggle")
    with pytest.raises(TypeError):
        m.execute("nod", speed=2)
    beat = m.execute("beat", at=1.0, approach=0.4)
    wave = m.execute("keyframe", at=3.0, name="wave")
    m.execute("handshape", at=0.5, shape="fist", duration=0.5)
    track = m.execute("eyetrack", at=5.0, target="violins", duration=1.0)
    m.execute("breathing", at=2.0, rate=30)
    times = np.arange(0, 8 * 60) / 60
    values, writers = m.evaluate(times)
    wrist = m.body.positions(values, ["r_wrist", "r_shoulder"])
    k = int(np.argmin(np.abs(times - 1.4)))
    y = wrist[:, 0, 1]
    window = (times > 1.2) & (times < 1.6)
    assert abs(times[window][np.argmin(y[window])] - 1.4) <= 1 / 60 and k  # the beat's ictus at at+approach
    assert (wrist[(times > 3.6) & (times < 4.3), 0, 1] > wrist[(times > 3.6) & (times < 4.3), 1, 1]).all()
    assert m.body.dof("r_fingers.roll") in range(values.shape[1])
    assert set(writers[(times > 5.4) & (times < 6.0), m.body.dof("skullbase.yaw")]) == {track.uid}
    assert beat.uid in set(writers[:, m.body.dof("r_shoulder.pitch")]) and wave.uid in set(writers.ravel())


def test_a_replaced_block_stops_its_motion_and_hands_the_body_back(tmp_path):
    r = Realizer()
    r.submit_at(0.0, block('<gesture id="g" lexeme="BEAT" mode="RIGHT_HAND" start="0.2" stroke="1.5" end="3"/>'
                           '<head id="n" lexeme="NOD" start="0.2" repetition="4"/>', "one"))
    r.submit_at(0.8, f'<bml xmlns="{BML_NS}" id="two" composition="REPLACE"><head id="s" lexeme="SHAKE"/></bml>')
    r.run()
    stream = evaluate_poses(r, fps=60)
    assert stream.unit("g", "one")["stop"] == pytest.approx(0.8)
    late = stream.times > 1.5
    rest = _wrist(stream)[0]
    assert _wrist(stream)[late].max() < rest + 0.05  # the arm went back down: no stroke after the drop
    (m,) = measure_strokes(stream, r.feedback.sync_times())
    assert m.behaviour == "s" and abs(m.error) <= 1 / 60
    png = plot_timeline(r, tmp_path / "timeline.png", stream=stream)
    assert png.stat().st_size > 10_000
