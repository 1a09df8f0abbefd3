"""Compiled kernels against their numpy counterparts: narrow phase, and the tree solve
against the dense Cholesky and scipy."""

from __future__ import annotations

from dataclasses import replace

import numba
import numpy as np
import pytest
import scipy.linalg
from rigbuild import chain, rheology

from solver import quat
from solver.collide import box as collide_box
from solver.collide import scene as collide
from solver.collide import segment as collide_segment
from solver.collide.box_kernel import segment_box
from solver.collide.pointer import pointer_contacts
from solver.collide.pointer_kernel import collide_pointer
from solver.collide.scene_kernel import collide_scene, world_shapes
from solver.collide.segment_kernel import segment_segment
from solver.compiled.layout import Contacts, Opt
from solver.compiled.pack import pack
from solver.compiled.views import packed_view
from solver.model import build_model
from solver.rows.build import build_rows
from solver.rows.grip import any_within, segment_distances
from solver.rows.grip_kernel import segment_distances as compiled_distances
from solver.rows.joints import joint_frames
from solver.rows.joints import limit_rows as numpy_limit_rows
from solver.rows.joints_kernel import LIMIT_SLACK, limit_arrays, limit_rows
from solver.rows.table_kernel import row_arrays
from solver.solve.direct_kernel import dense_solve, node_rows, tree_solve
from solver.solve.response import dense_system, regularize, row_response, world_inverse_inertia
from solver.spec import BoneSpec, GroundSpec, LimitSpec, PropSpec, RigSpec, ShapeSpec
from solver.state import initial_state

CAPSULE = ShapeSpec("capsule", radius=0.04)
SPHERE = ShapeSpec("sphere", radius=0.05)
BOX = ShapeSpec("box", half_extents=(0.08, 0.05, 0.12))


def mixed_scene() -> RigSpec:
    """Ground, static capsule and sphere props, dynamic spheres, capsules and one box."""
    root = BoneSpec("root", None, np.zeros(3), np.array([0.0, 0.2, 0.0]), CAPSULE, 1.0)
    r0 = np.array([1.0, 0.0, 0.0, 0.0])

    def prop(name, shape, dynamic, pos):
        return PropSpec(name, shape, np.array(pos, float), r0, dynamic=dynamic, friction=0.4)

    def apart(i):  # rest poses apart, so no pair is dropped as overlapping at rest
        return (1.0 + 0.5 * i, 1.0, 0.0)

    props = (
        prop(
            "pole",
            ShapeSpec("capsule", radius=0.05, half_extents=(0, 0.15, 0)),
            False,
            (0.1, 0.1, 0.0),
        ),
        prop("ball", SPHERE, False, (-0.1, 0.1, 0.1)),
        prop("s1", SPHERE, True, apart(0)),
        prop("s2", SPHERE, True, apart(1)),
        prop("c1", ShapeSpec("capsule", radius=0.03, half_extents=(0, 0.1, 0)), True, apart(2)),
        prop("c2", ShapeSpec("capsule", radius=0.06, half_extents=(0, 0.05, 0)), True, apart(3)),
        prop("box", BOX, True, apart(4)),
    )
    return RigSpec("mixed", (root,), root_mode="free", ground=GroundSpec(0.0, 0.7), props=props)


def assert_same_contacts(expected: collide.Contacts, cb: tuple, n: int, offset: int = 0):
    assert n == len(expected.key)
    assert np.array_equal(cb.key[:n], expected.key + offset)
    assert np.array_equal(cb.body_a[:n], expected.body_a)
    assert np.array_equal(cb.body_b[:n], expected.body_b)
    assert np.array_equal(cb.friction[:n], expected.friction)
    for got, want in (
        (cb.point, expected.point),
        (cb.normal, expected.normal),
        (cb.depth, expected.depth),
    ):
        assert np.abs(got[:n] - want).max(initial=0.0) < 4e-15  # measured 7.8e-16


