"""Helpers the tests share: realize BML and look at the feedback; where the BML 1.0 examples are."""

from __future__ import annotations

import json
import os
import time
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


# ------------------------------------------------------------------------------------------------ sweeps
#: A short text: a point of 'eval speech-sync --tts builtin' on it takes some 60 ms.
SWEEP_TEXT = ("The clock on the wall struck nine while the old man counted coins beside the window and hummed "
              "a quiet tune.\n")
#: The 12-point grid of the sweep tests (the spec's order: the last key varies fastest).
SWEEP_GRID = {"strategy": ["best", "chang-naive"], "seed": [1, 2, 3], "jitter": [0.03, 0.1]}
#: Figures that are wall-clock times, not results: they differ from run to run.
WALL_CLOCK = {"wall_seconds"}


def write_sweep_spec(folder, grid=None, text=SWEEP_TEXT, extra="") -> "Path":
    """A spec of 'eval speech-sync' with the built-in backend (deterministic, unlike espeak-ng across calls
    in one process) on a short text in ``folder``."""
    import json

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if text is not None:
        (folder / "story.txt").write_text(text)
    lines = ['command = ["eval", "speech-sync"]', "[grid]"]
    lines += [f"{key} = {json.dumps(values)}" for key, values in (grid or SWEEP_GRID).items()]
    lines += ["[fixed]", 'tts = "builtin"', 'text = "story.txt"', extra]
    path = folder / "spec.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def sweep_points(grid=None) -> list[dict]:
    """The points of a grid, in the order a sweep lists them."""
    import itertools

    grid = grid or SWEEP_GRID
    return [dict(zip(grid, values)) for values in itertools.product(*grid.values())]


def run_alone(folder, points: list[dict], timeout: float = 300.0) -> list[dict]:
    """Each point as its own 'agentsim eval speech-sync ... --json' process (two at a time); their JSON."""
    import json
    import subprocess
    import sys

    root = Path(__file__).resolve().parent.parent
    results: list = [None] * len(points)
    queue = list(enumerate(points))
    while queue:
        batch, queue = queue[:2], queue[2:]
        running = []
        for index, point in batch:
            argv = ["eval", "speech-sync", "--tts", "builtin", "--text", str(Path(folder) / "story.txt"), "--json"]
            for key, value in point.items():
                argv += [f"--{key}", str(value)]
            running.append((index, subprocess.Popen([sys.executable, "-m", "agentsim", *argv], cwd=root,
                                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)))
        for index, proc in running:
            out, err = proc.communicate(timeout=timeout)
            assert proc.returncode == 0, err
            results[index] = json.loads(out)
    return results


