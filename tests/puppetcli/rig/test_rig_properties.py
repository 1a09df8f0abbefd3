"""Property-based checks (Hypothesis) on random valid rigs: they load with the documented
mass properties, and a free one falls exactly as semi-implicit Euler says.

A strategy writes random rig documents as docs/rig-format.md describes them: a random tree of
1–8 bones (capsules, spheres, boxes), masses given or from densities, optional centres of mass
and inertia tensors, ball joints with random rheology (kf, df, dd, plastic, yield; scalars or
per axis; defaults merged key by key) and optional swing/twist limits, a random gravity and
solver settings (auto, hybrid or PGS), the root fixed, free or hanging by a ball joint.
Nothing collides: no ground, no props, collide: false.

Oracles, computed here from the document alone (no puppetcli or solver code):
* mass properties: mass = density × volume (sphere, capsule, box), the centre of mass, the
  inertia tensor about it (a capsule as a cylinder plus two hemispheres, each about its own
  centroid, then moved; a box of square cross-section; the parallel-axis theorem for an
  offset ``com``), each joint's kf after merging;
* a free rig (masses within a factor 20, springs soft enough for the step), bent out of its
  rest pose (random joint rotations, the springs holding them as their elastic part) and
  let go, stepped by solver.Engine (what the CLI runs) for 0.2–0.5 s:
  its joints are internal forces, so its linear momentum and centre of mass follow free
  fall's exact discrete recursion, P ← P + M g h, c ← c + h P / M (per substep when a step
  takes several), whatever the springs, dampers, limits and solver do inside.

No energy bound is asserted on random rigs, because the model does not guarantee one (seen
while writing these tests): with weak damping semi-implicit Euler's energy swings O(h) above
its start, a per-axis kf is not a potential at finite angles, and stiff springs between light
bones gain energy.

Derandomized: the same examples on every run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from puppetcli.rig.load import rig_from_text
from solver.engine import Engine
from solver.model import build_model
from solver.state import initial_state

BEND = 0.3  # rad: the largest initial joint rotation; limits are drawn at least LIMIT_GAP wider
LIMIT_GAP = 0.15  # rad: the bent pose starts clear of the limits (limit rows start at 0.05)

# Tolerances at about 5× the worst error measured over 2,000 random rigs (value in comment).
MASS_TOL = 2e-15  # relative, masses: 4.4e-16
REST_COM_TOL = 1e-15  # m, rest centres of mass: 0 (the same midpoint)
INERTIA_TOL = 6e-15  # relative, inertia tensors: 1.3e-15 (5.6e-7 while quat.from_two_vectors
# snapped bones within 1.4e-6 rad of −y onto −y: tests/solver/test_quat.py)
MOMENTUM_TOL = 8e-14  # × M·|g|·t, linear momentum vs M g t: 1.6e-14
FALL_COM_TOL = 6e-14  # m, centre of mass vs the recursion: 1.2e-14


# ---- random rig documents ----


def vectors(bound: float, least: float = 0.0):
    comp = st.floats(-bound, bound, allow_nan=False)
    return st.tuples(comp, comp, comp).map(np.array).filter(lambda v: np.linalg.norm(v) >= least)


def scalar_or_axes(low: float, high: float, zero: bool = False):
    """One number for all three axes, or ``[x, y, z]`` (the format allows both); with
    ``zero``, 0 too (the loader refuses numbers between 0 and 1e-9)."""
    value = st.floats(low, high)
    value = st.one_of(st.just(0.0), value) if zero else value
    return st.one_of(value, st.lists(value, min_size=3, max_size=3))


@st.composite
def joint_settings(draw) -> dict:
    """Some of a joint's keys, in physically sensible ranges (N·m/rad, N·m·s/rad, N·m, °)."""
    options = {
        "kf": scalar_or_axes(0.01, 300.0, zero=True),
        "df": scalar_or_axes(0.01, 20.0, zero=True),
        "dd": scalar_or_axes(0.5, 300.0),
        "plastic": st.booleans(),
        "yield": st.one_of(st.none(), st.floats(0.2, 50.0)),
        "swing": st.one_of(st.none(), st.floats(math.degrees(BEND + LIMIT_GAP), 180.0)),
        "twist": st.one_of(
            st.none(),
            st.tuples(
                st.floats(-180.0, -math.degrees(BEND + LIMIT_GAP)),
                st.floats(math.degrees(BEND + LIMIT_GAP), 180.0),
            ).map(list),
        ),
    }
    keys = draw(st.lists(st.sampled_from(sorted(options)), unique=True))
    return {key: draw(options[key]) for key in keys}


