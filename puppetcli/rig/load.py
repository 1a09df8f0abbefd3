"""Rig files: YAML → validated ``solver.spec.RigSpec``.

The format is documented in ``docs/rig-format.md``.  Everything the file states
is checked here, so that ``solver`` can trust a ``RigSpec``; every problem is
reported as one ``RigError`` line naming file, line, YAML path, what was
expected and what was found.  Angles in the file are degrees; the spec holds
radians.  Bones are returned parents-first, whatever their order in the file.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from puppetcli.errors import RigError
from puppetcli.yamldoc import Fields, Node, did_you_mean, load_file, load_text
from solver import quat
from solver.massprops import shape_volume
from solver.spec import (
    ROOT_MODES,
    SHAPE_KINDS,
    BoneSpec,
    GroundSpec,
    LimitSpec,
    PropSpec,
    RheologySpec,
    RigSpec,
    ShapeSpec,
    SolverSpec,
)

__all__ = [
    "SOLVER_METHODS",
    "STEP_RANGE",
    "load_rig",
    "read_step",
    "rig_from_text",
    "solver_overrides",
]

SOLVER_METHODS = ("auto", "pgs", "hybrid", "direct", "reference")
INTEGRATORS = ("euler", "bdf2")
DEFAULT_DENSITY = 1000.0  # kg/m³, water: a plausible body density
TOP_KEYS = ("name", "gravity", "ground", "root", "friction", "solver", "defaults", "bones", "props",
            "character")  # fmt: skip
DEFAULTS_KEYS = ("shape", "density", "joint")
BONE_KEYS = (
    "name",
    "parent",
    "head",
    "tail",
    "shape",
    "mass",
    "density",
    "com",
    "inertia",
    "collide",
)
BONE_KEYS += ("joint",)
PROP_KEYS = ("name", "shape", "position", "rotation", "dynamic", "mass", "density", "friction")
SHAPE_KEYS = {"capsule": ("type", "radius"), "sphere": ("type", "radius"), "box": ("type", "size")}
PROP_SHAPE_KINDS = ("sphere", "box")  # a capsule needs a bone's length


def load_rig(path: Path) -> RigSpec:
    """Read and validate a rig file; raises ``RigError``.  A ``character`` file is relative
    to the rig's folder."""
    spec = _rig_from_document(load_file(path, RigError))
    if spec.character is not None:
        gltf = Path(path).parent / spec.character[0]
        spec = replace(spec, character=(str(gltf), spec.character[1]))
    return spec


def rig_from_text(text: str, source: str) -> RigSpec:
    """Validate rig YAML ``text``; ``source`` names it in error messages."""
    return _rig_from_document(load_text(text, source, RigError))


MAX_BONES = 512  # a full-body skeleton with fingers and face has a few hundred at most
STEP_RANGE = (1e-5, 0.1)  # s: a physics step outside this is a mistake (rig, script, --h)
SLOP_RANGE = (0.0, 0.01)  # m: a contact sinking more than a centimetre is not resting


def read_step(node: Node) -> float:
    """A physics step h (s) in STEP_RANGE."""
    return node.number(*STEP_RANGE)


_SOLVER_READERS: dict[str, Callable[[Node], Any]] = {
    "h": read_step,
    "method": lambda node: node.choice(SOLVER_METHODS),
    "iterations": lambda node: node.integer(1),
    "warm_start": Node.boolean,
    "warm_start_factor": lambda node: node.number(0.0, 1.0),
    "integrator": lambda node: node.choice(INTEGRATORS),
    "contact_slop": lambda node: node.number(*SLOP_RANGE),
}


def solver_overrides(node: Node) -> dict[str, Any]:
    """Read a ``solver:`` block into ``SolverSpec`` field overrides (shared with scripts)."""
    fields = node.mapping(tuple(_SOLVER_READERS))
    return {key: _SOLVER_READERS[key](fields[key]) for key in fields}


