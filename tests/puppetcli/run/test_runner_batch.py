"""A timed action's steps run as one batch (Runner._run_batch, Sim.follow) when all their
inputs are known; the oracle is the same runner taking every step one by one through
``advance`` and ``_after_step``: the same states, keys, peaks and displayed wrench, to
the bit, on every example script."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from puppetcli.rig.load import load_rig
from puppetcli.run.runner import Runner, script_model
from puppetcli.script.load import load_script
from solver.model import build_model

ROOT = Path(__file__).resolve().parents[3]
SCRIPTS = sorted(p.stem for p in (ROOT / "scripts").glob("*.yaml"))


def _run(name: str, batched: bool):
    rig = "one_bone" if name == "creep" else "doll"
    spec = load_rig(ROOT / "rigs" / f"{rig}.yaml")
    plan = load_script(ROOT / "scripts" / f"{name}.yaml", spec)
    runner = Runner(script_model(build_model(spec), plan), plan)
    runner.batch_steps = batched
    batches = []
    original = runner._run_batch

    def spy(poses, first, end):
        batches.append(end - first)
        original(poses, first, end)

    runner._run_batch = spy
    return runner.run(), runner, batches


@pytest.mark.parametrize("name", SCRIPTS)
def test_batched_steps_are_the_steps_one_by_one(name):
    batched, runner_b, batches = _run(name, True)
    single, runner_s, none = _run(name, False)
    assert not none and sum(batches) > 0  # the batch path ran (and only when allowed)
    assert batched.steps == single.steps and batched.error is None
    for field in ("body_pos", "body_quat", "body_vel", "body_omega", "joint_q_sf"):
        assert np.array_equal(getattr(batched.state, field), getattr(single.state, field))
    assert [k.label for k in batched.keys] == [k.label for k in single.keys]
    for a, b in zip(batched.keys, single.keys, strict=True):
        assert a.extra == b.extra and a.bones.keys() == b.bones.keys()
        for bone, pose in a.bones.items():
            other = b.bones[bone]
            assert np.array_equal(pose.head, other.head)
            assert np.array_equal(pose.rotation, other.rotation)
    assert batched.peak_force == single.peak_force
    assert batched.peak_displayed == single.peak_displayed
    assert runner_b.displayed == runner_s.displayed
    assert runner_b.haptics.filtered == runner_s.haptics.filtered
