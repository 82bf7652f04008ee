"""Poses out: evaluate a realized plan into a PoseStream, and write it as BVH or npz.

``evaluate_poses`` takes the recording of a run (:class:`~agentsim.core.recording.Recording`, or anything
with a ``recording()`` method, such as a realizer after ``run()``), builds the drivers that play each
behaviour on top of the background drivers, and
evaluates the pose at every frame. ``write_bvh`` writes a BVH file (HIERARCHY with OFFSET/CHANNELS in
metres and Euler degrees in ZXY order, MOTION with Frames / Frame Time) that Blender's importer reads;
``write_npz`` the same numbers as numpy arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from agentsim.animation.behaviours import build_drivers
from agentsim.animation.body import FK_ROWS, Body
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.manager import DriverManager
from agentsim.animation.time_source import TimeSource
from agentsim.written import written

#: Joints whose world positions a PoseStream carries for every frame.
TRACKED_JOINTS = ("HumanoidRoot", "vt10", "skullbase", "l_eyeball", "r_eyeball", "l_shoulder", "r_shoulder",
                  "l_elbow", "r_elbow", "l_wrist", "r_wrist", "l_fingers", "r_fingers")
#: How many frames :func:`evaluate_poses` makes between two calls of its ``progress`` (about 4 s at 60 fps).
PROGRESS_FRAMES = 256


class FrameFile:
    """A ``.npy`` file of per-frame rows (``shape`` = frames x ...), written in order a block of frames at a
    time and read back a stretch of frames at a time by plain reads (a mapping of the whole file would
    count every page read against the process's memory until it is unmapped)."""

    def __init__(self, path: str | Path, shape: tuple[int, ...], dtype) -> None:
        self.path = Path(path)
        self.shape = tuple(int(x) for x in shape)
        self.dtype = np.dtype(dtype)
        self.row_size = int(np.prod(self.shape[1:], dtype=np.int64))
        self._file = open(self.path, "wb")
        np.lib.format.write_array_header_1_0(self._file, {"descr": np.lib.format.dtype_to_descr(self.dtype),
                                                          "fortran_order": False, "shape": self.shape})
        self.offset = self._file.tell()
        self.written = 0

    def append(self, block: np.ndarray) -> None:
        """Write the next frames (rows of ``shape[1:]``)."""
        block = np.ascontiguousarray(block, dtype=self.dtype)
        if block.shape[1:] != self.shape[1:] or self.written + len(block) > self.shape[0]:
            raise ValueError(f"{self.path}: a block of shape {block.shape} does not fit {self.shape}")
        self._file.write(block.tobytes())
        self.written += len(block)

    def close(self, check: bool = True) -> None:
        """Finish writing; ValueError if not every frame was written (unless ``check`` is false)."""
        self._file.close()
        if check and self.written != self.shape[0]:
            raise ValueError(f"{self.path}: {self.written} of {self.shape[0]} frames written")

    def read(self, first: int, last: int) -> np.ndarray:
        """Frames ``first .. last - 1``."""
        first, last = max(0, int(first)), min(self.shape[0], int(last))
        count = max(0, last - first)
        data = np.fromfile(self.path, dtype=self.dtype, count=count * self.row_size,
                           offset=self.offset + first * self.row_size * self.dtype.itemsize)
        return data.reshape((count,) + self.shape[1:])

    def mapped(self) -> np.ndarray:
        """The whole array, the file mapped read-only into memory."""
        return np.load(self.path, mmap_mode="r")


@dataclass
class PoseStream:
    """Poses at frame times: joint angles (degrees) and root translation (metres) per frame, and the
    world positions (metres) of a few joints.

    ``channels`` names the columns of ``values`` (DOF names such as ``"r_shoulder.yaw"``, in BVH channel
    order); ``writers`` holds, per value, the uid of the driver that wrote it (``driver_names`` maps uids
    to names; -1: nobody held the DOF). ``units`` describes what became of each behaviour.
    """

    times: np.ndarray
    channels: list[str]
    values: np.ndarray
    joints: list[str]
    positions: np.ndarray
    fps: float
    body: Body
    writers: np.ndarray | None = None
    driver_names: dict[int, str] = field(default_factory=dict)
    units: list[dict] = field(default_factory=list)
    seed: int | None = None
    manager: DriverManager | None = field(default=None, repr=False)
    #: where ``values``, ``writers`` and ``positions`` live when they were evaluated into files
    #: (:func:`evaluate_poses` with ``folder``; the arrays are then the files mapped into memory)
    files: dict[str, FrameFile] | None = field(default=None, repr=False)

    def rows(self, name: str, first: int, last: int) -> np.ndarray:
        """Frames ``first .. last - 1`` of ``values``, ``writers`` or ``positions`` (``name``), read from
        the file when the stream lives in files."""
        if self.files is not None:
            return self.files[name].read(first, last)
        return getattr(self, name)[max(0, first):last]

    def windows(self, name: str = "values", rows: int = FK_ROWS) -> Iterator[tuple[int, np.ndarray]]:
        """``(first frame, frames)`` of ``values``, ``writers`` or ``positions`` in order, ``rows`` frames at
        a time (a long stream is never held whole when it lives in files)."""
        for a in range(0, self.n_frames, rows):
            yield a, self.rows(name, a, a + rows)

    def take(self, name: str, frames: np.ndarray) -> np.ndarray:
        """The frames (increasing indices) ``frames`` of ``values``, ``writers`` or ``positions``."""
        frames = np.asarray(frames, dtype=np.intp)
        if self.files is None:
            return getattr(self, name)[frames]
        if len(frames) == 0:
            return self.files[name].read(0, 0)
        first = int(frames[0])
        return self.files[name].read(first, int(frames[-1]) + 1)[frames - first]

    def tracked(self, joint: str) -> np.ndarray:
        """World positions (frames, 3) of a joint over every frame, as :meth:`position` gives them but a copy
        made a window of frames at a time (from the files when the stream lives in files)."""
        if self.files is None:
            return np.array(self.position(joint))
        out = np.empty((self.n_frames, 3))
        if joint in self.joints:
            k = self.joints.index(joint)
            for a, block in self.windows("positions"):
                out[a:a + len(block)] = block[:, k]
        else:
            for a, block in self.windows():
                out[a:a + len(block)] = self.body.forward_kinematics(block, [joint])[joint][1]
        return out

    @property
    def n_frames(self) -> int:
        return len(self.times)

    @property
    def frame_time(self) -> float:
        return 1.0 / self.fps

    def channel(self, name: str) -> np.ndarray:
        """Values of one DOF over all frames."""
        return self.values[:, self.channels.index(name)]

    def position(self, joint: str, frames: np.ndarray | None = None) -> np.ndarray:
        """World positions (frames, 3) of a tracked joint (or of any joint, computed on demand), of every
        frame or of the frames (indices) given."""
        if joint in self.joints:
            if frames is None:
                return self.positions[:, self.joints.index(joint)]
            return self.take("positions", frames)[:, self.joints.index(joint)]
        values = self.values if frames is None else self.take("values", frames)
        return self.body.forward_kinematics(values, [joint])[joint][1]

    def forward(self, joint: str) -> np.ndarray:
        """World direction (frames, 3) of a joint's local +Z axis (where the face or an eye points)."""
        rot = self.body.forward_kinematics(self.values, [joint])[joint][0]
        return rot[:, :, 2]

    def writer(self, frame: int, dof: str) -> str | None:
        uid = int(self.writers[frame, self.channels.index(dof)]) if self.writers is not None else -1
        return self.driver_names.get(uid) if uid >= 0 else None

    def unit(self, behaviour_id: str, block_id: str | None = None) -> dict | None:
        for u in self.units:
            if u["id"] == behaviour_id and (block_id is None or u["block"] == block_id):
                return u
        return None


def records_of(source) -> list:
    """The behaviour records of a run: ``source`` is a Recording, something with a ``recording()`` method
    (a realizer), or an iterable of :class:`~agentsim.core.recording.BehaviourRecord`."""
    if hasattr(source, "recording"):
        source = source.recording()
    return list(source)


def lexicon_of(source) -> Lexicon:
    """What the lexemes of a run play: the lexicon of a Recording (or of a realizer), else the built-in one."""
    if hasattr(source, "recording") and not hasattr(source, "lexicon"):
        source = source.recording()
    lexicon = getattr(source, "lexicon", None)
    return lexicon if lexicon is not None else Lexicon.builtin()


def evaluate_poses(source, fps: float = 60.0, seed: int = 0, duration: float | None = None, start: float = 0.0,
                   scene: dict | None = None, animator_time: TimeSource | None = None,
                   manager: DriverManager | None = None, body: Body | None = None,
                   times=None, folder: str | Path | None = None, progress=None) -> PoseStream:
    """Evaluate the body's pose at ``fps`` frames per second for everything a realizer played.

    Parameters
    ----------
    source : Recording, Realizer (after ``run()``) or iterable of BehaviourRecord
        What to play: every behaviour of every submitted block, at its actual key times.
    fps : float
        Frames per second; frame k is at ``start + k / fps``.
    seed : int
        Seed of the background drivers' Generators (breathing phase, sway, saccades, blinks): the same
        seed gives the same poses.
    duration : float, optional
        Seconds to evaluate; by default until one second after the last behaviour ends.
    scene : dict, optional
        Extra named points (metres) for targets, on top of :data:`~agentsim.animation.scene.DEFAULT_SCENE`.
    animator_time : TimeSource, optional
        Time source for the drivers of speech and of behaviours tied to speech (default: the clock).
    manager : DriverManager, optional
        A manager to use (for instance with motor functions already executed), with its own lexicon; by
        default a new one with the lexicon of ``source`` (a Recording's, a realizer's; else the built-in one).
    body : Body, optional
        The skeleton of a new manager (default: a new :class:`~agentsim.animation.body.Body`).
    times : array of float, optional
        The frame times to evaluate (increasing, seconds) instead of the grid that ``start``, ``duration``
        and ``fps`` make; ``fps`` is then only recorded in the stream. The frames a live viewer is due,
        with a few frames before them where the pose matters to what comes next, say.
    folder : str or Path, optional
        Evaluate into files there (``values.npy``, ``writers.npy``, ``positions.npy``), a window of frames at
        a time, instead of into memory: a long run's poses are never held whole. The stream's arrays are then
        the files mapped into memory, and :meth:`PoseStream.windows`, :meth:`~PoseStream.rows` and
        :meth:`~PoseStream.take` read them a stretch at a time. The numbers are the same either way.
    """
    if fps <= 0:
        raise ValueError("fps must be positive")
    if manager is None:
        manager = DriverManager(body=body, seed=seed, scene=scene, lexicon=lexicon_of(source))
    records = records_of(source)
    infos = build_drivers(manager, records, animator_time)
    if times is not None:
        times = np.asarray(times, dtype=float)
    else:
        if duration is None:
            ends = [max(u.keys.values()) for u in infos if u.keys]
            ends += [float(max(d.keys.end, 0.0)) for d in manager.drivers if hasattr(d, "keys")]
            duration = max([1.0] + [e - start + 1.0 for e in ends if math.isfinite(e)])
        n = int(math.floor(duration * fps + 1e-9)) + 1
        times = start + np.arange(n) / fps
    joints = [j for j in TRACKED_JOINTS if j in manager.body.joint]
    files = None
    if folder is None and progress is not None:
        values = np.empty((len(times), manager.body.n_dofs))
        writers = np.empty((len(times), manager.body.n_dofs), np.int32)

        def told(first: int, block: np.ndarray, wrote: np.ndarray) -> None:
            end = first + len(block)
            values[first:end], writers[first:end] = block, wrote
            progress(manager.body, times[:end], values[:end])

        manager.evaluate(times, sink=told, window=PROGRESS_FRAMES)
        positions = manager.body.positions(values, joints)
    elif folder is None:
        values, writers = manager.evaluate(times)
        positions = manager.body.positions(values, joints)
    else:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        n, dofs = len(times), manager.body.n_dofs
        files = {"values": FrameFile(folder / "values.npy", (n, dofs), np.float64),
                 "writers": FrameFile(folder / "writers.npy", (n, dofs), np.int32),
                 "positions": FrameFile(folder / "positions.npy", (n, len(joints), 3), np.float64)}

        def sink(first: int, block: np.ndarray, wrote: np.ndarray) -> None:
            files["values"].append(block)
            files["writers"].append(wrote)
            files["positions"].append(manager.body.positions(block, joints))

        try:
            manager.evaluate(times, sink=sink, window=FK_ROWS)
        except BaseException:
            for f in files.values():
                f.close(check=False)
            raise
        for f in files.values():
            f.close()
        values, writers, positions = (files[k].mapped() for k in ("values", "writers", "positions"))
    return PoseStream(times=times, channels=list(manager.body.dof_names), values=values, joints=joints,
                      positions=positions, fps=float(fps), body=manager.body, writers=writers,
                      driver_names=manager.driver_names(), units=[u.as_dict() for u in infos], seed=seed,
                      manager=manager, files=files)


# --------------------------------------------------------------------------------------------- BVH
def bvh_hierarchy(body: Body) -> str:
    """The HIERARCHY section of a BVH file for ``body`` (offsets in metres)."""
    children: dict[str, list[str]] = {}
    for j in body.joints:
        if j.parent:
            children.setdefault(j.parent, []).append(j.name)
    out = ["HIERARCHY"]

    def fmt(v) -> str:
        return " ".join(f"{x:.6f}" for x in v)

    def visit(name: str, depth: int) -> None:
        j = body.joint[name]
        pad = "\t" * depth
        out.append(f"{pad}{'ROOT' if j.parent is None else 'JOINT'} {name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {fmt(j.offset)}")
        chans = [c for (jn, c) in body.channels if jn == name]
        out.append(f"{pad}\tCHANNELS {len(chans)} {' '.join(chans)}")
        kids = children.get(name, [])
        for c in kids:
            visit(c, depth + 1)
        if not kids:
            out.append(f"{pad}\tEnd Site")
            out.append(f"{pad}\t{{")
            out.append(f"{pad}\t\tOFFSET {fmt(j.end_site or (0.0, 0.05, 0.0))}")
            out.append(f"{pad}\t}}")
        out.append(f"{pad}}}")

    visit(body.joints[0].name, 0)
    return "\n".join(out) + "\n"


def write_bvh(path: str | Path, stream: PoseStream, precision: int = 5) -> Path:
    """Write ``stream`` as a BVH file: the skeleton (HIERARCHY) and one line of channel values per frame
    (MOTION, ``Frames:`` and ``Frame Time:``). Returns the path."""
    path = Path(path)
    body = stream.body
    if list(stream.channels) != list(body.dof_names):
        raise ValueError("the stream's channels do not match its body")
    # straight to the file (a long stream's text is not held in memory), under a temporary name until whole
    with written(path) as tmp, open(tmp, "w") as f:
        f.write(bvh_hierarchy(body))
        f.write("MOTION\n")
        f.write(f"Frames: {stream.n_frames}\n")
        f.write(f"Frame Time: {1.0 / stream.fps:.8f}\n")
        for _, block in stream.windows():  # a window of frames at a time (the same text)
            np.savetxt(f, block, fmt=f"%.{precision}f", delimiter=" ")
    return path


def write_npz(path: str | Path, stream: PoseStream, **extra) -> Path:
    """Write ``stream`` as a compressed npz: ``times``, ``channels``, ``values`` (frames x channels,
    degrees and metres), ``joints``, ``positions`` (frames x joints x 3), ``fps``, ``writers`` and
    ``driver_uids`` / ``driver_names``, and the ``extra`` arrays given by name."""
    path = Path(path)
    uids = sorted(stream.driver_names)
    np.savez_compressed(
        path, times=stream.times, channels=np.array(stream.channels), values=stream.values,
        joints=np.array(stream.joints), positions=stream.positions, fps=np.array(stream.fps),
        writers=stream.writers if stream.writers is not None else np.empty((0, 0), dtype=np.int32),
        driver_uids=np.array(uids, dtype=np.int64), driver_names=np.array([stream.driver_names[u] for u in uids]),
        **{k: np.asarray(v) for k, v in extra.items()})
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")
