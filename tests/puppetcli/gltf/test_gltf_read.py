"""glTF in: rig from-gltf, then pose writes the character itself animated by the keys.

Oracles: the geometry the test character was built from (character_fixture: heads,
radius); rigs/doll.yaml for the doll's own glb read back; ``glb_reader`` (no puppetcli or
pygltflib code) for what a viewer shows of the written file; the Khronos validator.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml
from character_fixture import HEADS, NAMES, RADIUS, write_character
from click.testing import CliRunner
from glb_reader import read_glb
from khronos import problems, validate
from scipy.spatial.transform import Rotation

from puppetcli.cli import cli
from puppetcli.render.inputs import key_poses
from puppetcli.render.picture import poses_from_keys
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import read_keyframes

ROOT = Path(__file__).resolve().parents[3]
DOLL = ROOT / "rigs" / "doll.yaml"
WAVE = ROOT / "scripts" / "wave.yaml"
PULL = """pointer: {start: [0.8, 1.1, 0.05]}
actions:
  - key: rest
  - grip: {bone: lower, point: [0.35, 0.05, 0.05], position_only: true}
  - move: {by: [0.0, 0.2, 0.1], duration: 1.0}
  - key: pulled
  - release:
  - wait: 0.5
  - key: held
"""


def run(*args) -> None:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture(scope="module")
def character(tmp_path_factory) -> dict[str, Path]:
    """The Blender-like character, its rig, and the character posed by a pull."""
    out = tmp_path_factory.mktemp("character")
    write_character(out / "arm.glb")
    run("rig", "from-gltf", out / "arm.glb", "-o", out / "rigs" / "arm.yaml")
    (out / "pull.yaml").write_text(PULL)
    run("pose", out / "rigs" / "arm.yaml", out / "pull.yaml", "-o", out / "posed", "--gltf",
        "--no-trace", "--no-render")  # fmt: skip
    return {"glb": out / "arm.glb", "rig": out / "rigs" / "arm.yaml", "posed": out / "posed"}


def test_rig_from_a_character_has_its_bind_pose_and_shapes(character) -> None:
    doc = yaml.safe_load(character["rig"].read_text())
    assert doc["character"] == {"gltf": "../arm.glb", "skin": 0}  # relative to the rig
    bones = doc["bones"]
    assert [b["name"] for b in bones] == list(NAMES)
    assert [b.get("parent") for b in bones] == [None, "root", "upper"]
    heads = np.array([b["head"] for b in bones])
    assert np.abs(heads - HEADS).max() < 1e-9  # measured 0 (the file keeps 10 decimals)
    radii = np.array([b["shape"]["radius"] for b in bones])
    assert np.abs(radii - RADIUS).max() < 2e-7  # measured 3.6e-8 (float32 vertices)
    # One-child bones end at the child's head; the leaf along its tube, to 1 radius short of
    # the tube's end (its last ring, 85 % of the way to the far end).
    assert bones[0]["tail"] == bones[1]["head"] and bones[1]["tail"] == bones[2]["head"]
    far = HEADS[2] + 0.85 * (np.array([0.8, 1.1, 0.05]) - HEADS[2])
    axis = (far - HEADS[2]) / np.linalg.norm(far - HEADS[2])
    assert np.abs(np.array(bones[2]["tail"]) - (far - RADIUS * axis)).max() < 3e-8  # 6e-9


def test_posed_character_is_the_character_animated(character) -> None:
    """keyframes.glb is the original file plus the keys: same nodes, mesh and skin; its
    joints stand at the keys' heads; a vertex bound to one bone moves with that bone."""
    out = character["posed"] / "keyframes.glb"
    reports = validate(out)
    assert problems(reports[str(out)]) == []
    before, after = read_glb(character["glb"]), read_glb(out)
    assert [n.get("name") for n in after.doc["nodes"]] == [
        n.get("name") for n in before.doc["nodes"]
    ]
    assert after.doc["skins"][0]["joints"] == before.doc["skins"][0]["joints"]
    for a, b in zip(after.doc["nodes"], before.doc["nodes"], strict=True):  # the rest pose
        assert all(a.get(k) == b.get(k) for k in ("translation", "rotation", "scale", "children"))
    prim = after.doc["meshes"][0]["primitives"][0]
    pos = after.accessor(prim["attributes"]["POSITION"])
    assert np.array_equal(pos, before.accessor(prim["attributes"]["POSITION"]))
    keys = json.loads((character["posed"] / "keyframes.json").read_text())["keys"]
    markers = after.doc["animations"][0]["extras"]["markers"]
    assert [m["label"] for m in markers] == [k["label"] for k in keys] == ["rest", "pulled", "held"]
    names = after.node_index()
    skin = after.doc["skins"][0]
    ibm = after.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    joints = after.accessor(prim["attributes"]["JOINTS_0"]).astype(int)
    weights = after.accessor(prim["attributes"]["WEIGHTS_0"])
    lone = weights[:, 0] == 1.0
    worst_head = worst_vertex = 0.0
    for marker, key in zip(markers, keys, strict=True):
        world = after.world(marker["time"])
        for bone, pose in key["bones"].items():
            worst_head = max(worst_head, np.abs(world[names[bone]][:3, 3] - pose["head"]).max())
        mats = np.array([world[j] @ ibm[s] for s, j in enumerate(skin["joints"])])
        homo = np.hstack((pos, np.ones((len(pos), 1))))
        skinned = np.einsum("nij,nj->ni", mats[joints[:, 0]], homo)[:, :3]
        for s, bone in enumerate(NAMES):
            pose = key["bones"][bone]
            rot = Rotation.from_quat(pose["rotation"], scalar_first=True)
            mine = lone & (joints[:, 0] == s)
            expected = np.array(pose["head"]) + rot.apply(pos[mine] - HEADS[s])
            worst_vertex = max(worst_vertex, np.abs(skinned[mine] - expected).max())
    assert worst_head < 1.5e-7  # m; measured 2.8e-8 (float32 channels)
    assert worst_vertex < 2e-7  # m; measured 3.8e-8
    moved = np.linalg.norm(np.subtract(keys[1]["bones"]["lower"]["head"], HEADS[2]))
    tip = np.subtract(keys[1]["bones"]["lower"]["rotation"], [1, 0, 0, 0])
    assert moved > 0.0 or np.abs(tip).max() > 0.01  # the pull did bend the arm


