"""One batch job, as a worker runs it: ``pose``'s run and outputs into the job's folder,
written whole or not at all, and the job's summary row.

The job runs in ``ROOT/.JOB.partial-PID``; when its files are written (the keys taken
before a failure too), ``job.json`` (its row and input hashes) goes in last and the
folder is renamed to ``ROOT/JOB``, replacing an older one.  So ``ROOT/JOB`` with a
``job.json`` is always a finished job's complete output.  A job that cannot start (a
rig or script with an error) writes nothing; its row says why.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import time
from dataclasses import asdict
from pathlib import Path

from puppetcli.batch.jobs import Job, apply_overrides, input_hashes
from puppetcli.errors import Interrupted, PuppetError, one_line
from puppetcli.jsontext import json_text
from puppetcli.outputs import write_text_atomic
from puppetcli.rig.load import rig_from_text
from puppetcli.run.pose import plan_pose, run_pose, write_pose
from solver.errors import SimulationError

__all__ = ["FIELDS", "JOB_FILE", "finished", "run_job", "worker_ready"]

JOB_FILE = "job.json"
# the summary's columns, in order
FIELDS = ("job", "status", "rig", "script", "inputs", "rig_hash", "script_hash",
          "options_hash", "solver_hash", "keys", "failed_expectations", "simulated_s",
          "wall_s", "steps", "steps_per_s", "attempts", "worker", "error")  # fmt: skip

_READY: set[int] = set()  # processes whose compiled solver is loaded


def worker_ready(model) -> None:
    """Load (or build) the compiled solver in this process once, with ``model``'s step: a
    worker then runs many jobs on it.  A worker is one core's: OpenCV draws on one thread
    (the solver runs on one), so N workers use N cores and do not contend."""
    if os.getpid() in _READY:
        return
    import cv2

    from puppetcli.run.build import compile_engine

    cv2.setNumThreads(1)
    compile_engine(model)
    _READY.add(os.getpid())


def engine_stamp() -> str:
    """The solver sources' fingerprint: outputs depend on them."""
    from solver.jit import fingerprint

    return fingerprint()


def _row(job: Job, status: str, **facts) -> dict:
    row = dict.fromkeys(FIELDS)
    row.update(job=job.id, status=status, rig=str(job.rig), script=str(job.script), **facts)
    return row


def finished(root: Path, job: Job) -> dict | None:
    """What ``job.json`` of ``job``'s finished output in ``root`` holds (its row, input
    hashes, options, overrides), or None."""
    path = root / job.id / JOB_FILE
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _publish(stage: Path, final: Path) -> None:
    """Put the finished folder ``stage`` at ``final``, replacing an older one."""
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    if final.exists():
        os.replace(final, old)
    os.replace(stage, final)
    shutil.rmtree(old, ignore_errors=True)


def run_job(job: Job, root: Path, attempt: int = 1) -> dict:
    """Run ``job`` into ``root/job.id``: its summary row (never raises for the job's own
    failures: bad input, a numerical breakdown, failed expectations)."""
    start = time.perf_counter()
    where = {"attempts": attempt, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    if job.error is not None:
        return _row(job, "bad input", error=job.error, **where)
    try:
        text = apply_overrides(job.rig.read_text(encoding="utf-8"), job.overrides)
        hashes = input_hashes(job, text, engine_stamp())
        spec = rig_from_text(text, str(job.rig))
        planned = plan_pose(spec, job.script, job.options.step)
    except (PuppetError, OSError, ValueError) as exc:
        return _row(job, "bad input", error=one_line(str(exc)), **where)
    worker_ready(planned.model)
    planned.model = planned.model.with_options(engine="compiled")
    stage = root / f".{job.id}.partial-{os.getpid()}"
    shutil.rmtree(stage, ignore_errors=True)
    try:
        stage.mkdir(parents=True)
        result = run_pose(planned, stage, job.options)
        if isinstance(result.error, Interrupted):  # Ctrl-C: nothing of it is kept
            shutil.rmtree(stage, ignore_errors=True)
            return _row(job, "interrupted", error=one_line(str(result.error)), **where)
        write_pose(stage, planned, result, job.options)
    except (PuppetError, OSError) as exc:  # the job's outputs could not be written
        shutil.rmtree(stage, ignore_errors=True)
        return _row(job, "output error", error=one_line(str(exc)), **where)
    failed = [r.message for r in result.expectations if not r.passed]
    status = "ok"
    if isinstance(result.error, SimulationError):
        status = "simulation error"
    elif result.error is not None:
        status = "stopped"
    elif failed:
        status = "expectation failed"
    wall = time.perf_counter() - start
    error = one_line(str(result.error)) if result.error is not None else (
        one_line(f"{len(failed)} failed: {failed[0]}") if failed else None)  # fmt: skip
    row = _row(
        job, status, inputs=hashes["inputs"], rig_hash=hashes["rig"],
        script_hash=hashes["script"], options_hash=hashes["options"],
        solver_hash=hashes["solver"], keys=len(result.keys), failed_expectations=len(failed),
        simulated_s=round(float(result.state.time), 9), wall_s=wall, steps=result.steps,
        steps_per_s=result.steps / result.wall_time if result.wall_time > 0 else None,
        error=error, **where,
    )  # fmt: skip
    facts = {"row": row, "hashes": hashes, "options": asdict(job.options),
             "overrides": [[k, v] for k, v in job.overrides]}  # fmt: skip
    write_text_atomic(stage / JOB_FILE, json_text(facts))
    _publish(stage, root / job.id)
    return row