@st.composite
def inertia_entries(draw, mass: float, size: float) -> list[float]:
    """Valid inertia: 3 principal values or the 6 entries of a turned tensor (kg·m²)."""
    scale = mass * size * size * draw(st.floats(0.02, 0.2))
    moments = [scale * draw(st.floats(1.0, 2.0)) for _ in range(3)]  # max ≤ sum of the others
    if draw(st.booleans()):
        return moments
    rot = Rotation.from_rotvec(draw(vectors(math.pi))).as_matrix()
    t = rot @ np.diag(moments) @ rot.T
    return [float(t[i, k]) for i, k in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))]


@st.composite
def bone_entry(draw, i: int, head: np.ndarray, parent: int | None, joint: bool,
               sensible: bool) -> dict:  # fmt: skip
    kind = draw(st.sampled_from(["capsule", "sphere", "box"]))
    direction = draw(vectors(1.0, least=0.1))
    length = 0.0 if kind == "sphere" and draw(st.booleans()) else draw(st.floats(0.05, 0.4))
    tail = head + length * direction / np.linalg.norm(direction)
    bone = {"name": f"bone{i}", "head": head.tolist(), "tail": tail.tolist(), "collide": False}
    if parent is not None:
        bone["parent"] = f"bone{parent}"
    if kind == "box":
        side = draw(st.floats(0.02, 0.2))
        depth = side if sensible else draw(st.one_of(st.just(side), st.floats(0.02, 0.2)))
        sizes = [side, draw(st.floats(0.02, 0.4)), depth]
        bone["shape"] = {"type": "box", "size": sizes}
    elif kind == "sphere" or draw(st.booleans()):
        bone["shape"] = {"type": kind, "radius": draw(st.floats(0.01, 0.1))}
    # else a capsule without a radius: 0.1 × its length
    given_as = "mass" if sensible else draw(st.sampled_from(["mass", "density", "neither"]))
    if given_as == "mass":
        bone["mass"] = draw(st.floats(0.2, 4.0) if sensible else st.floats(0.05, 10.0))
    elif given_as == "density":
        bone["density"] = draw(st.floats(200.0, 2000.0))
    if kind != "sphere" and draw(st.booleans()):  # a sphere is centred on its com: not drawn
        bone["com"] = (0.5 * (head + tail) + draw(vectors(0.02))).tolist()
    if given_as == "mass" and draw(st.booleans()):
        bone["inertia"] = draw(inertia_entries(bone["mass"], max(length, 0.05)))
    if joint:
        bone["joint"] = draw(joint_settings())
    return bone


@st.composite
def _rig_documents(draw, roots: tuple, sensible: bool) -> dict:
    root = draw(st.sampled_from(roots))
    n = draw(st.integers(1, 8))
    bones, heads, tails = [], [], []
    for i in range(n):
        parent = None if i == 0 else draw(st.integers(0, i - 1))
        if parent is None:
            head = np.array([0.0, 1.5, 0.0]) + draw(vectors(0.3))
        elif draw(st.booleans()):
            head = tails[parent]
        else:
            head = heads[parent] + draw(vectors(0.3))
        joint = parent is not None or (root == "ball" and draw(st.booleans()))
        bones.append(draw(bone_entry(i, head, parent, joint, sensible)))
        heads.append(np.array(bones[-1]["head"]))
        tails.append(np.array(bones[-1]["tail"]))
    doc = {"name": "random", "root": root, "bones": bones}
    defaults = {}
    if draw(st.booleans()):
        defaults["density"] = draw(st.floats(200.0, 2000.0))
    if draw(st.booleans()):
        defaults["joint"] = draw(joint_settings())
        if sensible:
            defaults["joint"].pop("kf", None)  # each joint's own, capped below
    if defaults:
        doc["defaults"] = defaults
    if draw(st.booleans()):
        doc["gravity"] = draw(vectors(12.0, least=1.0)).tolist()
    method = draw(st.sampled_from(["auto", "hybrid", "pgs"]))
    # Plain PGS relies on its warm start (the paper's): with 5 sweeps and none, a free rig
    # of light and heavy links was seen to blow up.  The exact methods take any setting.
    sweeps, reuse = ((15, 50), (0.5, 1.0)) if method == "pgs" else ((5, 30), (0.0, 1.0))
    doc["solver"] = {
        "h": draw(st.sampled_from([0.002, 0.005, 0.01])),
        "method": method,
        "iterations": draw(st.integers(*sweeps)),
        # (the loader refuses numbers between 0 and 1e-9: a positive one is at least 1e-9)
        "warm_start_factor": draw(st.floats(*reuse).filter(lambda x: x == 0.0 or x >= 1e-9)),
    }
    if sensible:
        _soft_enough(doc)
    _no_free_axes(doc)
    return doc


