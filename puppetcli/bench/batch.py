"""``puppetcli bench --batch``: a batch's throughput on 1 and 2 local workers, and its cost
per job against ``pose`` run in-process, in the same run.

The jobs: the doll's example scripts (rigs/doll.yaml, scripts/*.yaml that run on it),
``repeat`` times each, with ``pose``'s default outputs (keys, BVH, trace, pictures).

- *alone*: each job as ``pose`` does it (the rig and script read, the run, the
  outputs) in this process, one after another, the compiled solver loaded once
  beforehand, OpenCV on one thread as in a worker: the bare cost of the work on a core.
- *N workers*: ``puppetcli.batch.run`` on a fresh ``LocalPool(N)`` into an empty folder,
  timed whole (workers started, the solver loaded in each, the summary written).

Figures: jobs per minute and steps/s of each; the batch's speed-up from 1 to 2 workers;
its overhead per job, (batch time with 1 worker − alone) / jobs, and that over the
mean job alone; the workers' start (the first job's wall time inside a worker less the
same job alone).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from puppetcli.batch.jobs import jobs_from_scripts
from puppetcli.batch.run import LocalPool, run
from puppetcli.bench.scenes import ROOT
from puppetcli.rig.load import load_rig
from puppetcli.run.build import compile_engine
from puppetcli.run.pose import PoseOptions, plan_pose, run_pose, write_pose

RIG = ROOT / "rigs" / "doll.yaml"
SCRIPTS = ("wave", "kneel", "arm_push", "head_twist", "hand_on_table", "free_push")


@dataclass(frozen=True)
class BatchRow:
    """One way of running the jobs: wall seconds, jobs per minute, steps per second."""

    label: str
    jobs: int
    steps: int
    seconds: float
    jobs_per_min: float
    steps_per_s: float


def _alone(scripts: list[Path], folder: Path) -> tuple[float, int]:
    """(seconds, steps) of every job run here, one after another."""
    import cv2

    cv2.setNumThreads(1)  # a core's work, as a worker's
    compile_engine(plan_pose(load_rig(RIG), scripts[0], None).model)
    steps = 0
    start = time.perf_counter()
    for i, script in enumerate(scripts):
        planned = plan_pose(load_rig(RIG), script, None)  # as pose: the rig read per job
        planned.model = planned.model.with_options(engine="compiled")
        out = folder / f"{i}"
        out.mkdir(parents=True)
        result = run_pose(planned, out, PoseOptions())
        write_pose(out, planned, result, PoseOptions())
        steps += result.steps
    return time.perf_counter() - start, steps


def _row(label: str, jobs: int, steps: int, seconds: float) -> BatchRow:
    return BatchRow(label, jobs, steps, seconds, 60.0 * jobs / seconds, steps / seconds)


def _batch(scripts: list[Path], folder: Path, workers: int) -> tuple[float, int]:
    """(seconds, steps) of the jobs as a batch on a fresh LocalPool(workers)."""
    start = time.perf_counter()
    done = run(jobs_from_scripts(scripts, RIG, PoseOptions()), folder, LocalPool(workers))
    seconds = time.perf_counter() - start
    assert all(r["status"] == "ok" for r in done), [r["error"] for r in done]
    return seconds, sum(r["steps"] for r in done)


def measure_batch(repeat: int = 3, rounds: int = 3) -> tuple[list[BatchRow], dict[str, float]]:
    """The rows (alone, 1 worker, 2 workers: the best of ``rounds``, taken in turn round
    by round) and the derived figures."""
    scripts = [ROOT / "scripts" / f"{name}.yaml" for name in SCRIPTS] * repeat
    labels = ("alone (in-process pose)", "batch, 1 worker", "batch, 2 workers")
    best: dict[str, tuple[float, int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            folder = Path(tmp) / str(r)
            folder.mkdir()
            found = [_alone(scripts, folder / "alone"), _batch(scripts, folder / "one", 1),
                     _batch(scripts, folder / "two", 2)]  # fmt: skip
            for label, (seconds, steps) in zip(labels, found, strict=True):
                if label not in best or seconds < best[label][0]:
                    best[label] = (seconds, steps)
    rows = [_row(label, len(scripts), best[label][1], best[label][0]) for label in labels]
    alone, one, two = rows
    per_job = (one.seconds - alone.seconds) / one.jobs
    figures = {
        "speedup_2_over_1": one.seconds / two.seconds,
        "overhead_per_job_s": per_job,
        "overhead_share": per_job / (alone.seconds / alone.jobs),
    }
    return rows, figures


def format_batch(rows: list[BatchRow], figures: dict[str, float]) -> str:
    from puppetcli.feel.report import aligned

    head = ["run", "jobs", "steps", "seconds", "jobs/min", "steps/s"]
    body = [[r.label, str(r.jobs), f"{r.steps:,}", f"{r.seconds:.2f}", f"{r.jobs_per_min:.1f}",
             f"{r.steps_per_s:,.0f}"] for r in rows]  # fmt: skip
    return "\n".join([
        aligned([head, *body]),
        f"2 workers over 1: {figures['speedup_2_over_1']:.2f}x",
        f"overhead per job (1 worker, its start included): {figures['overhead_per_job_s']:.3f} s"
        f" = {100.0 * figures['overhead_share']:.1f} % of a job alone",
    ])  # fmt: skip
