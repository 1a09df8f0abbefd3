"""The frozen simulation model: struct-of-arrays built once from a ``RigSpec``.

Bodies are the rig's bones (in rig order) followed by its dynamic props.  Every
body frame has its origin at the centre of mass; a bone's body frame is
world-aligned in the rest pose (so a bone's quaternion *is* its rotation from
rest), a prop's body frame is its shape frame.  Static props and the ground
are geometry only.  A fixed root is a body with zero inverse mass and inertia.

Joints: one ball joint per non-root bone (parent = the parent bone's body) and,
for ``root_mode == "ball"``, one for the root (parent = -1, the world).  Since
every bone is world-aligned at rest, every joint's rest relative orientation is
the identity, and joint rotation = log(q_parent⁻¹ ⊗ q_child).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TypeVar

import numpy as np

from solver import quat
from solver.collide import scene as collide
from solver.massprops import shape_frame, shape_inertia_local, world_inertia
from solver.spec import CONTACT_SLOP, RigSpec, ShapeSpec

T = TypeVar("T")

SHAPE_CODE = {"sphere": 1, "capsule": 2, "box": 3}


@dataclass(frozen=True)
class Options:
    """Solver and safety settings.

    h: step (s).  method: "auto" | "pgs" | "hybrid" | "direct" | "reference"
    (auto: direct when every row is two-sided, else hybrid).
    iterations: PGS sweeps (over the whole table for pgs, over the bounded rows'
    Schur complement for hybrid).  warm_start / warm_start_factor: reuse of the
    previous step's row forces.  gravity: (3,) m/s².
    joint_erp: fraction of a joint's anchor gap removed per step (Baumgarte).
    contact_erp, contact_slop (m): penetration correction beyond the slop.
    contact_margin (m): gaps below this produce speculative contact rows.
    limit_margin (rad): limit rows exist once a joint is this close to a limit.
    regularization: relative compliance ε·A_ii added to every hard row (one with
        no compliance of its own): makes the row matrix definite when rows are
        redundant (more hard rows than degrees of freedom, e.g. several contacts
        plus limits on one body), so λ is unique and every solver solves the same
        well-posed problem; it lets a hard row yield by the fraction ε.
    yield_filter_time (s): time constant of the low-pass on the joint torque
        norm compared with the yield torque.
    max_speed (m/s), max_angular_speed (rad/s), max_joint_gap (m): beyond these
        the simulation is declared numerically broken.
    max_substeps: most equal substeps a step may take when its joints' geometric
        stiffness needs them (solver.advance.substep); 1 = never subdivide.
    Skips of work a scene does not need (each measured by ``puppetcli bench --skips``
    and tested to change nothing): cull_pairs: shape pairs whose bounding spheres are
    farther apart than contact_margin get no narrow phase; dormant_rows: the hybrid
    solve checks one-sided rows that neither pushed last step nor ask to push after the
    solve instead of iterating them (solver.solve.hybrid); leaf_contacts: the hybrid
    solve eliminates a bone's contacts with the static world with the joints while they
    stick, and iterates only those that slide (solver.solve.hybrid); sleep: islands at rest and
    untouched for sleep_time (s), every body slower than sleep_speed (m/s) and
    sleep_spin (rad/s), are frozen until touched (solver.advance.sleep).
    engine: "compiled" (the numba step, solver.compiled) or "numpy" (the readable
    step, solver.pipeline): the implementation solver.Engine runs.
    integrator: "euler" (the paper's step: backward Euler on the joints, semi-implicit
    Euler on the bodies, first order) or "bdf2" (second order, L-stable:
    solver.advance.bdf2).
    joint_space: a ``bdf2`` model that is one tree of spring-damper joints (no series
    dampers, limits, collisions or free bodies) is stepped in its joint coordinates by the
    in-place stepper (solver.advance.joint_space): the same BDF2 on the same momenta,
    without anchor rows, contacts or an LCP, so its joints cannot come apart.  Not a skip:
    its states differ from the maximal-coordinate step's by the two schemes' O(h²) errors.
    """

    h: float = 0.005
    method: str = "auto"
    iterations: int = 15
    warm_start: bool = True
    warm_start_factor: float = 1.0
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, -9.81, 0.0]))
    joint_erp: float = 0.8
    contact_erp: float = 0.2
    contact_slop: float = CONTACT_SLOP
    contact_margin: float = 0.01
    limit_margin: float = 0.05
    regularization: float = 1e-6
    yield_filter_time: float = 0.02
    max_speed: float = 100.0
    max_angular_speed: float = 1000.0
    max_joint_gap: float = 0.05
    max_substeps: int = 64
    cull_pairs: bool = True
    dormant_rows: bool = True
    leaf_contacts: bool = True
    sleep: bool = True
    sleep_speed: float = 5e-4
    sleep_spin: float = 5e-3
    sleep_time: float = 0.2
    joint_space: bool = True
    engine: str = "compiled"
    integrator: str = "euler"


@dataclass(frozen=True)
class Model:
    """Everything that does not change during a run.  Shapes in the field names.

    body_*: (nb, …) for nb bodies (bones then dynamic props).
      body_mass (nb,) kg; body_inv_mass (nb,) 1/kg (0 = immovable);
      body_inertia (nb,3,3) kg·m² in the body frame; body_inv_inertia (nb,3,3);
      body_pos0 (nb,3) m rest centre of mass; body_quat0 (nb,4) rest orientation.
    bone_*: (nbone, …): bone_parent (nbone,) body index or -1; bone_head0,
      bone_tail0 (nbone,3) m, rest pose.
    joint_*: (nj, …): joint_bone (nj,) child body; joint_parent (nj,) parent body
      or -1 = world; joint_anchor_parent (nj,3) anchor in the parent's body frame
      (world when -1); joint_anchor_child (nj,3) in the child's body frame;
      joint_kf, joint_df, joint_dd (nj,3) rheology (dd = inf: never flows);
      joint_yield (nj,) N·m (inf = none); joint_rheology (nj,) bool: has rows;
      joint_axis (nj,3) unit bone axis at rest (twist axis);
      joint_swing (nj,) rad cone half-angle (inf = none);
      joint_twist_lo, joint_twist_hi (nj,) rad (±inf = none).
    """

    name: str
    body_names: tuple[str, ...]
    bone_names: tuple[str, ...]
    joint_names: tuple[str, ...]
    body_mass: np.ndarray
    body_inv_mass: np.ndarray
    body_inertia: np.ndarray
    body_inv_inertia: np.ndarray
    body_pos0: np.ndarray
    body_quat0: np.ndarray
    bone_parent: np.ndarray
    bone_head0: np.ndarray
    bone_tail0: np.ndarray
    joint_bone: np.ndarray
    joint_parent: np.ndarray
    joint_anchor_parent: np.ndarray
    joint_anchor_child: np.ndarray
    joint_kf: np.ndarray
    joint_df: np.ndarray
    joint_dd: np.ndarray
    joint_yield: np.ndarray
    joint_rheology: np.ndarray
    joint_axis: np.ndarray
    joint_swing: np.ndarray
    joint_twist_lo: np.ndarray
    joint_twist_hi: np.ndarray
    geometry: collide.Geometry
    options: Options

    @property
    def nbody(self) -> int:
        return len(self.body_names)

    @property
    def njoint(self) -> int:
        return len(self.joint_names)

    @property
    def has_limits(self) -> bool:
        """True when any joint has a swing or twist limit."""
        return bool(
            np.any(np.isfinite(self.joint_swing))
            or np.any(np.isfinite(self.joint_twist_lo))
            or np.any(np.isfinite(self.joint_twist_hi))
        )

    @property
    def has_collision(self) -> bool:
        """True when the scene has any pair of shapes that could ever touch."""
        return len(self.geometry.pair_a) > 0

    def with_options(self, **changes) -> Model:
        """A copy with some options changed (e.g. a script's h or gravity)."""
        return replace(self, options=replace(self.options, **changes))


def shape_centre(bone) -> np.ndarray:
    """Rest-pose world centre (3,) of a bone's shape: a capsule's or box's midpoint of head
    and tail; a sphere's too, or its centre of mass when the bone gives one."""
    if bone.shape.kind == "sphere" and bone.com is not None:
        return np.asarray(bone.com, dtype=float)
    return 0.5 * (bone.head + bone.tail)


def build_model(spec: RigSpec) -> Model:
    """Build the frozen model of a validated rig."""
    bones = spec.bones
    index = {b.name: i for i, b in enumerate(bones)}
    nbone = len(bones)
    props_dyn = [p for p in spec.props if p.dynamic]
    nb = nbone + len(props_dyn)

    mass = np.zeros(nb)
    inertia = np.zeros((nb, 3, 3))
    pos0 = np.zeros((nb, 3))
    quat0 = np.tile(quat.IDENTITY, (nb, 1))
    for i, b in enumerate(bones):
        pos0[i] = b.com if b.com is not None else 0.5 * (b.head + b.tail)
        mass[i] = b.mass
        if b.inertia is not None:
            inertia[i] = b.inertia
        else:
            # Shape inertia about its centre, moved to the centre of mass.
            offset = shape_centre(b) - pos0[i]
            inertia[i] = world_inertia(b.shape, b.head, b.tail, b.mass) + b.mass * (
                offset @ offset * np.eye(3) - np.outer(offset, offset)
            )
    for k, p in enumerate(props_dyn):
        i = nbone + k
        pos0[i], quat0[i], mass[i] = p.position, quat.normalize(p.rotation), p.mass
        inertia[i] = shape_inertia_local(p.shape, 2.0 * p.shape.half_extents[1], p.mass)

    movable = np.ones(nb, dtype=bool)
    if spec.root_mode == "fixed":
        movable[0] = False
    inv_mass = np.where(movable, 1.0 / mass, 0.0)
    inv_inertia = np.linalg.inv(inertia) * movable[:, None, None]

    bone_parent = np.array([index[b.parent] if b.parent else -1 for b in bones], dtype=np.int64)
    joints = _joint_arrays(spec, bone_parent, pos0)
    geometry = _geometry(spec, bone_parent, pos0, quat0, nbone, movable)
    s = spec.solver
    options = Options(
        h=s.h,
        method=s.method,
        iterations=s.iterations,
        warm_start=s.warm_start,
        warm_start_factor=s.warm_start_factor,
        integrator=s.integrator,
        contact_slop=s.contact_slop,
        gravity=np.asarray(spec.gravity, dtype=float),
    )
    return Model(
        name=spec.name,
        body_names=tuple(b.name for b in bones) + tuple(p.name for p in props_dyn),
        bone_names=tuple(b.name for b in bones),
        joint_names=tuple(bones[j].name for j in joints["bone"]),
        body_mass=mass,
        body_inv_mass=inv_mass,
        body_inertia=inertia,
        body_inv_inertia=inv_inertia,
        body_pos0=pos0,
        body_quat0=quat0,
        bone_parent=bone_parent,
        bone_head0=np.array([b.head for b in bones], dtype=float),
        bone_tail0=np.array([b.tail for b in bones], dtype=float),
        **{f"joint_{key}": value for key, value in joints.items()},
        geometry=geometry,
        options=options,
    )


def _joint_arrays(spec: RigSpec, bone_parent: np.ndarray, pos0: np.ndarray) -> dict:
    """Per-joint arrays: one joint per non-root bone, plus the root's when it is "ball"."""
    rows = []
    for i, b in enumerate(spec.bones):
        if bone_parent[i] < 0 and spec.root_mode != "ball":
            continue
        p = int(bone_parent[i])
        anchor_parent = b.head - pos0[p] if p >= 0 else b.head.astype(float)
        axis = b.tail - b.head
        n = np.linalg.norm(axis)
        axis = axis / n if n > 1e-12 else np.array([0.0, 1.0, 0.0])
        rh = b.rheology
        kf = rh.kf if rh is not None else np.zeros(3)
        df = rh.df if rh is not None else np.zeros(3)
        dd = rh.dd if rh is not None else np.full(3, np.inf)
        rows.append(
            dict(
                bone=i,
                parent=p,
                anchor_parent=anchor_parent,
                anchor_child=b.head - pos0[i],
                kf=kf,
                df=df,
                dd=dd,
                yield_=rh.yield_torque if rh is not None else np.inf,
                rheology=rh is not None and rh.active,
                axis=axis,
                swing=b.limits.swing,
                twist_lo=b.limits.twist[0],
                twist_hi=b.limits.twist[1],
            )
        )

    def col(key: str, dtype=float, width: int | None = None) -> np.ndarray:
        if not rows:
            return np.zeros((0,) if width is None else (0, width), dtype=dtype)
        return np.array([r[key] for r in rows], dtype=dtype)

    return dict(
        bone=col("bone", np.int64),
        parent=col("parent", np.int64),
        anchor_parent=col("anchor_parent", width=3),
        anchor_child=col("anchor_child", width=3),
        kf=col("kf", width=3),
        df=col("df", width=3),
        dd=col("dd", width=3),
        **{"yield": col("yield_")},
        rheology=col("rheology", bool),
        axis=col("axis", width=3),
        swing=col("swing"),
        twist_lo=col("twist_lo"),
        twist_hi=col("twist_hi"),
    )


def _geometry(
    spec: RigSpec,
    bone_parent: np.ndarray,
    pos0: np.ndarray,
    quat0: np.ndarray,
    nbone: int,
    movable: np.ndarray,
) -> collide.Geometry:
    """Collision shapes of bones, props and the ground, and the pairs that can touch."""
    body, kind, centre, orient, radius, half, mu = [], [], [], [], [], [], []

    def add(b: int, shape: ShapeSpec, c: np.ndarray, q: np.ndarray, length: float, f: float):
        body.append(b)
        kind.append(SHAPE_CODE[shape.kind])
        centre.append(c)
        orient.append(q)
        radius.append(shape.radius)
        if shape.kind == "capsule":
            half.append((0.0, 0.5 * length, 0.0))
        elif shape.kind == "box":
            half.append(tuple(shape.half_extents))
        else:
            half.append((0.0, 0.0, 0.0))
        mu.append(f)

    if spec.ground is not None:
        body.append(-1)
        kind.append(0)
        centre.append(np.array([0.0, spec.ground.height, 0.0]))
        orient.append(quat.IDENTITY)
        radius.append(0.0)
        half.append((0.0, 0.0, 0.0))
        mu.append(spec.ground.friction)
    for i, b in enumerate(spec.bones):
        if b.collide:
            length = float(np.linalg.norm(b.tail - b.head))
            add(
                i,
                b.shape,
                shape_centre(b) - pos0[i],
                shape_frame(b.head, b.tail),
                length,
                spec.bone_friction,
            )
    k = nbone
    for p in spec.props:
        q = quat.normalize(np.asarray(p.rotation, dtype=float))
        if p.dynamic:
            add(k, p.shape, np.zeros(3), quat.IDENTITY, 2.0 * p.shape.half_extents[1], p.friction)
            k += 1
        else:
            add(
                -1,
                p.shape,
                np.asarray(p.position, dtype=float),
                q,
                2.0 * p.shape.half_extents[1],
                p.friction,
            )
    arrays = dict(
        shape_body=np.array(body, dtype=np.int64),
        shape_kind=np.array(kind, dtype=np.int64),
        shape_pos=np.array(centre, dtype=float).reshape(-1, 3),
        shape_quat=np.array(orient, dtype=float).reshape(-1, 4),
        shape_radius=np.array(radius, dtype=float),
        shape_half=np.array(half, dtype=float).reshape(-1, 3),
        shape_friction=np.array(mu, dtype=float),
    )
    body_parent = np.concatenate([bone_parent, -np.ones(len(pos0) - nbone, dtype=np.int64)])
    if len(body) < 2:
        pair_a = pair_b = np.zeros(0, dtype=np.int64)
    else:
        shapes = {k: v for k, v in arrays.items() if k != "shape_friction"}
        pair_a, pair_b = collide.candidate_pairs(
            **shapes, body_parent=body_parent, body_pos=pos0, body_quat=quat0,
            body_movable=movable,
        )  # fmt: skip
    return collide.Geometry(**arrays, pair_a=pair_a, pair_b=pair_b)


def kept_with(model: Model, store: dict, build: Callable[[], T], key=None) -> T:
    """store[key] (key: id(model) unless given), made by ``build()`` on first use and
    dropped when ``model`` is collected: what is derived from a frozen model never
    changes, and an id is not reused while its model lives."""
    key = id(model) if key is None else key
    got = store.get(key)
    if got is None:
        got = store[key] = build()
        weakref.finalize(model, store.pop, key, None)
    return got