@dataclass(frozen=True)
class _Defaults:
    """The rig's ``defaults:`` block, parsed (shape and joint keep only the keys given)."""

    shape: dict[str, Any]
    density: float
    joint: dict[str, Any]


@dataclass(frozen=True)
class _BoneEntry:
    """A bone mapping before its parent is resolved."""

    node: Node
    fields: Fields
    name: str


def _rig_from_document(doc: Node) -> RigSpec:
    top = doc.mapping(TOP_KEYS, required=("name", "bones"), what="a mapping of rig settings")
    name = top["name"].string()
    root_mode = top.read("root", lambda node: node.choice(ROOT_MODES), "fixed")
    defaults = top.read("defaults", _read_defaults, _Defaults({}, DEFAULT_DENSITY, {}))
    bones, entries = _read_bones(top["bones"], defaults, root_mode)
    bone_lines = {entry.name: entry.fields["name"].line for entry in entries}
    return RigSpec(
        name=name,
        bones=bones,
        root_mode=root_mode,
        gravity=top.read("gravity", lambda node: node.vector(3), np.array([0.0, -9.81, 0.0])),
        ground=top.read("ground", _read_ground, None),
        props=top.read("props", lambda node: _read_props(node, bone_lines), ()),
        bone_friction=top.read("friction", Node.non_negative, 0.6),
        solver=replace(SolverSpec(), **top.read("solver", solver_overrides, {})),
        character=top.read("character", _read_character, None),
    )


def _read_character(node: Node) -> tuple[str, int]:
    """``character: {gltf: FILE, skin: N}``: the glTF file the rig was made from."""
    fields = node.mapping(("gltf", "skin"), required=("gltf",), what="a mapping gltf, skin")
    return fields["gltf"].string("a file name"), fields.read("skin", lambda n: n.integer(0), 0)


def _read_ground(node: Node) -> GroundSpec:
    fields = node.mapping(("height", "friction"))
    height = fields.read("height", Node.number, GroundSpec.height)
    return GroundSpec(height, fields.read("friction", Node.non_negative, GroundSpec.friction))


def _read_defaults(node: Node) -> _Defaults:
    fields = node.mapping(DEFAULTS_KEYS)
    shape = fields.read("shape", lambda n: _shape_keys(n, "capsule", SHAPE_KINDS), {})
    density = fields.read("density", Node.positive, DEFAULT_DENSITY)
    return _Defaults(shape, density, fields.read("joint", _joint_settings, {}))


def _shape_keys(node: Node, inherited: str | None, kinds: tuple[str, ...]) -> dict[str, Any]:
    """Parse a shape mapping into the keys it gives: type (or ``inherited``), radius, size."""
    fields = node.mapping(("type", "radius", "size"))
    type_node = fields.get("type")
    if type_node is not None:
        kind = type_node.choice(kinds)
    elif inherited is None:
        node.fail(f"a 'type' ({', '.join(kinds)})", got="no 'type' key")
    else:
        kind = inherited
    allowed = SHAPE_KEYS[kind]
    for key in fields:
        if key not in allowed:
            fields.key_node(key).fail(f"one of the keys {', '.join(allowed)} for a {kind}")
    out: dict[str, Any] = {"type": kind}
    if (radius := fields.get("radius")) is not None:
        out["radius"] = radius.positive()
    if (size := fields.get("size")) is not None:
        out["size"] = size.vector(3, 0.0, exclusive=True)
    return out


def _shape_spec(keys: dict[str, Any], node: Node, default_radius: float) -> ShapeSpec:
    """Build a ShapeSpec from parsed keys; ``node`` takes the blame for missing sizes."""
    if keys["type"] == "box":
        if "size" not in keys:
            node.fail("a 'size' for a box shape", got="no 'size' key")
        return ShapeSpec("box", half_extents=tuple(float(s) / 2.0 for s in keys["size"]))
    radius = keys.get("radius", default_radius)
    if radius <= 0.0:
        node.fail(f"a 'radius' for a {keys['type']} on a zero-length bone", got="no 'radius' key")
    return ShapeSpec(keys["type"], radius=float(radius))


