"""A run's timeline pictures as files: one picture of a short run, or an overview and one picture per window
of a long one (:mod:`agentsim.animation.timeline` draws each), drawn side by side by worker processes while
the caller writes its other files.

=======================  ==========================================================================================
function                 what it does
=======================  ==========================================================================================
``plot_timelines``       a short run as one picture; a long one as an overview plus one picture per window
``start_timelines``      the same pictures begun, to be waited for later (a ``TimelineDrawing``)
``start_figures``        pictures of the caller's own begun in a process of their own
``warm_workers``         the server the drawing processes are forked from, started early
=======================  ==========================================================================================
"""

from __future__ import annotations

import glob
import math
import os
import pickle
import re
import threading
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from agentsim.animation.timeline import (DPI, LONG_RUN, PANEL_MARGIN, WINDOW, PosePanel, recording_of,
                                         overview_figure, plot_timeline, run_duration, time_windows, window_path)
from agentsim.written import save_figure

if TYPE_CHECKING:  # the poses' module (the body, the drivers) is not loaded to draw a run that has them
    from agentsim.animation.output import PoseStream

_WINDOW_FILE = re.compile(r"_\d{4,}(?:\.\d)?-\d{4,}(?:\.\d)?s")


#: How many worker processes draw the pictures of a long run side by side (at most one per core this
#: process may run on); 1: all of them in the calling process.
WORKERS = 2


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this system
        return os.cpu_count() or 1


def _may_start_processes() -> bool:
    """Whether this process may start worker processes (a daemonic one, a worker of a pool, may not)."""
    import multiprocessing

    return not multiprocessing.current_process().daemon


def _portable(recording):
    """``recording`` as the pictures need it, without what cannot pass to another process: the samples of
    its speech (the pictures draw its words) and the sound files it played."""
    speech = tuple(replace(s, utterance=replace(s.utterance, audio=None))
                   if getattr(s.utterance, "audio", None) is not None else s for s in recording.speech)
    return replace(recording, speech=speech, audio=())


def _changed_rc() -> dict:
    """The matplotlib settings this process changed (that a worker process changes in turn)."""
    import sys

    if "matplotlib" not in sys.modules:  # never imported here: nothing changed (and nothing to import)
        return {}
    import matplotlib

    # (the keys, not items(): reading ``backend`` resolves it, which imports pyplot, a quarter of a second)
    settings, original = matplotlib.rcParams, matplotlib.rcParamsOrig
    changed = {}
    for key in settings:
        if key != "backend" and key in original and original[key] != settings[key]:
            changed[key] = settings[key]
    return changed


#: What the server that drawing processes are forked from imports once, so that none imports it again:
#: this module and the parts of matplotlib a picture uses (the figure alone is a third of a second), after
#: :mod:`agentsim.animation.picture_server`, which makes the server leave a terminal's interrupt to the command.
PRELOADED = ["agentsim.animation.picture_server", __name__, "matplotlib.backends.backend_agg", "matplotlib.figure",
             "matplotlib.collections", "matplotlib.patches", "matplotlib.colors", "matplotlib.font_manager",
             "matplotlib.textpath"]

#: In a worker process: the recording and the pose panel it draws (``"run"``).
_WORKER: dict = {}


def warm_workers():
    """Start the server that the processes drawing pictures are forked from (multiprocessing's
    ``forkserver``: a process of its own, so that no thread of this one is copied half-way), if it is not
    running; it imports what they need while this process goes on. A run calls this early, so that its
    pictures begin (:func:`start_timelines`) without waiting for it. Returns the multiprocessing context,
    or None where there is no ``forkserver`` or this process may start none (a daemonic one): the
    pictures are then drawn in this process.

    As with any start method but ``fork``, a worker imports the main module again: a script that draws a
    long run's pictures keeps its work under ``if __name__ == "__main__":``.
    """
    import multiprocessing
    import multiprocessing.forkserver

    if "forkserver" not in multiprocessing.get_all_start_methods() or not _may_start_processes():
        return None
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(PRELOADED)
    multiprocessing.forkserver.ensure_running()
    return context


