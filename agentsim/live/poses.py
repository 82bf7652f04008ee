"""Live poses: the body's pose evaluated frame by frame while a :class:`~agentsim.live.runtime.LiveRealizer`
plays, streamed to the viewers that subscribed to them, and the viewer's files.

Messages (JSON text) to a client that sent ``{"subscribe": "poses"}``:

* first the skeleton, once::

    {"type": "skeleton", "joints": ["HumanoidRoot", ..., "l_fingers.end", ...], "parents": [-1, 0, ...],
     "rest": [[x, y, z], ...], "face": [...], "ends": [...], "fps": 30.0, "period": 0.1, "segments": [...]}

  ``joints`` are the points drawn (every joint of the body in BVH order, then the end sites named
  ``joint.end``; :func:`~agentsim.media.report.data.point_names`), ``parents`` the index of each one's
  parent (-1: the root), ``rest`` their world positions in the rest pose (m), ``face`` and ``ends`` the
  indices of the face's joints and of the end sites (drawn smaller), ``fps`` the frame rate of the poses,
  ``period`` how often a message of poses is sent (s), ``segments`` the capsules the viewer draws the body
  with (``[parent, child, radius]``, :func:`~agentsim.media.environment.body_segments`);
* then the poses, a few frames at a time (every ``period`` seconds)::

    {"type": "poses", "time": 4.2, "index": 126, "fps": 30.0, "frames": [[x1, y1, z1, x2, ...], ...]}

  frame ``k`` of a message is at ``time + k / fps`` on the realizer's clock (the ``globalTime`` of
  feedback); ``index`` is the first frame's number (``time = index / fps``); each frame holds the world
  positions of the skeleton's ``joints`` in that order, in metres rounded to the millimetre. Frames follow
  each other with no gap and no repeat from one message to the next. A message is sent
  :attr:`~agentsim.live.server.Server.delay` seconds after its last frame's time, as feedback is;
* and each change of the environment that the run's emotions make (:mod:`agentsim.live.environment`).

Where the work is done. Every ``period`` the realizer's thread (through
:meth:`~agentsim.live.runtime.LiveRealizer.every`) takes a snapshot of what the body may be doing: the
records (:func:`~agentsim.core.recording.record_behaviours`) of the blocks that have not ended or ended
lately, and of older blocks only the shifts that still hold a pose; that costs a few hundredths of a
millisecond and does not grow with the run. A worker thread of its own evaluates the frames due since the
last snapshot with :func:`~agentsim.animation.output.evaluate_poses` (:func:`window_records` says which
behaviours it is given), turns them into joint positions and hands the message to the server's loop. Nothing
is evaluated while nobody subscribes.

Frames evaluated a window at a time are the frames an evaluation of the whole run gives: a motion starts
from the pose it finds and hands the body back to the pose it leaves (:mod:`agentsim.animation.motion`), so
the window's evaluation also evaluates, on the same frame grid, the frame just before each instant where
one of its behaviours takes or gives back a joint (:func:`frames_before`); and the saccades and blinks of
the background are drawn once on the realizer's clock (:class:`Liveliness`) rather than anew for every
window.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from pathlib import Path

import numpy as np

from agentsim.animation import evaluate_poses
from agentsim.animation.background import EyeBlinkReflex, EyeFixation
from agentsim.animation.body import Body
from agentsim.animation.drivers import EPSILON
from agentsim.animation.manager import DriverManager
from agentsim.core.recording import record_behaviours
from agentsim.core.timed import REFUSED
from agentsim.live.runtime import LiveRealizer
from agentsim.live.server import Server
from agentsim.media.report.data import FACE, body_points, point_names
from agentsim.media.environment import body_segments

#: How often the poses are sent (s of the realizer's clock): the frames due since the last time.
PERIOD = 0.1
#: Behaviours that started this long (s) before a window are given to its evaluation while they overlap
#: the window's first behaviours (a gesture taking over a hand from another one starts from its pose).
LOOKBACK = 3.0
#: A behaviour that ended (or was stopped) this long before a window still blends out into it (s).
GUARD = 0.35
#: Behaviour types that hold a pose after they end: the latest :data:`HOLDS` of each are always given.
HOLDING = ("postureShift", "faceShift", "gazeShift", "headDirectionShift", "locomotion")
HOLDS = 8
#: Blocks that ended this long ago (s) are forgotten by the snapshot, but for their shifts.
FORGET = 2 * LOOKBACK + 1.0
#: At most this many frames are evaluated at once (a worker that fell behind catches up in steps).
MAX_FRAMES = 90
#: At most this share of one core goes to evaluating poses: the worker rests in proportion to what it
#: worked, so that the realizer's thread, whose clock the feedback keeps, always gets the interpreter.
#: (20 blocks a second of speech and gestures cost 29 ms per frame: more than a core at 30 fps.)
SHARE = 0.25
#: A worker this far behind (s) skips to the last half second of frames due: a viewer under a load it
#: cannot draw gets fewer frames, counted in :attr:`LivePoses.skipped`, never a late realizer.
LAG = 1.0
#: A blink lasts this long (s): a window's evaluation starts this early so that one under way goes on.
BLINK = 0.3
#: The viewer's page and the report files it loads.
VIEWER = Path(__file__).resolve().parent / "viewer"


def viewer_files() -> dict[str, Path]:
    """The viewer's files by URL path: its page and the report's script, style and three.js."""
    from agentsim.media.report.page import ASSETS, VENDOR

    return {"index.html": VIEWER / "index.html", "report.js": ASSETS / "report.js",
            "report.css": ASSETS / "report.css", "three.min.js": VENDOR / "three.min.js",
            "LICENSE-three.txt": VENDOR / "LICENSE-three.txt", "stage.js": ASSETS / "stage.js"}


def record_span(record) -> tuple[float, float] | None:
    """When a behaviour moves the body: from its first known time to its last (to where it was stopped if
    it was dropped or cut), ``inf`` while it waits for the world; None if it has no known time."""
    known = [t for t in record.times if t is not None]
    if not known:
        return None
    end = max(known)
    if record.state == "dropped" and record.stopped is not None:
        end = min(end, record.stopped)
    return known[0], end


def window_records(records, a: float, b: float, lookback: float = LOOKBACK, holds: int = HOLDS) -> list:
    """The behaviour records that the frames from time ``a`` to ``b`` depend on.

    Those that overlap the window (or ended at most :data:`GUARD` s before it); those that overlap the
    time since the earliest of them started (at most ``lookback`` s before ``a``), from which they take
    over; and the latest ``holds`` of each type in :data:`HOLDING` that ended earlier, whose pose still
    holds. Behaviours that start after ``b`` and waits are left out.
    """
    spans = []
    for record in records:
        if record.type == "wait":
            continue
        span = record_span(record)
        if span is None or span[0] > b:
            continue
        spans.append((record, span))
    inside = [(r, s) for r, s in spans if s[1] >= a - GUARD]
    horizon = a
    for record, (start, _) in inside:
        if record.type not in ("speech", "lips"):  # they take nothing over
            horizon = min(horizon, start)
    horizon = max(horizon, a - lookback)
    chosen = [r for r, s in spans if s[1] >= horizon - GUARD]
    picked = {id(r) for r in chosen}
    older: dict[str, list] = collections.defaultdict(list)
    for record, (start, end) in spans:
        if id(record) not in picked and record.type in HOLDING:
            older[record.type].append((end, record.order, record))
    for kind in older.values():
        chosen += [r for _, _, r in sorted(kind, key=lambda x: x[:2])[-holds:]]
    return chosen


def frame_before(t: float, fps: float) -> int:
    """The last frame of the grid ``k / fps`` that an evaluation ticks before an event at time ``t``."""
    k = int(math.floor((t - EPSILON) * fps))
    while k / fps >= t - EPSILON:
        k -= 1
    while (k + 1) / fps < t - EPSILON:
        k += 1
    return k


def frames_before(records, a: float, fps: float) -> set[int]:
    """The frames (of the grid ``k / fps``, from 0) just before every instant earlier than ``a`` where one
    of ``records`` may take or give back joints: its sync points and when it was stopped."""
    frames = set()
    for record in records:
        for t in list(record.times) + [record.stopped]:
            if t is not None and math.isfinite(t) and t < a:
                k = frame_before(t, fps)
                if k >= 0:
                    frames.add(k)
    return frames


class Liveliness:
    """The background's saccades and blinks drawn once on the realizer's clock, so that every window's
    evaluation has the same ones: drawn by the background drivers themselves (their ``prepare``), in
    chunks of :attr:`CHUNK` seconds, each from a seed of its own; chunks long past are forgotten."""

    CHUNK = 10.0

    def __init__(self, seed: int = 0):
        self.seed = seed
        self.chunks: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def chunk(self, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Saccade times, their offsets (n, 2) and blink arrivals of chunk ``c``."""
        if c not in self.chunks:
            streams = np.random.SeedSequence([self.seed, c]).spawn(2)
            eyes = EyeFixation(np.random.default_rng(streams[0]))
            blink = EyeBlinkReflex(eyes, np.random.default_rng(streams[1]))
            t0, t1 = c * self.CHUNK, (c + 1) * self.CHUNK
            eyes.prepare(t0, t1)
            blink.prepare(t0, t1)
            self.chunks[c] = (eyes.saccade_times, eyes.saccade_offsets[1:], blink.arrivals)
            for old in [k for k in self.chunks if k < c - 3]:
                del self.chunks[old]
        return self.chunks[c]

    def pin(self, manager: DriverManager, t_begin: float, t_end: float) -> None:
        """Give ``manager``'s eye fixation and blink reflex the saccades and blinks of ``t_begin``..``t_end``."""
        first = max(0, int(math.floor(t_begin / self.CHUNK)))
        last = max(first, int(math.floor(t_end / self.CHUNK)))
        parts = [self.chunk(c) for c in range(first, last + 1)]
        saccades = np.concatenate([p[0] for p in parts])
        offsets = np.concatenate([p[1] for p in parts]).reshape(-1, 2)
        blinks = np.concatenate([p[2] for p in parts])
        eyes, blink = manager.eyes, manager.blink
        if eyes is not None:
            # before the first saccade the eyes rest where the last one before these chunks left them
            before = self.chunk(first - 1)[1] if first > 0 else np.zeros((0, 2))
            rest = before[-1:] if len(before) else np.zeros((1, 2))

            def prepare(t0: float, t1: float) -> None:
                eyes.saccade_times = saccades
                eyes.saccade_offsets = np.vstack([rest, offsets])

            eyes.prepare = prepare  # instead of drawing saccades of its own for this window
        if blink is not None:
            blink.mean_interval = math.inf  # no blinks of its own: these
            blink.forced = [float(t) for t in blinks]


