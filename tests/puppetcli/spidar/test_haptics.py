"""What the hand feels, and a stiff coupling at a large step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from puppetcli.cli import cli
from puppetcli.mcap.trace import read_trace
from puppetcli.rig.load import load_rig
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.load import script_from_text
from puppetcli.spidar.haptics import HapticChain
from solver import quat
from solver.model import build_model
from solver.observe import kinetic_energy

ROOT = Path(__file__).resolve().parents[3]
PULL = """
pointer: {{start: [0.70, 1.36, 0.0]}}
{settings}
actions:
  - grip: {{bone: forearm_l, point: [0.24, 0, 0], stiffness: {k}, damping: {d},
            position_only: true}}
  - move: {{by: [0.0, 0.1, 0.2], duration: {t}}}
  - wait: 0.5
"""


def runner_for(script: str) -> Runner:
    spec = load_rig(ROOT / "rigs/doll.yaml")
    plan = script_from_text(script, "test.yaml", spec)
    return Runner(script_model(build_model(spec), plan), plan)


def test_coupling_force_is_the_backward_euler_spring_damper():
    # λ = −K (e[t+1]) − D (v[t+1] − u): recomputed from the state after each step.  The row
    # moves the grip point along its tangent, ω × r, while the bone turns it on an arc: the
    # point ends ½h²|ω|²|r| off (K's share) and its velocity h|ω|²|r| (D's share), so the
    # two differ by (½Kh + D)·h·|ω|²·|r| at most (measured: up to that, to 2e-8 of it);
    # 1 % more for the next order (hω ≤ 0.01 here).
    runner = runner_for(PULL.format(settings="", k=2000, d=40, t=1.0))
    runner.batch_steps = False  # every step through _after_step, to see each one
    seen = []
    original = runner._after_step

    def spy(inp):
        seen.append((inp, runner.sim.report, runner.state))
        original(inp)

    runner._after_step = spy
    runner.run()
    c = runner.coupling
    h = runner.model.options.h
    checked = 0
    for inp, report, s in seen:
        if inp.coupling is None or np.abs(report.grip_force).max() >= c.force_limit:
            continue
        ptr, b = inp.pointer, c.body
        r = quat.rotate(s.body_quat[b], c.anchor)
        target = ptr.pos + quat.rotate(ptr.quat, c.offset)
        v_point = s.body_vel[b] + np.cross(s.body_omega[b], r)
        expected = -c.stiffness * (s.body_pos[b] + r - target) - c.damping * (v_point - ptr.vel)
        arc = (0.5 * c.stiffness * h + c.damping) * h * (s.body_omega[b] @ s.body_omega[b])
        assert np.abs(report.grip_force - expected).max() <= 1.01 * arc * np.linalg.norm(r)
        checked += 1
    assert checked > 100


def test_displayed_wrench_is_minus_the_coupling_wrench_clamped_to_the_device(tmp_path):
    script = tmp_path / "pull.yaml"
    script.write_text(
        PULL.format(settings="haptics: {max_force: 20, max_torque: 1.0}", k=2000, d=40, t=1.0)
    )
    result = CliRunner().invoke(
        cli, ["pose", str(ROOT / "rigs/doll.yaml"), str(script), "-o", str(tmp_path / "out")]
    )
    assert result.exit_code == 0, result.output
    wrench = read_trace(tmp_path / "out/trace.mcap")["/haptic/wrench"]
    assert len(wrench) > 100
    clamped = 0
    for _, msg in wrench:
        req = np.array(msg["requested"]["force"])
        shown = np.array(msg["displayed"]["force"])
        assert np.linalg.norm(shown) <= 20.0 + 2e-14  # rounding
        if np.linalg.norm(req) <= 20.0:
            assert np.array_equal(shown, req)  # measured: the same floats
        else:  # attenuated along the same direction, never faked
            clamped += 1
            expected = req * 20.0 / np.linalg.norm(req)
            assert shown == pytest.approx(expected, abs=2e-14)  # measured 3.6e-15 N
    assert clamped > 0


@pytest.mark.parametrize("h", [0.02, 0.005])
def test_stiff_coupling_at_large_step_stays_stable(h):
    runner = runner_for(PULL.format(settings=f"h: {h}", k=1.0e4, d=100, t=1.0))
    energy = []
    runner.on_step = lambda s: energy.append(kinetic_energy(runner.model, s))
    result = runner.run()
    assert result.error is None
    assert max(energy) < 0.9  # J: a pose being dragged (measured 0.18), not an explosion


def test_a_one_metre_jump_of_the_pointer_in_one_step_does_not_explode():
    runner = runner_for(
        PULL.format(settings="h: 0.005", k=2000, d=40, t=0.005).replace(
            "[0.0, 0.1, 0.2]", "[0.0, 1.0, 0.0]"
        )
    )
    speeds = []
    runner.on_step = lambda s: speeds.append(np.abs(s.body_vel).max())
    result = runner.run()
    assert result.error is None
    assert result.peak_force <= np.sqrt(3) * 300.0 + 1e-6  # the per-axis force limit holds
    assert max(speeds) < 10.0  # m/s: measured 5.5


def test_haptic_chain_over_many_steps_is_the_chain_step_by_step():
    # display_many (a batch's wrenches) against display called row by row: the same floats.
    rng = np.random.default_rng(3)
    requested = rng.normal(scale=15.0, size=(400, 6))
    requested[::7] = -0.0  # no wrench, as a free pointer touching nothing asks: signs of zero
    requested[::11, :3] = 0.0
    for lowpass in (0.0, 0.6, 0.95):
        one, many = HapticChain(20.0, 2.0, lowpass), HapticChain(20.0, 2.0, lowpass)
        rows = [np.concatenate(one.display(r[:3], r[3:])) for r in requested]
        shown = many.display_many(requested[:150])
        shown = np.vstack((shown, many.display_many(requested[150:])))
        assert np.array_equal(np.array(rows), shown)
        assert np.array_equal(np.signbit(rows), np.signbit(shown))
        assert one.filtered == many.filtered
        assert np.array_equal(np.signbit(one.filtered), np.signbit(many.filtered))
        assert (np.linalg.norm(shown[:, :3], axis=1) <= 20.0 + 2e-14).all()  # over: ≤ 3.6e-15
