"""The physical body: the MuJoCo model is the skeleton (same joints, offsets and rotation order), with de
Leva's masses; mixed dynamics keeps the kinematic joints on the animation and a standing body on its feet."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from agentsim.animation.body import Body
from agentsim.physics.controllers import controller_spec, default_balance
from agentsim.physics.model import MASS, build_model, inertial, simulated_joints
from agentsim.physics.simulation import Push, simulate

BODY = Body()


def test_the_model_weighs_the_body_and_has_a_hinge_for_every_axis_a_joint_turns():
    model, layout = build_model(BODY, 0.001)
    assert math.isclose(float(np.sum(model.body_mass)), MASS, rel_tol=1e-9)
    joints = simulated_joints(BODY)
    assert len(joints) == 20 and "l_index1" not in joints and "temporomandibular" not in joints
    # three hinges a joint, but for the axes the skeleton never turns: the knees' and elbows' roll, the wrists' yaw
    # and the clavicles, which turn as animated
    assert model.nv == 6 + 3 * (len(joints) - 1) - 6 - 6
    assert [layout.qpos[j].count(-1) for j in ("l_knee", "r_elbow", "l_wrist", "l_hip", "r_sternoclavicular")] == [
        1, 1, 1, 0, 3]
    # de Leva 1996: the thigh is 14.16 % of the body mass, its centre 40.95 % of the way to the knee
    mass, com, _ = inertial(BODY, "l_hip")
    assert math.isclose(mass, 0.1416 * MASS) and math.isclose(com[1], 0.4095 * -0.42)


def test_the_model_turns_its_joints_as_the_skeleton_does():
    model, layout = build_model(BODY, 0.001)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(3)
    pose = BODY.rest_pose()
    for name in joints_of(layout):
        for col in BODY.rotation_columns[name]:
            pose[col] = rng.uniform(-40, 40)
    pose[list(BODY.rotation_columns["HumanoidRoot"])] = (10.0, -20.0, 30.0)
    data.qpos[0:3] = pose[list(BODY.translation_columns)]
    rot = BODY.forward_kinematics(pose[None], ["HumanoidRoot"])["HumanoidRoot"][0][0]
    mujoco.mju_mat2Quat(data.qpos[3:7], rot.ravel())
    for name in joints_of(layout):
        for address, col in zip(layout.qpos[name], BODY.rotation_columns[name]):
            if address < 0:  # an axis the skeleton never turns
                pose[col] = 0.0
            else:
                data.qpos[address] = np.radians(pose[col])
    mujoco.mj_kinematics(model, data)
    fk = BODY.forward_kinematics(pose[None])
    for name in layout.joints:
        np.testing.assert_allclose(data.xpos[layout.body_id[name]], fk[name][1][0], atol=1e-9)
        np.testing.assert_allclose(data.xmat[layout.body_id[name]].reshape(3, 3), fk[name][0][0], atol=1e-9)


def joints_of(layout):
    return layout.joints[1:]


def _standing(seconds: float, controllers, pushes=()):
    fps = 60.0
    n = int(seconds * fps) + 1
    times = np.arange(n) / fps
    values = np.tile(BODY.rest_pose(), (n, 1))
    nod = BODY.dof("skullbase.pitch")
    values[:, nod] = 15.0 * np.sin(2 * np.pi * times)
    out = np.empty_like(values)

    def sink(k, pose):
        out[k] = pose

    result = simulate(BODY, fps, times, lambda a, b: values[a:b], controllers, list(pushes), sink)
    return values, out, np.array(result.rows), result


def test_a_standing_body_keeps_its_feet_and_the_kinematic_joints_their_angles():
    values, out, rows, result = _standing(1.0, [default_balance()])
    assert result.fell_at is None and rows[:, 10].max() == 0
    kinematic = [BODY.dof(f"{j}.{a}") for j in ("skullbase", "vc4", "l_shoulder", "r_elbow", "l_index2")
                 for a in ("roll", "pitch", "yaw")]
    np.testing.assert_array_equal(out[:, kinematic], values[:, kinematic])  # physics never moves them
    assert np.all(np.abs(rows[:, 9] - 0.90) < 0.005)  # the pelvis stays at its height


@pytest.mark.parametrize("cls, params, message", [
    ("Balance", {}, "unknown controller class 'Balance'"),
    ("HangController", {"part": "tail"}, "unknown part 'tail'"),
    ("BalanceController", {"kpp": "3"}, "unknown parameter 'kpp'"),
    ("JointController", {"l_elbow.pitch": "x"}, "is not a number"),
])
def test_a_controller_that_is_not_known_is_refused_by_name(cls, params, message):
    with pytest.raises(ValueError, match=message):
        controller_spec(cls, params)


def test_a_hanging_arm_drops_under_gravity_and_returns_to_the_animation_without_a_jump():
    hang = controller_spec("HangController", {"part": "left_arm"})
    hang.start, hang.end = 0.2, 0.7
    values, out, rows, result = _standing(1.2, [default_balance(), hang], [Push(0.3, (0.0, 0.0, 100.0), 0.1)])
    roll = BODY.dof("l_shoulder.roll")
    assert abs(out[int(0.6 * 60), roll]) < 2.0 < values[0, roll]  # hung from its 6 degrees of abduction
    assert np.abs(np.diff(out[:, roll])).max() < 1.0  # no jump a frame, taking over or giving back
    assert out[-1, roll] == values[-1, roll]  # back on the animation once the transition is over


def test_a_joint_controller_and_a_lower_pelvis_are_reached_smoothly_and_given_back():
    squat = controller_spec("BalanceController", {"pelvis_height": "0.8"})
    squat.start, squat.end = 0.3, 1.3
    elbow = controller_spec("JointController", {"l_elbow.pitch": "-90"})
    elbow.start, elbow.end = 0.3, 1.3
    under = default_balance()
    under.start = -math.inf
    values, out, rows, result = _standing(2.0, [under, squat, elbow])
    assert result.fell_at is None
    at = {t: int(round(t * 60)) for t in (1.2, 2.0)}
    assert abs(rows[at[1.2], 9] - 0.8) < 0.015 and abs(rows[at[2.0], 9] - 0.90) < 0.005
    pitch = BODY.dof("l_elbow.pitch")
    assert abs(out[at[1.2], pitch] + 90.0) < 1.5 and out[at[2.0], pitch] == values[at[2.0], pitch]
    assert np.abs(np.diff(out[:, pitch])).max() < 8.0 and np.abs(np.diff(rows[:, 9])).max() < 0.01


def test_the_kinematic_arms_motion_pushes_the_physical_trunk():
    fps, n = 60.0, 61
    times = np.arange(n) / fps

    def run(raise_arms: bool):
        values = np.tile(BODY.rest_pose(), (n, 1))
        if raise_arms:  # both arms swing forward to the horizontal in 0.3 s from 0.5 s
            u = np.clip((times - 0.5) / 0.3, 0.0, 1.0)
            for side in "lr":
                values[:, BODY.dof(f"{side}_shoulder.pitch")] = -90.0 * u * u * (3 - 2 * u)
        out = np.empty_like(values)
        simulate(BODY, fps, times, lambda a, b: values[a:b], [default_balance()], [],
                 lambda k, pose: out.__setitem__(k, pose))
        return values, out

    _, still = run(False)
    values, swung = run(True)
    tz, arm = BODY.dof("HumanoidRoot.tz"), BODY.dof("l_shoulder.pitch")
    k = int(0.6 * fps)
    assert still[k, tz] - swung[k, tz] > 0.01  # the arms' reaction drives the pelvis back
    np.testing.assert_array_equal(swung[:, arm], values[:, arm])


def test_an_unstable_simulation_is_said_once_and_mujoco_writes_no_log(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    values, out, rows, result = _standing(0.3, [default_balance()], [Push(0.1, (0.0, float("nan"), 0.0), 0.05)])
    assert result.unstable_at == pytest.approx(7 / 60) and "unstable" in result.unstable
    assert len(rows) == len(values) and list(tmp_path.iterdir()) == []


def test_the_physics_runs_inside_the_frame_loop_the_same_in_memory_and_in_files(tmp_path):
    from agentsim.animation import evaluate_poses
    from agentsim.physics.run import PhysicalManager, run_controllers
    from agentsim.realizer import Realizer
    from speech_timing.builtin import BuiltinBackend

    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1">'
                    '<head id="h1" lexeme="NOD" start="0.2" end="0.8"/></bml>')
    realizer.run()
    pushes = [Push(0.3, (0.0, 0.0, 150.0), 0.2)]

    told = []  # what the progress of an in-memory run was told: the frames made so far, each time

    def physical(folder, progress=None, process=None):
        manager = PhysicalManager(run_controllers(realizer), pushes, fps=60.0, seed=0, progress=progress,
                                  process=process)
        stream = evaluate_poses(realizer, fps=60.0, manager=manager, folder=folder)
        return stream, manager.result

    memory, result = physical(None)
    files, _ = physical(tmp_path / "poses")
    plain = evaluate_poses(realizer, fps=60.0)
    np.testing.assert_array_equal(np.asarray(files.values), memory.values)
    from agentsim.physics.process import PhysicsProcess
    from agentsim.physics.run import PROGRESS_FRAMES

    for process in (None, PhysicsProcess()):  # simulated on this thread, or apart while the animation goes on
        told.clear()
        followed, apart = physical(None, lambda body, times, values: told.append((body, times.copy(),
                                                                                  values.copy())), process)
        np.testing.assert_array_equal(followed.values, memory.values)  # told or not, apart or not: the same
        assert apart.rows == result.rows
        # told each time PROGRESS_FRAMES frames or more were made, and of every frame at the end; each time
        # the frames made so far, the same as those of the run in files
        made = [len(times) for _, times, _ in told]
        assert len(told) >= 2 and made[-1] == memory.n_frames
        assert all(b - a >= PROGRESS_FRAMES for a, b in zip(made[:-2], made[1:-1])) and made[-1] > made[-2]
        for body, times, values in told:
            assert body is followed.body
            np.testing.assert_array_equal(times, memory.times[:len(times)])
            np.testing.assert_array_equal(values, memory.values[:len(times)])
    def named(stream):  # driver uids count on from run to run: compare the drivers' names
        names = {**stream.driver_names, -1: ""}
        return np.vectorize(names.get)(np.asarray(stream.writers))

    np.testing.assert_array_equal(named(files), named(plain))
    assert len(result.rows) == plain.n_frames == memory.n_frames
    nod = BODY.dof("skullbase.pitch")
    np.testing.assert_array_equal(memory.values[:, nod], plain.values[:, nod])
    pelvis = memory.position("HumanoidRoot")[:, 2] - plain.position("HumanoidRoot")[:, 2]
    assert pelvis.max() > 0.005  # the tracked positions are the pushed body's


def test_the_physical_bodys_process_says_what_went_wrong_and_ends_when_its_parent_goes():
    from agentsim.physics.process import PhysicsProcess

    process = PhysicsProcess()  # frames of the wrong shape: the child's failure is raised where frames are taken
    process.start(BODY, 60.0, np.arange(10) / 60.0, [default_balance()], [])
    process.feed(np.zeros((10, 3)))
    process._process.join(timeout=30)  # (it has failed and ended: what is sent now finds no reader)
    with pytest.raises(RuntimeError, match="the physical body's simulation failed: IndexError"):
        process.feed(np.zeros((10, 3)))
    process.close()
    assert process._process.exitcode == 0
    gone = PhysicsProcess()  # a parent that goes without a word: the child sees its end of the pipe close
    gone._connection.close()
    gone._process.join(timeout=30)
    assert gone._process.exitcode == 0
