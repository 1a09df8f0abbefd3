"""Keys as an animation of the glTF character a rig was made from (``rig from-gltf``).

The output is the character's own file (its meshes, materials, skins, other
animations) with one more animation, ``keys``, first in the list, that moves its
joint nodes through the keys; its data in one binary buffer, as a .glb.

A rig bone's rest frame is world-aligned at the joint's bind position, so in a
key a joint's world matrix is

    W_j = [ R(q_j) · A_j | h_j ],

A_j the 3×3 part of the joint's bind matrix (its bind rotation and scale), q_j
and h_j the key's rotation and head of the bone.  A node's local transform is
its parent node's world inverse times its own (parents that are not joints keep
their rest transforms and follow the joints above them); its translation and
rotation (the nearest rotation, scale removed) become the channels, its scale
stays the node's own.
"""

from __future__ import annotations

import base64
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from puppetcli.errors import PuppetError
from puppetcli.gltf.read import Gltf, GltfError, quat_from_matrix, read_gltf, skin_joints
from puppetcli.gltf.write import Blob, continuous, key_animation, save_glb
from puppetcli.rig.make import unique_names
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe
from solver import quat

__all__ = ["write_character_glb"]

ALIGN = 16  # bytes: each merged buffer starts on this boundary


def _node_order(parents: np.ndarray) -> list[int]:
    """Every node, parents before children."""
    depth = np.zeros(len(parents), dtype=np.int64)
    for i in range(len(parents)):
        j, d = i, 0
        while parents[j] >= 0 and d <= len(parents):
            j, d = parents[j], d + 1
        depth[i] = d
    return sorted(range(len(parents)), key=lambda i: (depth[i], i))


def character_motion(
    g: Gltf, skin: int, skel: Skeleton, keys: Sequence[Keyframe]
) -> tuple[list[int], np.ndarray, np.ndarray]:
    """(joint nodes, local translations (nk,nj,3), rotations (nk,nj,4) w-first)."""
    joints = skin_joints(g, skin)
    if unique_names(joints.names) != skel.names:
        raise GltfError(
            f"{g.source}: skins[{skin}]: expected the rig's bones as its joints, got other "
            f"joints ({len(joints.names)} against the rig's {len(skel.names)} bones): "
            "make the rig again with `puppetcli rig from-gltf`"
        )
    parents = g.parents()
    order = _node_order(parents)
    rest = g.world()
    rest_local = {i: np.linalg.inv(_world_or_eye(rest, parents[i])) @ rest[i] for i in order}
    linear = joints.bind[:, :3, :3]
    position = {int(n): k for k, n in enumerate(joints.nodes)}
    nk, nj = len(keys), len(joints.names)
    trans, rot = np.zeros((nk, nj, 3)), np.zeros((nk, nj, 4))
    for k, key in enumerate(keys):
        world: dict[int, np.ndarray] = {}
        for i in order:
            if i in position:
                bone = key.bones[skel.names[position[i]]]
                m = np.eye(4)
                m[:3, :3] = quat.matrix(quat.normalize(bone.rotation)) @ linear[position[i]]
                m[:3, 3] = bone.head
                world[i] = m
            else:
                world[i] = _world_or_eye(world, parents[i]) @ rest_local[i]
        for i, j in position.items():
            local = np.linalg.inv(_world_or_eye(world, parents[i])) @ world[i]
            trans[k, j] = local[:3, 3]
            rot[k, j] = quat_from_matrix(local)
    return [int(n) for n in joints.nodes], trans, continuous(rot)


def _world_or_eye(world, i: int) -> np.ndarray:
    """``world[i]``, the identity for no node (−1)."""
    return world[i] if i >= 0 else np.eye(4)


def _one_buffer(g: Gltf) -> bytes:
    """Every buffer in one blob, buffer views moved to it; images in files become data
    URIs (a .glb carries no files beside it)."""
    starts, blob = [], bytearray()
    for data in g.buffers:
        blob += bytes(-len(blob) % ALIGN)
        starts.append(len(blob))
        blob += data
    for view in g.doc.bufferViews:
        view.byteOffset = (view.byteOffset or 0) + starts[view.buffer]
        view.buffer = 0
    folder = Path(g.source).parent
    for image in g.doc.images:
        if image.uri and not image.uri.startswith("data:"):
            try:
                data = (folder / image.uri).read_bytes()
            except OSError as exc:
                raise PuppetError(f"{g.source}: image {image.uri!r}: cannot read: {exc}") from None
            mime = image.mimeType or ("image/png" if image.uri.endswith(".png") else "image/jpeg")
            image.uri = f"data:{mime};base64,{base64.b64encode(data).decode()}"
    return bytes(blob)


def write_character_glb(
    path: Path,
    character: tuple[str, int],
    skel: Skeleton,
    keys: Sequence[Keyframe],
    fps: float,
    interpolation: str,
) -> None:
    """Write the character of ``character`` (file, skin) animated by ``keys`` as a .glb."""
    g = read_gltf(Path(character[0]))
    nodes, trans, rot = character_motion(g, character[1], skel, keys)
    blob = Blob(g.doc, _one_buffer(g))
    animation = key_animation(blob, nodes, trans, rot, keys, fps, interpolation)
    g.doc.animations = [animation, *g.doc.animations]
    blob.close()
    save_glb(path, g.doc)
