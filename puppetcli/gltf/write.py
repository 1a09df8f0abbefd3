"""Keyframes of a rig as a glTF 2.0 binary file (.glb): a skinned doll and one animation.

Layout (docs/gltf.md):

- One joint node per bone, in rig order, named as the bone, children under
  their parent.  At rest a node has the translation head − parent head (the
  root: its head) and no rotation, as the rig's rest frames are world-aligned.
- One skin over those joints; inverse bind matrices T(−head₀) (the bind pose
  is the rest pose).
- One mesh, ``doll``: every bone's rig shape as triangles
  (``puppetcli.gltf.mesh``), each vertex bound to its own bone with weight 1
  (rigid skinning, so a viewer moves the shapes exactly as the simulation did).
- One animation, ``keys``: for every joint a rotation channel (the key's
  rotation relative to its parent, q_parent⁻¹ ⊗ q) and a translation channel
  (the head in the parent's frame, q_parent⁻¹ · (head − head_parent)), so the
  file's joints stand exactly at the keys' heads, gaps of a soft joint
  included.  ``STEP``: key k at k / fps, held; ``LINEAR``: each key at its own
  time from the first, and viewers slerp between them.  The keys' labels and
  times are in the animation's ``extras.markers``.

Binary layout (buffers, GLB chunks, alignment) is pygltflib's; this module only
declares the arrays.  Everything is float32 as glTF requires; times are nudged
up by one float32 step where two would round equal.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pygltflib as gl

from puppetcli.gltf.check import DTYPES, WIDTHS
from puppetcli.gltf.mesh import skeleton_mesh
from puppetcli.outputs import atomic_path
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe
from solver import quat

__all__ = [
    "INTERPOLATIONS", "Blob", "continuous", "key_animation", "keys_gltf", "save_glb",
    "write_keys_glb",
]  # fmt: skip

INTERPOLATIONS = ("STEP", "LINEAR")
BONE_RGB = (217, 191, 140)  # sRGB of the renderer's bone colour
_TYPES = {WIDTHS[t]: t for t in ("SCALAR", "VEC3", "VEC4", "MAT4")}  # by width, as written


class Blob:
    """The one binary buffer of a document: arrays appended as buffer views and accessors."""

    def __init__(self, doc: gl.GLTF2, data: bytes = b"") -> None:
        self.doc, self.data = doc, bytearray(data)

    def add(self, array: np.ndarray, component: int, target: int | None = None,
            bounds: bool = False) -> int:  # fmt: skip
        """Append ``array`` (n, k) as one accessor; its index.  ``bounds``: min/max
        (required for positions and animation inputs)."""
        values = np.ascontiguousarray(array, dtype=DTYPES[component])
        flat = values.reshape(len(values), -1)
        self.data += bytes(-len(self.data) % 4)
        offset = len(self.data)
        self.data += flat.tobytes()
        self.doc.bufferViews.append(
            gl.BufferView(buffer=0, byteOffset=offset, byteLength=flat.nbytes, target=target)
        )
        accessor = gl.Accessor(
            bufferView=len(self.doc.bufferViews) - 1,
            componentType=component,
            count=len(flat),
            type=_TYPES[flat.shape[1]],
        )
        if bounds:
            accessor.min = [_number(v) for v in flat.min(axis=0)]
            accessor.max = [_number(v) for v in flat.max(axis=0)]
        self.doc.accessors.append(accessor)
        return len(self.doc.accessors) - 1

    def close(self) -> None:
        self.data += bytes(-len(self.data) % 4)
        self.doc.buffers = [gl.Buffer(byteLength=len(self.data))]
        self.doc.set_binary_blob(bytes(self.data))


def _number(v) -> float | int:
    return int(v) if isinstance(v, np.integer) else float(v)


def keys_gltf(
    skel: Skeleton,
    keys: Sequence[Keyframe],
    name: str,
    fps: float = 30.0,
    interpolation: str = "STEP",
) -> gl.GLTF2:
    """The glTF document of ``keys`` (see the module docstring)."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be STEP or LINEAR, got {interpolation!r}")
    doc = gl.GLTF2(asset=gl.Asset(version="2.0", generator=f"puppetcli {version('puppetcli')}"))
    blob = Blob(doc)
    nb = len(skel.names)
    _joint_nodes(doc, skel)
    doc.nodes.append(gl.Node(name="doll", mesh=0, skin=0))
    doc.scenes = [gl.Scene(name=name, nodes=[*np.flatnonzero(skel.parents < 0).tolist(), nb])]
    doc.scene = 0
    bind = np.tile(np.eye(4), (nb, 1, 1))
    bind[:, :3, 3] = -skel.head0
    # glTF matrices are column-major: the transpose, flattened row by row.
    ibm = blob.add(np.transpose(bind, (0, 2, 1)).reshape(nb, 16), gl.FLOAT)
    doc.skins = [gl.Skin(name=name, joints=list(range(nb)), inverseBindMatrices=ibm)]
    doc.meshes = [_doll_mesh(blob, skel)]
    doc.materials = [_material()]
    if keys:
        doc.animations = [_animation(blob, skel, keys, fps, interpolation)]
    blob.close()
    return doc


def write_keys_glb(
    path: Path,
    skel: Skeleton,
    keys: Sequence[Keyframe],
    name: str,
    fps: float = 30.0,
    interpolation: str = "STEP",
) -> None:
    """Write ``keys`` as a .glb file atomically."""
    save_glb(path, keys_gltf(skel, keys, name, fps, interpolation))


def save_glb(path: Path, doc: gl.GLTF2) -> None:
    """Write a document with its binary blob as a .glb file, atomically."""
    data = b"".join(doc.save_to_bytes())
    with atomic_path(Path(path)) as tmp:
        tmp.write_bytes(data)


