"""feel --task: the built-in operator on the shipped tasks, its pointer arc, the device's
display capacity, and bad input.

Independent values: the targets read from the task files with json (not puppetcli's
reader) and compared with numpy's own quaternion algebra written here; the arc's closed
form (a rotation about a fixed pivot); the capacity checked with scipy's bounded least
squares (lsq_linear), another algorithm than the linear programme that found it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.optimize import lsq_linear

from puppetcli.cli import cli
from puppetcli.feel.operator import Hand, run_task
from puppetcli.feel.tasks import read_task
from puppetcli.rig.load import load_rig
from puppetcli.spidar.pointer import Motion
from puppetcli.spidar.presetfile import preset_from_option
from puppetcli.spidar.strings import structure_matrix
from puppetcli.spidar.tensions import least_capacity
from solver.model import build_model

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
TASKS = sorted((ROOT / "scripts" / "tasks").glob("*.json"))


def _angle(q: np.ndarray, r: np.ndarray) -> float:
    """The angle (rad) between unit quaternions q and r: 2 acos |q·r|."""
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(q, r)))))


def _targets(path: Path, joints: list[str]) -> list[np.ndarray]:
    doc = json.loads(path.read_text())
    return [np.array([key["bones"][name]["local"] for name in joints]) for key in doc["keys"]]


@pytest.fixture(scope="module")
def doll():
    return build_model(load_rig(DOLL)).with_options(engine="compiled")


def test_three_tasks_are_shipped():
    assert [t.stem for t in TASKS] == ["bend_elbow", "lift_knee", "turn_head"]


@pytest.mark.parametrize("task", TASKS, ids=lambda p: p.stem)
def test_six_dof_reaches_each_task_within_two_degrees(doll, task):
    joints = [doll.bone_names[b] for b in doll.joint_bone]
    keys = read_task(task, doll)
    results = run_task(doll, keys, Hand(dof=6))
    for result, target in zip(results, _targets(task, joints), strict=True):
        errors = [_angle(result.pose[j], target[j]) for j in range(len(joints))]
        # measured today: worst 0.58° (bend_elbow), 0.03° (turn_head), 0.68° (lift_knee)
        assert max(errors) < math.radians(2.0), (task.stem, np.degrees(errors).round(2))
        assert result.reached <= result.duration  # it got there, and said when
        np.testing.assert_allclose(result.final, errors, atol=1e-7)  # acos near 1: 4e-8


def test_three_dof_cannot_twist_the_head_and_says_so(doll):
    task = ROOT / "scripts" / "tasks" / "turn_head.json"
    joints = [doll.bone_names[b] for b in doll.joint_bone]
    (result,) = run_task(doll, read_task(task, doll), Hand(dof=3))
    head = joints.index("head")
    target = _targets(task, joints)[0]
    # a position grip on the head's axis has no lever about it: the head stays where it
    # settled, 30° from the target (the task's turn); measured 1e-16 rad off 30°
    assert _angle(result.pose[head], target[head]) == pytest.approx(math.radians(30.0), abs=6e-16)
    assert math.isnan(result.reached) and result.grips == 0


def test_a_motion_about_a_pivot_turns_on_an_arc_with_the_minimum_jerk_profile():
    pivot, start = np.array([0.1, 1.0, 0.0]), np.array([0.4, 1.2, 0.1])
    axis, angle = np.array([0.0, 0.6, 0.8]), 0.9
    arc = Motion(2.0, 1.5, start, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), axis * angle, pivot)
    times = np.array([2.0, 2.75, 3.5, 4.0])
    pos, q = arc.poses(times)
    radius = np.linalg.norm(pos - pivot, axis=1)
    np.testing.assert_allclose(radius, np.linalg.norm(start - pivot), rtol=1.5e-15)  # 3.0e-16
    for k, done in enumerate((0.0, 0.5, 1.0, 1.0)):  # min-jerk: half-way at half time
        a = angle * done  # Rodrigues' formula about the axis through the pivot
        v = start - pivot
        turned = (v * math.cos(a) + np.cross(axis, v) * math.sin(a)
                  + axis * (axis @ v) * (1.0 - math.cos(a)))  # fmt: skip
        # measured 3.5e-17 m and 5.6e-17
        np.testing.assert_allclose(pos[k], pivot + turned, rtol=0, atol=3e-16)
        np.testing.assert_allclose(q[k], [math.cos(a / 2), *(axis * math.sin(a / 2))], rtol=0,
                                   atol=3e-16)  # fmt: skip


def test_device_capacity_is_the_largest_force_its_strings_can_hold():
    dev = preset_from_option("SpidarG6X3R")
    force, torque = least_capacity(dev)
    a = structure_matrix(dev, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

    def misfit(wrench: np.ndarray) -> float:
        """The least |Aᵀ t − wrench| over tensions in bounds (0: the device can do it)."""
        return float(np.linalg.norm(lsq_linear(a.T, wrench, bounds=(dev.t_min, dev.t_max)).fun))

    cube = [np.array(d, float) for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)]
    units = [(d - 1.0) / np.linalg.norm(d - 1.0) for d in cube]
    for part, limit in ((slice(0, 3), force), (slice(3, 6), torque)):
        worst = []
        for u in units:
            w = np.zeros(6)
            w[part] = u * limit * 0.999
            assert misfit(w) < 5e-8 * limit  # every direction holds the capacity (8.7e-9)
            w[part] = u * limit * 1.01
            worst.append(misfit(w))
        assert max(worst) > 1e-4 * limit  # and some direction cannot take 1 % more (3.6e-4)


def test_feel_task_cli_compares_devices_and_writes_csv_and_plots(tmp_path):
    task = ROOT / "scripts" / "tasks" / "bend_elbow.json"
    out = CliRunner().invoke(cli, ["feel", str(DOLL), "--task", str(task), "--json",
                                   "--csv", str(tmp_path / "t.csv"),
                                   "--plot", str(tmp_path / "plots")])  # fmt: skip
    assert out.exit_code == 0, out.output
    facts = json.loads(out.stdout)
    runs = {r["run"]: r for r in facts["tasks"]}
    assert sorted(runs) == ["doll 3-DOF", "doll 6-DOF"]
    bones = set(json.loads(task.read_text())["keys"][0]["bones"]) - {"hips"}  # hips: no joint
    for run in runs.values():
        (key,) = run["keys"]
        assert set(key["error_final_deg"]) == bones
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("run,task,key,reached_s")
    assert (tmp_path / "plots" / "bend_elbow.png").stat().st_size > 0


def test_feel_task_compares_two_coefficient_sets(tmp_path):
    firm = tmp_path / "doll_firm.yaml"  # the doll with an elbow half as yielding again
    firm.write_text(
        DOLL.read_text().replace(
            "&elbow {kf: 150.0, df: 5.0, dd: 8.0, yield: 4.5",
            "&elbow {kf: 150.0, df: 5.0, dd: 12.0, yield: 6.75",
        )
    )
    task = ROOT / "scripts" / "tasks" / "bend_elbow.json"
    out = CliRunner().invoke(cli, ["feel", str(DOLL), "--task", str(task), "--dof", "6",
                                   "--compare", str(firm), "--json"])  # fmt: skip
    assert out.exit_code == 0, out.output
    runs = {r["run"]: r["keys"][0] for r in json.loads(out.stdout)["tasks"]}
    assert sorted(runs) == ["doll 6-DOF", "doll_firm 6-DOF"]
    assert runs["doll 6-DOF"] != runs["doll_firm 6-DOF"]  # the coefficients made a difference
    for key in runs.values():
        assert max(key["error_final_deg"].values()) < 2.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--dof", "3"], "--dof goes with --task"),
        (["--task", str(ROOT / "rigs" / "one_bone.yaml")], "expected JSON"),
    ],
)
def test_feel_task_bad_input_is_one_line(args, message):
    out = CliRunner().invoke(cli, ["feel", str(DOLL), *args])
    assert out.exit_code != 0 and message in out.output, out.output
    assert "Traceback" not in out.output


def test_a_task_for_another_rig_is_refused(tmp_path):
    chain = ROOT / "rigs" / "chain.yaml"
    task = ROOT / "scripts" / "tasks" / "bend_elbow.json"
    out = CliRunner().invoke(cli, ["feel", str(chain), "--task", str(task)])
    assert out.exit_code == 1, out.output
    line = out.output.strip().splitlines()[-1]
    assert line.startswith(f"error: {task}:keys[0].bones: expected the rig's bone "), line
