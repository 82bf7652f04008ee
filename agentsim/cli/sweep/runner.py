"""A sweep's run: the points missing from the folder's cache sent to Dask as tasks, on a ``LocalCluster``
of ``workers`` processes or through an existing scheduler, with a progress bar; the results written.

The folder (``--out DIR``) holds:

=====================  ================================================================================
``points/<key>.json``  each point that finished, written as it finishes (its command's JSON, its time,
                       worker and the project version): the cache a rerun reads, so that a rerun into
                       the folder computes only what is missing and a killed sweep resumes
``results.parquet``    one row per point of the spec (:mod:`agentsim.cli.sweep.results`), and the same
``results.csv``        as CSV; written when the sweep ends
``sweep.json``         the spec as read (command, grid, fixed options, report settings), for
                       ``agentsim sweep report``
``outputs/<point>/``   with ``keep_outputs = true``: each point's ``--out`` folder, named by its values in
                       the grid's order (``strategy=best,seed=1,jitter=0.03``; :class:`~agentsim.cli.
                       sweep.spec.OutputFolders` says how names that would clash or be too long end)
=====================  ================================================================================

The points are made as they are sent (:class:`~agentsim.cli.sweep.spec.Points`), and only
:data:`AHEAD_PER_WORKER` points per worker are sent ahead of the results: a grid of a million points starts
its first point at once. The sweep holds the points on their way and the failed ones' outcomes; the others'
are read back from ``points/`` when the results are written, :data:`~agentsim.cli.sweep.results.BATCH_ROWS`
rows at a time. (Dask's scheduler keeps a little of every task it was sent, about 0.7 kB: with a local
cluster it runs in this process.)

A point that fails is a row with its error and is not cached: a rerun tries it again. A worker that dies
takes its points with it, and the scheduler runs them on another worker (up to Dask's
``distributed.scheduler.allowed-failures`` deaths per point; beyond that the point fails); the sweep says
on stderr how many points were run again so, and the ``attempts`` column of the results counts the runs
of each point (1 where no worker was lost under it; a point from the cache keeps the count of its run).
The local cluster gives a worker one point at a time (Dask's ``worker-saturation`` 1.0; its default sends
a second one to wait there): a worker that dies loses only the point it was running, and the count stays true.

The local cluster (``--workers``) talks TLS with credentials made for it alone
(``distributed.Security.temporary()``: a certificate and key held in memory, never written): another user of
the machine cannot join it or run code in its workers. ``--scheduler`` reaches a scheduler with the
credentials of Dask's configuration (``distributed.comm.tls.*``).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from agentsim.cli.sweep import results
from agentsim.cli.sweep.point import run_point, worker_info
from agentsim.cli.sweep.spec import OutputFolders, Point, Spec, project_version
from agentsim.errors import AgentsimError, Unavailable
from agentsim.written import clear_partials
from agentsim.media.files import write_text

#: How long to wait for a scheduler to answer and for its first worker to join (seconds).
CONNECT_TIMEOUT = 30.0
#: How many points per worker are sent to the scheduler ahead of the results (at least :data:`MIN_AHEAD`):
#: enough that no worker waits for its next point, few enough that a long grid holds only these.
AHEAD_PER_WORKER = 4
MIN_AHEAD = 16
#: How many finished points are kept before the scheduler is asked how many times it ran them (and lets
#: them go).
ATTEMPTS_BATCH = 64


@dataclass
class Outcome:
    """What a sweep did."""

    points: int
    computed: int
    cached: int
    failed: int
    seconds: float
    parquet: Path
    csv: Path
    startup_seconds: float = 0.0  # starting or reaching the cluster and checking its workers
    compute_seconds: float = 0.0  # from the first point sent to the last result


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def distributed():
    """The ``distributed`` module, or a message saying what to install."""
    try:
        import distributed as dd
    except ImportError:
        raise Unavailable("agentsim sweep runs its points on Dask: pip install 'dask[distributed]'") from None
    return dd


@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None):
    """A Dask client: on a new ``LocalCluster`` of ``workers`` processes with one thread each, or on the
    scheduler at ``scheduler`` (``tcp://host:port``) once a worker has joined it."""
    dd = distributed()
    import dask  # installed with distributed

    with contextlib.ExitStack() as stack:
        if scheduler:
            try:
                client = stack.enter_context(dd.Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise AgentsimError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
            try:
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
            except (TimeoutError, dd.TimeoutError):
                raise AgentsimError(f"no worker joined the Dask scheduler at {scheduler} within "
                                    f"{CONNECT_TIMEOUT:g} s: start some with 'dask worker {scheduler} "
                                    f"--nthreads 1'") from None
        else:
            # one task on a worker at a time (Dask's default sends a second one to wait there): a worker
            # that dies then loses only the point it was running, and the attempts counted stay true
            stack.enter_context(dask.config.set({"distributed.scheduler.worker-saturation": 1.0}))
            cluster = stack.enter_context(dd.LocalCluster(
                n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                security=dd.Security.temporary(), protocol="tls://", host="127.0.0.1",
                # Dask's own log lines stay off the terminal: a worker's heartbeat that races the cluster's
                # shutdown is logged as an error with its traceback although nothing is lost; what does go
                # wrong reaches the sweep as a failed point or a lost worker, and is reported as such
                dashboard_address=None, silence_logs=logging.CRITICAL))
            client = stack.enter_context(dd.Client(cluster))
        check_workers(client, scheduler or "the local cluster")
        yield client


def check_workers(client, where: str) -> None:
    """Every worker can run the commands and runs this project version (else one line before any point)."""
    mine = project_version()
    try:
        infos = client.run(worker_info)
    except Exception as exc:  # noqa: BLE001 - the workers cannot import agentsim, or run other code
        raise AgentsimError(f"the workers of {where} cannot run agentsim: {type(exc).__name__}: {exc}") from None
    for address, info in infos.items():
        if info["version"] != mine:
            raise AgentsimError(f"the worker {address} runs agentsim {info['version']}, this one is {mine}: give "
                                f"the workers the same checkout")


def cached_outcome(folder: Path, key: str) -> dict | None:
    """The finished point of key ``key`` that ``folder/points/`` holds, or None."""
    path = folder / "points" / f"{key}.json"
    if not path.is_file():
        return None
    try:
        outcome = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None  # half written when a sweep was killed: computed again
    return outcome if outcome.get("status") == "ok" else None


def save(folder: Path, point: Point, outcome: dict) -> None:
    write_text(folder / "points" / f"{point.key}.json", json.dumps({**outcome, "argv": list(point.argv)}) + "\n")


def attempts(client, futures) -> dict[str, int]:
    """How many times the scheduler ran each future's task: one, and one more for each worker that died
    under it (the scheduler's count of the task's "suspicious" deaths)."""
    keys = [future.key for future in futures]

    def counted(dask_scheduler, keys=keys):
        return {k: dask_scheduler.tasks[k].suspicious + 1 for k in keys if k in dask_scheduler.tasks}

    try:
        return client.run_on_scheduler(counted)
    except Exception:  # noqa: BLE001 - a scheduler that cannot say (another version): no count rather than none
        return {}


def failure(exc: BaseException) -> dict:
    """The outcome of a point whose task did not return (its workers died, or it was cancelled)."""
    message = f"{type(exc).__name__}: {exc}".strip()
    return {"status": "failed", "error": " ".join(message.split()), "result": None, "seconds": None, "worker": None}


def progress_bar(total: int, done: int, quiet: bool):
    """A bar on stderr: points done of all, failed ones, and the time left."""
    from tqdm import tqdm

    return tqdm(total=total, initial=done, desc="sweep", unit="point", file=sys.stderr, disable=quiet,
                mininterval=0.5, dynamic_ncols=True, postfix={"failed": 0})


def run(spec: Spec, folder: Path, workers: int | None = None, scheduler: str | None = None,
        quiet: bool = False) -> Outcome:
    """Run the points of ``spec`` that ``folder`` lacks and write the results there."""
    started = time.perf_counter()
    results.pandas()  # a missing pandas or pyarrow is said before any work, like a missing dask
    dd = distributed()
    try:
        (folder / "points").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AgentsimError(f"cannot create the sweep folder {str(folder)!r}: {exc}") from None
    for where in (folder, folder / "points"):  # what a killed sweep was writing: never whole, never read
        clear_partials(where)
    write_text(folder / "sweep.json", json.dumps(spec.to_json(), indent=2, default=str) + "\n")
    points = spec.points
    failed: dict[str, dict] = {}  # by key, the outcomes of the points that failed; the others are in points/
    sent: dict = {}  # future -> point, of the points sent and not yet finished
    in_flight: set[str] = set()  # their keys
    counts = {"cached": 0, "computed": 0, "again": 0}
    bar = None

    def to_compute():
        """The first point of each command line that the cache lacks, in the grid's order; the cached ones
        are counted on the way."""
        for point in points.firsts():
            if point.key in in_flight or point.key in failed:  # two axes' values that give one command line
                continue
            if cached_outcome(folder, point.key) is None:
                yield point
                continue
            counts["cached"] += 1
            if bar is not None:
                bar.update(1)

    todo = to_compute()
    first = next(todo, None)
    startup = compute = 0.0
    if first is not None:
        mine = project_version()
        out_at = len(spec.command) if spec.takes_out else None
        folders = OutputFolders(points) if spec.keep_outputs else None
        bar = progress_bar(points.distinct, counts["cached"], quiet)
        connecting = time.perf_counter()
        with bar, connect(workers, scheduler) as client:
            sending = time.perf_counter()
            startup = sending - connecting
            ahead = max(MIN_AHEAD, AHEAD_PER_WORKER * (workers or len(client.scheduler_info()["workers"]) or 1))
            finished = dd.as_completed(with_results=True, raise_errors=False)

            def send(point: Point) -> None:
                keep = str((folder / "outputs" / folders.of(point)).resolve()) if folders is not None else None
                future = client.submit(run_point, list(point.argv), out_at, keep, key=f"agentsim-point-{point.key}",
                                       pure=False)
                sent[future] = point
                in_flight.add(point.key)
                finished.add(future)
                counts["computed"] += 1

            def send_more() -> None:
                while len(sent) < ahead:
                    point = next(todo, None)
                    if point is None:
                        return
                    send(point)

            unasked: list = []  # finished points whose runs the scheduler has not been asked to count

            def ask_attempts() -> None:
                retried = {k: n for k, n in attempts(client, [f for f, _, _ in unasked]).items() if n > 1}
                for future, point, outcome in unasked:
                    if future.key in retried:
                        counts["again"] += 1
                        outcome = {**outcome, "attempts": retried[future.key]}
                        if outcome["status"] == "ok":
                            save(folder, point, outcome)
                        else:
                            failed[point.key] = outcome
                unasked.clear()  # the futures let go: the scheduler forgets their tasks

            send(first)
            send_more()
            try:
                for future, outcome in finished:
                    point = sent.pop(future)
                    in_flight.discard(point.key)
                    if isinstance(outcome, BaseException):
                        outcome = failure(outcome)
                    elif outcome.get("version") not in (None, mine):
                        outcome = {**outcome, "status": "failed", "result": None,
                                   "error": f"the worker ran agentsim {outcome['version']}, not {mine}"}
                    outcome = {**outcome, "attempts": 1}  # unless a lost worker is found under it below
                    if outcome["status"] == "ok":
                        save(folder, point, outcome)
                    else:
                        failed[point.key] = outcome
                    unasked.append((future, point, outcome))
                    if len(unasked) >= ATTEMPTS_BATCH:
                        ask_attempts()
                    bar.set_postfix(failed=len(failed), refresh=False)
                    bar.update(1)
                    send_more()
                compute = time.perf_counter() - sending
                ask_attempts()
                again = counts["again"]
                if again:
                    print(f"agentsim: a worker was lost under {again} point{'s' if again > 1 else ''}, run again "
                          f"on another worker (the 'attempts' column of results.csv counts the runs)",
                          file=sys.stderr)
            finally:
                if sent:  # interrupted: nothing keeps running for a sweep that stopped
                    client.cancel(list(sent))

    def rows():  # made anew from the cache and the failures, a point at a time
        for point in points:
            outcome = failed.get(point.key) or cached_outcome(folder, point.key)
            yield results.make_row(point, outcome or failure(AgentsimError(f"points/{point.key}.json is gone")))

    parquet, csv, table = results.write_rows(rows, list(spec.grid), folder)
    return Outcome(points=table.rows, computed=counts["computed"], cached=counts["cached"], failed=table.failed,
                   seconds=time.perf_counter() - started, parquet=parquet, csv=csv, startup_seconds=startup,
                   compute_seconds=compute)