def _joint_nodes(doc: gl.GLTF2, skel: Skeleton) -> None:
    """One node per bone at its rest place, children listed under their parent."""
    for i, bone in enumerate(skel.names):
        p = skel.parents[i]
        offset = skel.head0[i] - (skel.head0[p] if p >= 0 else 0.0)
        children = np.flatnonzero(skel.parents == i).tolist()
        doc.nodes.append(
            gl.Node(name=bone, translation=[float(v) for v in offset], children=children)
        )


def _doll_mesh(blob: Blob, skel: Skeleton) -> gl.Mesh:
    """The rest shapes of every bone, each vertex bound to its bone alone."""
    mesh = skeleton_mesh(skel)
    n = len(mesh.positions)
    joints = np.zeros((n, 4), dtype=np.int64)
    joints[:, 0] = mesh.bone
    weights = np.zeros((n, 4))
    weights[:, 0] = 1.0
    joint_type = gl.UNSIGNED_BYTE if len(skel.names) <= 256 else gl.UNSIGNED_SHORT
    attributes = gl.Attributes(
        POSITION=blob.add(mesh.positions, gl.FLOAT, gl.ARRAY_BUFFER, bounds=True),
        NORMAL=blob.add(mesh.normals, gl.FLOAT, gl.ARRAY_BUFFER),
        JOINTS_0=blob.add(joints, joint_type, gl.ARRAY_BUFFER),
        WEIGHTS_0=blob.add(weights, gl.FLOAT, gl.ARRAY_BUFFER),
    )
    index_type = gl.UNSIGNED_SHORT if n < 65535 else gl.UNSIGNED_INT
    indices = blob.add(mesh.triangles.reshape(-1, 1), index_type, gl.ELEMENT_ARRAY_BUFFER)
    return gl.Mesh(
        name="doll", primitives=[gl.Primitive(attributes=attributes, indices=indices, material=0)]
    )


def _material() -> gl.Material:
    srgb = np.array(BONE_RGB) / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    return gl.Material(
        name="bone",
        pbrMetallicRoughness=gl.PbrMetallicRoughness(
            baseColorFactor=[*[float(c) for c in linear], 1.0],
            metallicFactor=0.0,
            roughnessFactor=0.8,
        ),
    )


def key_times(keys: Sequence[Keyframe], fps: float, interpolation: str) -> np.ndarray:
    """Animation times (s) of the keys: k / fps (STEP) or from the first key (LINEAR)."""
    if interpolation == "STEP":
        times = np.arange(len(keys)) / fps
    else:
        times = np.array([k.time for k in keys]) - keys[0].time
    out = times.astype(np.float32)
    for i in range(1, len(out)):  # strictly increasing after rounding to float32
        if out[i] <= out[i - 1]:
            out[i] = np.nextafter(out[i - 1], np.float32(np.inf))
    return out


def local_motion(skel: Skeleton, keys: Sequence[Keyframe]) -> tuple[np.ndarray, np.ndarray]:
    """(translations (nk,nb,3), rotations (nk,nb,4) w-first) of every joint relative to its
    parent, rotations sign-continuous from key to key."""
    head = np.array([[k.bones[n].head for n in skel.names] for k in keys], dtype=float)
    rot = np.array([[k.bones[n].rotation for n in skel.names] for k in keys], dtype=float)
    rot = quat.normalize(rot)
    parent = np.where(skel.parents >= 0, skel.parents, 0)
    rooted = (skel.parents < 0)[None, :, None]
    q_parent = np.where(rooted, quat.IDENTITY, rot[:, parent])
    h_parent = np.where(rooted, 0.0, head[:, parent])
    trans = quat.rotate(quat.conj(q_parent), head - h_parent)
    local = quat.mul(quat.conj(q_parent), rot)
    return trans, continuous(local)


def continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions (nk, n, 4) with signs flipped so each is within 90° of the key before
    (the shorter way for viewers that interpolate them linearly)."""
    q = np.array(q, dtype=float)
    for k in range(1, len(q)):
        q[k, np.sum(q[k] * q[k - 1], axis=-1) < 0.0] *= -1.0
    return q


def _animation(
    blob: Blob, skel: Skeleton, keys: Sequence[Keyframe], fps: float, interpolation: str
) -> gl.Animation:
    trans, rot = local_motion(skel, keys)
    return key_animation(blob, list(range(len(skel.names))), trans, rot, keys, fps, interpolation)


def key_animation(
    blob: Blob,
    nodes: list[int],
    trans: np.ndarray,
    rot: np.ndarray,
    keys: Sequence[Keyframe],
    fps: float,
    interpolation: str,
) -> gl.Animation:
    """The animation ``keys`` of ``nodes``: translations (nk,nn,3) and rotations (nk,nn,4)
    w-first, one translation and one rotation channel per node, key labels as markers."""
    times = key_times(keys, fps, interpolation)
    xyzw = rot[..., [1, 2, 3, 0]]
    inputs = blob.add(times.reshape(-1, 1), gl.FLOAT, bounds=True)
    samplers, channels = [], []
    for i, node in enumerate(nodes):
        for path, values in (("translation", trans[:, i]), ("rotation", xyzw[:, i])):
            output = blob.add(values, gl.FLOAT)
            samplers.append(
                gl.AnimationSampler(input=inputs, output=output, interpolation=interpolation)
            )
            target = gl.AnimationChannelTarget(node=node, path=path)
            channels.append(gl.AnimationChannel(sampler=len(samplers) - 1, target=target))
    markers = [{"time": float(t), "label": k.label, "key": i}
               for i, (t, k) in enumerate(zip(times, keys, strict=True))]  # fmt: skip
    return gl.Animation(
        name="keys", samplers=samplers, channels=channels, extras={"markers": markers}
    )