def _take_run(payload: bytes) -> None:
    """Start a worker process: keep the run it draws (pickled once for all of its pictures)."""
    import matplotlib

    from agentsim.core.gcpause import keep_out_of_collections

    recording, panel, rc = pickle.loads(payload)
    matplotlib.rcParams.update(rc)
    _WORKER["run"] = (recording, panel)
    keep_out_of_collections()  # (the run and matplotlib's modules stay for the worker's life)


def _draw(job: tuple, recording=None, panel=None) -> Path:
    """Draw one picture of :func:`plot_timelines` of the run given or, in a worker process, of its run;
    ``job``: ``("whole", file, title, width)``, ``("overview", file, title, width, window)``,
    ``("window", file, title, width, start, end)`` or ``("figure", file, function, arguments)`` (a module-level
    function making a matplotlib figure from the arguments, saved to the file); a whole run's or a window's
    job may end with the :class:`PosePanel` it draws (poses that came after the workers started). Returns
    the file."""
    if job[0] == "figure":  # ("figure", file, function, arguments): a figure of the caller's own
        _, path, function, arguments = job
        return save_figure(function(*arguments), path)
    if recording is None:
        recording, panel = _WORKER["run"]
    kind, path, title, width, *span = job
    if span and isinstance(span[-1], PosePanel):
        *span, panel = span
    if kind == "overview":
        save_figure(overview_figure(recording, title=title, width=width, window=span[0]), path, dpi=DPI)
        return path
    if kind == "whole":
        return plot_timeline(recording, path, stream=panel, title=title, width=width)
    return plot_timeline(recording, path, stream=panel, title=title, width=width, start=span[0], end=span[1])


