"""Running a batch: every job through one loop on an executor, a summary kept current.

The loop hands jobs to a ``concurrent.futures`` executor and takes their rows back as
they finish.  The embedded executor (``LocalPool``) is a pool of worker processes, one
per core by default, each loading the compiled solver once; a Dask cluster's is its
client's ``get_executor()`` (``dask_pool``).  The loop is the same for both:

- a job whose folder holds a finished run with the same input hashes is not run
  again (its row is kept, ``fresh`` false);
- a job's own failure (bad input, a numerical breakdown, failed expectations) is its
  row, and the batch goes on;
- a job whose worker died (the future raises) is run again, up to ``retries`` more
  times, elsewhere if the cluster has another worker (a local pool is restarted);
- summary.csv and summary.json are rewritten whole (atomically) as jobs finish, at
  most every ``SUMMARY_EVERY`` s (10,000 rows rewritten after every job would cost
  more than the jobs), and when the batch ends for any reason: each is a consistent
  snapshot, finished jobs and the others as ``not run``; a job's own ``job.json`` is
  written with its outputs;
- Ctrl-C stops the loop: finished jobs keep their complete folders, jobs in flight
  leave nothing behind (their unfinished folder is removed on the next run).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import csv
import io
import multiprocessing
import os
import shutil
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from puppetcli.batch.jobs import BatchError, Job, apply_overrides, input_hashes, unique_ids
from puppetcli.batch.work import FIELDS, engine_stamp, finished, run_job, worker_ready
from puppetcli.errors import PuppetError, one_line
from puppetcli.jsontext import json_text
from puppetcli.outputs import write_text_atomic
from puppetcli.rig.load import rig_from_text
from solver.model import build_model

__all__ = ["LocalPool", "dask_pool", "run"]

SUMMARY_EVERY = 2.0  # s: the summary is rewritten at most this often while jobs run


def _forking() -> bool:
    """Workers can be forked from this process: Linux, and no other thread running (a
    fork copies only the thread that calls it; a lock another holds would stay held)."""
    return sys.platform == "linux" and threading.active_count() == 1


@dataclass
class LocalPool:
    """The embedded executor: ``workers`` processes (default: one per core), each running
    job after job.  On Linux they are forked from this process once it has loaded the
    compiled solver (``prepare``), so they start with it loaded; elsewhere, or with
    other threads running, they start fresh (``spawn``) and load it on their first job."""

    workers: int | None = None

    @property
    def capacity(self) -> int:
        return self.workers or os.cpu_count() or 1

    @staticmethod
    def prepare(job: Job) -> None:
        """Load the compiled solver here, for forked workers to inherit (this process's
        OpenCV then draws on one thread too)."""
        if _forking():
            with contextlib.suppress(PuppetError, OSError, ValueError):  # the job's error
                text = apply_overrides(job.rig.read_text(encoding="utf-8"), job.overrides)
                worker_ready(build_model(rig_from_text(text, str(job.rig))))

    def start(self) -> cf.Executor:
        context = multiprocessing.get_context("fork" if _forking() else "spawn")
        return cf.ProcessPoolExecutor(self.capacity, mp_context=context)

    @staticmethod
    def stop(executor: cf.Executor) -> None:
        """Cancel what has not started and end the workers now (a job cut short leaves
        only its unfinished folder, removed by the next run)."""
        processes = list(getattr(executor, "_processes", None) or {})
        workers = [executor._processes[p] for p in processes]  # type: ignore[attr-defined]
        executor.shutdown(wait=False, cancel_futures=True)
        for worker in workers:
            worker.terminate()


@dataclass
class DaskPool:
    """A Dask cluster's executor (``distributed.Client.get_executor``); the cluster
    places the jobs and replaces a worker that dies."""

    client: object

    @property
    def capacity(self) -> int:
        return max(1, sum(self.client.nthreads().values()))  # type: ignore[attr-defined]

    @staticmethod
    def prepare(job: Job) -> None:
        """Nothing: each worker loads the solver on its first job."""

    def start(self) -> cf.Executor:
        return self.client.get_executor(pure=False)  # type: ignore[attr-defined]

    @staticmethod
    def stop(executor: cf.Executor) -> None:
        """Cancel the jobs not finished (the cluster's workers stay up)."""
        executor.shutdown(wait=False)


def dask_pool(scheduler: object, timeout: float = 10.0) -> DaskPool:
    """A DaskPool on a scheduler address (``tcp://HOST:PORT``) or an existing ``Client``."""
    try:
        from distributed import Client  # the optional 'cluster' extra
    except ImportError:
        raise BatchError("--scheduler: expected Dask distributed installed, got none "
                         "(pip install -e '.[cluster]')") from None  # fmt: skip
    if isinstance(scheduler, Client):
        return DaskPool(scheduler)
    try:
        return DaskPool(Client(str(scheduler), timeout=timeout))
    except (OSError, TimeoutError, ValueError) as exc:
        raise BatchError(
            f"--scheduler: expected a Dask scheduler at {scheduler}, "
            f"got {one_line(str(exc) or type(exc).__name__)}"
        ) from None


def _absolute(job: Job) -> Job:
    """Paths made absolute: a worker may run elsewhere (on a shared file system)."""
    if job.error is not None:
        return job
    return replace(job, rig=job.rig.resolve(), script=job.script.resolve())


def _not_run(job: Job) -> dict:
    row = dict.fromkeys(FIELDS)
    row.update(job=job.id, status="not run", rig=str(job.rig), script=str(job.script))
    return row


def _up_to_date(job: Job, root: Path, stamp: str) -> dict | None:
    """The finished row of ``job`` in ``root`` if its inputs' hashes still match."""
    if job.error is not None:
        return None
    done = finished(root, job)
    if done is None:
        return None
    try:
        text = apply_overrides(job.rig.read_text(encoding="utf-8"), job.overrides)
        now = input_hashes(job, text, stamp)
    except (OSError, ValueError):
        return None
    return done["row"] if done.get("hashes", {}).get("inputs") == now["inputs"] else None


def _write_summary(root: Path, rows: list[dict]) -> None:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=[*FIELDS, "fresh"], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(root / "summary.csv", out.getvalue())
    write_text_atomic(root / "summary.json", json_text({"jobs": rows}))


def _clean(root: Path) -> None:
    """Remove what jobs interrupted before left: ``.JOB.partial-*`` and ``.JOB.old-*``."""
    for stale in list(root.glob(".*.partial-*")) + list(root.glob(".*.old-*")):
        shutil.rmtree(stale, ignore_errors=True)


def run(
    jobs: list[Job], outdir: Path, executor: LocalPool | DaskPool | None = None,
    retries: int = 2, progress: Callable[[dict], None] | None = None, force: bool = False,
) -> list[dict]:  # fmt: skip
    """Run ``jobs`` into ``outdir`` (one folder each, and the summary): the summary's rows,
    in the jobs' order.  ``executor``: a LocalPool (default) or a DaskPool;
    ``progress`` is called with each row as its job ends (or is found up to date);
    ``force`` runs every job, up to date or not.
    KeyboardInterrupt propagates once the summary is written."""
    root = Path(outdir).resolve()
    root.mkdir(parents=True, exist_ok=True)
    _clean(root)
    jobs = [_absolute(j) for j in unique_ids(jobs)]
    rows, todo = _triage(jobs, root, progress, force)
    written = [time.monotonic()]

    def write() -> None:
        _write_summary(root, [rows[j.id] for j in jobs])
        written[0] = time.monotonic()

    def record(row: dict) -> None:
        rows[row["job"]] = {**row, "fresh": True}
        if time.monotonic() - written[0] >= SUMMARY_EVERY:
            write()
        if progress:
            progress(rows[row["job"]])

    write()
    try:
        if todo:
            _loop(executor or LocalPool(), todo, root, retries, record)
    finally:  # finished, failed or interrupted: the summary holds every finished job
        write()
    return [rows[j.id] for j in jobs]


def _triage(jobs: list[Job], root: Path, progress, force: bool) -> tuple[dict, deque]:
    """Each job's row so far (bad input, up to date, or not run) and the jobs to run (all
    that can run, with ``force``)."""
    stamp = engine_stamp()
    rows = {j.id: _not_run(j) for j in jobs}
    todo: deque[tuple[Job, int]] = deque()
    for job in jobs:
        if job.error is not None:  # nothing to run: its row says why
            rows[job.id] = {**run_job(job, root), "fresh": True}
        elif not force and (kept := _up_to_date(job, root, stamp)) is not None:
            rows[job.id] = {**kept, "fresh": False}
        else:
            todo.append((job, 1))
            continue
        if progress:
            progress(rows[job.id])
    return rows, todo


def _loop(pool, todo: deque, root: Path, retries: int, record: Callable[[dict], None]) -> None:
    """Submit up to the pool's capacity, record each row, rerun a job whose worker died."""
    pool.prepare(todo[0][0])
    executor = pool.start()
    flight: dict[cf.Future, tuple[Job, int]] = {}
    try:
        while todo or flight:
            while todo and len(flight) < pool.capacity:
                job, attempt = todo.popleft()
                flight[executor.submit(run_job, job, root, attempt)] = (job, attempt)
            done, _ = cf.wait(flight, return_when=cf.FIRST_COMPLETED)
            broken = False
            for future in done:
                job, attempt = flight.pop(future)
                try:
                    record(future.result())
                except Exception as exc:  # the worker (not the job) failed: run it again
                    broken |= isinstance(exc, cf.process.BrokenProcessPool)
                    if attempt <= retries:
                        todo.append((job, attempt + 1))
                    else:
                        row = _not_run(job)
                        row.update(status="worker died", attempts=attempt,
                                   error=one_line(f"{type(exc).__name__}: {exc}"))  # fmt: skip
                        record(row)
            if broken:  # a local worker died: the pool is unusable, start another
                for future, (job, attempt) in flight.items():
                    future.cancel()
                    todo.appendleft((job, attempt + 1))
                flight.clear()
                pool.stop(executor)
                executor = pool.start()
    finally:
        for future in flight:
            future.cancel()
        pool.stop(executor)
