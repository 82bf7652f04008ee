"""What a run's files will cost, said before they are written.

The writers do not hold a timeline whole: the WAV is mixed and written a stretch at a time
(:class:`~agentsim.media.audio.TrackStream`), the poses are evaluated a window of frames at a time into
files of a scratch folder and the BVH, npz and report read them back a window at a time. So a behaviour
far along the run's axis (``start="999999"``) costs memory by the window, but WAV and BVH have no way to
say "nothing happens here": their files are as long as the run, silence and rest poses included.

Before anything is written, :func:`check_budget` projects the size of each file asked for (and of the
scratch folder of the poses) from the run's duration, and refuses with one line:

* a file larger than :data:`MAX_FILE` (4 GiB, what a WAV file can hold at all; the same limit for every
  file of a run, so that a run of days is said at once and not after hours of evaluation);
* files that together need more than the free space of their file system (:func:`shutil.disk_usage`).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

from agentsim.errors import AgentsimError, UsageError

__all__ = ["MAX_FILE", "BVH_BYTES_PER_VALUE", "check_budget", "pose_bytes", "gib"]

#: The largest file a run writes (bytes): 4 GiB, the most a RIFF (WAV) file can hold.
MAX_FILE = 4 * 1024 ** 3
#: Bytes a BVH value takes as text: ``%.5f`` of a few degrees and the space after it (``-12.34567``).
BVH_BYTES_PER_VALUE = 10


def gib(n: float) -> str:
    return f"{n / 1024 ** 3:.1f} GiB" if n >= 1024 ** 3 / 10 else f"{n / 1024 ** 2:.1f} MiB"


def frames_of(duration: float, fps: float) -> int:
    """The frames :func:`~agentsim.animation.evaluate_poses` makes of a run of ``duration`` seconds (one
    second past its end)."""
    return int(math.floor((duration + 1.0) * fps + 1e-9)) + 1


def pose_bytes(frames: int) -> dict[str, int]:
    """Bytes of the poses of ``frames`` frames: the scratch files (values, writers, positions), the BVH,
    the npz (uncompressed, the most it takes) and the report's positions (base64 of 16-bit mm, 30 fps)."""
    from agentsim.animation.body import Body
    from agentsim.animation.output import TRACKED_JOINTS

    dofs, joints = Body().n_dofs, len(TRACKED_JOINTS)
    scratch = frames * (dofs * 8 + dofs * 4 + joints * 3 * 8)
    return {"scratch": scratch, "bvh": frames * dofs * BVH_BYTES_PER_VALUE, "npz": scratch,
            "report": frames * (joints + 8) * 3 * 2 * 4 // 3}


def check_budget(files: dict[str, tuple[Path, int]], duration: float,
                 scratch: tuple[Path, int] | None = None) -> None:
    """Refuse (one line) what cannot be written: ``files`` maps what asked for a file (``--bvh x.bvh``) to
    the file and its projected size in bytes; ``duration`` is the run's (s); ``scratch``: the folder of the
    poses' scratch files and their size. :class:`UsageError` for a file past :data:`MAX_FILE`,
    :class:`AgentsimError` (exit 1) for files (scratch included) that do not fit the free space of their
    file system."""
    for what, (path, size) in files.items():
        if size > MAX_FILE:
            raise UsageError(f"{what}: the run lasts {duration:.0f} s, so the file would take {gib(size)}, more "
                             f"than the {gib(MAX_FILE)} a run's file may take (a WAV cannot hold more): "
                             f"move what starts that late sooner")
    by_device: dict[int, list] = {}
    every = {**files, **({"the poses' scratch files": scratch} if scratch else {})}
    for what, (path, size) in every.items():
        folder = _existing(path)
        by_device.setdefault(folder.stat().st_dev, []).append((what, folder, size))
    for entries in by_device.values():
        need = sum(size for _, _, size in entries)
        folder = entries[0][1]
        free = shutil.disk_usage(folder).free
        if need > free:
            names = ", ".join(what for what, _, _ in entries)
            raise AgentsimError(f"not enough disk space for {names}: the run lasts {duration:.0f} s, so they "
                                f"would take {gib(need)}, and {folder} has {gib(free)} free")


def _existing(path: Path) -> Path:
    """The nearest folder of ``path`` (itself if it is one) that exists."""
    path = Path(path).absolute()
    while not path.is_dir():
        path = path.parent
    return path
