"""A Model packed once for the compiled step: arrays, the elimination forest, workspaces.

``pack(model)`` builds a ``FastModel`` (solver.engine.Engine holds it): the model's arrays,
geometry, forest and workspaces as the named structures of ``solver.compiled.layout``
(``Packed``), the options as two small arrays with named offsets (``Opt``, ``IOpt``), and
preallocated row/contact workspaces sized for the worst case (6 rows per joint, 3 limit
rows per joint, 3 rows per possible contact, the grip's 6 and 6 per bone for pins).  The
workspaces make a FastModel usable by one thread at a time.

Every array of those structures is a view into a few buffers, ``flat``
(solver.compiled.flat): the compiled step is passed the buffers and rebuilds the
structures itself, which saves unboxing ~100 arrays per call; writes through the views
(``fm.iopt[IOpt.profiling] = 1``) are seen by the step.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from solver.advance.sleep import body_islands
from solver.advance.substep import model_levers
from solver.collide import scene_kernel as sk
from solver.compiled.clock import STAGES
from solver.compiled.flat import flatten
from solver.compiled.layout import (
    BUFFERS,
    Contacts,
    Flags,
    Geometry,
    IOpt,
    ModelArrays,
    Opt,
    Packed,
    Pointer,
    ProjectionTree,
    ProjectionWorkspace,
    ReportInt,
    Rows,
    Tree,
    TreeWork,
    Workspace,
)  # fmt: skip
from solver.model import Model
from solver.rows.grip_kernel import MODE_NONE
from solver.rows.joints_kernel import limit_thresholds

METHODS = {"auto": 0, "pgs": 1, "direct": 2, "hybrid": 3}
INTEGRATORS = ("euler", "bdf2")
FEATURES = (2, 8, 3, 3, 16)  # most contacts per pair of each group
_GROUP = {  # shape classes (plane 0, segment 1, box 2) → the pair's group in collide_scene
    (0, 1): sk.GROUP_PLANE_SEGMENT, (0, 2): sk.GROUP_PLANE_BOX, (1, 1): sk.GROUP_SEGMENT_SEGMENT,
    (1, 2): sk.GROUP_SEGMENT_BOX, (2, 2): sk.GROUP_BOX_BOX,
}  # fmt: skip
_CLASS = np.array([0, 1, 1, 2])


NO_FLAGS = (MODE_NONE, 0, False, False, False)
"""layout.Flags of a step without input: no pointer, no gripped body, no loads."""


@dataclass
class FastModel:
    """Packed arrays and workspaces of one Model; ``reason`` is why it is unsupported.

    packed: views into ``flat`` (module docstring; the properties ``m`` … ``iopt`` are its
    parts); zeros (nb,3): the force and torque of a step without loads; pvec, ivec, rep_i
    (layout's Pointer, Flags, ReportInt): the step's pointer and flag inputs and integer
    report, rewritten by every step (solver.compiled.fast); pointer:
    pvec's position, quaternion, velocity and angular velocity views (made once: an
    assignment through a view costs a fifth of slicing pvec each step)."""

    packed: Packed
    flat: tuple
    zeros: np.ndarray
    reason: str | None
    model: Model
    pvec: np.ndarray = field(default_factory=lambda: np.zeros(Pointer.SIZE))
    ivec: np.ndarray = field(default_factory=lambda: np.zeros(Flags.SIZE, np.int64))
    rep_i: np.ndarray = field(default_factory=lambda: np.zeros(ReportInt.SIZE, np.int64))
    flags: tuple = NO_FLAGS  # what ivec holds
    last: tuple = (None, None)  # (State fast_step returned last, its kernel arrays)
    coupling: tuple = (None, None, None)  # (Coupling packed last, its array, its flags)
    pin_cache: tuple = ((), None)  # (pins packed last, their arrays: fast._pin_arrays)
    pointer: tuple = ()
    no_history: tuple = ()  # a StateSet's history arrays of a state without one (zeros)
    no_input: tuple | None = None  # the kernel's input of a step without one (fast._input_arrays)

    def __post_init__(self) -> None:
        p, at = self.pvec, Pointer
        self.pointer = (p[at.pos : at.quat], p[at.quat : at.vel], p[at.vel : at.omega],
                        p[at.omega : at.radius])  # fmt: skip
        nb, nj = len(self.zeros), len(self.m.joint_parent)
        z = np.zeros
        self.no_history = (z((nb, 3)), z((nb, 4)), z((nb, 3)), z((nb, 3)), z((nj, 3)), z(3))

    m = property(lambda self: self.packed.m)
    g = property(lambda self: self.packed.g)
    tree = property(lambda self: self.packed.tree)
    ptree = property(lambda self: self.packed.ptree)
    ws = property(lambda self: self.packed.ws)
    pws = property(lambda self: self.packed.pws)
    opt = property(lambda self: self.packed.opt)
    iopt = property(lambda self: self.packed.iopt)


def _c(x, dtype=float) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=dtype)


def pack(model: Model) -> FastModel:
    """Pack a model (see the module docstring for the layouts)."""
    nb, nj = model.nbody, model.njoint
    plastic = np.all(np.isfinite(model.joint_dd), axis=1) if nj else np.zeros(0, bool)
    m = ModelArrays(
        joint_parent=_c(model.joint_parent, np.int64),
        joint_bone=_c(model.joint_bone, np.int64),
        joint_anchor_parent=_c(model.joint_anchor_parent),
        joint_anchor_child=_c(model.joint_anchor_child),
        joint_kf=_c(model.joint_kf),
        joint_df=_c(model.joint_df),
        joint_dd=_c(model.joint_dd),
        joint_rheology=_c(model.joint_rheology, np.bool_),
        joint_axis=_c(model.joint_axis),
        joint_swing=_c(model.joint_swing),
        joint_twist_lo=_c(model.joint_twist_lo),
        joint_twist_hi=_c(model.joint_twist_hi),
        joint_yield=_c(model.joint_yield),
        joint_plastic=_c(plastic, np.bool_),
        joint_finite_yield=_c(np.isfinite(model.joint_yield), np.bool_),
        body_mass=_c(model.body_mass),
        body_inv_mass=_c(model.body_inv_mass),
        body_inertia=_c(model.body_inertia),
        body_inv_inertia=_c(model.body_inv_inertia),
        body_island=_c(body_islands(model), np.int64),
        joint_levers=_c(model_levers(model)),
        joint_limit_thresholds=_c(
            limit_thresholds(
                model.joint_swing,
                model.joint_twist_lo,
                model.joint_twist_hi,
                model.options.limit_margin,
            )
        ),
    )
    g, ncontact, reason = _geometry(model)
    tree, ptree = _forest(model, ncontact)
    o = model.options
    opt = np.zeros(Opt.SIZE)
    for entry, at in Opt.__members__.items():
        if entry != "SIZE":
            opt[at : at + np.size(getattr(o, entry))] = getattr(o, entry)
    iopt = np.zeros(IOpt.SIZE, np.int64)
    iopt[IOpt.method] = METHODS.get(o.method, -1)
    iopt[IOpt.bdf2] = o.integrator == "bdf2"
    iopt[IOpt.has_rheology] = bool(model.joint_rheology.any())
    iopt[IOpt.has_limits], iopt[IOpt.has_collision] = model.has_limits, model.has_collision
    options = (
        "iterations", "warm_start", "max_substeps", "cull_pairs", "dormant_rows", "leaf_contacts",
        "sleep",
    )  # fmt: skip
    for entry in options:
        iopt[IOpt[entry]] = getattr(o, entry)
    if o.method not in METHODS:
        reason = f"solver method '{o.method}' is not compiled"
    if o.integrator not in INTEGRATORS:
        reason = f"integrator '{o.integrator}' is not compiled"
    nrows = 9 * nj + 3 * ncontact + 6 + 6 * nb  # pins: one per bone, 6 rows at most
    ns = len(model.geometry.shape_body)
    ws = Workspace(
        rows=_zeros(Rows, nrows),
        resp_a=np.zeros((nrows, 6)),
        resp_b=np.zeros((nrows, 6)),
        rheo_joint=np.zeros(nrows, np.int64),
        contacts=_zeros(Contacts, ncontact),
        rot=np.zeros((nb, 3, 3)),
        inv_inertia=np.zeros((nb, 3, 3)),
        inertia=np.zeros((nb, 3, 3)),
        shape_centre=np.zeros((ns, 3)),
        shape_rot=np.zeros((ns, 3, 3)),
        cycles=np.zeros(len(STAGES), np.int64),
    )
    pws = ProjectionWorkspace(
        rows=_zeros(Rows, 3 * nj),
        resp_a=np.zeros((3 * nj, 6)),
        resp_b=np.zeros((3 * nj, 6)),
        rot=np.zeros((nb, 3, 3)),
        inv_inertia=np.zeros((nb, 3, 3)),
        inertia=np.zeros((nb, 3, 3)),
        lam=np.zeros(3 * nj),
    )
    flat, views = flatten(Packed(m, g, tree, ptree, ws, pws, opt, iopt))
    return FastModel(views, flat, np.zeros((nb, 3)), reason, model)


def _zeros(cls, n: int):
    """A structure of layout (``Rows``, ``Contacts``) whose arrays all have n zero rows."""
    return cls(*(np.zeros((n, *BUFFERS[kind][1]), BUFFERS[kind][0]) for kind in cls.KINDS))


def _geometry(model: Model) -> tuple[Geometry, int, str | None]:
    """(Geometry, most contacts a step can produce, reason it is unsupported or None)."""
    geo = model.geometry
    kind, body = geo.shape_kind, geo.shape_body
    cls = _CLASS[kind]
    a, b = geo.pair_a, geo.pair_b
    swap = cls[a] > cls[b]
    f, s = np.where(swap, b, a), np.where(swap, a, b)
    group = np.array(
        [_GROUP.get((int(x), int(y)), -1) for x, y in zip(cls[f], cls[s], strict=True)], np.int64
    )
    reason = "a shape pair of an unknown kind" if np.any(group < 0) else None
    bound = np.where(
        kind == 3, np.linalg.norm(geo.shape_half, axis=1), geo.shape_radius + geo.shape_half[:, 1]
    )
    mu = geo.shape_friction
    touchable = np.flatnonzero(body >= 0)
    g = Geometry(
        shape_body=_c(body, np.int64),
        shape_pos=_c(geo.shape_pos),
        shape_quat=_c(geo.shape_quat),
        shape_kind=_c(kind, np.int64),
        shape_radius=_c(geo.shape_radius),
        shape_half=_c(geo.shape_half),
        shape_bound=_c(bound),
        pair_first=_c(f, np.int64),
        pair_second=_c(s, np.int64),
        pair_group=group,
        pair_sign=_c(np.where(swap, -1.0, 1.0)),
        pair_body_a=_c(body[a], np.int64),
        pair_body_b=_c(body[b], np.int64),
        pair_friction=_c(np.sqrt(mu[a] * mu[b])),
        touchable=_c(touchable, np.int64),
        touch_friction=_c(np.sqrt(0.5 * mu[touchable])),
    )
    most = sum(FEATURES[k] for k in group if k >= 0) + 3 * len(touchable)
    return g, most, reason


def _forest(model: Model, ncontact: int) -> tuple[Tree, ProjectionTree]:
    """Elimination forest of bodies and joints (solver.solve.direct_kernel), children first.

    Nodes: body b (movable only), joint j as nb + j, the grip as nb + nj, and room for
    ncontact leaf contacts (solver.solve.hybrid) as nb + nj + 1 + k (the grip and the
    leaves placed first at run time, each hung from its body).  A component is rooted at
    its joint to the world (or to an immovable body) when it has one, else at its first
    body.  Why: a row node eliminated as a leaf adds C⁻¹ (10⁶/A_ii for a regularised
    anchor row, 10¹⁴ in the projection) to its body's block and ruins that block's
    conditioning; as the root it is eliminated last, after its bodies, as the
    well-conditioned Schur complement −C − J D⁻¹ Jᵀ."""
    nb, nj = model.nbody, model.njoint
    movable = model.body_inv_mass > 0.0
    adjacent: list[list[int]] = [[] for _ in range(nb + nj + 1)]
    for j in range(nj):
        for body in (model.joint_parent[j], model.joint_bone[j]):
            if body >= 0 and movable[body]:
                adjacent[nb + j].append(int(body))
                adjacent[int(body)].append(nb + j)
    parent = np.full(nb + nj + 1 + ncontact, -1, np.int64)
    seen = np.zeros(nb + nj + 1, bool)
    order: list[int] = []
    to_world = [nb + j for j in range(nj) if len(adjacent[nb + j]) < 2]
    roots = to_world + [b for b in range(nb) if movable[b]]
    for root in roots:
        if seen[root]:
            continue
        seen[root] = True
        queue, visit = deque([root]), []
        while queue:
            node = queue.popleft()
            visit.append(node)
            for nxt in adjacent[node]:
                if not seen[nxt]:
                    seen[nxt], parent[nxt] = True, node
                    queue.append(nxt)
        order.extend(reversed(visit))
    rank = np.cumsum(model.joint_rheology) - 1
    rheo_start = np.where(model.joint_rheology, 3 * nj + 3 * rank, -1).astype(np.int64)
    nn = nb + nj + 1 + ncontact
    tw = TreeWork(np.zeros((nn, 6, 6)), np.zeros((nn, 6, 6)), np.zeros((nn, 6)), np.zeros((6, 6)))
    order_arr, no_rheo = np.array(order, np.int64), np.full(nj, -1, np.int64)
    rows, size = np.zeros((nn, 6), np.int64), np.zeros(nn, np.int64)
    seq = np.zeros(nn, np.int64)
    tree = Tree(order_arr, parent.copy(), rheo_start, parent, no_rheo, seq, rows, size, tw)
    return tree, ProjectionTree(order_arr, parent, no_rheo, rows, size, tw)