_EVALUATORS: dict[tuple, tuple] = {}


def evaluate_window(records, k0: int, k1: int, fps: float, seed: int, lexicon=None,
                    physics=None) -> tuple[np.ndarray, int]:
    """Joint positions (frames, points * 3) of frames ``k0`` to ``k1`` of the grid ``k / fps`` given the
    ``records`` of what the body may be doing, and how many frames it took to evaluate them (those before
    the window where a motion takes over a joint, :func:`frames_before`, and the start of a blink under
    way). The body and the background drawn from ``seed`` are kept from one call to the next; the lexemes
    play as ``lexicon`` (the realizer's; default: the built-in one) has them. ``physics``: the pushes of a
    physical body (:class:`~agentsim.physics.run.LiveBody`, kept from one call to the next, whose root and
    physical joints the frames show); None: the animation's poses."""
    key = (float(fps), int(seed), None if physics is None else tuple(physics))
    if key not in _EVALUATORS:
        _EVALUATORS[key] = (Body(), Liveliness(seed), None)
    body, liveliness, live_body = _EVALUATORS[key]
    if physics is not None and live_body is None:
        from agentsim.physics.run import LiveBody

        live_body = LiveBody(body, fps, physics)
        _EVALUATORS[key] = (body, liveliness, live_body)
    a, b = k0 / fps, k1 / fps
    chosen = window_records(records, a, b)
    frames = set(range(k0, k1 + 1)) | frames_before(chosen, a, fps)
    frames.add(max(0, k0 - int(math.ceil(BLINK * fps))))
    frames = np.array(sorted(frames))
    times = frames / fps
    manager = DriverManager(body=body, seed=seed, lexicon=lexicon)
    liveliness.pin(manager, float(times[0]), float(times[-1]) + 1.0)
    stream = evaluate_poses(chosen, fps=fps, manager=manager, times=times)
    first = int(np.searchsorted(frames, k0))
    values = stream.values[first:]
    if live_body is not None:
        from agentsim.physics.run import run_controllers

        values = live_body.frames(k0, values, run_controllers(chosen))
    points = body_points(body, values)
    return points.reshape(len(points), -1), len(frames)


