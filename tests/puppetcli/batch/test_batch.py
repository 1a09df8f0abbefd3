"""puppetcli batch: the same keyframes as pose run alone, locally and on a Dask cluster,
through a worker's death, resumed, with bad jobs reported and a parameter sweep.

Independent values: ``pose`` run alone by its command (the batch shares its run code,
so this checks the batch adds and loses nothing: same bytes); the rig's own value for a
swept parameter (a sweep point equal to it must give the rig's keyframes, bit for bit).
"""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from puppetcli.batch import LocalPool, dask_pool, run
from puppetcli.batch.jobs import jobs_from_scripts, read_manifest
from puppetcli.cli import cli
from puppetcli.run.pose import PoseOptions

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
SCRIPTS = [
    ROOT / "scripts" / f"{name}.yaml" for name in ("wave", "kneel", "arm_push", "head_twist")
]
QUICK = PoseOptions(no_render=True, no_trace=True)
FLAGS = ["--no-render", "--no-trace"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> list[Path]:
    """The example scripts and a session recorded from one of them."""
    folder = tmp_path_factory.mktemp("inputs")
    session = folder / "wave_session.mcap"
    out = CliRunner().invoke(cli, ["record", str(DOLL), str(SCRIPTS[0]), "-o", str(session)])
    assert out.exit_code == 0, out.output
    return [*SCRIPTS, session]


@pytest.fixture(scope="module")
def alone(inputs, tmp_path_factory) -> dict[str, bytes]:
    """keyframes.json of pose run alone on each input."""
    folder = tmp_path_factory.mktemp("alone")
    found = {}
    for path in inputs:
        out = CliRunner().invoke(cli, ["pose", str(DOLL), str(path), "-o", str(folder / path.stem),
                                       *FLAGS])  # fmt: skip
        assert out.exit_code == 0, out.output
        found[path.stem] = (folder / path.stem / "keyframes.json").read_bytes()
    return found


def _keys(outdir: Path, job: str) -> bytes:
    return (outdir / job / "keyframes.json").read_bytes()


def _summary(outdir: Path) -> list[dict]:
    with open(outdir / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_local_batch_gives_pose_alone_keyframes(inputs, alone, tmp_path):
    out = CliRunner().invoke(cli, ["batch", *map(str, inputs), "--rig", str(DOLL), "-o",
                                   str(tmp_path), "--workers", "2", *FLAGS, "--json"])  # fmt: skip
    assert out.exit_code == 0, out.output
    rows = json.loads(out.stdout)["jobs"]
    assert [r["job"] for r in rows] == [p.stem for p in inputs]
    for row in rows:
        assert row["status"] == "ok" and row["keys"] > 0 and row["steps"] > 0
        assert _keys(tmp_path, row["job"]) == alone[row["job"]], row["job"]
    summary = _summary(tmp_path)
    assert [r["job"] for r in summary] == [p.stem for p in inputs]
    assert all(len(r["inputs"]) == 16 and r["fresh"] == "True" for r in summary)
    assert not list(tmp_path.glob(".*"))  # no unfinished folders left


def test_resume_skips_finished_jobs_and_reruns_a_changed_one(inputs, tmp_path):
    scripts = []
    for path in inputs[:3]:
        shutil.copy(path, tmp_path / path.name)
        scripts.append(tmp_path / path.name)
    jobs = jobs_from_scripts(scripts, DOLL, QUICK)
    out = tmp_path / "out"
    first = run(jobs, out, LocalPool(2))
    assert all(r["status"] == "ok" and r["fresh"] for r in first)
    stamp = (out / "kneel" / "job.json").stat().st_mtime_ns
    second = run(jobs, out, LocalPool(2))
    assert [r["fresh"] for r in second] == [False, False, False]  # nothing ran
    assert [r["inputs"] for r in second] == [r["inputs"] for r in first]
    assert (out / "kneel" / "job.json").stat().st_mtime_ns == stamp
    with open(scripts[1], "a") as f:  # kneel changes (a comment: the bytes differ)
        f.write("# touched\n")
    third = run(jobs, out, LocalPool(2))
    assert [r["fresh"] for r in third] == [False, True, False]
    assert third[1]["script_hash"] != first[1]["script_hash"]
    assert third[1]["rig_hash"] == first[1]["rig_hash"]


def test_bad_jobs_in_a_manifest_are_reported_and_the_rest_complete(tmp_path):
    manifest = tmp_path / "jobs.yaml"
    manifest.write_text(
        "jobs:\n"
        f"  - {{rig: {DOLL}, script: {SCRIPTS[0]}, options: {{no_render: true}}}}\n"
        f"  - {{id: missing, rig: {DOLL}, script: nosuch.yaml}}\n"
        f"  - {{id: badopt, rig: {DOLL}, script: {SCRIPTS[1]}, options: {{fps: -1}}}}\n"
        f"  - {{id: badset, rig: {DOLL}, script: {SCRIPTS[1]}, set: {{joints.nosuch.kf: 2}}}}\n"
        f"  - {{id: badvalue, rig: {DOLL}, script: {SCRIPTS[1]}, set: {{joints.shin_r.kf: -5}}}}\n"
    )
    out = CliRunner().invoke(cli, ["batch", str(manifest), "-o", str(tmp_path / "out"),
                                   "--workers", "1", "--no-trace"])  # fmt: skip
    assert out.exit_code == 1, out.output
    rows = {r["job"]: r for r in _summary(tmp_path / "out")}
    assert rows["wave"]["status"] == "ok"
    assert (tmp_path / "out" / "wave" / "keyframes.json").is_file()
    for name, where in (("missing", "jobs[1]"), ("badopt", "jobs[2]"), ("badset", "nosuch"),
                        ("badvalue", "kf")):  # fmt: skip
        assert rows[name]["status"] == "bad input", rows[name]
        assert where in rows[name]["error"], rows[name]["error"]
        assert "\n" not in rows[name]["error"]
        assert not (tmp_path / "out" / name).exists()
    assert "Traceback" not in out.output


def test_sweep_sets_rig_values_and_the_rig_s_own_value_gives_its_keys(alone, tmp_path):
    out = CliRunner().invoke(cli, ["batch", str(SCRIPTS[0]), "--rig", str(DOLL), "-o",
                                   str(tmp_path), "--sweep", "joints.forearm_l.kf=150,40",
                                   *FLAGS])  # fmt: skip
    assert out.exit_code == 0, out.output
    # the doll's forearm_l has kf 150: that point is the doll itself
    assert _keys(tmp_path, "wave~kf=150") == alone["wave"]
    assert _keys(tmp_path, "wave~kf=40") != alone["wave"]


def test_local_worker_killed_mid_run_loses_nothing(inputs, alone, tmp_path):
    jobs = jobs_from_scripts(inputs, DOLL, QUICK)
    killed = []
    before = {p.pid for p in multiprocessing.active_children()}  # not this pool's

    def kill_one(row):
        if not killed:
            workers = [p for p in multiprocessing.active_children() if p.pid not in before]
            if workers:
                os.kill(workers[0].pid, signal.SIGKILL)
                killed.append(workers[0].pid)

    rows = run(jobs, tmp_path, LocalPool(2), retries=2, progress=kill_one)
    assert killed
    assert [r["status"] for r in rows] == ["ok"] * len(inputs)
    assert max(r["attempts"] for r in rows) == 2  # the jobs in flight ran again
    for row in rows:
        assert _keys(tmp_path, row["job"]) == alone[row["job"]]


def test_interrupted_batch_keeps_finished_jobs_and_a_consistent_summary(tmp_path):
    jobs = jobs_from_scripts(SCRIPTS, DOLL, QUICK)
    seen = []

    def stop(row):
        seen.append(row["job"])
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(jobs, tmp_path, LocalPool(1), progress=stop)
    summary = {r["job"]: r for r in _summary(tmp_path)}
    assert summary[seen[0]]["status"] == "ok"
    assert sorted(r["status"] for r in summary.values()) == ["not run"] * 3 + ["ok"]
    for name, row in summary.items():
        assert (tmp_path / name / "job.json").is_file() == (row["status"] == "ok")
    again = run(jobs, tmp_path, LocalPool(2))  # the rest, and nothing twice
    assert [r["fresh"] for r in again] == [r["job"] != seen[0] for r in again]
    assert not list(tmp_path.glob(".*"))


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as c,
        distributed.Client(c) as client,
    ):
        yield client


def test_dask_cluster_gives_the_same_outputs_and_survives_a_killed_worker(
    cluster, inputs, alone, tmp_path
):
    jobs = jobs_from_scripts(inputs, DOLL, QUICK)
    pids = cluster.run(os.getpid)  # worker address → process id
    killed: list[int] = []

    def killer():  # kill the first worker seen running a job
        deadline = time.monotonic() + 60.0
        while not killed and time.monotonic() < deadline:
            busy = [a for a, tasks in cluster.processing().items() if tasks]
            if busy:
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed.append(pids[busy[0]])
            time.sleep(0.05)

    thread = threading.Thread(target=killer)
    thread.start()
    rows = run(jobs, tmp_path, dask_pool(cluster), retries=2)
    thread.join()
    assert killed
    assert [r["status"] for r in rows] == ["ok"] * len(inputs)
    summary = _summary(tmp_path)
    assert len(summary) == len(inputs) and all(r["status"] == "ok" for r in summary)
    for row in rows:
        assert _keys(tmp_path, row["job"]) == alone[row["job"]]


def test_manifest_csv_reads_options_and_overrides(tmp_path):
    manifest = tmp_path / "jobs.csv"
    manifest.write_text(
        "id,rig,script,options,set\n"
        f"a,{DOLL},{SCRIPTS[0]},no_render=true;fps=24,joints.forearm_l.kf=75\n"
    )
    (job,) = read_manifest(manifest, PoseOptions())
    assert job.error is None and job.options.no_render and job.options.fps == 24.0
    assert job.overrides == (("joints.forearm_l.kf", 75),)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([str(SCRIPTS[0])], "is a script or session: give the rig with --rig"),
        (["nosuch/*.yaml", "--rig", str(DOLL)], "nosuch/*.yaml: expected scripts"),
        ([str(DOLL)], "is a script or session"),  # a rig is not a manifest: it needs --rig
    ],
)
def test_batch_usage_errors_are_one_line(args, message, tmp_path):
    out = CliRunner().invoke(cli, ["batch", *args, "-o", str(tmp_path)])
    assert out.exit_code in (1, 2) and message in out.output, out.output
    assert "Traceback" not in out.output


