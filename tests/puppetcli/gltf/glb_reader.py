"""A minimal, independent glTF 2.0 binary reader for the tests.

Parses the GLB container with ``struct`` and ``json``, reads accessors with
numpy, builds 4×4 node matrices with scipy's ``Rotation`` and samples
animations (STEP, and LINEAR with scipy's ``Slerp``).  It shares no code with
puppetcli or pygltflib, so it is an oracle for what a viewer sees.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
               5125: np.uint32, 5126: np.float32}  # fmt: skip
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@dataclass
class Glb:
    doc: dict
    blob: bytes

    def accessor(self, index: int) -> np.ndarray:
        acc = self.doc["accessors"][index]
        view = self.doc["bufferViews"][acc["bufferView"]]
        dtype = np.dtype(_COMPONENTS[acc["componentType"]])
        width = _WIDTH[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        rows = [
            np.frombuffer(self.blob, dtype, width, start + i * stride) for i in range(acc["count"])
        ]
        return np.array(rows, dtype=float).reshape(acc["count"], width)

    def node_index(self) -> dict[str, int]:
        return {n.get("name", ""): i for i, n in enumerate(self.doc["nodes"])}

    def parents(self) -> dict[int, int]:
        return {c: i for i, n in enumerate(self.doc["nodes"]) for c in n.get("children", [])}

    def _trs(self, i: int, t: float | None, animation: int) -> np.ndarray:
        node = self.doc["nodes"][i]
        if "matrix" in node:
            return np.array(node["matrix"], dtype=float).reshape(4, 4).T
        trs = {
            "translation": np.array(node.get("translation", [0.0, 0.0, 0.0]), dtype=float),
            "rotation": np.array(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), dtype=float),
            "scale": np.array(node.get("scale", [1.0, 1.0, 1.0]), dtype=float),
        }
        if t is not None and self.doc.get("animations"):
            anim = self.doc["animations"][animation]
            for channel in anim["channels"]:
                if channel["target"].get("node") == i:
                    sampler = anim["samplers"][channel["sampler"]]
                    trs[channel["target"]["path"]] = self.sample(sampler, t, channel["target"])
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(trs["rotation"]).as_matrix() @ np.diag(trs["scale"])
        m[:3, 3] = trs["translation"]
        return m

    def sample(self, sampler: dict, t: float, target: dict) -> np.ndarray:
        times = self.accessor(sampler["input"])[:, 0]
        values = self.accessor(sampler["output"])
        k = int(np.searchsorted(times, t, side="right")) - 1
        if k < 0:
            return values[0]
        if sampler.get("interpolation", "LINEAR") == "STEP" or k >= len(times) - 1:
            return values[k]
        u = (t - times[k]) / (times[k + 1] - times[k])
        if target["path"] == "rotation":
            pair = Rotation.from_quat(values[k : k + 2])
            return Slerp([0.0, 1.0], pair)([u]).as_quat()[0]
        return (1.0 - u) * values[k] + u * values[k + 1]

    def world(self, t: float | None = None, animation: int = 0) -> dict[int, np.ndarray]:
        """World 4×4 matrix of every node at time ``t`` (None: the nodes' own TRS)."""
        out: dict[int, np.ndarray] = {}
        parents = self.parents()

        def visit(i: int) -> np.ndarray:
            if i not in out:
                local = self._trs(i, t, animation)
                out[i] = visit(parents[i]) @ local if i in parents else local
            return out[i]

        for i in range(len(self.doc["nodes"])):
            visit(i)
        return out


def read_glb(path: Path) -> Glb:
    data = Path(path).read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data)
    offset, doc, blob = 12, None, b""
    while offset < length:
        size, kind = struct.unpack_from("<I4s", data, offset)
        chunk = data[offset + 8 : offset + 8 + size]
        if kind == b"JSON":
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == b"BIN\x00":
            blob = chunk
        offset += 8 + size
    assert doc is not None
    return Glb(doc, blob)
