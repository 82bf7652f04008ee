"""The physical body simulated in a process of its own, beside the animation that feeds it.

MuJoCo steps without Python's lock, but a thread that steps the body has to take the lock back after each
call of ``mj_step`` from the thread that evaluates the animation, which holds it while it works: on two
threads the two mostly take turns. :class:`PhysicsProcess` steps the body in a child process instead. The
animation's frames are sent to it as they are evaluated; it makes the physical body's frames with a
:class:`~agentsim.physics.simulation.Stepper`, as one thread would, with the same numbers in the same order,
and sends them back. So the frames are the same, and the two halves use two cores.

:func:`physics_process` starts one where a child may be forked: a process with no thread but its main one
(a child forked then finds no lock held by a thread copied half-way) that is not a daemonic one. A caller
starts it early (the conductor does, before its piece plays), so that the child has imported MuJoCo by the
time the frames come; it serves one run of frames.
"""

from __future__ import annotations

import multiprocessing
import queue
import threading

import numpy as np

from agentsim.core.children import leave_interrupts_to_the_parent, may_fork

__all__ = ["PhysicsProcess", "physics_process"]


def physics_process() -> PhysicsProcess | None:
    """A :class:`PhysicsProcess` where this process may fork a child
    (:func:`~agentsim.core.children.may_fork`), else None."""
    return PhysicsProcess() if may_fork() else None


def _read(connection, frames: queue.Queue) -> None:
    """The child's reader: every message of the parent into ``frames`` as it comes (so that the parent,
    sending frames, never waits for the simulation), and None when the parent has gone."""
    try:
        while True:
            frames.put(connection.recv())
    except (EOFError, OSError):
        frames.put(None)


def _serve(connection, parents) -> None:
    """The child: ``("start", body, fps, times, controllers, pushes)``, then ``("frames", array)`` for each
    block of the animation's frames and ``("finish",)``; it answers ``("made", first, array)`` with the
    physical frames each block made, then ``("done", PhysicsResult)``, or ``("failed", text)``.
    ``parents``: the parent's end of the pipe, which the fork copied, closed here first (held open, it would
    keep the child from seeing the parent go)."""
    parents.close()
    leave_interrupts_to_the_parent()  # (a terminal's Ctrl-C: the parent ends, and with it this child)
    from agentsim.physics.simulation import Stepper

    import mujoco  # noqa: F401  (imported while the parent goes on, before the frames come)

    messages: queue.Queue = queue.Queue()
    threading.Thread(target=_read, args=(connection, messages), daemon=True).start()
    try:
        start = messages.get()
        if start is None or start[0] != "start":
            return
        made: list[np.ndarray] = []
        stepper = Stepper(*start[1:], lambda k, pose: made.append(pose))
        first = 0
        while True:
            message = messages.get()
            if message is None:
                return
            if message[0] == "frames":
                stepper.feed(message[1])
                result = None
            else:
                result = stepper.finish()
            if made:
                connection.send(("made", first, np.array(made)))
                first += len(made)
                made.clear()
            if result is not None:
                connection.send(("done", result))
                return
    except (EOFError, BrokenPipeError):  # the parent has gone
        return
    except Exception as exc:
        try:
            connection.send(("failed", f"{type(exc).__name__}: {exc}"))
        except OSError:
            pass


class PhysicsProcess:
    """A child process that simulates the physical body of one run of frames: :meth:`start`, :meth:`feed`
    the animation's frames in order (it does not wait), take the frames made so far with :meth:`made`, and
    the rest and the :class:`~agentsim.physics.simulation.PhysicsResult` with :meth:`finish`. What went wrong
    in the child is raised (RuntimeError) where frames are taken."""

    def __init__(self) -> None:
        context = multiprocessing.get_context("fork")
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_serve, name="physical body", daemon=True,
                                        args=(child, self._connection))
        self._process.start()
        child.close()
        self._started = False

    def start(self, body, fps: float, times: np.ndarray, controllers: list, pushes: list) -> None:
        """Begin the run of frames at ``times`` (the arguments of a
        :class:`~agentsim.physics.simulation.Stepper`); once only."""
        if self._started:
            raise RuntimeError("a PhysicsProcess simulates one run of frames")
        self._started = True
        self._send(("start", body, float(fps), np.asarray(times, dtype=float), list(controllers), list(pushes)))

    def feed(self, block: np.ndarray) -> None:
        """The animation's next frames."""
        self._send(("frames", np.asarray(block, dtype=float)))

    def _send(self, message: tuple) -> None:
        try:
            self._connection.send(message)
        except (BrokenPipeError, ConnectionResetError):  # the child has ended: say why
            while True:
                self._take(wait=True)

    def _take(self, wait: bool) -> tuple:
        try:
            message = self._connection.recv() if wait or self._connection.poll() else None
        except EOFError:
            raise RuntimeError("the physical body's process ended before its frames were made") from None
        if message is not None and message[0] == "failed":
            raise RuntimeError(f"the physical body's simulation failed: {message[1]}")
        return message

    def made(self) -> list[tuple[int, np.ndarray]]:
        """The physical frames made since the last call, as ``(first frame, poses)``, without waiting."""
        out = []
        while (message := self._take(wait=False)) is not None:
            out.append(message[1:])
        return out

    def finish(self, made) -> object:
        """Hand every frame not yet taken to ``made(first, poses)`` and return the run's
        :class:`~agentsim.physics.simulation.PhysicsResult` once the child has made the last frames (then
        :meth:`close` it)."""
        self._send(("finish",))
        while True:
            message = self._take(wait=True)
            if message[0] == "done":
                return message[1]
            made(*message[1:])

    def close(self) -> None:
        """End the child (it ends by itself once its run is over or its parent has gone)."""
        self._connection.close()
        self._process.join(timeout=5)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()

    def __del__(self) -> None:
        process = getattr(self, "_process", None)
        if process is not None and process.is_alive() and not self._connection.closed:
            self._connection.close()