def test_a_manifest_without_jobs_is_refused(tmp_path):
    manifest = tmp_path / "jobs.yaml"
    manifest.write_text("jobs: 3\n")
    out = CliRunner().invoke(cli, ["batch", str(manifest), "-o", str(tmp_path / "o")])
    assert out.exit_code == 1
    assert out.output.strip() == f"error: {manifest}: expected a mapping with a 'jobs' list"


def test_job_ids_are_unique_even_against_ids_that_look_numbered():
    from puppetcli.batch.jobs import Job, unique_ids

    jobs = [Job(i, DOLL, SCRIPTS[0]) for i in ("a", "a-2", "a", "b c", ".x")]
    # the rule: a taken id gets -2, -3, … until free; unsafe characters become _
    assert [j.id for j in unique_ids(jobs)] == ["a", "a-2", "a-3", "b_c", "x"]


def test_a_job_whose_outputs_cannot_be_written_is_its_own_error(tmp_path, monkeypatch):
    from puppetcli.batch import work
    from puppetcli.outputs import OutputError

    def full(*args, **kwargs):
        raise OutputError("keyframes.json: No space left on device")

    monkeypatch.setattr(work, "write_pose", full)
    (job,) = jobs_from_scripts([SCRIPTS[0]], DOLL, QUICK)
    row = work.run_job(job, tmp_path)  # in this process: the patch applies
    assert row["status"] == "output error" and "No space left" in row["error"]
    assert list(tmp_path.iterdir()) == []  # nothing half-written left behind