@pytest.mark.parametrize("seed", range(12))
def test_narrow_phase_equals_numpy_collide(seed):
    rng = np.random.default_rng(seed)
    model = build_model(mixed_scene())
    fm = pack(model)
    g, cb, centre, rot = fm.g, fm.ws.contacts, fm.ws.shape_centre, fm.ws.shape_rot
    nb = model.nbody
    pos = rng.uniform([-0.2, -0.02, -0.2], [0.2, 0.25, 0.2], size=(nb, 3))
    q = quat.normalize(rng.normal(size=(nb, 4)))
    if seed % 3 == 0:  # axis-aligned poses: parallel and face-on configurations
        q = np.tile(quat.IDENTITY, (nb, 1))
    for margin in (0.0, 0.01, 0.1):
        world_shapes(g, pos, q, centre, rot)
        n = collide_scene(g, centre, rot, margin, cb, True, np.ones(nb, np.bool_))
        assert_same_contacts(collide.collide(model.geometry, pos, q, margin), cb, n)
    state = replace(initial_state(model), body_pos=pos, body_quat=q)
    for radius in (0.02, 0.1):
        centre_p = rng.uniform(-0.15, 0.15, 3) + [0.0, 0.1, 0.0]
        n = collide_pointer(g, centre, rot, centre_p, radius, 0.01, cb, 0)
        expected = pointer_contacts(
            model.with_options(contact_margin=0.01), state, centre_p, radius
        )
        assert_same_contacts(expected, cb, n)


def _buffers(k: int = 8) -> Contacts:
    """Contact buffers for k contacts."""
    z = np.zeros
    return Contacts(
        z(k, np.int64), z(k, np.int64), z((k, 3)), z((k, 3)), z(k), z(k), z(k, np.int64)
    )


CTX = (0, 1, 0.5, 1.0, 0)  # a narrow kernel's pair: bodies 0, 1, friction, sign, key base


def _tup(x):
    """A vector as the compiled kernels take it (a tuple of floats), a scalar as a float."""
    return tuple(float(v) for v in x) if np.ndim(x) else float(x)


