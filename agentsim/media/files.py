"""The files a run writes, on its one time axis, each saying so where its format has room: the WAV's comment,
the npz's ``time_axis`` entry, the TextGrid's ``axis`` tier, the JSON's ``time_axis`` field. BVH has no
syntax for comments (a reader we test refuses one), so the BVH says nothing; its frame 0 is at 0 s too.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Iterable


from agentsim.errors import UsageError
from agentsim.written import check_output, written
from agentsim.media import AXIS
if TYPE_CHECKING:  # checking where to write needs no audio
    from agentsim.media.audio import Track


def _cannot_write_in(folder: Path) -> str | None:
    """Why nothing can be written in ``folder`` (a read-only mount, which permissions do not tell), or None."""
    probe = folder / f".agentsim-probe-{os.getpid()}"
    try:
        probe.touch()
        probe.unlink()
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def check_writable(files: Iterable[str | Path | None] = (), folders: Iterable[str | Path | None] = (),
                   inputs: Iterable[str | Path | None] = ()) -> None:
    """Raise :class:`UsageError` naming the first output that cannot be written: a device, a FIFO, a folder
    where a file is meant or one of the run's ``inputs`` (:func:`~agentsim.written.check_output`), a file
    whose folder cannot be made (folders are made on demand) or is not writable, a folder that cannot be made
    or written. Called before any work is done."""
    inputs = list(inputs)
    for name in files:
        if name is None:
            continue
        path = Path(name)
        folder = path.parent if str(path.parent) else Path(".")
        check_output(path, inputs)
        if not folder.is_dir():
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except (FileExistsError, NotADirectoryError):
                raise UsageError(f"cannot write {path}: a file is in the way of its folder {folder}") from None
            except OSError as exc:
                raise UsageError(f"cannot write {path}: cannot make the folder {folder} "
                                 f"({exc.strerror or exc})") from None
        if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
            raise UsageError(f"cannot write {path}: no permission to write in {folder}")
        problem = _cannot_write_in(folder)
        if problem:
            raise UsageError(f"cannot write {path}: {problem}")
    for name in folders:
        if name is None:
            continue
        path = Path(name)
        check_output(path, inputs, folder=True)
        try:
            path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise UsageError(f"cannot make the output folder {path}: a file of that name is in the way") from None
        except NotADirectoryError:
            raise UsageError(f"cannot make the output folder {path}: a file is in the way on its path") from None
        except OSError as exc:
            raise UsageError(f"cannot make the output folder {path}: {exc.strerror or exc}") from None
        problem = _cannot_write_in(path)
        if problem:
            raise UsageError(f"cannot write in the output folder {path}: {problem}")


def write_text(path: str | Path, text: str) -> Path:
    """Write a text file (UTF-8) whole or not at all (see :func:`written`)."""
    with written(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_feedback(path: str | Path, feedback) -> Path:
    """Write feedback as JSON lines (:func:`~agentsim.core.feedback.to_json`), a line at a time (a long run's
    text is not held whole), whole or not at all (see :func:`written`)."""
    from agentsim.core.feedback import to_json

    with written(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.writelines(to_json(item) + "\n" for item in feedback)
    return Path(path)


def write_wav(path: str | Path, track: Track) -> Path:
    """Write a track (a :class:`~agentsim.media.audio.Track`, or a
    :class:`~agentsim.media.audio.TrackStream` stretch by stretch) as 16-bit PCM WAV; its comment (INFO
    chunk) says the time axis."""
    import soundfile

    path = Path(path)
    with written(path) as tmp, soundfile.SoundFile(str(tmp), "w", track.rate, 1, "PCM_16", format="WAV") as f:
        f.comment = f"agentsim: {AXIS}"
        f.software = "agentsim"
        for stretch in track.stretches():
            f.write(stretch)
    return path


def write_npz(path: str | Path, stream) -> Path:
    """The poses as :func:`agentsim.animation.write_npz` writes them, plus ``time_axis``."""
    from agentsim.animation import write_npz as write_poses

    path = Path(path)
    if path.suffix != ".npz":  # numpy adds it
        path = path.with_name(path.name + ".npz")
    with written(path) as tmp:
        write_poses(tmp, stream, time_axis=AXIS)
    return path


def heard_words(heard) -> list[tuple[str, float, float]]:
    """A heard speech's words on the run's axis: (text, onset, offset), up to an interruption."""
    speed = 1.0 + heard.drift_ppm * 1e-6
    words = []
    for w in heard.utterance.words:
        a, b = heard.t0 + w.start * speed, heard.t0 + w.end * speed
        if heard.stopped is not None:
            if a >= heard.stopped:
                break
            b = min(b, heard.stopped)
        words.append((w.text, a, b))
    return words


def write_textgrid(path: str | Path, recording, gestures=(), end: float | None = None) -> Path:
    """A Praat TextGrid of the run on its axis: ``words`` and ``phones`` of every speech where they were
    heard, ``marks`` (the speeches' sync points as fed back), ``strokes`` (each pegged behaviour's sync point,
    labelled with its id and error), and an empty ``axis`` tier whose name says the axis."""
    from praatio import textgrid
    from praatio.utilities.constants import Interval, Point

    sync_times = {f["id"]: f["globalTime"] for f in recording.feedback if f["type"] == "syncPointProgress"}
    if end is None:
        end = max([0.0, *sync_times.values(), *(heard_words(h)[-1][2] for h in recording.speech if heard_words(h))])
    end = max(end, 1e-3)

    def intervals(items):
        out, last = [], 0.0
        for label, a, b in sorted(items, key=lambda x: x[1]):
            a, b = max(a, last), min(b, end)
            if b - a > 1e-6 and label:
                out.append(Interval(a, b, label))
                last = b
        return out

    words, phones, marks = [], [], {}
    synced: dict[tuple[str, str], list[tuple[str, str, float]]] = {}  # each speech's sync points, in their order
    for sync_id, t in sync_times.items() if recording.speech else ():
        block, behaviour, sync = sync_id.split(":", 2)
        synced.setdefault((block, behaviour), []).append((sync_id, sync, t))
    for heard in recording.speech:
        words.extend(heard_words(heard))
        speed = 1.0 + heard.drift_ppm * 1e-6
        for p in heard.utterance.phonemes:
            a, b = heard.t0 + p.start * speed, heard.t0 + p.end * speed
            if heard.stopped is None or a < heard.stopped:
                phones.append((p.symbol + ("ˈ" if p.stressed else ""), a, b))
        for sync_id, sync, t in synced.get((heard.block, heard.behaviour), ()):
            if sync not in ("start", "end") and t <= end:
                marks.setdefault(round(t, 9), []).append(sync_id)
    strokes: dict[float, list[str]] = {}
    for row in gestures:
        if row.happened_s is not None and row.happened_s <= end:
            label = f"{row.block}:{row.behaviour}" + (f" {row.error_ms:+.1f}ms" if row.error_ms is not None else "")
            strokes.setdefault(round(row.happened_s, 9), []).append(label)
    grid = textgrid.Textgrid(0.0, end)
    grid.addTier(textgrid.IntervalTier("words", intervals(words), 0.0, end))
    grid.addTier(textgrid.IntervalTier("phones", intervals(phones), 0.0, end))
    grid.addTier(textgrid.PointTier("marks", [Point(t, " ".join(v)) for t, v in sorted(marks.items())], 0.0, end))
    grid.addTier(textgrid.PointTier("strokes", [Point(t, " ".join(v)) for t, v in sorted(strokes.items())], 0.0, end))
    grid.addTier(textgrid.PointTier(f"axis: {AXIS}", [], 0.0, end))
    path = Path(path)
    with written(path) as tmp:
        grid.save(str(tmp), format="long_textgrid", includeBlankSpaces=True)
    return path