def _twist(node: Node) -> tuple[float, float]:
    lo, hi = node.vector(2, -180.0, 180.0)
    if not lo <= 0.0 <= hi:
        node.fail("[lo, hi] degrees with lo <= 0 <= hi", got=f"[{lo:g}, {hi:g}]")
    return (math.radians(lo), math.radians(hi))


def _or_none(read: Callable[[Node], float | tuple], none: Any) -> Callable[[Node], Any]:
    """A reader where an explicit null means ``none`` (no yield, no limit)."""
    return lambda node: none if node.is_null() else read(node)


_JOINT_READERS: dict[str, Callable[[Node], Any]] = {
    "kf": lambda node: node.scalar_or_vector(3, 0.0),
    "df": lambda node: node.scalar_or_vector(3, 0.0),
    "dd": lambda node: node.scalar_or_vector(3, 0.0, exclusive=True),
    "plastic": Node.boolean,
    "yield": _or_none(Node.positive, math.inf),
    "swing": _or_none(lambda node: math.radians(node.number(0.0, 180.0, True)), math.inf),
    "twist": _or_none(_twist, (-math.inf, math.inf)),
}


def _joint_settings(node: Node) -> dict[str, Any]:
    """Parse a ``joint:`` mapping into the settings it gives (null yield/swing/twist = none)."""
    fields = node.mapping(tuple(_JOINT_READERS))
    return {key: _JOINT_READERS[key](fields[key]) for key in fields}


def _joint_specs(settings: dict[str, Any]) -> tuple[RheologySpec, LimitSpec]:
    """Rheology and limits from merged settings; absent dd (or plastic: false) = never flows."""
    dd = settings.get("dd", np.full(3, math.inf))
    if not settings.get("plastic", True):
        dd = np.full(3, math.inf)
    rheology = RheologySpec(
        kf=np.array(settings.get("kf", np.zeros(3)), dtype=float),
        df=np.array(settings.get("df", np.zeros(3)), dtype=float),
        dd=np.array(dd, dtype=float),
        yield_torque=settings.get("yield", math.inf),
    )
    limits = LimitSpec(settings.get("swing", math.inf), settings.get("twist", LimitSpec.twist))
    return rheology, limits


def _read_bones(
    node: Node, defaults: _Defaults, root_mode: str
) -> tuple[tuple[BoneSpec, ...], list[_BoneEntry]]:
    """All bones, parents first, plus the raw entries (for name clashes with props)."""
    items = node.items("a non-empty list of bones")
    if not items:
        node.fail("a non-empty list of bones")
    if len(items) > MAX_BONES:
        node.fail(f"at most {MAX_BONES} bones (a step's memory grows as the bones squared: "
                  f"1,000 took 5 GB)", got=f"{len(items):,} bones")  # fmt: skip
    entries: list[_BoneEntry] = []
    seen: dict[str, Node] = {}
    for item in items:
        fields = item.mapping(BONE_KEYS, required=("name", "head", "tail"), what="a bone mapping")
        name = _unique_name(fields["name"], seen, "bone")
        seen[name] = fields["name"]
        entries.append(_BoneEntry(item, fields, name))
    parents = _resolve_parents(entries)
    _check_cycles(entries, parents)
    bones = tuple(
        _build_bone(entries[i], parents[i] is None, defaults, root_mode)
        for i in _parents_first(parents)
    )
    return bones, entries


def _unique_name(node: Node, seen: dict[str, Node], what: str) -> str:
    name = node.string(f"a {what} name (a string)")
    if name in seen:
        node.fail(f"a unique {what} name", got=f"'{name}' again (first at line {seen[name].line})")
    return name


