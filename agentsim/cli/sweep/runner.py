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
                       the grid's order (``strategy=best,seed=1,jitter=0.03``; :func:`~agentsim.cli.
                       sweep.spec.output_folders` says how names that would clash or be too long end)
=====================  ================================================================================

A point that fails is a row with its error and is not cached: a rerun tries it again. A worker that dies
takes its points with it, and the scheduler runs them on another worker (up to Dask's
``distributed.scheduler.allowed-failures`` deaths per point; beyond that the point fails); the sweep says
on stderr how many points were run again so, and the ``attempts`` column of the results counts the runs
of each point (1 where no worker was lost under it; a point from the cache keeps the count of its run).

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
from agentsim.cli.sweep.spec import Point, Spec, output_folders, project_version
from agentsim.errors import AgentsimError, Unavailable
from agentsim.written import clear_partials
from agentsim.media.files import write_text

#: How long to wait for a scheduler to answer and for its first worker to join (seconds).
CONNECT_TIMEOUT = 30.0


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


def cached_outcomes(folder: Path, points: list[Point]) -> dict[str, dict]:
    """The finished points of ``points`` that ``folder/points/`` holds, by key."""
    found = {}
    for point in points:
        path = folder / "points" / f"{point.key}.json"
        if point.key in found or not path.is_file():
            continue
        try:
            outcome = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue  # half written when a sweep was killed: computed again
        if outcome.get("status") == "ok":
            found[point.key] = outcome
    return found


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
    distributed()
    try:
        (folder / "points").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AgentsimError(f"cannot create the sweep folder {str(folder)!r}: {exc}") from None
    for where in (folder, folder / "points"):  # what a killed sweep was writing: never whole, never read
        clear_partials(where)
    write_text(folder / "sweep.json", json.dumps(spec.to_json(), indent=2, default=str) + "\n")
    outcomes = cached_outcomes(folder, spec.points)
    cached = len({p.key for p in spec.points if p.key in outcomes})
    todo: dict[str, list[Point]] = {}
    for point in spec.points:
        if point.key not in outcomes:
            todo.setdefault(point.key, []).append(point)
    total = cached + len(todo)
    failed = 0
    startup = compute = 0.0
    if todo:
        mine = project_version()
        out_at = len(spec.command) if spec.takes_out else None
        bar = progress_bar(total, cached, quiet)
        connecting = time.perf_counter()
        with bar, connect(workers, scheduler) as client:
            sending = time.perf_counter()
            startup = sending - connecting
            futures = {}
            kept = output_folders(spec.points)
            for key, (point, *_) in todo.items():
                keep = str((folder / "outputs" / kept[key]).resolve()) if spec.keep_outputs else None
                futures[client.submit(run_point, list(point.argv), out_at, keep, key=f"agentsim-point-{key}",
                                      pure=False)] = point
            pending = set(futures)
            try:
                for future, outcome in distributed().as_completed(futures, with_results=True, raise_errors=False):
                    pending.discard(future)
                    point = futures[future]
                    if isinstance(outcome, BaseException):
                        outcome = failure(outcome)
                    elif outcome.get("version") not in (None, mine):
                        outcome = {**outcome, "status": "failed", "result": None,
                                   "error": f"the worker ran agentsim {outcome['version']}, not {mine}"}
                    outcome = {**outcome, "attempts": 1}  # unless a lost worker is found under it below
                    if outcome["status"] == "ok":
                        save(folder, point, outcome)
                    else:
                        failed += 1
                    outcomes[point.key] = outcome
                    bar.set_postfix(failed=failed, refresh=False)
                    bar.update(1)
                compute = time.perf_counter() - sending
                retried = {k: n for k, n in attempts(client, futures).items() if n > 1}
                for future, point in futures.items():
                    if future.key in retried:
                        outcomes[point.key] = {**outcomes[point.key], "attempts": retried[future.key]}
                        if outcomes[point.key]["status"] == "ok":
                            save(folder, point, outcomes[point.key])
                again = len(retried)
                if again:
                    print(f"agentsim: a worker was lost under {again} point{'s' if again > 1 else ''}, run again "
                          f"on another worker (the 'attempts' column of results.csv counts the runs)",
                          file=sys.stderr)
            finally:
                if pending:  # interrupted: nothing keeps running for a sweep that stopped
                    client.cancel(list(pending))
    rows = [results.make_row(p, outcomes[p.key]) for p in spec.points]
    parquet, csv = results.write(results.frame(rows, list(spec.grid)), folder)
    return Outcome(points=len(spec.points), computed=len(todo), cached=cached,
                   failed=sum(row["status"] != "ok" for row in rows),
                   seconds=time.perf_counter() - started, parquet=parquet, csv=csv, startup_seconds=startup,
                   compute_seconds=compute)
