"""A Model packed once for the compiled step: arrays, the elimination forest, workspaces.

``pack(model)`` builds a ``FastModel`` (solver.engine.Engine holds it): struct-of-arrays
tuples with fixed layouts the kernels index by position, the options as two small
arrays, and preallocated row/contact workspaces sized for the worst case (6 rows per
joint, 3 limit rows per joint, 3 rows per possible contact, and the grip's 6). The
workspaces make a FastModel usable by one thread at a time.

Every array of those tuples is a view into three buffers, ``flat`` (solver.compiled.flat):
the compiled step is passed the buffers and rebuilds the tuples itself, which saves
unboxing ~100 arrays per call; writes through the views (``fm.iopt[7] = 1``) are seen by
the step.

Tuple layouts:
  m    0 joint_parent 1 joint_bone 2 anchor_parent 3 anchor_child 4 kf 5 df 6 dd
       7 joint_rheology 8 joint_axis 9 swing 10 twist_lo 11 twist_hi 12 yield
       13 plastic (all D_d finite) 14 finite yield 15 body_mass 16 body_inv_mass
       17 body_inertia 18 body_inv_inertia 19 body island (solver.advance.sleep)
       20 joints' tension levers (solver.advance.substep.tension_levers) 21 limit thresholds
       (solver.rows.joints_kernel.limit_thresholds)
  g    0 shape_body 1 shape_pos 2 shape_quat 3 kind 4 radius 5 half 6 bound 7 pair first
       8 pair second 9 group 10 normal sign 11 body_a 12 body_b 13 friction
       14 pointer-touchable shapes 15 their friction with the pointer
  tree 0 static elimination order 1 node parent 2 first rheology row per joint
       3 no-rheology marker 4 sequence buffer 5 node rows 6 node sizes 7 (D, Y, w, g)
  ws   0 rows 1 resp_a 2 resp_b 3 joint of each rheology row 4 contacts 5 rot 6 I_w⁻¹
       7 I_w 8 shape centres 9 shape rotations 10 cycles per stage (solver.compiled.kernel)
  opt  h, joint_erp, contact_erp, contact_slop, contact_margin, limit_margin,
       regularization, yield_filter_time, max_speed, max_angular_speed, max_joint_gap,
       warm_start_factor, gravity (3), sleep speed, sleep spin, sleep time
  iopt method (0 auto, 1 pgs, 2 direct, 3 hybrid), iterations, warm_start, has rheology,
       has limits, has collision, max substeps, profiling on, cull pairs, dormant rows,
       sleep
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from solver.advance.sleep import body_islands
from solver.advance.substep import model_levers, sub_model
from solver.compiled.clock import STAGES
from solver.compiled.flat import flatten
from solver.model import Model
from solver.rows.joints_kernel import limit_thresholds

METHODS = {"auto": 0, "pgs": 1, "direct": 2, "hybrid": 3}
FEATURES = (2, 8, 3, 3, 16)  # most contacts per pair of each group
BOX_BOX = 4
_GROUP = {(0, 1): 0, (0, 2): 1, (1, 1): 2, (1, 2): 3, (2, 2): BOX_BOX}
_CLASS = np.array([0, 1, 1, 2])


@dataclass
class FastModel:
    """Packed arrays and workspaces of one Model; ``reason`` is why it is unsupported.

    m … iopt: views into ``flat`` (module docstring); zeros (nb,3): the force and torque
    of a step without loads; pvec (14,), ivec (5,), rep_i (4,): the step's pointer and
    flag inputs and integer report, rewritten by every step (solver.compiled.fast); pointer:
    pvec's position, quaternion, velocity and angular velocity views (made once: an
    assignment through a view costs a fifth of slicing pvec each step)."""

    m: tuple
    g: tuple
    tree: tuple
    ptree: tuple
    ws: tuple
    pws: tuple
    opt: np.ndarray
    iopt: np.ndarray
    flat: tuple
    zeros: np.ndarray
    reason: str | None
    model: Model
    pvec: np.ndarray = field(default_factory=lambda: np.zeros(14))
    ivec: np.ndarray = field(default_factory=lambda: np.zeros(5, np.int64))
    rep_i: np.ndarray = field(default_factory=lambda: np.zeros(4, np.int64))
    flags: tuple = (0, 0, False, False, False)  # what ivec holds
    last: tuple = (None, None)  # (State fast_step returned last, its kernel arrays)
    coupling: tuple = (None, None, None)  # (Coupling packed last, its array, its flags)
    pointer: tuple = ()
    subs: dict = field(default_factory=dict)  # n → the FastModel of the step at h/n

    def __post_init__(self) -> None:
        p = self.pvec
        self.pointer = (p[0:3], p[3:7], p[7:10], p[10:13])

    def sub(self, n: int) -> FastModel:
        """The packed model of this model's step at h/n (solver.advance.substep),
        packed the first time a step needs it and kept with this one."""
        got = self.subs.get(n)
        if got is None:
            got = self.subs[n] = pack(sub_model(self.model, n))
        return got


def _c(x, dtype=float) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=dtype)


def pack(model: Model) -> FastModel:
    """Pack a model (see the module docstring for the layouts)."""
    nb, nj = model.nbody, model.njoint
    plastic = np.all(np.isfinite(model.joint_dd), axis=1) if nj else np.zeros(0, bool)
    m = (
        _c(model.joint_parent, np.int64),
        _c(model.joint_bone, np.int64),
        _c(model.joint_anchor_parent),
        _c(model.joint_anchor_child),
        _c(model.joint_kf),
        _c(model.joint_df),
        _c(model.joint_dd),
        _c(model.joint_rheology, np.bool_),
        _c(model.joint_axis),
        _c(model.joint_swing),
        _c(model.joint_twist_lo),
        _c(model.joint_twist_hi),
        _c(model.joint_yield),
        _c(plastic, np.bool_),
        _c(np.isfinite(model.joint_yield), np.bool_),
        _c(model.body_mass),
        _c(model.body_inv_mass),
        _c(model.body_inertia),
        _c(model.body_inv_inertia),
        _c(body_islands(model), np.int64),
        _c(model_levers(model)),
        _c(
            limit_thresholds(
                model.joint_swing,
                model.joint_twist_lo,
                model.joint_twist_hi,
                model.options.limit_margin,
            )
        ),
    )
    g, ncontact, reason = _geometry(model)
    tree, ptree = _forest(model)
    o = model.options
    opt = _c(
        [
            o.h,
            o.joint_erp,
            o.contact_erp,
            o.contact_slop,
            o.contact_margin,
            o.limit_margin,
            o.regularization,
            o.yield_filter_time,
            o.max_speed,
            o.max_angular_speed,
            o.max_joint_gap,
            o.warm_start_factor,
            *o.gravity,
            o.sleep_speed,
            o.sleep_spin,
            o.sleep_time,
        ]
    )
    iopt = _c(
        [
            METHODS.get(o.method, -1),
            o.iterations,
            o.warm_start,
            bool(model.joint_rheology.any()),
            model.has_limits,
            model.has_collision,
            o.max_substeps,
            0,
            o.cull_pairs,
            o.dormant_rows,
            o.sleep,
        ],
        np.int64,
    )
    if o.method not in METHODS:
        reason = f"solver method '{o.method}' is not compiled"
    nrows = 9 * nj + 3 * ncontact + 6
    ns = len(model.geometry.shape_body)
    ws = (
        _rows(nrows),
        np.zeros((nrows, 6)),
        np.zeros((nrows, 6)),
        np.zeros(nrows, np.int64),
        _contacts(ncontact),
        np.zeros((nb, 3, 3)),
        np.zeros((nb, 3, 3)),
        np.zeros((nb, 3, 3)),
        np.zeros((ns, 3)),
        np.zeros((ns, 3, 3)),
        np.zeros(len(STAGES), np.int64),
    )
    pws = (
        _rows(3 * nj),
        np.zeros((3 * nj, 6)),
        np.zeros((3 * nj, 6)),
        np.zeros((nb, 3, 3)),
        np.zeros((nb, 3, 3)),
        np.zeros((nb, 3, 3)),
        np.zeros(3 * nj),
    )
    flat, views = flatten((m, g, tree, ptree, ws, pws, opt, iopt))
    return FastModel(*views, flat, np.zeros((nb, 3)), reason, model)


def _rows(n: int) -> tuple:
    """An empty row table for n rows (layout of solver.rows.table_kernel.set_row)."""
    i, f = np.zeros(n, np.int64), np.zeros(n)
    return (
        i,
        i.copy(),
        np.zeros((n, 6)),
        np.zeros((n, 6)),
        f,
        f.copy(),
        f.copy(),
        f.copy(),
        i.copy(),
        f.copy(),
        i.copy(),
        i.copy(),
    )


def _contacts(n: int) -> tuple:
    """Contact buffers: body_a, body_b, point, normal, depth, friction, key."""
    i = np.zeros(n, np.int64)
    return (i, i.copy(), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros(n), i.copy())


def _geometry(model: Model) -> tuple[tuple, int, str | None]:
    """(g tuple, most contacts a step can produce, reason it is unsupported or None)."""
    geo = model.geometry
    kind, body = geo.shape_kind, geo.shape_body
    cls = _CLASS[kind]
    a, b = geo.pair_a, geo.pair_b
    swap = cls[a] > cls[b]
    f, s = np.where(swap, b, a), np.where(swap, a, b)
    group = np.array(
        [_GROUP.get((int(x), int(y)), -1) for x, y in zip(cls[f], cls[s], strict=True)], np.int64
    )
    movable = np.append(model.body_inv_mass > 0.0, False)  # index −1: static
    reason = None
    if np.any(group < 0):
        reason = "a shape pair of an unknown kind"
    elif np.any((group == BOX_BOX) & (movable[body[a]] | movable[body[b]])):
        reason = "box–box contact is not compiled"
    bound = np.where(
        kind == 3, np.linalg.norm(geo.shape_half, axis=1), geo.shape_radius + geo.shape_half[:, 1]
    )
    mu = geo.shape_friction
    touchable = np.flatnonzero(body >= 0)
    g = (
        _c(body, np.int64),
        _c(geo.shape_pos),
        _c(geo.shape_quat),
        _c(kind, np.int64),
        _c(geo.shape_radius),
        _c(geo.shape_half),
        _c(bound),
        _c(f, np.int64),
        _c(s, np.int64),
        group,
        _c(np.where(swap, -1.0, 1.0)),
        _c(body[a], np.int64),
        _c(body[b], np.int64),
        _c(np.sqrt(mu[a] * mu[b])),
        _c(touchable, np.int64),
        _c(np.sqrt(0.5 * mu[touchable])),
    )
    most = sum(FEATURES[k] for k in group if k >= 0) + 3 * len(touchable)
    return g, most, reason


def _forest(model: Model) -> tuple[tuple, tuple]:
    """Elimination forest of bodies and joints (solver.solve.direct_kernel), children first.

    Nodes: body b (movable only), joint j as nb + j, the grip as nb + nj (placed first
    at run time).  A component is rooted at its joint to the world (or to an immovable
    body) when it has one, else at its first body.  Why: a row node eliminated as a
    leaf adds C⁻¹ (10⁶/A_ii for a regularised anchor row, 10¹⁴ in the projection) to
    its body's block and ruins that block's conditioning; as the root it is eliminated
    last, after its bodies, as the well-conditioned Schur complement −C − J D⁻¹ Jᵀ."""
    nb, nj = model.nbody, model.njoint
    movable = model.body_inv_mass > 0.0
    adjacent: list[list[int]] = [[] for _ in range(nb + nj + 1)]
    for j in range(nj):
        for body in (model.joint_parent[j], model.joint_bone[j]):
            if body >= 0 and movable[body]:
                adjacent[nb + j].append(int(body))
                adjacent[int(body)].append(nb + j)
    parent = np.full(nb + nj + 1, -1, np.int64)
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
    nn = nb + nj + 1
    tw = (np.zeros((nn, 6, 6)), np.zeros((nn, 6, 6)), np.zeros((nn, 6)), np.zeros((6, 6)))
    order_arr, no_rheo = np.array(order, np.int64), np.full(nj, -1, np.int64)
    rows, size = np.zeros((nn, 6), np.int64), np.zeros(nn, np.int64)
    tree = (order_arr, parent, rheo_start, no_rheo, np.zeros(nn, np.int64), rows, size, tw)
    return tree, (order_arr, parent, no_rheo, rows, size, tw)