class TimelineDrawing:
    """The pictures of :func:`start_timelines` as they are drawn: by worker processes from the start, or
    (one process) here when :meth:`result` asks for them.

    The workers are started on a thread of their own, so that beginning the pictures does not wait for
    them. Use it as a context manager, or call :meth:`close`, so that the workers are let go if the files
    are never asked for.

    With poses that come later (:func:`start_timelines` ``poses_later``), the pictures that need none begin
    at once and each of the others when :meth:`poses_until` has brought the poses it shows.

    Attributes
    ----------
    workers : int
        How many worker processes draw the pictures; 0 if :meth:`result` draws them (one worker asked
        for, or a run that cannot pass to another process), or drew any of them (workers that could not
        start, or died).
    """

    def __init__(self, jobs: list[tuple], png: Path | None, recording, panel: PosePanel | None, workers: int,
                 aside: bool = False, poses_later: bool = False) -> None:
        self._jobs, self._png, self._recording, self._panel = jobs, png, recording, panel
        self._written: list[Path] | None = None
        self._pool = None
        self._futures: dict = {}  # job index -> its future, once handed to a worker
        #: the jobs that wait for poses, and those ready but not yet handed to a worker (the pool is starting)
        self._waiting = {k for k, job in enumerate(jobs) if poses_later and job[0] in ("window", "whole")}
        self._ready = [k for k in range(len(jobs)) if k not in self._waiting]
        self._lock = threading.Lock()
        self._starting: threading.Thread | None = None
        self.workers = 0
        context = warm_workers() if workers > 1 or aside and workers == 1 else None
        if context is not None:
            try:
                run = _portable(recording) if recording is not None else None
                payload = pickle.dumps((run, panel, _changed_rc()), protocol=pickle.HIGHEST_PROTOCOL)
            except (pickle.PicklingError, TypeError, AttributeError):  # a run that cannot pass is drawn here
                return
            self.workers = workers
            self._starting = threading.Thread(target=self._start, args=(context, workers, payload),
                                              name="timeline workers", daemon=True)
            self._starting.start()

    def _start(self, context, workers: int, payload: bytes) -> None:
        """Start the workers and hand them the pictures (what cannot start leaves them to :meth:`result`)."""
        import concurrent.futures

        try:
            pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=context, initializer=_take_run,
                                                          initargs=(payload,))
            with self._lock:
                self._pool = pool
                self._hand_ready()
        except (OSError, RuntimeError, concurrent.futures.BrokenExecutor):
            self._futures = {}

    def _hand_ready(self) -> None:
        """Hand the jobs ready to the workers (under the lock, once the pool is there)."""
        for k in self._ready:
            self._futures[k] = self._pool.submit(_draw, self._jobs[k])
        self._ready = []

    def poses_until(self, panel: PosePanel, complete: bool = False) -> None:
        """The run's poses from its start to the last frame of ``panel`` have come (``complete``: all of
        them): the pictures that show none later begin."""
        with self._lock:
            if complete:
                self._panel = panel
            last = float(panel.times[-1]) if len(panel.times) else -math.inf
            for k in sorted(self._waiting):
                kind, *rest = self._jobs[k]
                if kind == "window" and (complete or last > rest[4] + PANEL_MARGIN):
                    self._jobs[k] = (kind, *rest, panel.around(rest[3], rest[4]))
                elif complete:
                    self._jobs[k] = (kind, *rest, panel)
                else:
                    continue
                self._waiting.discard(k)
                self._ready.append(k)
            if self._pool is not None:
                self._hand_ready()

    def _started(self) -> None:
        if self._starting is not None:
            self._starting.join()
            self._starting = None

    @property
    def waiting(self) -> list[Path]:
        """The files of the pictures that wait for poses (:meth:`poses_until`), in order."""
        with self._lock:
            return [self._jobs[k][1] for k in sorted(self._waiting)]

    def follow(self):
        """A ``progress(body, times, values)`` for poses of ``body`` made a stretch at a time (the frames made so
        far, from the run's start, as arrays), which brings each new stretch to :meth:`poses_until`."""
        parts: list[PosePanel] = []
        seen = [0]

        def progress(body, times, values) -> None:
            if len(times) > seen[0]:
                parts.append(PosePanel.of_poses(body, times[seen[0]:], values[seen[0]:]))
                seen[0] = len(times)
                self.poses_until(PosePanel.joined(parts))

        return progress

    def result(self) -> list[Path]:
        """Wait for the pictures (or draw them) and return their files, the overview (or the one picture)
        first; window files of an earlier, longer run left in the folder are removed. Raises what drawing
        one of them raised. A picture whose worker died (killed, or unable to start) is drawn here."""
        from concurrent.futures import BrokenExecutor

        if self._written is None:
            if self._waiting:
                raise RuntimeError("the pictures wait for poses: call poses_until(panel, complete=True) first")
            self._started()
            try:
                written = []
                for k, job in enumerate(self._jobs):
                    try:
                        written.append(self._futures[k].result() if k in self._futures else None)
                    except BrokenExecutor:
                        written.append(None)
                    if written[-1] is None:
                        written[-1] = _draw(job, self._recording, self._panel)
                        self.workers = 0
            finally:
                self.close()
            png = self._png
            for old in png.parent.glob(f"{glob.escape(png.stem)}_*s{glob.escape(png.suffix)}") if png else ():
                if _WINDOW_FILE.fullmatch(old.name[len(png.stem):-len(png.suffix)]) and old not in written:
                    old.unlink()
            self._written = written
        return list(self._written)

    def close(self) -> None:
        """Let the workers go: pictures not begun are not drawn, those under way are finished."""
        self._started()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> TimelineDrawing:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def start_timelines(source, out: str | Path, stream: PoseStream | PosePanel | None = None, window: float = WINDOW,
                    threshold: float | None = None, title: str | None = None, width: float = 16.0,
                    workers: int | None = None, poses_later: bool = False) -> TimelineDrawing:
    """Begin drawing the pictures of :func:`plot_timelines`; the caller writes its other files meanwhile
    and asks :meth:`TimelineDrawing.result` for these when it needs them.

    A long run's overview and windows (two windows or more) are drawn by worker processes started here
    (:func:`warm_workers`); a short run's one picture, or every picture with one worker, on one core, in a
    daemonic process or where there is no ``forkserver``, is drawn by :meth:`TimelineDrawing.result` in
    this process. Either way the files are the same.

    Parameters
    ----------
    source : Recording
        The run (or a realizer after ``run()``).
    out, window, threshold, title, width
        As :func:`plot_timelines` takes them.
    stream : PoseStream or PosePanel, optional
        The run's poses; their :class:`PosePanel` is taken here, once (the stream may be gone by the time
        the pictures are drawn).
    workers : int, optional
        How many processes draw side by side (default :data:`WORKERS`; at most one per core this process
        may run on, and one per picture).
    poses_later : bool
        The poses come later, a stretch at a time, each from the run's start (``stream`` then None): the
        pictures that show none (a long run's overview) begin at once, each window as soon as
        :meth:`TimelineDrawing.poses_until` has brought the poses it shows, a short run's one picture when
        it has brought them all. For poses that take long to make (the physical body's).

    Returns
    -------
    TimelineDrawing
        The pictures under way; use it as a context manager.
    """
    if not window > 0:
        raise ValueError(f"a window must last a positive number of seconds, not {window}")
    recording = recording_of(source)
    out = Path(out)
    png = out if out.suffix else out / "timeline.png"
    png.parent.mkdir(parents=True, exist_ok=True)
    panel = None if stream is None else PosePanel.of(stream)
    duration = run_duration(recording)
    limit = LONG_RUN if threshold is None else threshold
    if duration <= limit:
        jobs = [("whole", png, title, width)]
    else:
        jobs = [("overview", png, title, width, window)]
        for a, b in time_windows(duration, window):
            part = f"{a:g}-{b:g} s of {duration:.0f} s"
            jobs.append(("window", window_path(png, a, b), f"{title}: {part}" if title else part, width, a, b))
    n = min(WORKERS if workers is None else workers, _cores(), len(jobs))
    if len(jobs) < 3:  # one window at most: nothing to draw side by side
        n = 1
    return TimelineDrawing(jobs, png, recording, panel, n, poses_later=poses_later)