def _resolve_parents(entries: list[_BoneEntry]) -> list[int | None]:
    """Index of each bone's parent; unknown parents and second roots are errors."""
    index = {entry.name: i for i, entry in enumerate(entries)}
    parents: list[int | None] = []
    root: str | None = None
    for entry in entries:
        node = entry.fields.get("parent")
        if node is None:
            if root is not None:
                where = entry.fields.raw("parent") or entry.node
                got = f"none, so '{entry.name}' would be a second root besides '{root}'"
                where.fail("a 'parent' (a rig has one root bone)", got=got)
            root = entry.name
            parents.append(None)
            continue
        parent = node.string("a parent bone name")
        if parent not in index:
            node.fail("the name of a bone in this rig", hint=did_you_mean(parent, index))
        parents.append(index[parent])
    return parents


def _check_cycles(entries: list[_BoneEntry], parents: list[int | None]) -> None:
    """Every parent chain must end at the root; name the bones of the first cycle found."""
    done: set[int] = set()
    for start in range(len(entries)):
        chain: list[int] = []
        i: int | None = start
        while i is not None and i not in done:
            if i in chain:
                cycle = chain[chain.index(i) :]
                first = min(cycle)
                cycle = cycle[cycle.index(first) :] + cycle[: cycle.index(first)] + [first]
                names = " -> ".join(entries[j].name for j in cycle)
                entries[first].fields["parent"].fail(
                    "a parent chain that ends at the root", got=f"a cycle {names}"
                )
            chain.append(i)
            i = parents[i]
        done.update(chain)


def _parents_first(parents: list[int | None]) -> list[int]:
    """File order, except that each bone's ancestors come before it."""
    order: list[int] = []
    placed: set[int] = set()
    for start in range(len(parents)):
        chain: list[int] = []
        i: int | None = start
        while i is not None and i not in placed:
            chain.append(i)
            i = parents[i]
        order.extend(reversed(chain))
        placed.update(chain)
    return order


def _build_bone(entry: _BoneEntry, is_root: bool, defaults: _Defaults, root_mode: str) -> BoneSpec:
    fields = entry.fields
    head, tail = fields["head"].vector(3), fields["tail"].vector(3)
    length = float(np.linalg.norm(tail - head))
    shape_node = fields.get("shape")
    keys = defaults.shape
    if shape_node is not None:
        own = _shape_keys(shape_node, defaults.shape.get("type", "capsule"), SHAPE_KINDS)
        # Inherit only the default keys that make sense for the bone's own shape type.
        keys = {k: v for k, v in keys.items() if k in SHAPE_KEYS[own["type"]]} | own
    keys = {"type": "capsule", **keys}
    if keys["type"] != "sphere" and length < 1e-12:
        fields["tail"].fail(
            "a tail away from the head (a bone of zero length needs a sphere shape)",
            got=f"the head's position for a {keys['type']}",
        )
    shape = _shape_spec(keys, shape_node or entry.node, 0.1 * length)
    rheology, limits = _bone_joint(entry, is_root, defaults.joint, root_mode)
    return BoneSpec(
        name=entry.name,
        parent=None if is_root else fields["parent"].string(),
        head=head,
        tail=tail,
        shape=shape,
        mass=_mass(fields, shape_volume(shape, length), defaults.density),
        com=fields.read("com", lambda node: node.vector(3), None),
        inertia=fields.read("inertia", _inertia, None),
        rheology=rheology,
        limits=limits,
        collide=fields.read("collide", Node.boolean, True),
    )


def _bone_joint(
    entry: _BoneEntry, is_root: bool, defaults: dict[str, Any], root_mode: str
) -> tuple[RheologySpec | None, LimitSpec]:
    """The joint at the bone's head: defaults.joint overridden key by key by the bone's."""
    node = entry.fields.get("joint")
    own = {} if node is None else _joint_settings(node)
    if not is_root or root_mode == "ball":
        rheology, limits = _joint_specs({**defaults, **own})
        free = (rheology.kf == 0.0) & (rheology.df == 0.0)
        if rheology.active and free.any():
            (node or entry.node).fail(
                "kf or df above 0 about every axis of a joint that has a spring or damper"
                " (for a nearly free axis, a small df)",
                got=f"kf {_axes_text(rheology.kf)} and df {_axes_text(rheology.df)}",
            )
        return rheology, limits
    if node is not None:
        node.fail(f"no 'joint' on a {root_mode} root (it has one only with root: ball)")
    return None, LimitSpec()


