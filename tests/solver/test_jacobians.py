"""Every constraint row's Jacobian against finite differences of its constraint function.

A row's velocity is w = jac_a·(v_a, ω_a) + jac_b·(v_b, ω_b) (solver.rows.table).  A row
that holds a constraint C(pose) = 0 (or ≥ 0) must have w = dC/dt along every motion.

Oracle: each row's C written here from its definition, with numpy and scipy's Rotation
(scalar_first=True), reading nothing of the model but its rest geometry (centres of mass,
bone heads and tails, shapes, limits) and nothing of the solver at all:

* ball joint, 3 rows, world axes e_k: C = (anchor on the child − anchor on the parent)_k,
  each anchor the material point at the bone's rest head;
* rheology, 3 rows: C_k = log(q_rel ⊗ q_rel(base)⁻¹)_k, parent axes: the deflection from
  the elastic rest, with that rest (state.joint_anchor) the base pose's relative rotation;
* limits: swing θ = ∠(d, q_rel d) (d the rest bone axis), C = swing − θ; twist φ from a
  swing-twist split built here (swing = the shortest arc d → q_rel d, twist = the rest),
  C = φ − lo and hi − φ;
* contacts: the signed gap between the shapes' surfaces (box corner to ground plane,
  capsule to capsule by an exhaustive closest-point search) for normal rows; friction rows
  the tangential displacement of the two bodies' material points at the contact point;
  in the posed doll (every kind of pair) the normal rows by the same material-point rule;
* grip: the grip point minus its target on the pointer (world axes), and the orientation
  error log(q_bone ⊗ q_target⁻¹) (world).

For random poses and random velocities (v, ω) per body, the central difference
(C(pose ⊕ ε(v,ω)) − C(pose ⊖ ε(v,ω)))/2ε, with a body moved by ε·v and turned by the world
rotation exp(ε·ω) on the left, must equal the row's w up to its O(ε²) truncation
(measured: halving ε quarters the error).  Where a row's axis is a property of the pose
(a contact's normal and tangents) it is frozen at the base pose: the identity is that of C
with the axis held fixed.

Where the rows are a linearisation the identity holds at the linearisation point only,
and the poses are chosen there: the rheology and grip rotation rows measure the rate of a
rotation vector where it vanishes (the elastic rest, the grip at its rest: both are where
those rows start); joint anchors are pushed at their common midpoint (momentum conserving),
so with the anchors apart by C, w = dC/dt − ½(ω_a + ω_b) × C exactly.  The twist rate's
gradient is R_p (d + d')/(1 + d·d') (d' = q_rel d), the twist rows' axis (an earlier
axis, R_p d', was right only without swing or for rotations about d' and d × d').

Both builders are checked: the numpy table (solver.rows.build.build_rows) and the compiled
kernels (solver.rows.*_kernel) called one by one on the same pose and the same contacts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from rigbuild import chain, rheology
from scipy.spatial.transform import Rotation

from puppetcli.rig.load import load_rig
from solver.collide import scene as collide
from solver.compiled.layout import BUFFERS, Contacts, Joints, Rheology, Rows
from solver.compiled.pack import pack
from solver.model import build_model
from solver.rows import contacts_kernel, grip_kernel, joints_kernel
from solver.rows.build import build_rows
from solver.rows.grip import Coupling, Pointer
from solver.rows.table import (
    KEY_SHIFT,
    KIND_CONTACT,
    KIND_FRICTION,
    KIND_GRIP,
    KIND_JOINT,
    KIND_LIMIT,
    KIND_RHEOLOGY,
)
from solver.spec import BoneSpec, GroundSpec, LimitSpec, PropSpec, RigSpec, ShapeSpec, SolverSpec
from solver.state import StepInput, initial_state

ROOT = Path(__file__).resolve().parents[2]
EPS = 1e-5  # the finite-difference step (s, for velocities |v|, |ω| ~ 1 m/s, rad/s)
# Tolerances on |FD − w| (m/s, rad/s) at that step: O(ε²) truncation (below ε ≈ 3e-6
# rounding, ~1e-16·C/ε, takes over).  A 1 % error in a Jacobian entry is ~1e-2.
ANCHOR_TOL = 4e-10  # measured 8.4e-11
RHEOLOGY_TOL = 1e-9  # measured 2.2e-10
LIMIT_TOL = 3e-8  # measured 6.4e-9 (the worst of 20 poses): a twist row at a swing near 2.6 rad
NEAR_FLIP = 2.6  # rad (149°): limit rows of joints swung further are not checked (see the test)
TWIST_TOL = 1.5e-9  # measured 3.0e-10
GAP_TOL = 1.5e-9  # measured 3.4e-10
CONTACT_TOL = 3e-10  # measured 6.9e-11
GRIP_TOL = 1e-10  # measured 1.9e-11

# -- poses and their motion ------------------------------------------------------------


@dataclass(frozen=True)
class Pose:
    """Centres of mass (nb,3) and body → world rotations (nb)."""

    pos: np.ndarray
    rot: Rotation

    def moved(self, s: float, vel: np.ndarray) -> Pose:
        """Each body moved by s·v and turned by exp(s·ω) on the left (world frame)."""
        return Pose(self.pos + s * vel[:, :3], Rotation.from_rotvec(s * vel[:, 3:]) * self.rot)

    def quat(self) -> np.ndarray:
        return np.ascontiguousarray(self.rot.as_quat(scalar_first=True))

    def frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions (nb+1,3), matrices (nb+1,3,3)); index −1 is the world."""
        return np.vstack((self.pos, np.zeros(3))), np.concatenate(
            (self.rot.as_matrix(), np.eye(3)[None])
        )

    def relative(self, parent: np.ndarray, child: np.ndarray) -> Rotation:
        """R_p⁻¹ R_c per joint (the world: identity)."""
        ext = Rotation.concatenate((self.rot, Rotation.identity()))
        return ext[parent].inv() * ext[child]


