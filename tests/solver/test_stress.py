"""Stress cases (issue 6): every case stays stable within its bounds (puppetcli.bench.stress).

The bounds and their reasons are in each scene (``Scene.why``) and in docs/stress.md.
The cases run on the compiled step with each scene's own solver (auto: direct, or the
hybrid when contacts or limits are near); the paper's PGS is shown to fail where the
hybrid was needed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from puppetcli.bench import stress
from puppetcli.bench.stress_scenes import Scene
from puppetcli.cli import cli
from solver.pipeline import step

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", list(stress.CASES))
def test_case_is_stable(name):
    scene = stress.CASES[name]()
    res = stress.run_scene(scene)
    why = f"{res.problems}; bounds: {scene.why}"
    assert not res.crash and not res.error, why
    assert not res.nonfinite, why
    assert res.energy_growth <= res.energy_bound, why
    assert res.joint_gap <= res.gap_limit, why
    assert res.penetration <= res.penetration_bound, why
    assert res.stable, why


def test_the_papers_pgs_fails_the_landing_mass_ratio_chain_that_auto_passes():
    # 15 PGS sweeps over the whole table leave the joints between 0.01 and 10 kg links
    # unconverged once the ground contacts make the problem an LCP (docs/stress.md).
    scene = stress.mass_ratio_ground()
    pgs = stress.run_scene(scene, "pgs")
    assert not pgs.stable and pgs.penetration > pgs.penetration_bound
    assert stress.run_scene(scene).stable


def test_overlapping_capsules_part_at_the_baumgarte_speed():
    # Independent value: the contact rows ask for erp·(depth − slop)/h along the normal.
    scene = stress.overlap_capsules()
    model = scene.model
    state, _ = step(model, scene.start)
    opt = model.options
    expected = opt.contact_erp * (0.025 - opt.contact_slop) / opt.h
    parting = state.body_vel[1, 1] - state.body_vel[0, 1]
    assert parting == pytest.approx(expected, rel=1e-3)


def test_spin_keeps_momentum_and_energy_below_the_carried_momentum_bound():
    # What integrate_pose guarantees today: L exactly, E ≤ |L|²/(2 I_min).
    scene = stress.spin()
    res = stress.run_scene(scene)
    inertia = np.linalg.eigvalsh(scene.model.body_inertia[0])
    ang = inertia[1] * 20.0  # |L| of the initial spin about the middle axis
    e0 = 0.5 * inertia[1] * 20.0**2
    assert res.momentum_drift <= stress.MOMENTUM_TOL
    assert e0 + res.energy_growth <= ang**2 / (2.0 * inertia[0]) * (1.0 + 1e-6)


@pytest.fixture(scope="module")
def random_runs() -> list[stress.CaseResult]:
    return [stress.run_random(seed) for seed in range(stress.RANDOM_SEEDS)]


def test_random_rigs_never_write_a_nonfinite_state(random_runs):
    bad = [r.name for r in random_runs if r.nonfinite]
    assert not bad


def test_random_rigs_never_crash(random_runs):
    crashed = [f"{r.name}: {r.crash}" for r in random_runs if r.crash]
    assert not crashed, "\n".join(crashed)


def test_random_rigs_are_stable(random_runs):
    # Every random rig is physically reasonable (docs/stress.md): neighbours within ~900×
    # in mass, rheology around each joint's natural units, pushes up to 20× a bone's
    # weight.  So a SimulationError is a failure here, not an acceptable detection.
    bad = [f"{r.name}: {'; '.join(r.problems)}" for r in random_runs if not r.stable]
    assert not bad, "\n".join(bad)


def test_random_scenes_are_reproducible():
    a, b = stress.sc.random_scene(7), stress.sc.random_scene(7)
    assert np.array_equal(a.model.body_mass, b.model.body_mass)
    assert np.array_equal(a.drive.pushes[0].force, b.drive.pushes[0].force)


def _strict_json(text: str):
    def refuse(constant: str):
        raise ValueError(f"non-finite number {constant} in an output")

    return json.loads(text, parse_constant=refuse)


# 1e9 N is the largest force a script may give (a larger one is refused where it is read).
@pytest.mark.parametrize("force", ["1.0e6", "1.0e9"])
def test_pose_that_blows_up_writes_only_finite_numbers(tmp_path, force):
    script = tmp_path / "blow.yaml"
    script.write_text(
        "actions:\n  - key: rest\n  - wait: 0.05\n  - key: before\n"
        f"  - push: {{bone: forearm_l, force: [0.0, {force}, 0.0], point: [0.25, 0.0, 0.0],"
        " duration: 0.2}\n  - key: pushed\n"
    )
    out = tmp_path / "out"
    args = ["pose", str(ROOT / "rigs/doll.yaml"), str(script), "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    assert "error: simulation failed at step" in result.stderr
    keys = _strict_json((out / "keyframes.json").read_text())["keys"]
    assert [k["label"] for k in keys] == ["rest", "before"]
    messages = 0
    with open(out / "trace.mcap", "rb") as f:
        for _schema, _channel, message in make_reader(f).iter_messages():
            _strict_json(message.data.decode("utf-8"))
            messages += 1
    assert messages > 10


def test_stress_command_prints_a_row_per_case_and_writes_csv(tmp_path):
    csv = tmp_path / "stress.csv"
    args = ["stress", "--case", "kf-1e6", "--case", "overlap-capsules", "--csv", str(csv)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    rows = [line.split()[:2] for line in result.stdout.splitlines()[2:]]
    assert rows == [["kf-1e6", "yes"], ["overlap-capsules", "yes"]]
    lines = csv.read_text().splitlines()
    assert lines[0].startswith("name,stable,energy_growth")
    assert [line.split(",")[:2] for line in lines[1:]] == [
        ["kf-1e6", "True"],
        ["overlap-capsules", "True"],
    ]


def test_stress_command_exits_1_when_a_case_is_unstable(monkeypatch):
    def unstable() -> Scene:
        scene = stress.overlap_capsules()  # its Baumgarte kick, with no allowance for it
        return Scene(scene.name, scene.model, scene.start, 0.05, "", energy_extra=0.0)

    monkeypatch.setitem(stress.CASES, "overlap-capsules", unstable)
    result = CliRunner().invoke(cli, ["stress", "--case", "overlap-capsules"])
    assert result.exit_code == 1
    assert result.stdout.splitlines()[2].split()[:2] == ["overlap-capsules", "NO"]
    assert "energy grew" in result.stdout


def test_stress_command_runs_one_random_seed_and_rejects_a_seed_without_random():
    result = CliRunner().invoke(cli, ["stress", "--seed", "3"])
    assert result.stdout.splitlines()[2].split()[0] == "random-3"
    wrong = CliRunner().invoke(cli, ["stress", "--seed", "3", "--case", "spin"])
    assert wrong.exit_code == 2
    assert "--seed selects a random rig" in wrong.stderr