def _unit_rows(rng, k: int) -> np.ndarray:
    v = rng.normal(size=(k, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _assert_features(found: tuple, cb: tuple, n: int) -> None:
    """The compiled kernel's contacts (features in order, key = feature) are numpy's kept ones."""
    point, normal, depth, keep = (x[0] for x in found)
    kept = np.flatnonzero(keep)
    assert np.array_equal(cb.key[:n], kept)
    for got, want in ((cb.point, point), (cb.normal, normal), (cb.depth, depth)):
        # measured 6.3e-14 (segments up to 10 m long)
        assert np.abs(got[:n] - want[kept]).max(initial=0.0) < 3e-13


@pytest.mark.parametrize("seed", range(4))
def test_narrow_early_outs_keep_every_contact(seed):
    """segment_segment and segment_box leave a pair early when its closest points (the
    box: a Lipschitz bound) are beyond the margin; on pairs placed so their distance
    straddles the margin — near-parallel segments, spheres, segments up to 10 m long —
    they keep exactly numpy's contacts (solver.collide.segment / collide_box)."""
    rng = np.random.default_rng(seed)
    margin, k = 0.01, 400
    da, db = _unit_rows(rng, k), _unit_rows(rng, k)
    near_parallel = rng.random(k) < 0.25
    db[near_parallel] = da[near_parallel] + 1e-7 * _unit_rows(rng, near_parallel.sum())
    length = 10.0 ** rng.uniform(-2, 1, size=(k, 2))
    length[rng.random(k) < 0.1, 0] = 0.0  # spheres
    radius = rng.uniform(0.01, 0.1, size=(k, 2))
    ca = rng.uniform(-0.5, 0.5, size=(k, 3))
    kept_some = skipped = 0
    for i in range(k):
        la, lb, ra, rb = length[i, 0], length[i, 1], radius[i, 0], radius[i, 1]
        # b's centre at a distance from a's closest point that straddles the margin
        side = np.cross(da[i], db[i])
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else _unit_rows(rng, 1)[0]
        gap = ra + rb + margin + rng.uniform(-0.02, 0.02)
        cb_ = ca[i] + rng.uniform(-la, la) * da[i] + gap * side
        args = (ca[i], da[i], la, ra, cb_, db[i], lb, rb)
        buffers = _buffers()
        n = segment_segment(*(_tup(a) for a in args), margin, CTX, buffers, 0)
        found = collide_segment.segment_segment(*(np.array([a]) for a in args), margin)
        _assert_features(found, buffers, n)
        kept_some += n > 0
        skipped += n == 0
    assert kept_some > k // 5 and skipped > k // 5  # both sides of the margin were tried


@pytest.mark.parametrize("seed", range(4))
def test_segment_box_early_out_keeps_every_contact(seed):
    rng = np.random.default_rng(seed)
    margin, k = 0.01, 400
    kept_some = skipped = 0
    for _ in range(k):
        half = 10.0 ** rng.uniform(-2, 0.5, size=3)
        q = quat.normalize(rng.normal(size=4))
        rot = quat.matrix(q)
        cbox = rng.uniform(-0.5, 0.5, 3)
        d = _unit_rows(rng, 1)[0]
        lseg, r = 10.0 ** rng.uniform(-2, 1) * (rng.random() > 0.1), rng.uniform(0.01, 0.1)
        # the segment's middle just outside a face, at a distance straddling its reach
        axis = rng.integers(3)
        local = rng.uniform(-1, 1, 3) * half
        local[axis] = np.sign(rng.normal()) * (half[axis] + r + margin + rng.uniform(-0.02, 0.2))
        c = cbox + rot @ local
        buffers = _buffers()
        n = segment_box(_tup(cbox), rot[None], 0, _tup(half), _tup(c), _tup(d), lseg, r, margin,
                        CTX, buffers, 0)  # fmt: skip
        args = (cbox, rot, half, c, d, lseg, r)
        point, normal, depth, keep = collide_box.segment_box(*(np.array([a]) for a in args), margin)
        found = point, -normal, depth, keep  # numpy's is the box's; the kernel's box-ward
        _assert_features(found, buffers, n)
        kept_some += n > 0
        skipped += n == 0
    assert kept_some > k // 10 and skipped > k // 10


def box_scene() -> RigSpec:
    """Three dynamic boxes of different sizes and a static one, on the ground."""
    r0 = np.array([1.0, 0.0, 0.0, 0.0])
    root = BoneSpec("root", None, np.zeros(3), np.array([0.0, 0.2, 0.0]), CAPSULE, 1.0)
    sizes = ((0.08, 0.05, 0.12), (0.05, 0.05, 0.05), (0.15, 0.02, 0.1), (0.2, 0.03, 0.2))
    where = [np.array([1.0 + i, 1.0, 0.0]) for i in range(len(sizes))]
    props = tuple(
        PropSpec(f"box{i}", ShapeSpec("box", half_extents=size), where[i], r0, dynamic=i < 3,
                 friction=0.3 + 0.1 * i)
        for i, size in enumerate(sizes)
    )  # fmt: skip
    return RigSpec("boxes", (root,), root_mode="free", ground=GroundSpec(0.0, 0.7), props=props)


@pytest.mark.parametrize("seed", range(24))
def test_box_box_equals_numpy_collide(seed):
    """The compiled box–box narrow phase against solver.collide.boxbox (arrays of pairs, a
    separate implementation): the same contacts, features, points, normals and depths,
    over random poses within reach of each other (every third seed axis-aligned: face-on
    and parallel-edge configurations, the clipping's cases), at three margins (1,191
    contacts, 1.1e-16 apart at most)."""
    rng = np.random.default_rng(seed)
    model = build_model(box_scene())
    fm = pack(model)
    assert fm.reason is None
    g, cb, centre, rot = fm.g, fm.ws.contacts, fm.ws.shape_centre, fm.ws.shape_rot
    nb = model.nbody
    pos = rng.uniform([-0.15, 0.0, -0.15], [0.15, 0.2, 0.15], size=(nb, 3))
    q = quat.normalize(rng.normal(size=(nb, 4)))
    if seed % 3 == 0:
        q = np.tile(quat.IDENTITY, (nb, 1))
        q[-2] = quat.normalize(np.array([1.0, 0.0, 0.3 * rng.normal(), 0.0]))  # one turned
    boxbox = 0
    for margin in (0.0, 0.01, 0.1):
        world_shapes(g, pos, q, centre, rot)
        n = collide_scene(g, centre, rot, margin, cb, True, np.ones(nb, np.bool_))
        expected = collide.collide(model.geometry, pos, q, margin)
        assert_same_contacts(expected, cb, n)
        kinds = model.geometry.shape_kind
        pair = expected.key // collide.FEATURES
        boxbox += int(np.sum((kinds[model.geometry.pair_a[pair]] == 3)
                             & (kinds[model.geometry.pair_b[pair]] == 3)))  # fmt: skip
    assert boxbox > 0  # the poses put boxes against boxes


@pytest.mark.parametrize("root_mode", ["free", "fixed", "ball"])
def test_tree_and_dense_solves_equal_scipy_on_a_joint_table(root_mode):
    rng = np.random.default_rng(3)
    model = build_model(chain(7, 0.01, root_mode=root_mode, rheo=rheology(2.0, 0.5, 3.0)))
    state = replace(initial_state(model), body_omega=rng.normal(size=(7, 3)))
    rot = quat.matrix(state.body_quat)
    inv_i = world_inverse_inertia(model.body_inv_inertia, rot)
    vel_free = np.hstack((state.body_vel, state.body_omega))
    rows, _, _ = build_rows(model, state, rot, vel_free)
    resp = row_response(rows, model.body_inv_mass, inv_i, model.options.h)
    rows = regularize(rows, resp, model.options.regularization)
    q, c = dense_system(rows, resp, vel_free)
    expected = scipy.linalg.solve(q, -c, assume_a="pos")
    rw = row_arrays(rows)
    lam = np.zeros(len(rows))
    assert dense_solve(rw, resp[0], resp[1], len(rows), vel_free, lam)
    # measured ≤ 1.2e-15 (dense) and 1.6e-15 (tree) relative; cond Q ≈ 5e5
    assert np.abs(lam - expected).max() < 8e-15 * np.abs(expected).max()
    order, parent, rheo_start, _, _, _, node_rows_, size, tw = pack(model).tree
    for i in order:
        size[i] = node_rows(i, model.nbody, rheo_start, node_rows_[i])
    inertia_w = rot @ model.body_inertia @ np.swapaxes(rot, 1, 2)
    lam = np.zeros(len(rows))
    assert tree_solve(
        order,
        len(order),
        parent,
        model.nbody,
        rw,
        vel_free,
        model.options.h,
        model.body_mass,
        inertia_w,
        node_rows_,
        size,
        tw,
        lam,
    )
    assert np.abs(lam - expected).max() < 8e-15 * np.abs(expected).max()


def test_qexp_series_equals_the_exact_exponential():
    """kin_kernel.qexp's Taylor branch (θ/2 < EXP_SERIES) and its sin/cos branch against numpy's
    quat.exp (sin and cos for every angle), across and at the switch."""
    from solver.kin_kernel import EXP_SERIES, qexp

    rng = np.random.default_rng(5)
    axes = _unit_rows(rng, 3000)
    at_switch = 2.0 * EXP_SERIES * (1 + rng.uniform(-1e-6, 1e-6, 1000))
    angles = np.concatenate((10.0 ** rng.uniform(-12, 0.4, 2000), at_switch))
    rotvecs = axes * angles[:, None]
    got = np.array([qexp(_tup(v)) for v in rotvecs])
    want = quat.exp(rotvecs)
    assert np.abs(got[:, 0] - want[:, 0]).max() < 3e-16  # measured 0
    sine = np.linalg.norm(want[:, 1:], axis=1)  # sin(θ/2): the vector part, relatively
    assert (np.linalg.norm(got[:, 1:] - want[:, 1:], axis=1) / sine).max() < 3e-16  # 2.2e-16


def test_qlog_series_equals_the_exact_logarithm():
    """kin_kernel.qlog's series branch (tan(θ/4) < 0.03) and its atan2 branch against numpy's
    quat.log (arctan2 for every angle), across and at the switch, both hemispheres."""
    from solver.kin_kernel import LOG_SERIES, qlog

    rng = np.random.default_rng(6)
    axes = _unit_rows(rng, 3000)
    at_switch = 4.0 * np.arctan(LOG_SERIES) * (1 + rng.uniform(-1e-6, 1e-6, 1000))
    angles = np.concatenate((10.0 ** rng.uniform(-11, 0.4, 2000), at_switch))
    q = quat.exp(axes * angles[:, None])
    q[::2] *= -1.0  # the other hemisphere: the same rotation
    got = np.array([qlog(_tup(v)) for v in q])
    want = quat.log(q)
    assert (np.linalg.norm(got - want, axis=1) / angles).max() < 6e-16  # ≤ 3 ulp: 4.1e-16


@numba.njit
def _fast_limit_rows(flat, body_quat, body_rot):
    packed = packed_view(flat, 0)
    opt = packed.opt
    asleep = np.zeros(len(body_quat), dtype=np.bool_)
    limits = limit_arrays(packed.m)
    nj = len(limits.parent)
    gaps, turned = np.empty((nj, 3)), np.empty((nj, 3))
    return limit_rows(
        limits, body_quat, body_rot, opt[Opt.h], opt[Opt.joint_erp], opt[Opt.limit_margin],
        asleep, packed.ws.rows, 0, gaps, turned,
    )  # fmt: skip


def _near(rng, edge: float, far: tuple[float, float]) -> float:
    """An angle within 3·10⁻⁹ rad of ``edge`` (three times the thresholds' slack), or
    anywhere in ``far``."""
    if rng.random() < 0.7:
        return edge + rng.uniform(-3.0, 3.0) * LIMIT_SLACK
    return rng.uniform(*far)


@pytest.mark.parametrize(
    "limits",
    [LimitSpec(0.6, (-0.4, 0.5)), LimitSpec(0.02, (-3.1, 3.13)), LimitSpec(2.9, (0.3, 0.35)),
     LimitSpec(0.6), LimitSpec(twist=(-np.inf, 0.4))],
)  # fmt: skip
def test_limit_rows_at_their_margins_equal_numpys(limits):
    # Poses whose swing and twist sit within a few slacks of the margin from each finite
    # bound (where the thresholds must not skip what the angles keep), and anywhere else
    # (an infinite bound is never reached); the compiled rows (thresholds, one angle
    # per joint) must be numpy's (every angle).
    model = build_model(chain(9, 0.001, root_mode="free", limits=limits))
    fm, margin, rng = pack(model), model.options.limit_margin, np.random.default_rng(7)
    lo, hi = limits.twist
    twist_edges = [b for b in (lo + margin, hi - margin) if np.isfinite(b)] or [0.0]
    swing_edge = limits.swing - margin if np.isfinite(limits.swing) else 1.0
    made = skipped = 0
    for _ in range(60):
        q = [quat.normalize(rng.normal(size=4))]
        for j in range(model.njoint):
            d = model.joint_axis[j]
            n = np.cross(d, rng.normal(size=3))
            theta = _near(rng, swing_edge, (0.0, min(limits.swing + 0.2, 3.0)))
            edge = twist_edges[rng.integers(len(twist_edges))]
            phi = _near(rng, edge, (max(lo, -3.0) - 0.1, min(hi, 3.0) + 0.1))
            q_rel = quat.mul(quat.exp(theta * n / np.linalg.norm(n)), quat.exp(phi * d))
            q.append(quat.normalize(quat.mul(q[model.joint_parent[j]], q_rel)))
        body_quat = np.array(q)
        body_rot = np.ascontiguousarray(quat.matrix(body_quat))
        frames = joint_frames(model, model.body_pos0, body_quat, body_rot)
        want = numpy_limit_rows(model, frames, 0.001)
        n = _fast_limit_rows(fm.flat, body_quat, body_rot)
        rw = fm.ws.rows
        assert np.array_equal(rw.key[:n], want.key)
        assert np.array_equal(rw.body_b[:n], want.body_b)
        # measured 1.8e-15, and 4.5e-13 on biases up to 160 (C/h, h = 1 ms)
        assert np.abs(rw.jac_b[:n] - want.jac_b).max(initial=0.0) < 9e-15
        assert np.abs(rw.bias[:n] - want.bias).max(initial=0.0) < 2.3e-12
        made, skipped = made + n, skipped + 3 * model.njoint - n
    assert made > 100 and skipped > 100


@pytest.mark.parametrize("seed", range(4))
def test_compiled_segment_distances_are_the_numpy_ones(seed):
    """The distances a released pointer is checked against, compiled (``any_within``):
    the same floats as solver.rows.grip.segment_distances, bones anywhere, turned anyhow,
    the point anywhere (ends of the axis included)."""
    rng = np.random.default_rng(seed)
    model = build_model(chain(6, 0.005))
    state = initial_state(model)
    n = len(model.body_pos0)
    state = replace(
        state,
        body_pos=state.body_pos + rng.normal(scale=0.3, size=(n, 3)),
        body_quat=quat.normalize(rng.normal(size=(n, 4))),
    )
    nb = len(model.bone_names)
    for point in rng.normal(scale=0.5, size=(50, 3)):
        want, _ = segment_distances(model, state, point)
        got = np.empty(nb)
        compiled_distances(state.body_pos, state.body_quat, model.body_pos0, model.bone_head0,
                           model.bone_tail0, point, got)  # fmt: skip
        np.testing.assert_array_equal(got, want)
        gap = float(np.sort(want)[1])  # the second nearest bone: one is within, exactly on it
        assert any_within(model, state, point, gap) and not any_within(
            model, state, point, want.min() / 2
        )