def test_doll_glb_read_back_is_the_doll(tmp_path) -> None:
    """A glb exported from the doll, read back with from-gltf: the same bones, hierarchy and
    heads (1e-9), capsules' tails and radii to float32."""
    run("pose", DOLL, WAVE, "-o", tmp_path / "p", "--gltf", "--no-trace", "--no-render")
    run("rig", "from-gltf", tmp_path / "p" / "keyframes.glb", "-o", tmp_path / "doll.yaml")
    doll, back = load_rig(DOLL), load_rig(tmp_path / "doll.yaml")
    assert [b.name for b in back.bones] == [b.name for b in doll.bones]
    assert [b.parent for b in back.bones] == [b.parent for b in doll.bones]
    heads = np.array([b.head for b in back.bones]) - np.array([b.head for b in doll.bones])
    assert np.abs(heads).max() < 1e-9  # measured 0
    for a, b in zip(doll.bones, back.bones, strict=True):
        if a.shape.kind == "capsule":
            assert np.abs(np.subtract(a.tail, b.tail)).max() < 2e-7  # measured 4.4e-8
            assert abs(a.shape.radius - b.shape.radius) < 1e-7  # measured 1.3e-8


def test_render_a_glb_like_its_keys(character) -> None:
    """The glb's key frames drawn on the rig are the poses of keyframes.json."""
    spec = load_rig(character["rig"])
    skel = Skeleton.from_spec(spec)
    got = key_poses(character["posed"] / "keyframes.glb", "gltf", skel, spec)
    expected = poses_from_keys(skel, read_keyframes(character["posed"] / "keyframes.json")[1])
    assert [p.label for p in got] == [p.label for p in expected]
    for a, b in zip(got, expected, strict=True):
        assert np.abs(a.head - b.head).max() < 1.5e-7  # measured 2.8e-8 (float32)
        assert np.abs(a.tail - b.tail).max() < 2e-7  # measured 3.5e-8


def test_bad_gltf_input_is_one_line(tmp_path) -> None:
    junk = tmp_path / "junk.glb"
    junk.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    result = CliRunner().invoke(cli, ["rig", "from-gltf", str(junk), "-o", str(tmp_path / "r")])
    assert result.exit_code == 1
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith(f"error: {junk}: expected a glTF 2.0 file")
    write_character(tmp_path / "arm.glb")
    result = CliRunner().invoke(
        cli,
        ["rig", "from-gltf", str(tmp_path / "arm.glb"), "--skin", "3", "-o", str(tmp_path / "r")],
    )
    assert result.exit_code == 1
    assert result.stderr.strip() == (
        f"error: {tmp_path / 'arm.glb'}: --skin: expected a skin index from 0 to 0, got 3"
    )


def test_a_gltf_with_its_buffer_in_a_file(tmp_path) -> None:
    """The same character as .gltf + .bin gives the same bones as the .glb, and its posed
    keyframes.glb carries the buffer inside (valid, no file beside it needed)."""
    write_character(tmp_path / "arm.glb")
    data = (tmp_path / "arm.glb").read_bytes()
    (size,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + size])
    doc["buffers"][0]["uri"] = "arm.bin"
    (tmp_path / "arm.bin").write_bytes(data[20 + size + 8 :])
    (tmp_path / "arm.gltf").write_text(json.dumps(doc))
    run("rig", "from-gltf", tmp_path / "arm.glb", "-o", tmp_path / "a.yaml")
    run("rig", "from-gltf", tmp_path / "arm.gltf", "-o", tmp_path / "b.yaml")
    a, b = (yaml.safe_load((tmp_path / n).read_text())["bones"] for n in ("a.yaml", "b.yaml"))
    assert a == b
    (tmp_path / "pull.yaml").write_text(PULL)
    run("pose", tmp_path / "b.yaml", tmp_path / "pull.yaml", "-o", tmp_path / "out", "--gltf",
        "--no-trace", "--no-render")  # fmt: skip
    out = tmp_path / "out" / "keyframes.glb"
    assert "uri" not in read_glb(out).doc["buffers"][0]
    assert problems(validate(out)[str(out)]) == []
