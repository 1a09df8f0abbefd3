"""A rig (YAML text, docs/rig-format.md) from a skeleton's geometry: the part of
``rig from-bvh`` and ``rig from-gltf`` that does not depend on the file format.

Shapes and masses.  A capsule from head to tail of the given radius (by default
``RADIUS_FRACTION`` × its length), at least ``RADIUS_FLOOR`` × the skeleton's
size, or a sphere of that floor radius when head and tail coincide; masses from
the density 1000 kg/m³ (``defaults.density``).  Bones shorter than 5 % of the
skeleton's size (fingers, toe ends, zero-length joints) get ``collide: false``:
touching contacts between such light links and heavy limbs are where projected
Gauss–Seidel converges worst.

Joints.  ``defaults.joint`` holds rigs/doll.yaml's defaults (kf 100, df 4, dd
20, yield 8 N·m, swing 60°, twist ±45°); every joint scales kf, df, dd and
yield by its own factor

    f = max(τ_g / (0.5 · 8 N·m), 1e-4),   capped so that sqrt(kf/I)·h ≤ 0.5,

τ_g = g · Σ_subtree m_b · |c_b − head| (its gravity torque with every lever
horizontal) and I = Σ_subtree (m_b |c_b − head|² + I_b,max) (the subtree's
inertia about the joint).  So each joint yields at twice the largest gravity
torque it can carry (the doll holds any pose, as rigs/doll.yaml does), the
ratios of the four (time constants) stay those of the doll, and a light link
(a finger) is not a spring too stiff for the step (ω·h ≤ 0.5).  The root is
fixed; the ground lies 2 cm below the lowest shape (beyond the 1 cm contact
margin, so nothing touches at rest); PGS runs 50 sweeps instead of 15, because
light links between heavy bones (mass ratios of 100 and more) converge slowly.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from puppetcli.errors import PuppetError
from puppetcli.naming import deduplicated
from puppetcli.outputs import make_parent, write_text_atomic
from puppetcli.rig.load import MAX_BONES, rig_from_text
from solver.model import Model, build_model

__all__ = [
    "BoneGeometry", "bone_geometry", "children_tail", "rig_text", "unique_names", "write_rig",
]  # fmt: skip

RADIUS_FRACTION = 0.15  # capsule radius / bone length
RADIUS_FLOOR = 0.005  # minimum radius / skeleton size
DENSITY = 1000.0  # kg/m³
JOINT = {"kf": 100.0, "df": 4.0, "dd": 20.0, "yield": 8.0}  # rigs/doll.yaml's defaults
SWING, TWIST = 60.0, 45.0  # degrees
LOAD_FRACTION = 0.5  # a joint's gravity torque is this fraction of its yield
MIN_FACTOR = 1e-4  # joint factor of a joint that carries no torque (a point mass on it)
MAX_OMEGA_H = 0.5  # cap on ω·h = sqrt(kf/I)·h of a joint's spring
COLLIDE_LENGTH = 0.05  # bones shorter than this × skeleton size do not collide
GROUND_GAP = 0.02  # m between the lowest shape and the ground
ITERATIONS = 50  # PGS sweeps: light links between heavy bones converge slowly
GRAVITY = 9.81  # m/s²


@dataclass(frozen=True)
class BoneGeometry:
    """Bone geometry in metres: names, parents (nb,) (−1: the root), head, tail (nb,3),
    radius (nb,), collide (nb,) bool."""

    names: tuple[str, ...]
    parents: np.ndarray
    head: np.ndarray
    tail: np.ndarray
    radius: np.ndarray
    collide: np.ndarray


def bone_geometry(
    names: tuple[str, ...],
    parents: np.ndarray,
    head: np.ndarray,
    tail: np.ndarray,
    radius: np.ndarray | None = None,
) -> BoneGeometry:
    """Capsules head → tail (see the module docstring): a bone of no length (below 1e-9 ×
    the skeleton's size) becomes a sphere, ``radius`` defaults to ``RADIUS_FRACTION`` ×
    length, every radius is at least the floor; names made unique."""
    pts = np.vstack([head, tail])
    size = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    length = np.linalg.norm(tail - head, axis=1)
    floor = RADIUS_FLOOR * size if size > 0.0 else 0.01
    tail = np.where((length <= 1e-9 * max(size, 1e-12))[:, None], head, tail)
    radius = RADIUS_FRACTION * length if radius is None else np.asarray(radius, dtype=float)
    radius = np.maximum(radius, floor)
    collide = length >= COLLIDE_LENGTH * size
    return BoneGeometry(unique_names(names), np.asarray(parents), head, tail, radius, collide)


def write_rig(path: Path, text: str) -> Model:
    """Write rig ``text`` to ``path`` (its folder made, atomically) once it loads and builds;
    the built model."""
    model = build_model(rig_from_text(text, str(path)))
    make_parent(Path(path))
    write_text_atomic(Path(path), text)
    return model


def rig_text(
    name: str, bones: BoneGeometry, note: str, source: str, extra: tuple[str, ...] = ()
) -> str:
    """Rig YAML for ``bones`` (see the module docstring), checked by the rig loader;
    ``source`` names the input in errors; ``extra``: more top-level lines."""
    if len(bones.names) > MAX_BONES:
        raise PuppetError(
            f"{source}: expected at most {MAX_BONES} joints (a rig's limit), "
            f"got {len(bones.names):,}"
        )
    first = _yaml(name, bones, {}, note, extra)
    model = build_model(rig_from_text(first, f"<rig from {source}>"))
    nb = len(bones.names)
    factors = _joint_factors(
        bones, model.body_mass[:nb], model.body_pos0[:nb], model.body_inertia[:nb], model.options.h
    )
    return _yaml(name, bones, factors, note, extra)


def unique_names(names: tuple[str, ...]) -> tuple[str, ...]:
    """Names as in the file; a repeated name gets ``.001``, ``.002`` … (as Blender does)."""
    return deduplicated(names, lambda k: f".{k:03d}")


def _joint_factors(
    bones: BoneGeometry, mass: np.ndarray, com: np.ndarray, inertia: np.ndarray, h: float
) -> dict[int, float]:
    """The factor f_j on ``JOINT`` of every joint (see the module docstring)."""
    subtree = [[i] for i in range(len(mass))]
    for i in reversed(range(len(mass))):  # children come after their parents
        if bones.parents[i] >= 0:
            subtree[bones.parents[i]].extend(subtree[i])
    factors: dict[int, float] = {}
    for i, members in enumerate(subtree):
        if bones.parents[i] < 0:
            continue
        lever = np.linalg.norm(com[members] - bones.head[i], axis=1)
        torque = GRAVITY * float(np.sum(mass[members] * lever))
        # Subtree inertia about the joint, bounded below by the largest principal moments.
        moment = float(
            np.sum(mass[members] * lever**2 + np.linalg.eigvalsh(inertia[members])[:, -1])
        )
        f = max(torque / (LOAD_FRACTION * JOINT["yield"]), MIN_FACTOR)
        factors[i] = min(f, (MAX_OMEGA_H / h) ** 2 * moment / JOINT["kf"])
    return factors


def _num(x: float) -> str:
    """A YAML 1.1 float: fixed point (PyYAML reads ``1e-05`` as a string), no ``-0``."""
    text = f"{float(x):.10f}".rstrip("0")
    text = text + "0" if text.endswith(".") else text
    return "0.0" if text == "-0.0" else text


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _yaml(
    name: str, bones: BoneGeometry, factors: dict[int, float], note: str, extra: tuple[str, ...]
) -> str:
    """The rig document; names are JSON strings, which YAML reads as double-quoted scalars."""
    low = np.minimum(bones.head[:, 1], bones.tail[:, 1]) - bones.radius
    joint = ", ".join(f"{k}: {_num(v)}" for k, v in JOINT.items())
    lines = [f"# {line}" for line in note.splitlines()] + [
        f"name: {json.dumps(name, ensure_ascii=False)}",
        *extra,
        "root: fixed",
        f"ground: {{height: {_num(float(low.min()) - GROUND_GAP)}, friction: 0.8}}",
        "friction: 0.6",
        f"solver: {{h: 0.005, method: auto, iterations: {ITERATIONS}, warm_start: true}}",
        "defaults:",
        f"  density: {_num(DENSITY)}",
        f"  joint: {{{joint}, swing: {_num(SWING)}, twist: [{_num(-TWIST)}, {_num(TWIST)}]}}",
        "bones:",
    ]
    for i, bone in enumerate(bones.names):
        lines.append(f"  - name: {json.dumps(bone, ensure_ascii=False)}")
        if bones.parents[i] >= 0:
            parent = bones.names[bones.parents[i]]
            lines.append(f"    parent: {json.dumps(parent, ensure_ascii=False)}")
        lines += [f"    head: {_vec(bones.head[i])}", f"    tail: {_vec(bones.tail[i])}"]
        zero = bool(np.array_equal(bones.head[i], bones.tail[i]))
        kind = "sphere" if zero else "capsule"
        lines.append(f"    shape: {{type: {kind}, radius: {_num(bones.radius[i])}}}")
        if not bones.collide[i]:
            lines.append("    collide: false")
        if factors.get(i, 1.0) != 1.0:
            scaled = ", ".join(f"{k}: {_num(v * factors[i])}" for k, v in JOINT.items())
            lines.append(f"    joint: {{{scaled}}}")
    return "\n".join(lines) + "\n"


def children_tail(i: int, heads: np.ndarray, parents: np.ndarray) -> np.ndarray | None:
    """A joint's tail from its children's heads; None without a child away from its head.

    One child: its head.  Several: the mean of their heads, unless that mean lies within
    half of their mean distance of the head (children on opposite sides, e.g. hips with two
    legs and a spine), then the first child's head away from the head."""
    children = np.flatnonzero(parents == i)
    reach = np.linalg.norm(heads[children] - heads[i], axis=1)
    away = children[reach > 1e-9 * max(float(np.abs(heads).max()), 1e-12)]
    if len(away) == 0:
        return None
    points = heads[away]
    mean = points.mean(axis=0)
    reach = np.linalg.norm(points - heads[i], axis=1)
    if np.linalg.norm(mean - heads[i]) >= 0.5 * reach.mean():
        return mean
    return points[0]