def _no_free_axes(doc: dict) -> None:
    """Give a small df (0.05 N·m·s/rad) to every axis where a joint with a spring or damper
    has neither: the loader refuses such a free axis (docs/rig-format.md)."""
    defaults = doc.get("defaults", {}).get("joint", {})
    for bone in doc["bones"]:
        if "parent" not in bone and doc["root"] != "ball":
            continue
        merged = {**defaults, **bone.get("joint", {})}
        kf = np.broadcast_to(merged.get("kf", 0.0), 3).astype(float)
        df = np.broadcast_to(merged.get("df", 0.0), 3).astype(float)
        free = (kf == 0.0) & (df == 0.0)
        if free.any() and not free.all():
            bone.setdefault("joint", {})["df"] = np.where(free, 0.05, df).tolist()


def _soft_enough(doc: dict) -> None:
    """Cap every joint's kf so that ω·h = √(kf/I)·h ≤ 0.5, I the least principal moment of
    the lighter body it joins (rig/make.py's rule for rigs it makes): a spring far too stiff
    for the step (a 1 g sphere holding 6 kg by kf 250) was seen to blow up at step 1."""
    bodies = mass_properties(doc)
    h = doc["solver"]["h"]
    least = [float(np.linalg.eigvalsh(b.inertia)[0]) for b in bodies]
    for i, bone in enumerate(doc["bones"]):
        if "kf" not in bone.get("joint", {}):
            continue
        p = bodies[i].parent
        inertia = (
            least[i] if p < 0 or (p == 0 and doc["root"] == "fixed") else min(least[i], least[p])
        )
        cap = 0.25 * inertia / h**2
        kf = bone["joint"]["kf"]
        bone["joint"]["kf"] = [min(k, cap) for k in kf] if isinstance(kf, list) else min(kf, cap)


def _half_free(doc: dict) -> bool:
    """A joint with springs or dampers on some axes and kf = df = 0 on another: valid by
    docs/rig-format.md, but the step divides by kf·h + df = 0 on that axis (NaN at step 0,
    reported with a reproduction); left out until it is fixed."""
    defaults = doc.get("defaults", {}).get("joint", {})
    for bone in doc["bones"]:
        merged = {**defaults, **bone.get("joint", {})}
        if "parent" not in bone and doc["root"] != "ball":
            continue
        resists = np.broadcast_to(merged.get("kf", 0.0), 3) + np.broadcast_to(
            merged.get("df", 0.0), 3
        )
        if np.any(resists > 0) and np.any(resists == 0):
            return True
    return False


def rig_documents(roots=("fixed", "free", "ball"), sensible: bool = False):
    """Random valid rig documents (see ``_rig_documents``), without the reported bug's;
    ``sensible``: masses within a factor 20 (explicit, 0.2–4 kg), square boxes and springs
    soft enough for the step, for simulating."""
    docs = _rig_documents(roots, sensible)
    return docs.filter(lambda doc: not _half_free(doc))


# ---- the oracle's mass properties, from the document alone ----