def _axes_text(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:g}" for v in values) + "]"


def _mass(fields: Fields, volume: float, default_density: float) -> float:
    """The given mass, or density (the bone's, else the default) times the shape volume."""
    if fields.get("mass") is not None and fields.get("density") is not None:
        fields.key_node("density").fail("either 'mass' or 'density'", got="both")
    if (mass := fields.get("mass")) is not None:
        return mass.positive()
    return fields.read("density", Node.positive, default_density) * volume


def _inertia(node: Node) -> np.ndarray:
    """3 principal values or 6 tensor entries [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] → (3, 3)."""
    count = len(node.node.value) if isinstance(node.node, yaml.SequenceNode) else -1
    if count == 3:
        tensor = np.diag(node.vector(3, 0.0, exclusive=True))
    elif count == 6:
        xx, yy, zz, xy, xz, yz = node.vector(6)
        tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    else:
        node.fail("a list of 3 or 6 numbers")
    moments = np.linalg.eigvalsh(tensor)
    # A real body's principal moments obey I_max <= I_a + I_b (equality for a flat one).
    if moments[0] <= 0.0 or moments[2] > (moments[0] + moments[1]) * (1.0 + 1e-9):
        shown = ", ".join(f"{m:.6g}" for m in moments)
        node.fail(
            "a positive-definite inertia tensor satisfying the triangle inequality",
            got=f"principal moments [{shown}]",
        )
    return tensor


def _read_props(node: Node, bone_lines: dict[str, int]) -> tuple[PropSpec, ...]:
    props: list[PropSpec] = []
    seen: dict[str, Node] = {}
    for item in node.items("a list of props"):
        fields = item.mapping(PROP_KEYS, required=("name", "shape"), what="a prop mapping")
        name = _unique_name(fields["name"], seen, "prop")
        if name in bone_lines:
            fields["name"].fail(
                "a prop name not used by a bone",
                got=f"'{name}' (a bone at line {bone_lines[name]})",
            )
        seen[name] = fields["name"]
        shape_node = fields["shape"]
        shape = _shape_spec(_shape_keys(shape_node, None, PROP_SHAPE_KINDS), shape_node, 0.0)
        props.append(
            PropSpec(
                name=name,
                shape=shape,
                position=fields.read("position", lambda n: n.vector(3), np.zeros(3)),
                rotation=fields.read("rotation", _rotation, quat.IDENTITY.copy()),
                dynamic=fields.read("dynamic", Node.boolean, False),
                mass=_mass(fields, shape_volume(shape, 0.0), DEFAULT_DENSITY),
                friction=fields.read("friction", Node.non_negative, PropSpec.friction),
            )
        )
    return tuple(props)


def _rotation(node: Node) -> np.ndarray:
    """A quaternion [w, x, y, z] (normalised) or {axis: [x, y, z], angle: degrees}."""
    if isinstance(node.node, yaml.MappingNode):
        fields = node.mapping(("axis", "angle"), required=("axis", "angle"))
        axis = fields["axis"].vector(3)
        norm = float(np.linalg.norm(axis))
        if norm < 1e-12:
            fields["axis"].fail("a non-zero rotation axis", got="[0, 0, 0]")
        return quat.exp(axis / norm * math.radians(fields["angle"].number()))
    if not isinstance(node.node, yaml.SequenceNode) or len(node.node.value) != 4:
        node.fail("a quaternion [w, x, y, z] or {axis: [x, y, z], angle: degrees}")
    q = node.vector(4)
    norm = float(np.linalg.norm(q))
    if norm < 1e-12:
        node.fail("a non-zero quaternion [w, x, y, z]", got="[0, 0, 0, 0]")
    return q / norm
