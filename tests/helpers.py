"""Helpers the tests share: realise BML and look at the feedback; where the BML 1.0 examples are."""

from __future__ import annotations

from pathlib import Path

from agentsim.realizer import Realizer

# The BML 1.0 examples of the OpenBMLParser/AsapRealizer test suite (MIT licence, LICENSE-OpenBMLParser.txt),
# with their "Required timing" headers
EXAMPLES = Path(__file__).resolve().parent / "bml-examples"


class Result:
    """Feedback of one run, indexed for assertions."""

    def __init__(self, realizer: Realizer):
        self.realizer = realizer
        self.items = list(realizer.feedback.items)
        self.syncs = [f for f in self.items if f["type"] == "syncPointProgress"]
        self.local = {f["id"].split(":", 1)[1]: f["time"] for f in self.syncs}
        self.glob = {f["id"]: f["globalTime"] for f in self.syncs}
        self.warnings = [f for f in self.items if f["type"] == "warningFeedback"]
        self.blocks = [f for f in self.items if f["type"] == "blockProgress"]

    def t(self, name: str) -> float:
        """Block-relative time of ``behaviour:sync``."""
        return self.local[name]

    def dropped(self) -> set[str]:
        return {b for w in self.warnings for b in w["modifiedBehaviours"]}


def realize(*documents, at=None, until=None, **kwargs) -> Result:
    realizer = Realizer(**kwargs)
    times = at or [0.0] * len(documents)
    for t, doc in zip(times, documents):
        realizer.submit_at(t, doc)
    realizer.run(until=until)
    return Result(realizer)


def bvh_reader(path):
    """A BVH file as a reader (bvhio) reads it: the container, its joints by name, each joint's parent, and
    ``world(name, k)``: the joint's world rotation and position at frame k, its rotations and offsets
    composed from the root, independently of our own forward kinematics."""
    import bvhio
    import glm

    container = bvhio.readAsBvh(str(path))
    parent, by_name = {}, {}

    def walk(joint, up=None):
        by_name[joint.Name] = joint
        parent[joint.Name] = up
        for child in joint.Children:
            walk(child, joint)

    walk(container.Root)

    def world(name, k):
        j = by_name[name]
        if parent[name] is None:
            return j.Keyframes[k].Rotation, glm.vec3(j.Keyframes[k].Position)
        rot, pos = world(parent[name].Name, k)
        return rot * j.Keyframes[k].Rotation, pos + rot * glm.vec3(j.Offset)

    return container, by_name, parent, world


def bvh_positions(path, names: list[str]) -> dict:
    """World positions (frames, 3) of joints as a BVH reader reads the file (:func:`bvh_reader`)."""
    import numpy as np

    container, _, _, world = bvh_reader(path)
    return {name: np.array([list(world(name, k)[1]) for k in range(container.FrameCount)]) for name in names}


#: A conductor's configuration whose ensemble ignores the conductor and falls apart (it is stopped).
FALLS_APART = {
    "piece": {"title": "short", "meter": "4/4", "bars": 12, "tempo": 120.0},
    "ensemble": {"model": {"timekeeper_sd": 0.05, "alpha_partner": 0.0, "alpha_conductor": 0.0,
                           "beta_conductor": 0.0}}}


def whole_run_points(poses, recording, times):
    """What an evaluation of the whole run gives at ``times`` (s) for a :class:`~agentsim.live.poses.LivePoses`:
    world positions (frames, points, 3) of its skeleton's points, each time between the two frames of the
    ``k / fps`` grid around it (linearly, as the viewer draws it), the background's saccades and blinks those
    the live poses drew (:class:`~agentsim.live.poses.Liveliness`)."""
    import numpy as np

    from agentsim.animation import evaluate_poses
    from agentsim.animation.manager import DriverManager
    from agentsim.media.report.data import body_points

    times = np.asarray(times, dtype=float)
    n = int(np.ceil(times.max() * poses.fps)) + 2
    grid = np.arange(n) / poses.fps
    manager = DriverManager(body=poses.body, seed=poses.seed)
    poses.liveliness.pin(manager, 0.0, grid[-1] + 1.0)
    points = body_points(poses.body, evaluate_poses(recording, fps=poses.fps, manager=manager, times=grid).values)
    flat = points.reshape(n, -1)
    out = np.stack([np.interp(times, grid, flat[:, q]) for q in range(flat.shape[1])], axis=1)
    return out.reshape(len(times), -1, 3)