class LivePoses:
    """The poses of a live run, streamed: see the module's docstring.

    ``fps`` frames per second of the realizer's clock, sent every ``period`` seconds; ``seed`` seeds the
    background (sway, breathing, saccades, blinks). :attr:`costs` keeps, for recent evaluations, the frames
    sent, the frames evaluated and the seconds it took; :attr:`snapshots` the seconds each snapshot took
    in the realizer's thread.
    """

    def __init__(self, live: LiveRealizer, fps: float, period: float = PERIOD, seed: int = 0, physics=None):
        if fps <= 0:
            raise ValueError("fps must be positive")
        self.live = live
        self.fps = float(fps)
        self.period = float(period)
        self.seed = seed
        #: the pushes of the physical body whose poses are sent (``serve --physics``), or None
        self.physics = physics
        #: what the lexemes play: the realizer's lexicon
        self.lexicon = live.realizer.lexicon
        self.body = Body()
        self.names, self.parents = point_names(self.body)
        self.liveliness = Liveliness(seed)
        self.server: Server | None = None
        self.next_frame = 0
        self.sent_frames = 0
        #: the evaluator process (:meth:`start_process`), or None: evaluated in the worker thread
        self.process = None
        #: frames skipped because the worker fell more than :data:`LAG` behind
        self.skipped = 0
        self.costs: collections.deque = collections.deque(maxlen=2000)
        self.snapshots: collections.deque = collections.deque(maxlen=2000)
        self.error: BaseException | None = None
        # the snapshot: blocks still watched, and the shifts of those forgotten
        self.watched: list = []
        self.seen = 0
        self.held: dict[str, collections.deque] = collections.defaultdict(lambda: collections.deque(maxlen=HOLDS))
        self.latest: tuple[float, list] | None = None
        self.wake = threading.Condition()
        self.stopping = False
        self.worker = threading.Thread(target=self.work, name="agentsim-poses", daemon=True)
        live.every(self.period, self.take_snapshot)

    # ------------------------------------------------------------------------------------------- viewer
    def files(self) -> dict[str, Path]:
        """The viewer's files by URL path (:func:`viewer_files`)."""
        return viewer_files()

    def skeleton(self) -> dict:
        """The skeleton message (see the module's docstring)."""
        rest = body_points(self.body, self.body.rest_pose()[None])[0]
        return {"type": "skeleton", "joints": list(self.names), "parents": list(self.parents),
                "rest": np.round(rest, 3).tolist(),
                "face": [i for i, n in enumerate(self.names) if n.split(".")[0] in FACE],
                "ends": [i for i, n in enumerate(self.names) if n.endswith(".end")],
                "fps": self.fps, "period": self.period, "segments": body_segments(self.body)}

    def publish(self, server: Server) -> None:
        """Greet subscribers of ``"poses"`` with the skeleton and start sending them poses."""
        self.server = server
        server.routing.hello["poses"] = self.skeleton()
        from agentsim.live.environment import LiveEmotions

        def send(message: dict) -> None:  # from the realizer's thread
            if server.loop is not None:
                server.loop.call_soon_threadsafe(server.routing.broadcast, message, {"poses"})

        self.live.listeners.append(LiveEmotions(self.live, send))
        if not self.worker.is_alive():
            self.worker.start()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker thread."""
        with self.wake:
            self.stopping = True
            self.wake.notify()
        if self.worker.is_alive():
            self.worker.join(timeout)
        if self.process is not None:
            self.process.shutdown(wait=False, cancel_futures=True)
            self.process = None

    # ------------------------------------------------------------------------------------------- snapshot
    def take_snapshot(self, now: float) -> None:
        """In the realizer's thread: which blocks the poses may need, handed to the worker (nothing while
        nobody subscribes: nothing is evaluated then). Only references are taken here, a few microseconds
        a block; the worker reads their records (:meth:`read`)."""
        started = time.perf_counter()
        watched = self.watch(now) if self.subscribed() else None
        with self.wake:
            self.latest = (now, watched)
            self.wake.notify()
        self.snapshots.append(time.perf_counter() - started)

    def watch(self, now: float) -> tuple[list, list]:
        """The blocks not ended or ended less than :data:`FORGET` s ago, and those forgotten since the last
        time (whose shifts still hold a pose)."""
        runs = self.live.realizer.scheduler.book.all_runs
        if len(runs) > self.seen:
            self.watched += runs[self.seen:]
            self.seen = len(runs)
        kept, forgotten = [], []
        for run in self.watched:
            if run.state is REFUSED:
                continue
            if run.ended_at is not None and run.ended_at < now - FORGET:
                forgotten.append(run)
                continue
            kept.append(run)
        self.watched = kept
        return list(kept), forgotten

    def read(self, watched: tuple[list, list]) -> list:
        """The records of what :meth:`watch` found: of the blocks kept, and the latest shifts of the blocks
        forgotten (kept from then on)."""
        kept, forgotten = watched
        for run in forgotten:
            for record in record_behaviours(t for t in run.timed if t.behaviour.type in HOLDING):
                self.held[record.type].append(record)
        records = record_behaviours(t for run in kept for t in run.timed)
        for held in self.held.values():
            records += list(held)
        return records

    def records(self, now: float) -> list:
        """Records of the blocks not ended or ended less than :data:`FORGET` s ago, and the latest shifts
        of the blocks forgotten (:meth:`watch` and :meth:`read` at once)."""
        return self.read(self.watch(now))

    # ------------------------------------------------------------------------------------------- worker
    def subscribed(self) -> bool:
        """Whether a client of the server subscribed to the poses."""
        server = self.server
        if server is None or server.loop is None:
            return False
        return server.routing.wanted("poses")

    def work(self) -> None:
        """The worker thread: evaluate and send the frames due at each snapshot."""
        while True:
            with self.wake:
                while self.latest is None and not self.stopping and not self.live.closing:
                    self.wake.wait(0.2)
                if self.stopping or self.live.closing:
                    return
                now, watched = self.latest
                self.latest = None
            try:
                # the blocks are read while the realizer's thread goes on with them: a block changing under
                # the reading is read again at the next snapshot, a tenth of a second later
                records = self.read(watched) if watched is not None else None
                for k0, frames in self.catch_up(now, records, None if records is not None else False, LAG):
                    self.send(k0, frames)
                    self.rest(self.costs[-1][2])
            except Exception as exc:  # a fault of the viewer's must not stop the realizer: it is kept
                self.error = exc
                self.next_frame = int(math.floor(now * self.fps + 1e-9)) + 1

    def catch_up(self, now: float, records, subscribed: bool | None = None, lag: float | None = None):
        """The messages due at ``now`` given a snapshot's ``records``: ``(first frame, positions)`` for the
        frames from the last one sent up to ``now``, at most :data:`MAX_FRAMES` at a time; none, and nothing
        evaluated, while nobody subscribes (``subscribed``, by default :meth:`subscribed`): the frames due
        meanwhile are skipped. More than ``lag`` seconds behind, it skips to the last half second due."""
        due = int(math.floor(now * self.fps + 1e-9))
        if not (self.subscribed() if subscribed is None else subscribed):
            self.next_frame = due + 1
            return
        if lag is not None and due - self.next_frame + 1 > lag * self.fps:
            ahead = due - int(0.5 * self.fps) + 1
            self.skipped += ahead - self.next_frame
            self.next_frame = ahead
        while self.next_frame <= due:
            k0 = self.next_frame
            k1 = min(due, k0 + MAX_FRAMES - 1)
            started = time.perf_counter()
            frames, evaluated = self.evaluate(records, k0, k1)
            self.costs.append((k1 - k0 + 1, evaluated, time.perf_counter() - started))
            self.next_frame = k1 + 1
            yield k0, frames

    def rest(self, worked: float) -> None:
        """Wait in proportion to ``worked`` seconds of evaluation, keeping to :data:`SHARE` of a core."""
        deadline = time.monotonic() + worked * (1.0 - SHARE) / SHARE
        with self.wake:  # snapshots notify it too: wait out the whole rest unless it is stopping
            while not self.stopping and not self.live.closing and time.monotonic() < deadline:
                self.wake.wait(deadline - time.monotonic())

    def evaluate(self, records, k0: int, k1: int) -> tuple[np.ndarray, int]:
        """Joint positions (frames, points * 3) of frames ``k0`` to ``k1``, and how many frames it took: in
        the evaluator process if :meth:`start_process` started one, else here."""
        if self.process is not None:
            return self.process.submit(evaluate_window, records, k0, k1, self.fps, self.seed,
                                       self.lexicon, self.physics).result()
        return evaluate_window(records, k0, k1, self.fps, self.seed, self.lexicon, self.physics)

    def start_process(self) -> None:
        """Evaluate in a process of its own from now on (on another core, and not holding this one's
        interpreter lock, which the realizer's thread needs to keep time); it is started and warmed here."""
        import concurrent.futures
        import multiprocessing

        self.process = concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        self.process.submit(evaluate_window, [], 0, 0, self.fps, self.seed).result()

    def send(self, k0: int, frames: np.ndarray) -> None:
        """Hand a message of poses to the server's loop, to be sent when its last frame is due."""
        server = self.server
        loop = server.loop if server is not None else None
        if loop is None:
            return
        message = {"type": "poses", "time": k0 / self.fps, "index": k0, "fps": self.fps,
                   "frames": np.round(frames, 3).tolist()}
        last = (k0 + len(frames) - 1) / self.fps
        self.sent_frames += len(frames)

        def schedule() -> None:
            when = self.live.wall_time(last) + server.delay
            if when > loop.time() + 0.0005:
                loop.call_at(when, server.routing.broadcast, message, {"poses"}, True)
            else:
                server.routing.broadcast(message, {"poses"}, True)

        try:
            loop.call_soon_threadsafe(schedule)
        except RuntimeError:  # the loop is closed: the server has stopped
            pass

    def cost(self) -> dict:
        """What evaluating cost so far (recent evaluations): ms per message, per frame sent, per frame
        evaluated; and the snapshot's ms in the realizer's thread (mean, max)."""
        costs = list(self.costs)
        snaps = list(self.snapshots)
        sent = sum(c[0] for c in costs)
        evaluated = sum(c[1] for c in costs)
        seconds = sum(c[2] for c in costs)
        return {"messages": len(costs), "frames": sent, "evaluated": evaluated, "skipped": self.skipped,
                "ms_per_message": 1000 * seconds / max(len(costs), 1),
                "ms_per_frame": 1000 * seconds / max(sent, 1),
                "ms_max": 1000 * max((c[2] for c in costs), default=0.0),
                "snapshot_ms": 1000 * sum(snaps) / max(len(snaps), 1),
                "snapshot_ms_max": 1000 * max(snaps, default=0.0)}
