"""A skinned glTF character made the way Blender exports one, with known bind geometry.

Three joints ``root`` → ``upper`` → ``lower`` under an ``Armature`` node that is
rotated, moved and scaled by 0.5 (the root joint scales back by 2); every joint
node has a Blender-style rotation (its local y along the bone) rather than
world-aligned axes.  The mesh is a tube of rings around the bones: rings near a
joint are shared 50/50 between the two bones, the others bound to one bone.

The heads, bone directions and radii are chosen here (``HEADS``, ``RADIUS``), and
the node transforms and inverse bind matrices derived from them, so a reader
must give these numbers back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl
from scipy.spatial.transform import Rotation

NAMES = ("root", "upper", "lower")
HEADS = np.array([[0.1, 0.8, -0.05], [0.1, 1.0, -0.05], [0.45, 1.05, 0.0]])
END = np.array([0.8, 1.1, 0.05])  # the lower bone's far end
RADIUS = 0.04
ARMATURE = (np.array([0.3, 0.0, -0.2]), Rotation.from_euler("y", 30, degrees=True), 0.5)
RING = 12


def _bone_frame(head: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """A rotation (3,3) whose y axis runs head → tail (Blender's bone axes)."""
    y = (tail - head) / np.linalg.norm(tail - head)
    x = np.cross(y, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    return np.stack((x, y, np.cross(x, y)), axis=1)


def bind_matrices() -> np.ndarray:
    """World bind matrices (3, 4, 4): bone frames at the heads, scale 1."""
    tails = np.vstack((HEADS[1:], END))
    out = np.tile(np.eye(4), (3, 1, 1))
    for j in range(3):
        out[j, :3, :3] = _bone_frame(HEADS[j], tails[j])
        out[j, :3, 3] = HEADS[j]
    return out


def _trs(m: np.ndarray) -> dict:
    scale = np.linalg.norm(m[:3, :3], axis=0)
    rot = Rotation.from_matrix(m[:3, :3] / scale)
    return {"translation": m[:3, 3].tolist(), "rotation": rot.as_quat().tolist(),
            "scale": scale.tolist()}  # fmt: skip


def _mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(positions, joints, weights, triangle indices) of a tube along the three bones."""
    path = np.vstack((HEADS, END))
    pos, joints, weights = [], [], []
    for seg in range(3):
        a, b = path[seg], path[seg + 1]
        frame = _bone_frame(a, b)
        for u in (0.15, 0.5, 0.85):
            centre = a + u * (b - a)
            for k in range(RING):
                t = 2 * np.pi * k / RING
                pos.append(centre + RADIUS * (frame[:, 0] * np.cos(t) + frame[:, 2] * np.sin(t)))
                if u == 0.15 and seg > 0:  # shared with the bone before
                    joints.append([seg, seg - 1, 0, 0])
                    weights.append([0.5, 0.5, 0.0, 0.0])
                else:
                    joints.append([seg, 0, 0, 0])
                    weights.append([1.0, 0.0, 0.0, 0.0])
    tris = []
    for r in range(8):
        for k in range(RING):
            a, b = r * RING + k, r * RING + (k + 1) % RING
            tris += [[a, b, b + RING], [a, b + RING, a + RING]]
    return np.array(pos), np.array(joints), np.array(weights), np.array(tris)


def write_character(path: Path) -> None:
    """The character as a .glb file."""
    bind = bind_matrices()
    t, r, s = ARMATURE
    arm = np.eye(4)
    arm[:3, :3] = r.as_matrix() * s
    arm[:3, 3] = t
    parents_world = [arm, bind[0], bind[1]]
    nodes = [gl.Node(name="Armature", translation=t.tolist(), rotation=r.as_quat().tolist(),
                     scale=[s, s, s], children=[1])]  # fmt: skip
    for j in range(3):
        local = np.linalg.inv(parents_world[j]) @ bind[j]
        nodes.append(gl.Node(name=NAMES[j], children=[j + 2] if j < 2 else [], **_trs(local)))
    nodes.append(gl.Node(name="body", mesh=0, skin=0))
    pos, joints, weights, tris = _mesh()
    blob = bytearray()
    doc = gl.GLTF2(asset=gl.Asset(version="2.0"), nodes=nodes,
                   scenes=[gl.Scene(nodes=[0, 4])], scene=0)  # fmt: skip

    def add(array, component, dtype, kind, target=None, bounds=False):
        data = np.ascontiguousarray(array, dtype=dtype)
        blob.extend(bytes(-len(blob) % 4))
        doc.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob),
                                             byteLength=data.nbytes, target=target))  # fmt: skip
        blob.extend(data.tobytes())
        acc = gl.Accessor(bufferView=len(doc.bufferViews) - 1, componentType=component,
                          count=len(data), type=kind)  # fmt: skip
        if bounds:
            acc.min, acc.max = data.min(axis=0).tolist(), data.max(axis=0).tolist()
        doc.accessors.append(acc)
        return len(doc.accessors) - 1

    ibm = np.linalg.inv(bind).transpose(0, 2, 1).reshape(3, 16)
    attributes = gl.Attributes(
        POSITION=add(pos, gl.FLOAT, np.float32, "VEC3", gl.ARRAY_BUFFER, True),
        JOINTS_0=add(joints, gl.UNSIGNED_BYTE, np.uint8, "VEC4", gl.ARRAY_BUFFER),
        WEIGHTS_0=add(weights, gl.FLOAT, np.float32, "VEC4", gl.ARRAY_BUFFER),
    )
    indices = add(tris.reshape(-1), gl.UNSIGNED_SHORT, np.uint16, "SCALAR",
                  gl.ELEMENT_ARRAY_BUFFER)  # fmt: skip
    doc.meshes = [gl.Mesh(primitives=[gl.Primitive(attributes=attributes, indices=indices)])]
    doc.skins = [gl.Skin(joints=[1, 2, 3], skeleton=1,
                         inverseBindMatrices=add(ibm, gl.FLOAT, np.float32, "MAT4"))]  # fmt: skip
    blob.extend(bytes(-len(blob) % 4))
    doc.buffers = [gl.Buffer(byteLength=len(blob))]
    doc.set_binary_blob(bytes(blob))
    Path(path).write_bytes(b"".join(doc.save_to_bytes()))
