"""keyframes.glb: valid glTF 2.0 (Khronos validator) that shows what keyframes.json says.

Oracles: the Khronos validator; ``glb_reader`` (struct + json + scipy, no puppetcli or
pygltflib code) for joint world positions and skinned vertices; keyframes.json read with
the json module.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from glb_reader import read_glb
from khronos import problems, validate
from scipy.spatial.transform import Rotation

from puppetcli.cli import cli

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
ARM_PUSH = ROOT / "scripts" / "arm_push.yaml"  # keys at 0, 0.5 and 1.5 s
WAVE = ROOT / "scripts" / "wave.yaml"


def run(*args) -> None:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def posed(tmp_path_factory) -> dict[str, Path]:
    """The doll posed by arm_push with keys held (STEP) and slerped (LINEAR), and wave
    converted at 20 fps."""
    out = tmp_path_factory.mktemp("glb")
    run("pose", DOLL, ARM_PUSH, "-o", out / "step", "--gltf", "--no-trace", "--no-render",
        "--fps", "12")  # fmt: skip
    run("pose", DOLL, ARM_PUSH, "-o", out / "linear", "--gltf", "--no-trace", "--no-render",
        "--interpolate", "slerp")  # fmt: skip
    run("convert", WAVE, "--rig", DOLL, "-o", out / "wave.glb", "--fps", "20")
    return {"step": out / "step", "linear": out / "linear", "wave": out / "wave.glb"}


def _keys(folder: Path) -> list[dict]:
    return json.loads((folder / "keyframes.json").read_text())["keys"]


def _size(glb) -> float:
    """The doll's extent: the diagonal of its rest mesh's bounding box (m)."""
    prim = glb.doc["meshes"][0]["primitives"][0]
    pos = glb.accessor(prim["attributes"]["POSITION"])
    return float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))


def test_the_validator_finds_nothing(posed) -> None:
    files = [posed["step"] / "keyframes.glb", posed["linear"] / "keyframes.glb", posed["wave"]]
    reports = validate(*files)
    for f in files:
        assert problems(reports[str(f)]) == [], f


@pytest.mark.parametrize("mode", ["step", "linear"])
def test_joints_stand_at_the_keys_heads(posed, mode) -> None:
    """Each key's time in the file (k / 12 s held, or the key's own time) puts every joint
    node at the key's head (float32 data)."""
    glb = read_glb(posed[mode] / "keyframes.glb")
    keys = _keys(posed[mode])
    names = glb.node_index()
    size = _size(glb)
    anim = glb.doc["animations"][0]
    markers = anim["extras"]["markers"]
    assert [m["label"] for m in markers] == [k["label"] for k in keys]
    worst = 0.0
    for k, key in enumerate(keys):
        t = k / 12.0 if mode == "step" else key["time"] - keys[0]["time"]
        assert markers[k]["time"] == pytest.approx(t, abs=1e-6)
        world = glb.world(markers[k]["time"])  # t rounded to float32, as stored
        for bone, pose in key["bones"].items():
            worst = max(worst, np.abs(world[names[bone]][:3, 3] - pose["head"]).max())
    assert worst < 6e-8 * size  # measured 1.5e-8 × size


def test_skinned_capsules_follow_their_bones(posed) -> None:
    """Vertices skinned as a viewer does (Σ w · world · inverse bind) lie on each bone's
    capsule as the key places it: distance from the key's segment = radius."""
    glb = read_glb(posed["step"] / "keyframes.glb")
    rig = {b["name"]: b for b in _rig_bones()}
    keys = _keys(posed["step"])
    prim = glb.doc["meshes"][0]["primitives"][0]
    pos = glb.accessor(prim["attributes"]["POSITION"])
    joints = glb.accessor(prim["attributes"]["JOINTS_0"]).astype(int)
    weights = glb.accessor(prim["attributes"]["WEIGHTS_0"])
    skin = glb.doc["skins"][0]
    ibm = glb.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    size = _size(glb)
    worst = 0.0
    for k, key in enumerate(keys):
        world = glb.world(glb.doc["animations"][0]["extras"]["markers"][k]["time"])
        mats = np.array([world[j] @ ibm[s] for s, j in enumerate(skin["joints"])])
        homo = np.hstack((pos, np.ones((len(pos), 1))))
        skinned = np.einsum("nk,nkij,nj->ni", weights, mats[joints], homo)[:, :3]
        for s, j in enumerate(skin["joints"]):
            bone = glb.doc["nodes"][j]["name"]
            if rig[bone]["shape"]["type"] != "capsule":
                continue
            head = np.array(key["bones"][bone]["head"])
            rot = Rotation.from_quat(key["bones"][bone]["rotation"], scalar_first=True)
            tail = head + rot.apply(np.subtract(rig[bone]["tail"], rig[bone]["head"]))
            v = skinned[joints[:, 0] == s]
            d = tail - head
            u = np.clip((v - head) @ d / (d @ d), 0.0, 1.0)
            dist = np.linalg.norm(v - (head + u[:, None] * d), axis=1)
            worst = max(worst, np.abs(dist - rig[bone]["shape"]["radius"]).max())
    assert worst < 2e-7 * size  # measured 4.6e-8 × size (float32 vertices)


def _rig_bones() -> list[dict]:
    import yaml

    return yaml.safe_load(DOLL.read_text())["bones"]


def test_hierarchy_and_rest_pose(posed) -> None:
    """Joint nodes: the rig's names, parents and rest heads (inverse bind = T(−head))."""
    glb = read_glb(posed["wave"])
    bones = _rig_bones()
    names = glb.node_index()
    parents = glb.parents()
    rest = glb.world(None)
    skin = glb.doc["skins"][0]
    ibm = glb.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    assert [glb.doc["nodes"][j]["name"] for j in skin["joints"]] == [b["name"] for b in bones]
    for s, b in enumerate(bones):
        i = names[b["name"]]
        parent = glb.doc["nodes"][parents[i]]["name"] if i in parents else None
        assert parent == b.get("parent")
        assert np.allclose(rest[i][:3, 3], b["head"], atol=1e-12)
        # float32 matrices: measured 5.2e-8
        assert np.allclose(ibm[s] @ rest[i], np.eye(4), rtol=0, atol=2e-7)


def test_convert_samples_at_the_rate(posed) -> None:
    """convert --fps 20: LINEAR samples 1/20 s apart, from 0."""
    glb = read_glb(posed["wave"])
    sampler = glb.doc["animations"][0]["samplers"][0]
    assert sampler["interpolation"] == "LINEAR"
    times = glb.accessor(sampler["input"])[:, 0]
    assert np.allclose(times, np.arange(len(times)) / 20.0, atol=1e-6)