def start_figures(figures: list[tuple]) -> TimelineDrawing:
    """Begin drawing pictures of the caller's own, ``(file, function, arguments)``: ``function(*arguments)`` (a
    function a worker can import by name, arguments it can be handed) makes a matplotlib figure saved to
    ``file``, so that the caller never imports matplotlib's figures itself. They are drawn in a process of
    their own (:func:`warm_workers`; where none can start, in this one when
    :meth:`TimelineDrawing.result` asks for them): for what can be drawn while this process does other work
    (the poses, before the timeline pictures can begin)."""
    jobs = [("figure", Path(file), function, tuple(arguments)) for file, function, arguments in figures]
    return TimelineDrawing(jobs, None, None, None, 1 if jobs else 0, aside=True)


def plot_timelines(source, out: str | Path, stream: PoseStream | PosePanel | None = None, window: float = WINDOW,
                   threshold: float | None = None, title: str | None = None, width: float = 16.0,
                   workers: int | None = None) -> list[Path]:
    """The timeline of a run as pictures that read: one if it is short, an overview plus windows if long.

    ``out``: the overview's file (``.png``, or another format matplotlib writes) or a folder (a path
    without a suffix: ``timeline.png`` inside). A run no longer than
    ``threshold`` seconds (default ``LONG_RUN``) is drawn whole in that file by :func:`plot_timeline`. A
    longer one gets :func:`overview_figure` there, and each of its :func:`time_windows` of ``window``
    seconds in detail in its own file next to it (:func:`window_path`: ``timeline_0000-0030s.png``, ...),
    drawn by ``workers`` processes side by side (:func:`start_timelines`); window files of an earlier,
    longer run left in the folder are removed. Returns the files written, the overview (or the one
    picture) first.
    """
    with start_timelines(source, out, stream=stream, window=window, threshold=threshold, title=title, width=width,
                         workers=workers) as drawing:
        return drawing.result()
