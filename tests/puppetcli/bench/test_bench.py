"""``puppetcli bench``'s speed table: its scene, its rows and ratios, the stage-table hook
and the peers switch (no timing is asserted)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner

from puppetcli.bench import peers
from puppetcli.bench import solvers as bench
from puppetcli.bench.scenes import GRIP_BONE, LIFT, grip_inputs
from puppetcli.bench.solvers import BenchRow, measure, repeats_for, stage_table
from puppetcli.commands.bench import command
from puppetcli.spidar.pointer import min_jerk


def test_grip_inputs_start_at_the_grip_point_and_follow_the_lift():
    model = bench.doll_scenes()["doll"].with_options(h=0.01)
    tail = model.bone_tail0[model.bone_names.index(GRIP_BONE)]
    inputs = grip_inputs(model, 0.5, 80)  # lift over 50 steps, then 30 still
    assert len(inputs) == 80
    assert np.allclose(inputs[0].coupling.offset, 0.0)  # gripped where the pointer was
    assert inputs[0].coupling.position_only and inputs[0].coupling.stiffness == 2000.0
    for k in (0, 10, 25, 49, 79):
        expected = tail + min_jerk((k + 1) * 0.01 / 0.5) * LIFT
        assert np.allclose(inputs[k].pointer.pos, expected, atol=1e-12)
    # Mean velocities over the steps add up to the whole displacement.
    total = sum(inp.pointer.vel for inp in inputs) * 0.01
    assert np.allclose(total, LIFT, atol=1e-12)


def test_repeats_time_enough_steps():
    assert repeats_for(25, "fast") * 25 >= bench.MIN_TIMED_STEPS["fast"]
    assert repeats_for(5000, "fast") == bench.MIN_REPEATS["fast"]
    assert repeats_for(500, "numpy") == 1


def test_stage_table_shares_add_up():
    text = stage_table({"rows": 10.0, "pgs": 30.0, "integrate": 10.0})
    lines = {ln.split()[0]: ln.split()[1:] for ln in text.splitlines()[2:]}
    assert lines["pgs"] == ["30.00", "60.0%"] and lines["rows"] == ["10.00", "20.0%"]
    assert lines["total"] == ["50.00", "100.0%"]


def _by(rows, scene, solver, engine) -> BenchRow:
    (row,) = [r for r in rows if (r.scene, r.solver, r.engine) == (scene, solver, engine)]
    return row


@pytest.fixture(scope="module")
def tiny_rows():
    return measure(bench.doll_scenes(), [0.02], ["pgs", "direct"], 0.04)


def test_measure_rows_against_the_numpy_baseline(tiny_rows):
    assert {(r.scene, r.solver, r.engine) for r in tiny_rows} == {
        (s, solver, engine)
        for s in ("doll", "doll-joints")
        for solver, engine in (("pgs", "numpy"), ("pgs", "fast"), ("direct", "fast"))
    }
    for scene in ("doll", "doll-joints"):
        base = _by(tiny_rows, scene, "pgs", "numpy")
        fast = _by(tiny_rows, scene, "pgs", "fast")
        assert base.ratio == 1.0 and fast.ratio == pytest.approx(
            fast.steps_per_s / base.steps_per_s
        )
        assert fast.steps == 2 and fast.realtime == pytest.approx(0.04 / fast.seconds)
    direct = _by(tiny_rows, "doll", "direct", "fast")  # contacts and limits: cannot run
    assert direct.note.startswith("n/a") and math.isnan(direct.steps_per_s)
    assert _by(tiny_rows, "doll-joints", "direct", "fast").steps_per_s > 0
    # Only the doll has a ground: its feet's speculative contacts, none without it.
    assert _by(tiny_rows, "doll", "pgs", "fast").contacts > 0
    assert _by(tiny_rows, "doll-joints", "pgs", "fast").contacts == 0


@pytest.mark.peers
def test_peers_rows_sit_beside_ours():
    rows = measure({"doll": bench.doll_scenes()["doll"]}, [0.02], ["pgs"], 0.1, peers=True)
    euler = _by(rows, "doll", "euler", "mujoco")
    _by(rows, "doll", "implicitfast", "mujoco")
    ours = _by(rows, "doll", "pgs", "fast")
    assert euler.vs_mujoco == 1.0 and euler.steps == ours.steps
    assert ours.vs_mujoco == pytest.approx(ours.steps_per_s / euler.steps_per_s)
    (line,) = bench.peer_summary(rows)
    assert line.startswith("doll h=0.02: pgs (fast)") and "MuJoCo implicitfast" in line


def test_cli_peers_without_mujoco_carries_on(tmp_path, monkeypatch):
    monkeypatch.setattr(peers, "mujoco_version", lambda: None)
    out = tmp_path / "bench.csv"
    args = ["--peers", "--h", "0.02", "--seconds", "0.02", "--solver", "pgs", "--csv", str(out)]
    result = CliRunner().invoke(command, args)
    assert result.exit_code == 0, result.output
    assert result.output.count("pip install -e '.[bench]'") == 1
    with open(out, newline="") as f:
        reader = csv.DictReader(f)
        table = list(reader)
    assert reader.fieldnames == list(BenchRow.__dataclass_fields__)
    assert [(t["scene"], t["solver"], t["engine"]) for t in table] == [
        (scene, "pgs", engine)
        for scene in ("doll", "doll-joints")
        for engine in ("numpy", "fast", "sim")
    ]


def test_skips_command_prints_each_skip_with_its_ratio():
    from puppetcli.bench.skips import SKIPS

    result = CliRunner().invoke(command, ["--skips", "--seconds", "0.02"])
    assert result.exit_code == 0, result.output
    rows = [line.split() for line in result.output.splitlines()[3:]]
    assert [r[0] for r in rows] == list(SKIPS)
    for r in rows:
        on, off, ratio = (float(x.replace(",", "")) for x in r[2:5])
        assert ratio == pytest.approx(on / off, rel=0.01, abs=0.006)
        assert float(r[5]) <= 1e-5 and float(r[6]) <= 1e-5  # the runs agree


def test_pins_command_prints_0_1_and_4_pins_holding():
    result = CliRunner().invoke(command, ["--pins", "--seconds", "0.02"])
    assert result.exit_code == 0, result.output
    printed = [line.split() for line in result.output.splitlines()[3:]]
    assert [r[0] for r in printed] == ["0", "1", "4"]
    for count, _, ratio, _, _, solver, drift in printed:
        assert solver == "hybrid" and float(drift) < 1e-6  # the pinned points held
        assert count != "0" or float(ratio) == 1.0  # the ratio's base


def test_doll_stages_cover_the_step():
    stages = bench.doll_stages(0.005, 0.05)
    from solver.compiled.clock import STAGES

    assert list(stages)[: len(STAGES)] == list(STAGES)
    assert all(v >= 0.0 for k, v in stages.items() if k in STAGES)
    solve, collision = STAGES[5], STAGES[3]
    assert solve.startswith("solve") and collision.startswith("collision")
    assert stages[solve] > 0.0 and stages[collision] > 0.0


def test_sim_engine_runs_the_same_scene_as_fast_step():
    # The in-place Sim steps the same kernel on the same inputs: the same contacts and
    # substeps, step for step, so their means over the run agree exactly.
    rows = measure({"doll": bench.doll_scenes()["doll"]}, [0.02], ["auto"], 0.1, ("fast", "sim"))
    fast, sim = _by(rows, "doll", "auto", "fast"), _by(rows, "doll", "auto", "sim")
    assert sim.steps == fast.steps == 5 and sim.steps_per_s > 0
    assert (sim.contacts, sim.substeps) == (fast.contacts, fast.substeps)
    assert sim.contacts > 0


def test_trials_run_round_by_round_and_keep_their_fastest_run():
    calls = []

    def trial(name, seconds):
        def run():
            calls.append(name)
            t = seconds.pop(0)
            return BenchRow("s", 0.01, name, "fast", 10, 1, t, 10 / t, 0.1 / t, math.nan)

        return bench.Trial(len(seconds), run)

    a, b = trial("a", [3.0, 1.0, 2.0]), trial("b", [2.0])
    rows = bench._interleaved([a, b])
    assert calls == ["a", "b", "a", "a"]
    assert [r.seconds for r in rows] == [1.0, 2.0] and [r.repeats for r in rows] == [3, 1]