def flat_json(value, prefix: str = "") -> dict:
    """Nested JSON objects as one level of dotted keys (the tests' own reading of a row's columns)."""
    flat = {}
    for key, item in value.items():
        if isinstance(item, dict):
            flat.update(flat_json(item, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = item
    return flat


def row_differences(row: dict, alone: dict, grid_keys) -> list[str]:
    """Where a sweep's row differs from the JSON of the same point run alone (wall-clock times aside); a
    figure named like a grid key is in the row as ``result.<name>``."""
    found = []
    for key, value in flat_json(alone).items():
        column = f"result.{key}" if key in grid_keys else key
        if key in WALL_CLOCK:
            continue
        if column not in row:
            found.append(f"{column} missing")
        elif row[column] != value:
            found.append(f"{column}: {row[column]!r} != {value!r}")
    return found


def receive(ws, done, timeout: float = 10.0) -> list[tuple[float, dict]]:
    """(arrival on time.monotonic(), message) on a websockets client until ``done(message)``, or an
    AssertionError after ``timeout`` seconds."""
    got = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            message = json.loads(ws.recv(timeout=0.2))
        except TimeoutError:
            continue
        got.append((time.monotonic(), message))
        if done(message):
            return got
    raise AssertionError(f"timed out after {len(got)} messages")


def counted(server, name: str, at_least: int = 1):
    """A ``threading.Event`` set (with the ``time.monotonic()`` it happened at in its ``at``) once the live
    server's counter ``name`` is at least ``at_least``: a test waits on it instead of polling."""
    import threading

    reached = threading.Event()
    reached.at = None

    def listener(key: str, value: int) -> None:
        if key == name and value >= at_least and not reached.is_set():
            reached.at = time.monotonic()
            reached.set()

    server.counters.listeners.append(listener)
    listener(name, server.counters[name])
    return reached


# ------------------------------------------------------------------------------------------------ BVH
class BvhFk:
    """A BVH file read and composed here, from its text alone (not the project's kinematics nor a BVH
    library): each joint's offset, channels and End Site, and every frame's world positions of joints and
    end sites (``Zrotation Xrotation Yrotation`` channels compose as R = Rz Rx Ry, in degrees)."""

    def __init__(self, path):
        import numpy as np

        words = open(path).read().split()
        self.names, self.parent, self.offset, self.channels, self.site = [], {}, {}, {}, {}
        stack, i, last = [], 0, None
        while words[i] != "MOTION":
            w = words[i]
            if w in ("ROOT", "JOINT"):
                last = words[i + 1]
                self.names.append(last)
                self.parent[last] = stack[-1] if stack else None
                i += 2
            elif w == "End":
                last = ("site", stack[-1])
                i += 2
            elif w == "{":
                stack.append(last)
                i += 1
            elif w == "}":
                stack.pop()
                i += 1
            elif w == "OFFSET":
                v = np.array([float(x) for x in words[i + 1:i + 4]])
                if isinstance(stack[-1], tuple):
                    self.site[stack[-1][1]] = v
                else:
                    self.offset[stack[-1]] = v
                i += 4
            elif w == "CHANNELS":
                n = int(words[i + 1])
                self.channels[stack[-1]] = words[i + 2:i + 2 + n]
                i += 2 + n
            else:
                i += 1
        frames = int(words[i + 2])
        self.frame_time = float(words[i + 5])
        data = np.array([float(x) for x in words[i + 6:]]).reshape(frames, -1)
        self.frames = frames
        self.column = {}
        k = 0
        for name in self.names:
            for c in self.channels[name]:
                self.column[(name, c)] = k
                k += 1
        self.data = data
        self.world = self._compose()

    def _compose(self):
        import numpy as np

        def axis(angle, which):
            a = np.radians(angle)
            c, s = np.cos(a), np.sin(a)
            m = np.zeros((len(a), 3, 3))
            i, j = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[which]
            k = 3 - i - j
            m[:, k, k] = 1
            m[:, i, i], m[:, i, j], m[:, j, i], m[:, j, j] = c, -s, s, c
            return m

        out = {}
        for name in self.names:
            rot = np.tile(np.eye(3), (self.frames, 1, 1))
            pos = np.zeros((self.frames, 3))
            for c in self.channels[name]:
                col = self.data[:, self.column[(name, c)]]
                if c.endswith("position"):
                    pos[:, "XYZ".index(c[0])] = col
                else:
                    rot = rot @ axis(col, c[0])
            up = self.parent[name]
            if up is None:
                out[name] = (rot, pos + self.offset[name])
            else:
                prot, ppos = out[up]
                out[name] = (prot @ rot, ppos + prot @ self.offset[name])
        return out

    def position(self, name):
        """World positions (frames, 3) of a joint, or of a joint's End Site as ``name.end``."""
        if name.endswith(".end"):
            joint = name[:-4]
            rot, pos = self.world[joint]
            return pos + rot @ self.site[joint]
        return self.world[name][1]

    def time(self, t: float) -> int:
        """The frame at time t (s)."""
        return int(round(t / self.frame_time))


def open_run_report(bml: str, browser, path, fps: int = 60):
    """Realize ``bml`` with the built-in timing model, write its run report to ``path`` and open it in
    ``browser`` (headless Chromium) until it is ready; returns the realizer, its recording and the poses."""
    from agentsim.animation import evaluate_poses
    from agentsim.media.report import write_report
    from agentsim.media.report.browser import open_report
    from speech_timing.builtin import BuiltinBackend

    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(bml)
    realizer.run()
    recording = realizer.recording()
    stream = evaluate_poses(recording, fps=fps)
    open_report(write_report(path, recording=recording, stream=stream), browser)
    return realizer, recording, stream


def seek_drawn(browser, t: float) -> None:
    """Seek the open report to ``t`` and wait until the page has drawn that time (two animation frames)."""
    browser.evaluate(f"report.seek({t!r})")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", await_promise=True)


# ------------------------------------------------------------------------------------------------ renders
#: Where renders the tests share are kept between runs (outside the checkout).
RENDERS = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "agentsim" / "test-renders"


def cached_render(make, *args, **kwargs):
    """``make(*args, **kwargs)`` (an ensemble's render: audio and its true beats), rendered once per test run
    and machine and read back from :data:`RENDERS` after that. The key holds the function's name, its
    arguments and the source of ``agentsim.music`` (a change of the renderer renders anew); test processes
    running side by side wait for each other's render rather than make it twice."""
    import fcntl
    import hashlib
    import pickle

    import agentsim.music

    music = Path(agentsim.music.__file__).parent
    key = hashlib.sha256(repr((make.__module__, make.__qualname__, args, sorted(kwargs.items()))).encode())
    for source in sorted(music.rglob("*.py")):
        key.update(source.read_bytes())
    RENDERS.mkdir(parents=True, exist_ok=True)
    path = RENDERS / f"{make.__name__}-{key.hexdigest()[:20]}.pickle"
    with open(RENDERS / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if path.exists():
            with open(path, "rb") as f:
                return pickle.load(f)
        made = make(*args, **kwargs)
        scratch = path.with_suffix(f".{os.getpid()}.tmp")
        with open(scratch, "wb") as f:
            pickle.dump(made, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(scratch, path)
        return made


def fenced_blocks(path, languages=("sh", "python")) -> list[tuple[str, int, str]]:
    """The fenced blocks of a Markdown page marked with one of ``languages``, in order: (language, the line of
    its first command, its text). A block marked otherwise (```text, ```console, ```toml, ...) is only shown."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    found = []
    for number, line in enumerate(lines, 1):
        if line.startswith("```") and line[3:].strip() in languages:
            end = lines.index("```", number)
            found.append((line[3:].strip(), number + 1, "\n".join(lines[number:end]) + "\n"))
    return found