@dataclass
class Body:
    """What the test knows of a bone: mass (kg), rest centre of mass (m), rest inertia about
    it in world axes (kg·m², None for a box of unequal x and z sizes), its head, its parent's
    index, its joint's kf (3,) or None."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray | None
    head: np.ndarray
    parent: int
    kf: np.ndarray | None


def _about_axis(axis: np.ndarray, perpendicular: float, axial: float) -> np.ndarray:
    """The inertia of a body symmetric about the unit ``axis``."""
    along = np.outer(axis, axis)
    return perpendicular * (np.eye(3) - along) + axial * along


def _shape_mass_properties(bone: dict, radius: float, length: float, density: float):
    """(mass, inertia about the shape's centre) of a bone's shape."""
    shape = bone.get("shape", {"type": "capsule"})
    head, tail = np.array(bone["head"]), np.array(bone["tail"])
    axis = (tail - head) / length if length > 0 else np.array([0.0, 1.0, 0.0])
    if shape["type"] == "sphere":
        mass = bone.get("mass", density * 4.0 / 3.0 * math.pi * radius**3)
        return mass, 0.4 * mass * radius**2 * np.eye(3)
    if shape["type"] == "box":
        sx, sy, sz = shape["size"]  # sy along the bone
        mass = bone.get("mass", density * sx * sy * sz)
        if sx != sz:  # which way x and z point is not documented: only a square's is known
            return mass, None
        return mass, _about_axis(axis, mass * (sy * sy + sx * sx) / 12.0, mass * sx * sx / 6.0)
    cylinder, caps = math.pi * radius**2 * length, 4.0 / 3.0 * math.pi * radius**3
    mass = bone.get("mass", density * (cylinder + caps))
    m_cyl = mass * cylinder / (cylinder + caps)
    m_hemi = (mass - m_cyl) / 2.0
    # a hemisphere about its own centroid (3r/8 from its flat face): 83/320 m r² across
    across = m_cyl * (length**2 / 12.0 + radius**2 / 4.0) + 2.0 * m_hemi * (
        83.0 / 320.0 * radius**2 + (length / 2.0 + 3.0 * radius / 8.0) ** 2
    )
    axial = 0.5 * m_cyl * radius**2 + 2.0 * 0.4 * m_hemi * radius**2
    return mass, _about_axis(axis, across, axial)


def mass_properties(doc: dict) -> list[Body]:
    """Every bone's Body, in document order (parents come first in these documents)."""
    defaults = doc.get("defaults", {})
    names = [b["name"] for b in doc["bones"]]
    out = []
    for bone in doc["bones"]:
        head, tail = np.array(bone["head"]), np.array(bone["tail"])
        length = float(np.linalg.norm(tail - head))
        radius = bone.get("shape", {}).get("radius", 0.1 * length)
        density = bone.get("density", defaults.get("density", 1000.0))
        mass, inertia = _shape_mass_properties(bone, radius, length, density)
        centre = 0.5 * (head + tail)
        com = np.array(bone.get("com", centre))
        d = centre - com
        if inertia is not None:
            inertia = inertia + mass * (d @ d * np.eye(3) - np.outer(d, d))
        if "inertia" in bone:
            given = bone["inertia"]
            inertia = np.diag(given) if len(given) == 3 else _tensor(given)
        has_joint = "parent" in bone or doc["root"] == "ball"
        merged = {**defaults.get("joint", {}), **bone.get("joint", {})}
        kf = np.broadcast_to(merged.get("kf", 0.0), 3).astype(float) if has_joint else None
        parent = names.index(bone["parent"]) if "parent" in bone else -1
        out.append(Body(mass, com, inertia, head, parent, kf))
    return out


def _tensor(e: list[float]) -> np.ndarray:
    xx, yy, zz, xy, xz, yz = e
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def load(doc: dict):
    """The rig as the loader reads the document's YAML text, and its model."""
    spec = rig_from_text(yaml.safe_dump(doc, sort_keys=False), "random.yaml")
    return spec, build_model(spec)


def gravity(doc: dict) -> np.ndarray:
    return np.array(doc.get("gravity", [0.0, -9.81, 0.0]))


# ---- a bent rig at rest ----


@st.composite
def bends(draw, n: int) -> list[np.ndarray]:
    """A rotation vector of at most BEND rad per bone (the root's: the whole rig's turn)."""
    return [draw(vectors(BEND).map(lambda v: v * min(1.0, BEND / max(np.linalg.norm(v), 1e-300))))
            for _ in range(n)]  # fmt: skip


def bent_state(bodies: list[Body], model, bend: list[np.ndarray], shift: np.ndarray):
    """A free rig at rest, turned and moved by ``shift`` as a whole, every joint bent by
    ``bend`` (forward kinematics with scipy: R_b = R_parent R_bend, head_b = head_parent +
    R_parent (head0_b − head0_parent)), each spring's elastic part q_sf holding its bend."""
    world, heads, pos, q = [], [], np.zeros((len(bodies), 3)), np.zeros((len(bodies), 4))
    for b, body in enumerate(bodies):
        local = Rotation.from_rotvec(bend[b])
        if body.parent < 0:
            rot, head = local, body.head + shift
        else:
            p = body.parent
            rot = world[p] * local
            head = heads[p] + world[p].apply(body.head - bodies[p].head)
        world.append(rot)
        heads.append(head)
        pos[b] = head + rot.apply(body.com - body.head)
        q[b] = rot.as_quat(scalar_first=True)
    order = [int(name[4:]) for name in model.bone_names]  # the model's body order: "bone{b}"
    q_sf = np.array([bend[int(name[4:])] for name in model.joint_names]).reshape(-1, 3)
    return replace(initial_state(model), body_pos=pos[order], body_quat=q[order], joint_q_sf=q_sf)


def steps_of(doc: dict, seconds: float) -> int:
    return round(seconds / doc["solver"]["h"])


# ---- the properties ----


@settings(max_examples=40, derandomize=True, deadline=None)
@given(doc=rig_documents())
def test_random_rigs_load_with_the_documented_mass_properties(doc) -> None:
    _, model = load(doc)
    bodies = mass_properties(doc)
    index = {f"bone{b}": b for b in range(len(bodies))}
    assert sorted(model.bone_names) == sorted(index)
    for i, name in enumerate(model.bone_names):
        body = bodies[index[name]]
        assert abs(model.body_mass[i] - body.mass) <= MASS_TOL * body.mass
        assert np.abs(model.body_pos0[i] - body.com).max() <= REST_COM_TOL
        if body.inertia is not None:
            size = np.abs(body.inertia).max()
            assert np.abs(model.body_inertia[i] - body.inertia).max() <= INERTIA_TOL * size, name
    jointed = [f"bone{b}" for b, body in enumerate(bodies) if body.kf is not None]
    assert sorted(model.joint_names) == sorted(jointed)
    for j, name in enumerate(model.joint_names):
        np.testing.assert_array_equal(model.joint_kf[j], bodies[index[name]].kf)


@settings(max_examples=25, derandomize=True, deadline=None)
@given(data=st.data(), doc=rig_documents(roots=("free",), sensible=True),
       seconds=st.floats(0.2, 0.5))  # fmt: skip
def test_a_free_rig_falls_as_semi_implicit_euler_says(data, doc, seconds) -> None:
    """The joints are internal forces: whatever the bent springs do inside the rig, its
    momentum and centre of mass follow free fall's exact discrete recursion."""
    _, model = load(doc)
    bodies = mass_properties(doc)
    bend = data.draw(bends(len(bodies)))
    state = bent_state(bodies, model, bend, data.draw(vectors(1.0)))
    engine = Engine(model)
    index = [int(name[4:]) for name in model.bone_names]
    mass = np.array([bodies[b].mass for b in index])[:, None]
    total, g, h = mass.sum(), gravity(doc), doc["solver"]["h"]
    momentum = np.zeros(3)
    centre = (mass * state.body_pos).sum(axis=0) / total
    moved = 0.0  # the largest spread of the bones' velocities seen
    for k in range(steps_of(doc, seconds)):
        state, report = engine.step(state)
        for _ in range(report.substeps):  # n equal substeps of h / n
            momentum = momentum + total * g * h / report.substeps
            centre = centre + h / report.substeps * momentum / total
        found = (mass * state.body_vel).sum(axis=0)
        bound = MOMENTUM_TOL * total * np.linalg.norm(g) * state.time
        assert np.abs(found - momentum).max() <= bound, (k, found, momentum)
        com = (mass * state.body_pos).sum(axis=0) / total
        assert np.abs(com - centre).max() <= FALL_COM_TOL, (k, com, centre)
        spread = np.ptp(state.body_vel, axis=0).max() + np.ptp(state.body_omega, axis=0).max()
        moved = max(moved, spread)
    # not vacuous: a spring bent with 0.01 N·m or more turned the bones relative to each other
    torque = max((np.abs(b.kf * bend[i]).max() for i, b in enumerate(bodies) if b.kf is not None),
                 default=0.0)  # fmt: skip
    assert moved > 1e-9 or torque < 0.01, (moved, torque)
