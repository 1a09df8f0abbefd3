"""Rigs from BVH skeletons: they validate, build and pose; BVH → rig → BVH keeps the skeleton.

Independent values: joint positions from test_bvh_fixtures.independent_fk (the
``bvh`` package + scipy matrices) and the ``bvh`` package's parse of the
re-exported file.
"""

from __future__ import annotations

import bvh as bvh_package
import numpy as np
import pytest
from test_bvh_fixtures import independent_fk, make_bvh

from puppetcli.bvh.read import bvh_from_text
from puppetcli.bvh.rig import rig_text_from_bvh
from puppetcli.bvh.units import infer_unit
from puppetcli.bvh.write import write_keys_bvh
from puppetcli.rig.load import load_rig, rig_from_text
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.runner import Runner, script_model
from puppetcli.run.snapshot import capture
from puppetcli.script.load import script_from_text
from solver.model import build_model
from solver.state import initial_state

CMU_SCALE = 0.056444  # CMU units to metres
SKELETONS = [
    ("simple19", "XYZ", None, 19),
    ("simple19", "YZX", None, 19),
    ("cmu31", "ZYX", CMU_SCALE, 31),
    ("cmu31", "mixed", CMU_SCALE, 31),
    ("mixamo65", "ZYX", None, 65),
    ("mixamo65", "mixed", None, 65),
]
SCRIPT = "actions:\n  - key: start\n  - wait: 0.1\n  - key: end\n"


def make_rig(tmp_path, kind, order, scale, frame=None):
    text = make_bvh(kind, order, frames=3)
    bvh = bvh_from_text(text, f"{kind}.bvh")
    scale = scale or infer_unit(bvh).scale
    path = tmp_path / f"{kind}.yaml"
    path.write_text(rig_text_from_bvh(bvh, kind, scale, frame))
    return text, scale, load_rig(path)


@pytest.mark.parametrize(("kind", "order", "scale", "count"), SKELETONS)
def test_rig_validates_builds_and_poses(tmp_path, kind, order, scale, count) -> None:
    text, scale, spec = make_rig(tmp_path, kind, order, scale)
    names, parents, _ = independent_fk(text)
    assert [b.name for b in spec.bones] == names and len(names) == count
    assert [b.parent for b in spec.bones] == [None if p < 0 else names[p] for p in parents]
    # The rest pose comes from the OFFSETs: the root at its OFFSET, every channel 0.
    offsets = np.array([bvh_package.Bvh(text).joint_offset(n) for n in names])
    rest = np.array([b.head for b in spec.bones])
    np.testing.assert_allclose(rest, _chain(offsets, parents) * scale, atol=1e-9)
    model = build_model(spec)
    plan = script_from_text(SCRIPT, "wait.yaml", spec)
    result = Runner(script_model(model, plan), plan).run()
    assert result.error is None and len(result.keys) == 2
    assert min(b.mass for b in spec.bones) > 0.0


def _chain(offsets: np.ndarray, parents: list[int]) -> np.ndarray:
    """Rest positions: sums of OFFSETs along the parent chain (no rotations at rest)."""
    out = np.zeros_like(offsets)
    for i, p in enumerate(parents):
        out[i] = offsets[i] + (out[p] if p >= 0 else 0.0)
    return out


@pytest.mark.parametrize(("kind", "order", "scale"), [("cmu31", "mixed", CMU_SCALE),
                                                      ("mixamo65", "ZYX", 0.01)])  # fmt: skip
def test_rest_pose_from_a_frame_is_that_posed_skeleton(tmp_path, kind, order, scale) -> None:
    text, scale, spec = make_rig(tmp_path, kind, order, scale, frame=2)
    _, _, positions = independent_fk(text)
    heads = np.array([b.head for b in spec.bones])
    np.testing.assert_allclose(heads, positions[2] * scale, atol=1e-9)
    plan = script_from_text(SCRIPT, "wait.yaml", spec)
    assert Runner(script_model(build_model(spec), plan), plan).run().error is None


@pytest.mark.parametrize(("kind", "order", "scale"), [("simple19", "XYZ", 1.0),
                                                      ("cmu31", "ZYX", CMU_SCALE),
                                                      ("mixamo65", "ZYX", 0.01)])  # fmt: skip
def test_bvh_rig_bvh_keeps_names_hierarchy_and_offsets(tmp_path, kind, order, scale) -> None:
    text, scale, spec = make_rig(tmp_path, kind, order, scale)
    model = build_model(spec)
    key = capture(model, initial_state(model), "rest", {})
    out = tmp_path / "again.bvh"
    write_keys_bvh(out, Skeleton.from_spec(spec), [key], order="ZYX", scale=1.0 / scale)
    before, after = bvh_package.Bvh(text), bvh_package.Bvh(out.read_text())
    names = before.get_joints_names()
    assert after.get_joints_names() == names
    size = np.ptp(
        _chain(
            np.array([before.joint_offset(n) for n in names]),
            [before.joint_parent_index(n) for n in names],
        ),
        axis=0,
    ).max()
    for n in names:
        assert after.joint_parent_index(n) == before.joint_parent_index(n)
        if before.joint_parent_index(n) >= 0:
            np.testing.assert_allclose(after.joint_offset(n), before.joint_offset(n),
                                       atol=1e-6 * size)  # fmt: skip
    root = [float(v) for v in after.frames[0][:3]]
    np.testing.assert_allclose(root, before.joint_offset(names[0]), atol=1e-6 * size)
    np.testing.assert_allclose([float(v) for v in after.frames[0][3:]], 0.0, atol=1e-6)


def test_tails_shapes_and_joint_strength(tmp_path) -> None:
    _, _, spec = make_rig(tmp_path, "mixamo65", "ZYX", 0.01)
    bones = {b.name: b for b in spec.bones}
    hips, spine = bones["mixamorig:Hips"], bones["mixamorig:Spine"]
    # Hips: children on opposite sides (legs, spine) → its tail is the first child's head.
    np.testing.assert_allclose(hips.tail, spine.head)
    # Spine2: neck and shoulders → the mean of the three heads.
    kids = [b.head for b in spec.bones if b.parent == "mixamorig:Spine2"]
    np.testing.assert_allclose(bones["mixamorig:Spine2"].tail, np.mean(kids, axis=0))
    # A leaf JOINT with a zero End Site is a sphere; the others capsules.
    assert bones["mixamorig:HeadTop_End"].shape.kind == "sphere"
    assert bones["mixamorig:LeftArm"].shape.kind == "capsule"
    # Each joint yields at twice its worst-case gravity torque (when the cap does not bind).
    arm = bones["mixamorig:LeftArm"]
    members = [b for b in spec.bones if _descends(b.name, arm.name, bones)]
    torque = 9.81 * sum(
        b.mass * np.linalg.norm(0.5 * (b.head + b.tail) - arm.head) for b in members
    )
    assert arm.rheology.yield_torque == pytest.approx(2.0 * torque, rel=1e-6)


def _descends(name: str, ancestor: str, bones: dict) -> bool:
    while name is not None:
        if name == ancestor:
            return True
        name = bones[name].parent
    return False


def test_names_are_quoted_and_made_unique() -> None:
    text = make_bvh("simple19").replace("Spine", "on").replace("LHand", "1: x #y")
    text = text.replace("JOINT RHand", "JOINT Chest")
    spec = rig_from_text(rig_text_from_bvh(bvh_from_text(text), "yes", 1.0), "odd.yaml")
    names = [b.name for b in spec.bones]
    assert spec.name == "yes" and "on" in names and "1: x #y" in names
    assert "Chest.001" in names and len(set(names)) == len(names)
