"""Reading glTF 2.0 files (.glb, or .gltf with its buffers): skins, bind poses, animations.

pygltflib parses the document and finds the buffers (GLB chunk, data URI or
file next to a .gltf); this module reads accessors as numpy arrays, composes
node transforms and samples animations.

Node transforms.  A node's local matrix is its ``matrix`` or T·R·S; a node's
world matrix is its parent's world times its local matrix.  Animations
override T, R or S: ``STEP`` holds the value at or before t, ``LINEAR`` lerps
(slerps rotations), ``CUBICSPLINE`` is read at its keys' values (its tangents
are ignored, between keys it is lerped); before the first key and after the
last the end values hold.

Skins.  A skin's joints, in the order parents first (depth first over the
scene), each with its parent: the nearest ancestor node that is a joint of the
same skin.  The bind pose of joint j is the inverse of its inverse bind
matrix; where the nodes' own transforms give the same matrices (within
``BIND_MATCH`` of the skeleton's size), those are used instead, in double
precision (inverse bind matrices are float32).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pygltflib as gl

from puppetcli.errors import PuppetError, shown
from puppetcli.gltf.check import DTYPES, WIDTHS, check_document
from puppetcli.yamldoc import LARGEST
from solver import quat

__all__ = ["Gltf", "GltfError", "SkinJoints", "quat_from_matrix", "read_gltf", "skin_joints"]

BIND_MATCH = 1e-5  # × skeleton size: the nodes' rest transforms are the bind pose
_NORMALIZED = {gl.BYTE: 127.0, gl.UNSIGNED_BYTE: 255.0, gl.SHORT: 32767.0,
               gl.UNSIGNED_SHORT: 65535.0}  # fmt: skip


class GltfError(PuppetError):
    """A glTF file is unreadable or lacks what is asked of it."""


@dataclass
class Gltf:
    """A loaded glTF document and its buffers' bytes; ``source`` names it in messages;
    ``decoded``: accessors read so far (sampling an animation at many times reads each
    once)."""

    doc: gl.GLTF2
    buffers: list[bytes]
    source: str
    decoded: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    def fail(self, where: str, expected: str, got: str) -> GltfError:
        return GltfError(f"{self.source}: {where}: expected {expected}, got {got}")

    def check(self, where: str, expected: str, value: object) -> GltfError:
        """``fail`` with a value shown short (what ``check_document`` raises)."""
        return self.fail(where, expected, shown(value))

    def accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` (checked by ``check_document``) as float64 (count, width);
        normalized integers scaled to [0, 1] or [−1, 1].  Read-only (it is kept)."""
        if index not in self.decoded:
            out = self._decode(index)
            out.flags.writeable = False
            self.decoded[index] = out
        return self.decoded[index]

    def _decode(self, index: int) -> np.ndarray:
        where = f"accessors[{index}]"
        acc = self.doc.accessors[index]
        if acc.sparse is not None:
            raise self.fail(where, "a dense accessor", "a sparse one (not supported)")
        dtype = np.dtype(DTYPES[acc.componentType]).newbyteorder("<")
        width = WIDTHS[acc.type]
        if acc.bufferView is None or acc.count == 0:
            return np.zeros((acc.count, width))
        view = self.doc.bufferViews[acc.bufferView]
        data = self.buffers[view.buffer]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        item = dtype.itemsize * width
        stride = view.byteStride or item
        end = start + stride * (acc.count - 1) + item
        if stride < item or end > min(len(data), (view.byteOffset or 0) + view.byteLength):
            raise self.fail(where, f"{acc.count} items inside its buffer view", "too few bytes")
        if start % dtype.itemsize or stride % dtype.itemsize:
            raise self.fail(where, f"data aligned to {dtype.itemsize} bytes", "unaligned data")
        flat = np.frombuffer(data, dtype, offset=start, count=(end - start) // dtype.itemsize)
        step = stride // dtype.itemsize
        rows = np.stack([flat[k : k + step * (acc.count - 1) + 1 : step] for k in range(width)], 1)
        with np.errstate(invalid="ignore"):  # signalling NaNs: refused below
            out = rows.astype(float)
        if acc.normalized is True and acc.componentType in _NORMALIZED:
            out = np.maximum(out / _NORMALIZED[acc.componentType], -1.0)
        if not np.all(np.abs(out) <= LARGEST):  # NaN fails too
            raise self.fail(where, "finite numbers", shown(out[~(np.abs(out) <= LARGEST)][0]))
        return out

    def local_trs(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | np.ndarray:
        """A node's rest transform: (translation, rotation w-first, scale), or its matrix."""
        node = self.doc.nodes[i]
        if node.matrix is not None:
            return np.array(node.matrix, dtype=float).reshape(4, 4).T
        t = np.array(node.translation or [0.0, 0.0, 0.0], dtype=float)
        x, y, z, w = node.rotation or [0.0, 0.0, 0.0, 1.0]
        s = np.array(node.scale or [1.0, 1.0, 1.0], dtype=float)
        return t, quat.normalize(np.array([w, x, y, z], dtype=float)), s

    def parents(self) -> np.ndarray:
        """Parent node of every node (−1 for a scene root)."""
        out = np.full(len(self.doc.nodes), -1, dtype=np.int64)
        for i, node in enumerate(self.doc.nodes):
            for c in node.children or []:
                if 0 <= c < len(out):
                    out[c] = i
        return out

    def world(self, animated: dict[int, dict[str, np.ndarray]] | None = None) -> np.ndarray:
        """World matrices (nnodes, 4, 4) of every node; ``animated`` overrides a node's
        ``translation``, ``rotation`` (w-first) or ``scale``."""
        parents = self.parents()
        out = np.zeros((len(self.doc.nodes), 4, 4))
        done = np.zeros(len(self.doc.nodes), dtype=bool)
        for start in range(len(self.doc.nodes)):
            chain = []
            i = start
            while i >= 0 and not done[i] and i not in chain:
                chain.append(i)
                i = parents[i]
            base = out[i] if i >= 0 and done[i] else np.eye(4)
            with np.errstate(over="ignore", invalid="ignore"):  # checked below
                for j in reversed(chain):
                    base = base @ self._local(j, (animated or {}).get(j, {}))
                    out[j], done[j] = base, True
        if not np.all(np.abs(out) <= LARGEST):
            raise self.fail("nodes", "transforms with finite world matrices", "an overflow")
        return out

    def _local(self, i: int, override: dict[str, np.ndarray]) -> np.ndarray:
        rest = self.local_trs(i)
        if isinstance(rest, np.ndarray):
            return rest
        t = override.get("translation", rest[0])
        q = override.get("rotation", rest[1])
        s = override.get("scale", rest[2])
        m = np.eye(4)
        m[:3, :3] = quat.matrix(quat.normalize(q)) * s[None, :]
        m[:3, 3] = t
        return m

    def animation_times(self, animation: int) -> np.ndarray:
        """Every key time of an animation's samplers, sorted, unique."""
        anim = self.doc.animations[animation]
        times = [self.accessor(s.input)[:, 0] for s in anim.samplers]
        return np.unique(np.concatenate(times)) if times else np.zeros(0)

    def sample(self, animation: int, t: float) -> dict[int, dict[str, np.ndarray]]:
        """Node transforms an animation sets at time ``t`` (rotations w-first)."""
        anim = self.doc.animations[animation]
        out: dict[int, dict[str, np.ndarray]] = {}
        for channel in anim.channels:
            path, node = channel.target.path, channel.target.node
            if node is None or path not in ("translation", "rotation", "scale"):
                continue
            sampler = anim.samplers[channel.sampler]
            times = self.accessor(sampler.input)[:, 0]
            values = self.accessor(sampler.output)
            if sampler.interpolation == "CUBICSPLINE":
                values = values[1::3]  # (in-tangent, value, out-tangent) per key
            width = {"translation": 3, "rotation": 4, "scale": 3}[path]
            if len(times) == 0 or len(values) < len(times) or values.shape[1] != width:
                raise self.fail(f"animations[{animation}].samplers[{channel.sampler}]",
                                f"a {width}-vector per key time", "other output")  # fmt: skip
            if path == "rotation" and not np.all(np.linalg.norm(values, axis=1) > 0.0):
                raise self.fail(f"animations[{animation}].samplers[{channel.sampler}].output",
                                "unit quaternions", "a zero quaternion")  # fmt: skip
            if np.any(np.diff(times) < 0.0):
                raise self.fail(f"animations[{animation}].samplers[{channel.sampler}].input",
                                "increasing times", shown(times[:4].tolist()))  # fmt: skip
            value = _interpolate(times, values, t, sampler.interpolation, path == "rotation")
            if path == "rotation":
                value = quat.normalize(value[[3, 0, 1, 2]])
            out.setdefault(node, {})[path] = value
        return out


def _interpolate(
    times: np.ndarray, values: np.ndarray, t: float, how: str, rotation: bool
) -> np.ndarray:
    k = int(np.searchsorted(times, t, side="right")) - 1
    if k < 0:
        return values[0]
    if how == "STEP" or k >= len(times) - 1 or times[k + 1] <= times[k]:
        return values[min(k, len(values) - 1)]
    u = (t - times[k]) / (times[k + 1] - times[k])
    a, b = values[k], values[k + 1]
    if not rotation:
        return (1.0 - u) * a + u * b
    a_wxyz, b_wxyz = quat.normalize(a[[3, 0, 1, 2]]), quat.normalize(b[[3, 0, 1, 2]])
    if np.dot(a_wxyz, b_wxyz) < 0.0:
        b_wxyz = -b_wxyz
    q = quat.mul(a_wxyz, quat.exp(u * quat.log(quat.mul(quat.conj(a_wxyz), b_wxyz))))
    return q[[1, 2, 3, 0]]


def read_gltf(path: Path) -> Gltf:
    """Load a .glb or .gltf file and its buffers; a one-line GltfError when it cannot."""
    path = Path(path)
    try:
        with warnings.catch_warnings():
            # pygltflib warns about chunks of unknown types, which glTF says to ignore (a
            # missing binary chunk is caught below), and about versions, checked below.
            warnings.simplefilter("ignore")
            doc = gl.GLTF2().load(str(path))
    except Exception as exc:  # pygltflib raises anything from struct, json, dataclasses
        raise GltfError(
            f"{path}: expected a glTF 2.0 file (.glb or .gltf), got one that does not load "
            f"({type(exc).__name__}: {shown(str(exc))})"
        ) from None
    if doc is None:
        raise GltfError(f"{path}: expected a glTF 2.0 file, got no JSON chunk")
    version = getattr(doc.asset, "version", None)
    if not (isinstance(version, str) and version.startswith("2.")):
        raise GltfError(f"{path}: asset.version: expected 2.x (glTF 2.0), got {shown(version)}")
    if not isinstance(doc.buffers, list):
        raise GltfError(f"{path}: buffers: expected a list, got {shown(doc.buffers)}")
    buffers = []
    for k, buffer in enumerate(doc.buffers):
        if not (isinstance(buffer.byteLength, int) and 0 <= buffer.byteLength <= 2**40):
            raise GltfError(f"{path}: buffers[{k}].byteLength: expected a byte count, "
                            f"got {shown(buffer.byteLength)}")  # fmt: skip
        if buffer.uri is None and k > 0:
            raise GltfError(f"{path}: buffers[{k}]: expected a uri (only the first buffer of a "
                            "glb may be its binary chunk), got none")  # fmt: skip
        try:
            data = (
                doc.binary_blob()
                if buffer.uri is None
                else doc.get_data_from_buffer_uri(buffer.uri)
            )
        except Exception as exc:
            raise GltfError(
                f"{path}: buffers[{k}]: expected its data, got {type(exc).__name__}: "
                f"{shown(str(exc))}"
            ) from None
        if data is None or len(data) < buffer.byteLength:
            raise GltfError(
                f"{path}: buffers[{k}]: expected {buffer.byteLength} bytes, "
                f"got {0 if data is None else len(data)}"
            )
        buffers.append(bytes(data))
    g = Gltf(doc, buffers, str(path))
    check_document(doc, g.check)
    return g


@dataclass(frozen=True)
class SkinJoints:
    """A skin's joints, parents first: nodes (nj,) node indices; names (nj,); parents (nj,)
    (−1: the root); skin_index (nj,) position in the skin's ``joints`` list; bind (nj,4,4)
    world matrices at the bind pose."""

    nodes: np.ndarray
    names: tuple[str, ...]
    parents: np.ndarray
    skin_index: np.ndarray
    bind: np.ndarray


def skin_joints(g: Gltf, skin: int) -> SkinJoints:
    """The joints of skin ``skin`` (see the module docstring)."""
    skins = g.doc.skins
    if not skins:
        raise g.fail("skins", "a skinned character (a skin with joints)", "no skin")
    if not 0 <= skin < len(skins):
        raise g.fail("--skin", f"a skin index from 0 to {len(skins) - 1}", str(skin))
    joints = list(dict.fromkeys(skins[skin].joints))
    if not joints:
        raise g.fail(f"skins[{skin}]", "joints", "none")
    if not all(0 <= n < len(g.doc.nodes) for n in joints):
        raise g.fail(f"skins[{skin}].joints", f"node indices below {len(g.doc.nodes)}",
                     shown(joints))  # fmt: skip
    parent_of = _joint_parents(joints, g.parents())
    order = _parents_first(joints, parent_of)
    position = {n: k for k, n in enumerate(order)}
    parents = np.array([position.get(parent_of[n], -1) for n in order], dtype=np.int64)
    roots = [g.doc.nodes[n].name or f"node {n}" for n, p in zip(order, parents, strict=True)
             if p < 0]  # fmt: skip
    if len(roots) != 1:
        raise g.fail(f"skins[{skin}]", "joints under one root joint", f"{len(roots)} roots "
                     f"({', '.join(shown(r) for r in roots[:3])})")  # fmt: skip
    names = tuple(g.doc.nodes[n].name or f"joint{k}" for k, n in enumerate(order))
    skin_index = np.array([joints.index(n) for n in order], dtype=np.int64)
    return SkinJoints(np.array(order), names, parents, skin_index,
                      _bind(g, skins[skin], order, skin_index))  # fmt: skip


def _joint_parents(joints: list[int], node_parents: np.ndarray) -> dict[int, int]:
    """Each joint's nearest ancestor that is a joint (−1: none)."""
    members = set(joints)
    out = {}
    for n in joints:
        p, steps = node_parents[n], 0
        while p >= 0 and p not in members and steps <= len(node_parents):
            p, steps = node_parents[p], steps + 1
        out[n] = int(p) if p in members else -1
    return out


def _parents_first(joints: list[int], parent_of: dict[int, int]) -> list[int]:
    """The skin's joint order when parents already come first in it, else depth first from
    the roots with children in the skin's order."""
    place = {n: k for k, n in enumerate(joints)}
    if all(parent_of[n] < 0 or place[parent_of[n]] < place[n] for n in joints):
        return joints
    out: list[int] = []
    stack = [n for n in reversed(joints) if parent_of[n] < 0]
    while stack:
        n = stack.pop()
        out.append(n)
        stack.extend(c for c in reversed(joints) if parent_of[c] == n)
    return out


def _bind(g: Gltf, skin, order: list[int], skin_index: np.ndarray) -> np.ndarray:
    """World matrices of the joints at the bind pose (see the module docstring)."""
    rest = g.world()[order]
    if skin.inverseBindMatrices is None:
        return rest
    where = f"accessors[{skin.inverseBindMatrices}]"
    values = g.accessor(skin.inverseBindMatrices)
    if values.shape[1] != 16 or len(values) < len(skin.joints):
        raise g.fail(where, f"{len(skin.joints)} MAT4 inverse bind matrices", f"{len(values)} "
                     f"of {values.shape[1]} numbers")  # fmt: skip
    ibm = values.reshape(-1, 4, 4).transpose(0, 2, 1)[skin_index]
    det = np.linalg.det(ibm[:, :3, :3])
    if not np.all(np.abs(det) > 1e-12):
        raise g.fail(where, "invertible inverse bind matrices", f"determinant {det.min():.3g}")
    bind = np.linalg.inv(ibm)
    size = float(np.ptp(bind[:, :3, 3], axis=0).max()) if len(bind) > 1 else 1.0
    if np.abs(rest - bind).max() <= BIND_MATCH * max(size, 1e-12):
        return rest
    return bind


def quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (…, 4) w-first of the rotation part of matrices (…, 3+, 3+), any
    scale removed (the nearest rotation, by polar decomposition)."""
    from scipy.spatial.transform import Rotation

    a = np.asarray(m, dtype=float)[..., :3, :3]
    u, _, vt = np.linalg.svd(a)
    r = u @ vt
    r = np.where((np.linalg.det(r) < 0.0)[..., None, None], -r, r)
    flat = Rotation.from_matrix(r.reshape(-1, 3, 3)).as_quat(scalar_first=True)
    return flat.reshape(*a.shape[:-2], 4)
