"""The parts of a glTF document puppetcli reads, checked once after loading.

pygltflib keeps whatever the JSON holds (a string where an index belongs, NaN in
a translation), so every field the readers use is checked here, with its JSON
path: ``FILE: nodes[3].rotation: expected 4 finite numbers, got ['x']``.
Indices must name an existing object, node children must form trees (one
parent each, no cycles), numbers must be finite and at most ``LARGEST``.
Accessor data is checked where it is read (``Gltf.accessor``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pygltflib as gl

from puppetcli.yamldoc import LARGEST

__all__ = ["COMPONENTS", "DTYPES", "MAX_COUNT", "TYPES", "WIDTHS", "check_document"]

# glTF's accessor component types (as numpy types) and element types (as widths): the ones
# it defines, which the readers and the writer share.
DTYPES = {
    gl.BYTE: np.int8, gl.UNSIGNED_BYTE: np.uint8, gl.SHORT: np.int16,
    gl.UNSIGNED_SHORT: np.uint16, gl.UNSIGNED_INT: np.uint32, gl.FLOAT: np.float32,
}  # fmt: skip
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
COMPONENTS = tuple(DTYPES)
TYPES = tuple(WIDTHS)
INTERPOLATIONS = (None, "LINEAR", "STEP", "CUBICSPLINE")
MAX_COUNT = 10**8  # items of one accessor
_LISTS = {"nodes": gl.Node, "accessors": gl.Accessor, "bufferViews": gl.BufferView,
          "buffers": gl.Buffer, "skins": gl.Skin, "meshes": gl.Mesh, "animations": gl.Animation,
          "images": gl.Image, "scenes": gl.Scene}  # fmt: skip

Fail = Callable[[str, str, Any], Exception]


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _index(fail: Fail, where: str, v: Any, count: int, optional: bool = True) -> None:
    if v is None and optional:
        return
    if not (_is_int(v) and 0 <= v < count):
        raise fail(where, f"an index from 0 to {count - 1}" if count else "no index", v)


def _natural(fail: Fail, where: str, v: Any, optional: bool = True, top: int = 2**40) -> None:
    if v is None and optional:
        return
    if not (_is_int(v) and 0 <= v <= top):
        raise fail(where, f"a whole number from 0 to {top:,}", v)


def _numbers(fail: Fail, where: str, v: Any, n: int) -> None:
    if v is None:
        return
    ok = isinstance(v, list) and len(v) == n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
        and abs(x) <= LARGEST for x in v
    )  # fmt: skip
    if not ok:
        raise fail(where, f"{n} finite numbers", v)


def _items(fail: Fail, where: str, values: Any, kind: type) -> None:
    """A list of ``kind`` objects (glTF objects, not numbers or nulls)."""
    if not isinstance(values, list):
        raise fail(where, "a list", values)
    for k, v in enumerate(values):
        if not isinstance(v, kind):
            raise fail(f"{where}[{k}]", "an object", v)


def check_document(doc: gl.GLTF2, fail: Fail) -> None:
    """Raise ``fail(where, expected, got)`` at the first field that cannot be read."""
    for name, kind in _LISTS.items():
        _items(fail, name, getattr(doc, name), kind)
    counts = {name: len(getattr(doc, name)) for name in _LISTS}
    for i, view in enumerate(doc.bufferViews):
        at = f"bufferViews[{i}]"
        _index(fail, f"{at}.buffer", view.buffer, counts["buffers"], optional=False)
        _natural(fail, f"{at}.byteOffset", view.byteOffset)
        _natural(fail, f"{at}.byteLength", view.byteLength, optional=False)
        _natural(fail, f"{at}.byteStride", view.byteStride, top=252)
    for i, acc in enumerate(doc.accessors):
        at = f"accessors[{i}]"
        if acc.componentType not in COMPONENTS:
            raise fail(f"{at}.componentType", "a glTF component type", acc.componentType)
        if acc.type not in TYPES:
            raise fail(f"{at}.type", "SCALAR, VEC2…VEC4 or MAT2…MAT4", acc.type)
        _natural(fail, f"{at}.count", acc.count, optional=False, top=MAX_COUNT)
        _index(fail, f"{at}.bufferView", acc.bufferView, counts["bufferViews"])
        _natural(fail, f"{at}.byteOffset", acc.byteOffset)
    _check_nodes(doc, fail, counts)
    for i, skin in enumerate(doc.skins):
        at = f"skins[{i}]"
        _index(fail, f"{at}.inverseBindMatrices", skin.inverseBindMatrices, counts["accessors"])
        if not isinstance(skin.joints, list):
            raise fail(f"{at}.joints", "a list of node indices", skin.joints)
        for k, j in enumerate(skin.joints):
            _index(fail, f"{at}.joints[{k}]", j, counts["nodes"], optional=False)
    for i, mesh in enumerate(doc.meshes):
        _items(fail, f"meshes[{i}].primitives", mesh.primitives, gl.Primitive)
        for k, prim in enumerate(mesh.primitives):
            if not isinstance(prim.attributes, gl.Attributes):
                raise fail(f"meshes[{i}].primitives[{k}].attributes", "a mapping",
                           prim.attributes)  # fmt: skip
            for name in ("POSITION", "JOINTS_0", "WEIGHTS_0"):
                at = f"meshes[{i}].primitives[{k}].attributes.{name}"
                _index(fail, at, getattr(prim.attributes, name, None), counts["accessors"])
    for i, anim in enumerate(doc.animations):
        _check_animation(fail, f"animations[{i}]", anim, counts)


def _check_nodes(doc: gl.GLTF2, fail: Fail, counts: dict[str, int]) -> None:
    parent: dict[int, int] = {}
    for i, node in enumerate(doc.nodes):
        at = f"nodes[{i}]"
        if node.name is not None and not isinstance(node.name, str):
            raise fail(f"{at}.name", "a string", node.name)
        _numbers(fail, f"{at}.matrix", node.matrix, 16)
        _numbers(fail, f"{at}.translation", node.translation, 3)
        _numbers(fail, f"{at}.rotation", node.rotation, 4)
        _numbers(fail, f"{at}.scale", node.scale, 3)
        if node.rotation is not None and not any(node.rotation):
            raise fail(f"{at}.rotation", "a unit quaternion", node.rotation)
        _index(fail, f"{at}.mesh", node.mesh, counts["meshes"])
        _index(fail, f"{at}.skin", node.skin, counts["skins"])
        children = node.children or []
        if not isinstance(children, list):
            raise fail(f"{at}.children", "a list of node indices", children)
        for k, c in enumerate(children):
            _index(fail, f"{at}.children[{k}]", c, counts["nodes"], optional=False)
            if c in parent or c == i:
                raise fail(f"{at}.children[{k}]", "a node with no other parent", c)
            parent[c] = i
    for start in range(len(doc.nodes)):  # a chain of parents longer than the nodes: a cycle
        i, steps = start, 0
        while i in parent and steps <= len(doc.nodes):
            i, steps = parent[i], steps + 1
        if steps > len(doc.nodes):
            raise fail(f"nodes[{start}]", "nodes that form trees", "a cycle of children")


def _check_animation(fail: Fail, at: str, anim: Any, counts: dict[str, int]) -> None:
    _items(fail, f"{at}.samplers", anim.samplers, gl.AnimationSampler)
    _items(fail, f"{at}.channels", anim.channels, gl.AnimationChannel)
    for k, sampler in enumerate(anim.samplers):
        _index(fail, f"{at}.samplers[{k}].input", sampler.input, counts["accessors"], False)
        _index(fail, f"{at}.samplers[{k}].output", sampler.output, counts["accessors"], False)
        if sampler.interpolation not in INTERPOLATIONS:
            raise fail(f"{at}.samplers[{k}].interpolation", "LINEAR, STEP or CUBICSPLINE",
                       sampler.interpolation)  # fmt: skip
    for k, channel in enumerate(anim.channels):
        _index(fail, f"{at}.channels[{k}].sampler", channel.sampler, len(anim.samplers), False)
        target = channel.target
        if not isinstance(target, gl.AnimationChannelTarget) or not isinstance(target.path, str):
            raise fail(f"{at}.channels[{k}].target", "a node and a path", target)
        _index(fail, f"{at}.channels[{k}].target.node", target.node, counts["nodes"])