def carry(pose: Pose, body: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World positions of body-frame points (body −1: world points)."""
    pos, mat = pose.frames()
    return pos[body] + np.einsum("nij,nj->ni", mat[body], local)


def body_frame(pose: Pose, body: np.ndarray, world: np.ndarray) -> np.ndarray:
    """Body-frame coordinates of world points (the inverse of ``carry``)."""
    pos, mat = pose.frames()
    return np.einsum("nji,nj->ni", mat[body], world - pos[body])


def rest_local(model, body: np.ndarray, world: np.ndarray) -> np.ndarray:
    """Body-frame coordinates of points given in the rest pose."""
    rest = Pose(model.body_pos0, Rotation.from_quat(model.body_quat0, scalar_first=True))
    return body_frame(rest, body, world)


def random_velocity(rng, nb: int) -> np.ndarray:
    return rng.normal(size=(nb, 6))


def row_velocity(rows, vel: np.ndarray) -> np.ndarray:
    """w = jac_a·(v_a, ω_a) + jac_b·(v_b, ω_b), the world (−1) at rest."""
    v = np.vstack((vel, np.zeros((1, 6))))
    return np.einsum("ni,ni->n", rows.jac_a, v[rows.body_a]) + np.einsum(
        "ni,ni->n", rows.jac_b, v[rows.body_b]
    )


def central_difference(constraint, base: Pose, vel: np.ndarray, eps: float = EPS) -> np.ndarray:
    return (constraint(base.moved(eps, vel)) - constraint(base.moved(-eps, vel))) / (2.0 * eps)


# -- the constraint functions ----------------------------------------------------------


@dataclass(frozen=True)
class JointGeometry:
    """What the joint oracles read of the model: topology and rest geometry."""

    parent: np.ndarray
    child: np.ndarray
    anchor_parent: np.ndarray  # (nj,3) the rest head in the parent's frame (world: world)
    anchor_child: np.ndarray  # (nj,3) the rest head in the child's frame
    axis: np.ndarray  # (nj,3) unit rest bone axis, head → tail
    swing: np.ndarray
    twist_lo: np.ndarray
    twist_hi: np.ndarray

    @classmethod
    def of(cls, model) -> JointGeometry:
        p, c = model.joint_parent, model.joint_bone
        head, tail = model.bone_head0[c], model.bone_tail0[c]
        axis = (tail - head) / np.linalg.norm(tail - head, axis=1, keepdims=True)
        return cls(p, c, rest_local(model, p, head), rest_local(model, c, head), axis,
                   model.joint_swing, model.joint_twist_lo, model.joint_twist_hi)  # fmt: skip

    def gap(self, pose: Pose) -> np.ndarray:
        """(nj,3) anchor on the child − anchor on the parent."""
        return carry(pose, self.child, self.anchor_child) - carry(
            pose, self.parent, self.anchor_parent
        )

    def swing_twist(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(swing angle θ, twist angle φ) per joint; q_rel = swing ⊗ twist, the swing the
        shortest arc from d to q_rel d, the twist about d."""
        rel = pose.relative(self.parent, self.child)
        d = self.axis
        turned = rel.apply(d)
        u = np.cross(d, turned)
        sin, cos = np.linalg.norm(u, axis=1), np.einsum("ni,ni->n", d, turned)
        theta = np.arctan2(sin, cos)
        ratio = np.where(sin > 1e-12, theta / np.maximum(sin, 1e-300), 1.0)
        twist = Rotation.from_rotvec(u * ratio[:, None]).inv() * rel
        phi = np.einsum("ni,ni->n", twist.as_rotvec(), d)
        return theta, phi


def segment_closest(p0, p1, q0, q1) -> tuple[np.ndarray, np.ndarray]:
    """The closest points of segments p0–p1 and q0–q1: |p0 + s·dp − q0 − t·dq|² is convex
    on [0,1]², so its minimum is the interior stationary point (if inside) or the best
    of the four edges' clamped one-dimensional minima."""
    dp, dq, r = p1 - p0, q1 - q0, p0 - q0
    a, e, b, c, f = dp @ dp, dq @ dq, dp @ dq, dp @ r, dq @ r
    candidates = [(s, np.clip((b * s + f) / e, 0.0, 1.0)) for s in (0.0, 1.0)]
    candidates += [(np.clip((b * t - c) / a, 0.0, 1.0), t) for t in (0.0, 1.0)]
    den = a * e - b * b
    if den > 1e-14 * a * e:
        s, t = (b * f - c * e) / den, (a * f - b * c) / den
        if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
            candidates.append((s, t))
    s, t = min(candidates, key=lambda pair: np.linalg.norm(r + pair[0] * dp - pair[1] * dq))
    return p0 + s * dp, q0 + t * dq


@dataclass(frozen=True)
class Shapes:
    """What the contact oracles read of the model's shapes."""

    body: np.ndarray
    kind: np.ndarray  # 0 plane, 1 sphere, 2 capsule, 3 box (solver.collide.scene)
    pos: np.ndarray
    rot: Rotation
    radius: np.ndarray
    half: np.ndarray

    @classmethod
    def of(cls, model) -> Shapes:
        g = model.geometry
        return cls(g.shape_body, g.shape_kind, g.shape_pos,
                   Rotation.from_quat(g.shape_quat, scalar_first=True), g.shape_radius,
                   g.shape_half)  # fmt: skip

    def of_body(self, b: int) -> int:
        (found,) = np.flatnonzero(self.body == b)
        return int(found)

    def frame(self, pose: Pose, s: int) -> tuple[np.ndarray, np.ndarray]:
        """(world centre, world matrix) of shape s."""
        pos, mat = pose.frames()
        b = self.body[s]
        return pos[b] + mat[b] @ self.pos[s], mat[b] @ self.rot[s].as_matrix()

    def corners(self, pose: Pose, s: int) -> np.ndarray:
        centre, mat = self.frame(pose, s)
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        return centre + (signs * self.half[s]) @ mat.T

    def segment(self, pose: Pose, s: int) -> tuple[np.ndarray, np.ndarray]:
        centre, mat = self.frame(pose, s)
        half = self.half[s, 1] * mat[:, 1]
        return centre - half, centre + half

    def plane(self, pose: Pose, s: int) -> tuple[np.ndarray, np.ndarray]:
        centre, mat = self.frame(pose, s)
        return centre, mat[:, 1]


def gap_function(shapes: Shapes, base: Pose, a: int, b: int, point: np.ndarray):
    """The signed surface gap C(pose) of the contact of bodies a, b at ``point`` (base
    pose), when the pair is box–plane (the corner at the point) or capsule–capsule (the
    contact at their closest points); None otherwise."""
    sa, sb = shapes.of_body(a), shapes.of_body(b)
    kinds = (shapes.kind[sa], shapes.kind[sb])
    if kinds == (0, 3):
        corner = int(np.argmin(np.linalg.norm(shapes.corners(base, sb) - point, axis=1)))

        def box_plane(pose):
            origin, normal = shapes.plane(pose, sa)
            return normal @ (shapes.corners(pose, sb)[corner] - origin)

        return box_plane
    if kinds == (2, 2):

        def capsules(pose):
            x, y = segment_closest(*shapes.segment(pose, sa), *shapes.segment(pose, sb))
            return np.linalg.norm(y - x) - shapes.radius[sa] - shapes.radius[sb]

        x, y = segment_closest(*shapes.segment(base, sa), *shapes.segment(base, sb))
        u = (y - x) / np.linalg.norm(y - x)
        midway = 0.5 * (x + shapes.radius[sa] * u + y - shapes.radius[sb] * u)  # the surfaces'
        return capsules if np.linalg.norm(midway - point) < 1e-9 else None
    return None


@dataclass(frozen=True)
class Grip:
    """A grip: bone, grip point (bone frame), its target on the pointer and the target
    orientation (world), all fixed while the bones move."""

    body: int
    anchor: np.ndarray
    target: np.ndarray
    target_rot: Rotation


def constraint_of(model, base: Pose, rows, con=None, grip: Grip | None = None, gaps=None):
    """C(pose) (n,) for the rows of a table (read by their kind and key).

    con: the contacts the table's contact rows were made of; gaps: (contact → C(pose)) for
    the normal rows that have a surface-gap oracle (the others: the material points'
    separation along the frozen normal)."""
    jg = JointGeometry.of(model)
    kind = np.asarray(rows.kind)
    ident = np.asarray(rows.key) - (kind.astype(np.int64) << KEY_SHIFT)
    rel_base = base.relative(jg.parent, jg.child)
    if con is not None:
        by_key = {int(k): i for i, k in enumerate(con.key)}
        point_a = body_frame(base, con.body_a, con.point)
        point_b = body_frame(base, con.body_b, con.point)
        # a friction row's tangent: the direction its linear block measures on body b
        axis = np.where(rows.body_b[:, None] >= 0, rows.jac_b[:, :3], -rows.jac_a[:, :3])
    gaps = gaps or {}
    unchecked = ((KIND_CONTACT, KIND_FRICTION) if con is None else ()) + (
        (KIND_GRIP,) if grip is None else ()
    )  # rows whose data the caller did not give: left NaN

    def constraint(pose: Pose) -> np.ndarray:
        out = np.full(len(kind), np.nan)
        gap = jg.gap(pose)
        deflection = (pose.relative(jg.parent, jg.child) * rel_base.inv()).as_rotvec()
        theta, phi = jg.swing_twist(pose)
        limit = np.stack((jg.swing - theta, phi - jg.twist_lo, jg.twist_hi - phi), axis=1)
        if con is not None:
            apart = carry(pose, con.body_b, point_b) - carry(pose, con.body_a, point_a)
        for i, (k, n) in enumerate(zip(kind, ident, strict=True)):
            if k in unchecked:
                continue
            if k == KIND_JOINT:
                out[i] = gap[n // 3, n % 3]
            elif k == KIND_RHEOLOGY:
                out[i] = deflection[n // 3, n % 3]
            elif k == KIND_LIMIT:
                out[i] = limit[n // 4, n % 4]
            elif k == KIND_CONTACT:
                c = by_key[int(n)]
                out[i] = gaps[c](pose) if c in gaps else con.normal[c] @ apart[c]
            elif k == KIND_FRICTION:
                out[i] = axis[i] @ apart[by_key[int(n) // 2]]
            elif k == KIND_GRIP and n < 3:
                point = carry(pose, np.array([grip.body]), grip.anchor[None])[0]
                out[i] = (point - grip.target)[n]
            elif k == KIND_GRIP:
                out[i] = (pose.rot[grip.body] * grip.target_rot.inv()).as_rotvec()[n - 3]
        return out

    return constraint


# -- scenes and poses ------------------------------------------------------------------


@functools.cache
def scene(name: str):
    """(model, packed model) of: the doll rig (16 joints with rheology, limits, ground,
    a table); a chain of 4 hanging from the world by a ball joint; contact bodies."""
    if name == "doll":
        spec = load_rig(ROOT / "rigs" / "doll.yaml")
    elif name == "chain":
        spec = chain(4, 0.005, rheo=rheology(5.0, 0.5, 2.0), root_mode="ball",
                     limits=LimitSpec(0.5, (-0.3, 0.4)))  # fmt: skip
    else:
        spec = contact_spec()
    model = build_model(spec)
    return model, pack(model)


def contact_spec() -> RigSpec:
    """A free box above the ground and two free capsules (props), apart at rest."""
    box = BoneSpec("block", None, np.zeros(3), np.array([0.0, 0.1, 0.0]),
                   ShapeSpec("box", half_extents=(0.1, 0.05, 0.07)), 2.0)  # fmt: skip

    def rod(name, radius, half, x):
        shape = ShapeSpec("capsule", radius=radius, half_extents=(0.0, half, 0.0))
        return PropSpec(name, shape, np.array([x, 1.0, 0.0]), np.array([1.0, 0, 0, 0]),
                        dynamic=True, mass=1.0, friction=0.5)  # fmt: skip

    return RigSpec("contacts", (box,), root_mode="free", ground=GroundSpec(0.0, 0.7),
                   props=(rod("rod1", 0.03, 0.12, 1.0), rod("rod2", 0.05, 0.08, 2.0)),
                   solver=SolverSpec(h=0.005))  # fmt: skip


def tree_pose(model, rng, rel: Rotation, apart: float = 0.0) -> Pose:
    """Bones turned so that joint j's relative rotation is rel[j], the root anyhow, the
    anchors together (``apart`` = 0) or each body moved off by ~``apart`` (m)."""
    jg = JointGeometry.of(model)
    nb = model.nbody
    rot = [Rotation.random(random_state=rng) for _ in range(nb)]
    pos = model.body_pos0 + rng.normal(scale=0.05, size=(nb, 3))
    for j in np.argsort(jg.child):  # parents first
        p, c = jg.parent[j], jg.child[j]
        rot_p = rot[p] if p >= 0 else Rotation.identity()
        rot[c] = rot_p * rel[j]
        anchor = (pos[p] if p >= 0 else 0.0) + rot_p.apply(jg.anchor_parent[j])
        pos[c] = anchor - rot[c].apply(jg.anchor_child[j])
    pos = pos + rng.normal(scale=apart, size=(nb, 3))
    return Pose(pos, Rotation.concatenate(rot))


def random_pose(model, rng, apart: float = 0.0) -> Pose:
    return tree_pose(model, rng, Rotation.random(model.njoint, random_state=rng), apart)


def state_at(model, pose: Pose):
    """The state at ``pose`` with every elastic rest at the pose (zero deflection)."""
    jg = JointGeometry.of(model)
    rel = pose.relative(jg.parent, jg.child).as_quat(scalar_first=True)
    return replace(initial_state(model), body_pos=pose.pos, body_quat=pose.quat(),
                   joint_anchor=rel)  # fmt: skip


def numpy_rows(model, pose: Pose, vel_free: np.ndarray, inp: StepInput | None = None):
    """The numpy step's table at ``pose`` and the contacts it was made of."""
    state = state_at(model, pose)
    rows, _, _ = build_rows(model, state, pose.rot.as_matrix(), vel_free, inp)
    con = collide.collide(model.geometry, state.body_pos, state.body_quat,
                          model.options.contact_margin)  # fmt: skip
    return rows, con


def compiled_rows(name: str, pose: Pose, vel_free: np.ndarray, con, pointer=None, cpl=None):
    """The compiled kernels' rows at ``pose``: anchor, rheology, limit rows, the rows of
    the contacts ``con``, and the grip's rows (pointer, Coupling) when given.  No arc terms
    in the anchor rows (they change the bias only)."""
    model, fm = scene(name)
    m, o = fm.m, model.options
    nb, nj, nc = model.nbody, model.njoint, len(con.key)
    size = 9 * nj + 3 * nc + 6
    rw = Rows(*(np.zeros((size, *BUFFERS[kind][1]), BUFFERS[kind][0]) for kind in Rows.KINDS))
    pos, q = np.ascontiguousarray(pose.pos), pose.quat()
    rot = np.ascontiguousarray(pose.rot.as_matrix())
    asleep = np.zeros(nb, np.bool_)
    joints = Joints(m.joint_parent, m.joint_bone, m.joint_anchor_parent, m.joint_anchor_child)
    n = joints_kernel.anchor_rows(joints, pos, rot, np.zeros((nb, 3)), o.h, o.joint_erp,
                                  False, asleep, rw, 0)  # fmt: skip
    rheo = Rheology(m.joint_parent, m.joint_bone, m.joint_kf, m.joint_df, m.joint_dd,
                    m.joint_rheology, m.joint_yield, m.joint_plastic,
                    m.joint_finite_yield)  # fmt: skip
    n = joints_kernel.rheology_rows(rheo, q, rot, o.h, np.zeros((nj, 3)), np.zeros(nj, np.bool_),
                                    state_at(model, pose).joint_anchor, asleep,
                                    np.zeros(size, np.int64), rw, n)  # fmt: skip
    n = joints_kernel.limit_rows(joints_kernel.limit_arrays(m), q, rot, o.h, o.joint_erp,
                                 o.limit_margin, asleep, rw, n, np.empty((nj, 3)),
                                 np.empty((nj, 3)))  # fmt: skip
    cb = Contacts(*(np.ascontiguousarray(getattr(con, f)) for f in Contacts._fields))
    n = contacts_kernel.contact_rows(cb, 0, nc, pos, vel_free, (0.0, 0.0, 0.0), o.h,
                                     o.contact_erp, o.contact_slop, rw, n)  # fmt: skip
    if cpl is not None:
        ptr = tuple(tuple(float(x) for x in v) for v in (pointer.pos, pointer.quat,
                                                          pointer.vel, pointer.omega))  # fmt: skip
        gains = (cpl.stiffness, cpl.damping, cpl.rot_stiffness, cpl.rot_damping,
                 cpl.force_limit, cpl.torque_limit)  # fmt: skip
        cvec = (*(tuple(float(x) for x in v) for v in (cpl.anchor, cpl.offset, cpl.rest)),
                *(float(g) for g in gains))  # fmt: skip
        n = grip_kernel.coupling_rows(pos, q, o.h, ptr, cvec, cpl.body, 0, rw, n)
    return Rows(*(getattr(rw, f)[:n] for f in Rows._fields))


def table(engine: str, name: str, pose: Pose, vel_free: np.ndarray, inp=None):
    """(rows, contacts) by the numpy step's build_rows or by the compiled kernels; the
    contacts are the numpy collider's either way (the compiled rows are made of them)."""
    model, _ = scene(name)
    rows, con = numpy_rows(model, pose, vel_free, inp)
    if engine == "compiled":
        ptr, cpl = (inp.pointer, inp.coupling) if inp is not None else (None, None)
        rows = compiled_rows(name, pose, vel_free, con, ptr, cpl)
    return rows, con


def mismatch(rows, constraint, base: Pose, vel: np.ndarray, select: np.ndarray) -> float:
    """Worst |dC/dt − w| over the selected rows (at least one)."""
    assert select.any()
    fd = central_difference(constraint, base, vel)
    return float(np.abs(fd - row_velocity(rows, vel))[select].max())


ENGINES = ["numpy", "compiled"]
JOINT_SCENES = ["doll", "chain"]


def posed_tables(engine: str, name: str, seed: int, pose=None, count: int = 4):
    """(model, rng, pose, rows, C) for ``count`` poses of scene ``name`` made by
    ``pose(model, rng)`` (random_pose by default), each with its table and constraint."""
    model, _ = scene(name)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        base = (pose or random_pose)(model, rng)
        rows, _ = table(engine, name, base, np.zeros((model.nbody, 6)))
        yield model, rng, base, rows, constraint_of(model, base, rows)


# -- the tests --------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", JOINT_SCENES)
def test_joint_anchor_rows_at_random_poses(engine, name):
    # Anchors together: w = d(anchor_c − anchor_p)/dt.  Anchors apart by C (each body
    # moved by ~3 cm): the rows push both bodies at the anchors' midpoint, so
    # w = dC/dt − ½(ω_a + ω_b) × C, which this checks too.
    model, _ = scene(name)
    jg = JointGeometry.of(model)
    rng = np.random.default_rng(1)
    for apart in (0.0, 0.0, 0.03, 0.03):
        base = random_pose(model, rng, apart)
        rows, _ = table(engine, name, base, np.zeros((model.nbody, 6)))
        joint = rows.kind == KIND_JOINT
        assert joint.sum() == 3 * model.njoint
        constraint = constraint_of(model, base, rows)
        ident = rows.key[joint] - (KIND_JOINT << KEY_SHIFT)
        gap = jg.gap(base)
        assert (np.abs(gap).max() < 1e-12) == (apart == 0.0)
        for _ in range(2):
            vel = random_velocity(rng, model.nbody)
            omega = np.vstack((vel[:, 3:], np.zeros(3)))
            spin = np.cross(omega[jg.parent] + omega[jg.child], gap)
            fd = central_difference(constraint, base, vel)
            w = row_velocity(rows, vel)
            expected = fd[joint] - 0.5 * spin[ident // 3, ident % 3]
            assert np.abs(expected - w[joint]).max() < ANCHOR_TOL


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", JOINT_SCENES)
def test_rheology_rows_at_random_poses(engine, name):
    for model, rng, base, rows, constraint in posed_tables(engine, name, 2):
        rheo = rows.kind == KIND_RHEOLOGY
        assert rheo.sum() == 3 * model.joint_rheology.sum() > 0
        for _ in range(2):
            vel = random_velocity(rng, model.nbody)
            assert mismatch(rows, constraint, base, vel, rheo) < RHEOLOGY_TOL


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", JOINT_SCENES)
def test_limit_rows_at_random_poses(engine, name):
    # Swing, twist-low and twist-high rows at random poses, for every velocity, of joints
    # swung less than NEAR_FLIP: towards θ = π the twist is undefined (its rate's gradient
    # grows as 1/(1 + cos θ), capped by the rows) and the swing axis d × d' ill-defined.
    slots = np.zeros(3, int)
    for model, rng, base, rows, constraint in posed_tables(engine, name, 3):
        limit = rows.kind == KIND_LIMIT
        slot = (rows.key - (KIND_LIMIT << KEY_SHIFT)) % 4
        slots += np.bincount(slot[limit], minlength=3)
        theta, _ = JointGeometry.of(model).swing_twist(base)
        joint = (rows.key - (KIND_LIMIT << KEY_SHIFT)) // 4
        checked = limit & (theta[np.where(limit, joint, 0)] < NEAR_FLIP)
        for _ in range(2):
            vel = random_velocity(rng, model.nbody)
            assert mismatch(rows, constraint, base, vel, checked) < LIMIT_TOL
    assert (slots > 0).all()  # swing, twist-low and twist-high rows were all checked


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", JOINT_SCENES)
def test_twist_limit_rows_without_swing(engine, name):
    # Every joint turned about its own bone axis only, near or past a twist limit: the
    # twist row's axis is then the gradient of the twist for every relative motion.
    def twisted(model, rng) -> Pose:
        jg = JointGeometry.of(model)
        bound = np.where(rng.random(model.njoint) < 0.5, jg.twist_lo, jg.twist_hi)
        phi = bound + rng.uniform(-0.1, 0.1, model.njoint)
        return tree_pose(model, rng, Rotation.from_rotvec(phi[:, None] * jg.axis))

    checked = 0
    for model, rng, base, rows, constraint in posed_tables(engine, name, 4, twisted):
        twist = (rows.kind == KIND_LIMIT) & ((rows.key - (KIND_LIMIT << KEY_SHIFT)) % 4 > 0)
        for _ in range(2):
            vel = random_velocity(rng, model.nbody)
            assert mismatch(rows, constraint, base, vel, twist) < TWIST_TOL
        checked += twist.sum()
    assert checked >= model.njoint


def contact_pose(model, rng) -> Pose:
    """The box tilted with its lowest corner near the ground (within ±5 mm), the two
    capsules crossing at a gap between −3 and +6 mm, at 1 m height, away from the box."""
    shapes = Shapes.of(model)
    rot = Rotation.random(3, random_state=rng)
    pos = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    pos[0] += rng.uniform(-0.2, 0.2, 3)
    low = shapes.corners(Pose(pos, rot), shapes.of_body(0))[:, 1].min()
    pos[0, 1] += rng.uniform(-0.005, 0.005) - low
    pos[2] += rng.normal(scale=0.03, size=3)
    s1, s2 = shapes.of_body(1), shapes.of_body(2)
    target = rng.uniform(-0.003, 0.006) + shapes.radius[s1] + shapes.radius[s2]
    for _ in range(4):  # slide rod2 along the closest points' line to the target distance
        x, y = segment_closest(*shapes.segment(Pose(pos, rot), s1),
                               *shapes.segment(Pose(pos, rot), s2))  # fmt: skip
        pos[2] += (target - np.linalg.norm(y - x)) * (y - x) / np.linalg.norm(y - x)
    return Pose(pos, rot)


@pytest.mark.parametrize("engine", ENGINES)
def test_contact_rows_against_the_surface_gap(engine):
    # Normal rows: the signed gap of a box corner over the ground and of two capsules'
    # surfaces; friction rows: the tangential slip of the contact point (tangents frozen).
    model, _ = scene("contacts")
    shapes = Shapes.of(model)
    rng = np.random.default_rng(5)
    kinds = {KIND_CONTACT: 0, KIND_FRICTION: 0}
    pairs = set()
    for _ in range(6):
        base = contact_pose(model, rng)
        vel_free = random_velocity(rng, model.nbody)  # sets the friction tangents
        rows, con = table(engine, "contacts", base, vel_free)
        gaps = {}
        for c in range(len(con.key)):
            gap = gap_function(shapes, base, con.body_a[c], con.body_b[c], con.point[c])
            assert gap is not None or (con.body_a[c], con.body_b[c]) == (1, 2)
            if gap is not None:
                assert abs(gap(base) + con.depth[c]) < 1e-12  # the oracle's contact
                gaps[c] = gap
                pairs.add((int(con.body_a[c]), int(con.body_b[c])))
        check_contact_rows(model, base, rows, con, gaps, rng, kinds, GAP_TOL)
    assert pairs == {(-1, 0), (1, 2)}
    assert min(kinds.values()) >= 12


def check_contact_rows(model, base, rows, con, gaps, rng, counts: dict, tol: float):
    """Every contact and friction row of the table against its C; the friction basis
    orthonormal and tangent to the normal."""
    contact = (rows.kind == KIND_CONTACT) | (rows.kind == KIND_FRICTION)
    assert (rows.kind == KIND_CONTACT).sum() == len(con.key) > 0
    friction = np.flatnonzero(rows.kind == KIND_FRICTION)
    tangents = rows.jac_b[friction, :3].reshape(-1, 2, 3)
    of_contact = (rows.key[friction[::2]] - (KIND_FRICTION << KEY_SHIFT)) // 2
    normals = con.normal[np.searchsorted(con.key, of_contact)]
    basis = np.concatenate((tangents, normals[:, None]), axis=1)
    assert np.abs(basis @ basis.transpose(0, 2, 1) - np.eye(3)).max() < 1e-12
    constraint = constraint_of(model, base, rows, con, gaps=gaps)
    for _ in range(2):
        vel = random_velocity(rng, model.nbody)
        assert mismatch(rows, constraint, base, vel, contact) < tol
    for kind in counts:
        counts[kind] += (rows.kind == kind).sum()


@pytest.mark.parametrize("engine", ENGINES)
def test_contact_rows_of_a_posed_doll(engine):
    # The doll turned anyhow: its bones cross each other, the hips box, the ground and
    # the table (every pair kind); normal rows by the material points' separation along
    # the frozen normal, friction rows by their slip along the frozen tangents.
    model, _ = scene("doll")
    rng = np.random.default_rng(6)
    counts = {KIND_CONTACT: 0, KIND_FRICTION: 0}
    for _ in range(3):
        base = random_pose(model, rng)
        rows, con = table(engine, "doll", base, random_velocity(rng, model.nbody))
        check_contact_rows(model, base, rows, con, {}, rng, counts, CONTACT_TOL)
    assert counts[KIND_CONTACT] >= 20


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", JOINT_SCENES)
def test_grip_coupling_rows_at_random_poses(engine, name):
    # The grip point anywhere on a bone, the pointer anywhere nearby and turned anyhow; the
    # rotation rows at the coupling's rest (zero orientation error, as at gripping).
    model, _ = scene(name)
    rng = np.random.default_rng(7)
    for _ in range(4):
        base = random_pose(model, rng)
        body = int(rng.integers(model.nbody))
        anchor = rest_local(model, np.array([body]), model.bone_head0[body][None])[0]
        anchor = anchor * rng.uniform(-1.0, 1.0) + rng.normal(scale=0.02, size=3)
        grip_point = carry(base, np.array([body]), anchor[None])[0]
        ptr_rot = Rotation.random(random_state=rng)
        ptr_pos = grip_point + rng.normal(scale=0.1, size=3)
        offset = ptr_rot.inv().apply(grip_point + rng.normal(scale=0.05, size=3) - ptr_pos)
        rest = ptr_rot.inv() * base.rot[body]
        pointer = Pointer(ptr_pos, ptr_rot.as_quat(scalar_first=True), rng.normal(size=3),
                          rng.normal(size=3))  # fmt: skip
        coupling = Coupling(body, anchor, offset, rest.as_quat(scalar_first=True), 2000.0, 40.0,
                            50.0, 2.0, 100.0, 10.0)  # fmt: skip
        inp = StepInput(pointer=pointer, coupling=coupling)
        rows, _ = table(engine, name, base, np.zeros((model.nbody, 6)), inp)
        grip = rows.kind == KIND_GRIP
        assert grip.sum() == 6 and (rows.body_b[grip] == body).all()
        target = Grip(body, anchor, ptr_pos + ptr_rot.apply(offset), ptr_rot * rest)
        constraint = constraint_of(model, base, rows, grip=target)
        assert np.abs(constraint(base)[grip][3:]).max() < 1e-12  # at the coupling's rest
        for _ in range(2):
            vel = random_velocity(rng, model.nbody)
            assert mismatch(rows, constraint, base, vel, grip) < GRIP_TOL


def test_the_mismatch_is_the_truncation_error():
    # The tolerances' ground: on the posed doll's joint, rheology and swing rows, halving ε
    # divides the worst mismatch by 4: it is the central difference's O(ε²) term, with no
    # floor that a small error in the rows (a constant, independent of ε) would leave.
    model, _ = scene("doll")
    rng = np.random.default_rng(8)
    base = random_pose(model, rng)
    rows, _ = table("numpy", "doll", base, np.zeros((model.nbody, 6)))
    constraint = constraint_of(model, base, rows)
    slot = (rows.key - (rows.kind.astype(np.int64) << KEY_SHIFT)) % 4
    select = (rows.kind == KIND_JOINT) | (rows.kind == KIND_RHEOLOGY)
    select |= (rows.kind == KIND_LIMIT) & (slot == 0)
    vel = random_velocity(rng, model.nbody)
    w = row_velocity(rows, vel)
    err = np.array([np.abs(central_difference(constraint, base, vel, eps) - w)[select].max()
                    for eps in (4e-4, 2e-4, 1e-4)])  # fmt: skip
    assert np.abs(err[:-1] / err[1:] - 4.0).max() < 1e-4  # measured 2.2e-5
