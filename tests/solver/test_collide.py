"""Collision detection against independent values.

Closed forms (plane, sphere, crossed and parallel capsules, a sphere at known
offsets from a rotated box, stacked and crossed boxes), and a brute-force second
implementation: dense samples of the segments and box surfaces, nearest
neighbours by a k-d tree, poses built with scipy's Rotation rather than
``solver.quat``.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.transform import Rotation

from solver.collide.scene import Contacts, Geometry, candidate_pairs, collide
from solver.collide.segment import segment_params

Q0 = (1.0, 0.0, 0.0, 0.0)
S2 = np.sqrt(2.0)
ROUND = 2e-14
"""Closed-form checks hold to rounding: the worst of them is 3.8e-15 (a rotated box's
normal; depths and points ≤ 1.8e-15 m at metre scale)."""
assert_close = partial(np.testing.assert_allclose, rtol=0.0)  # absolute tolerances only


def rot(axis, angle: float) -> np.ndarray:
    """Quaternion (w,x,y,z) of a rotation by angle (rad) about axis, via scipy."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * angle).as_quat(scalar_first=True)


def plane(pos=(0.0, 0.0, 0.0), q=Q0):
    return (0, -1, pos, q, 0.0, (0.0, 0.0, 0.0))


def sphere(body, pos, r, q=Q0):
    return (1, body, pos, q, r, (0.0, 0.0, 0.0))


def capsule(body, pos, q, r, half_len):
    return (2, body, pos, q, r, (0.0, half_len, 0.0))


def box(body, pos, q, half):
    return (3, body, pos, q, 0.0, half)


def make_geom(shapes, pairs, friction=None) -> Geometry:
    kind, body, pos, q, radius, half = (np.array(v) for v in zip(*shapes, strict=True))
    n = len(shapes)
    return Geometry(
        shape_body=body.astype(np.int64),
        shape_kind=kind.astype(np.int64),
        shape_pos=pos.astype(float),
        shape_quat=q.astype(float),
        shape_radius=radius.astype(float),
        shape_half=half.astype(float),
        shape_friction=np.full(n, 0.5) if friction is None else np.asarray(friction, float),
        pair_a=np.array([p[0] for p in pairs], dtype=np.int64),
        pair_b=np.array([p[1] for p in pairs], dtype=np.int64),
    )


def run(shapes, pairs, body_pos=None, body_quat=None, margin=0.01, friction=None) -> Contacts:
    """Collide static shapes and shapes of bodies at identity unless poses are given."""
    nb = max(1, max(s[1] for s in shapes) + 1)
    body_pos = np.zeros((nb, 3)) if body_pos is None else np.asarray(body_pos, float)
    body_quat = np.tile(Q0, (nb, 1)) if body_quat is None else np.asarray(body_quat, float)
    return collide(make_geom(shapes, pairs, friction), body_pos, body_quat, margin)


def test_contacts_fields_have_documented_shapes_and_dtypes():
    c = run([plane(), sphere(0, (0.0, 0.05, 0.0), 0.1)], [(0, 1)])
    assert c.key.dtype == np.int64 and c.body_a.dtype == np.int64 and c.body_b.dtype == np.int64
    assert c.point.shape == (1, 3) and c.normal.shape == (1, 3) and c.depth.shape == (1,)
    assert c.body_a.tolist() == [-1] and c.body_b.tolist() == [0]


def test_no_contacts_gives_empty_arrays_of_the_right_shapes():
    c = run(
        [plane(), sphere(0, (0.0, 5.0, 0.0), 0.1), box(1, (3.0, 5.0, 0.0), Q0, (1, 1, 1))],
        [(0, 1), (0, 2), (1, 2)],
    )
    assert c.point.shape == (0, 3) and c.normal.shape == (0, 3)
    for field in (c.body_a, c.body_b, c.depth, c.friction, c.key):
        assert field.shape == (0,)
    assert c.key.dtype == np.int64


# --- closed forms: planes -------------------------------------------------------------


@pytest.mark.parametrize("height", [0.04, 0.1, 0.105])
def test_sphere_on_tilted_plane(height):
    q = rot((1.0, 0.0, 2.0), 0.4)
    p0 = np.array([0.3, -0.2, 0.1])
    n = Rotation.from_quat(q, scalar_first=True).apply([0.0, 1.0, 0.0])
    tangent = np.cross(n, [0.0, 0.0, 1.0])
    centre = p0 + height * n + 0.7 * tangent
    c = run(
        [plane(tuple(p0), q), sphere(0, (0.0, 0.0, 0.0), 0.1)],
        [(0, 1)],
        body_pos=[centre],
        margin=0.01,
    )
    assert len(c.depth) == 1
    assert_close(c.depth, [0.1 - height], atol=ROUND)
    assert_close(c.normal[0], n, atol=ROUND)
    # Midway between the plane (height 0) and the sphere's lowest point (height h − r).
    assert_close(c.point[0], centre - n * (height + 0.1) / 2, atol=ROUND)


def test_sphere_beyond_margin_is_not_reported():
    shapes = [plane(), sphere(0, (0.0, 0.0, 0.0), 0.1)]
    near = run(shapes, [(0, 1)], body_pos=[[0.0, 0.109, 0.0]], margin=0.01)
    far = run(shapes, [(0, 1)], body_pos=[[0.0, 0.111, 0.0]], margin=0.01)
    assert_close(near.depth, [-0.009], atol=ROUND)
    assert len(far.depth) == 0


@pytest.mark.parametrize(("margin", "count"), [(0.1, 2), (0.01, 1)])
def test_tilted_capsule_on_plane_has_one_contact_per_end(margin, count):
    theta, half_len, r, height = np.radians(80.0), 0.2, 0.05, 0.08
    c = run(
        [plane(), capsule(0, (0.0, 0.0, 0.0), Q0, r, half_len)],
        [(0, 1)],
        body_pos=[[0.5, height, 0.0]],
        body_quat=[rot((0, 0, 1), theta)],
        margin=margin,
    )
    ends_y = height + np.array([-1.0, 1.0]) * half_len * np.cos(theta)
    ends_x = 0.5 + np.array([1.0, -1.0]) * half_len * np.sin(theta)
    assert len(c.depth) == count
    assert_close(c.depth, (r - ends_y)[:count], atol=ROUND)
    assert_close(c.point[:, 0], ends_x[:count], atol=ROUND)
    assert_close(c.point[:, 1], (-(r - ends_y) / 2)[:count], atol=ROUND)
    assert_close(c.normal, np.tile([0.0, 1.0, 0.0], (count, 1)), atol=ROUND)


def test_capsule_lying_on_plane_through_body_and_shape_offsets():
    # The shape sits 0.3 m along body x, turned −90° about z so its axis is body x.
    # The body turns 90° about z (body x → world y), then 90° about x (world y → z):
    # the centre lands 0.3 m along world z from the body origin and the axis along z.
    body_q = Rotation.from_rotvec([np.pi / 2, 0, 0]) * Rotation.from_rotvec([0, 0, np.pi / 2])
    shape = capsule(0, (0.3, 0.0, 0.0), rot((0, 0, 1), -np.pi / 2), 0.05, 0.2)
    c = run(
        [plane(), shape],
        [(0, 1)],
        body_pos=[[1.0, 0.04, 2.0]],
        body_quat=[body_q.as_quat(scalar_first=True)],
        margin=0.0,
    )
    assert_close(c.depth, [0.01, 0.01], atol=ROUND)
    assert_close(np.sort(c.point[:, 2]), [2.1, 2.5], atol=ROUND)
    assert_close(c.point[:, [0, 1]], [[1.0, -0.005]] * 2, atol=ROUND)


def test_box_flat_on_plane_gives_four_corner_contacts():
    q = rot((0, 1, 0), np.radians(30.0))
    half = (0.2, 0.1, 0.15)
    c = run(
        [plane((0.0, 0.5, 0.0)), box(0, (0.0, 0.0, 0.0), q, half)],
        [(0, 1)],
        body_pos=[[1.0, 0.5 + 0.1 - 0.003, -1.0]],
        margin=0.01,
    )
    assert len(c.depth) == 4
    assert_close(c.depth, 0.003, atol=ROUND)
    assert_close(c.point[:, 1], 0.5 - 0.0015, atol=ROUND)
    corners = Rotation.from_quat(q, scalar_first=True).apply(
        [[sx * half[0], 0.0, sz * half[2]] for sx in (-1, 1) for sz in (-1, 1)]
    )
    assert_close(c.point[:, [0, 2]], corners[:, [0, 2]] + [1.0, -1.0], atol=ROUND)


def test_tilted_box_on_plane_reports_only_corners_within_margin():
    alpha, half = 0.1, np.array([0.2, 0.1, 0.15])
    q = rot((0, 0, 1), alpha)  # the x = −h side dips
    low = half[0] * np.sin(alpha) + half[1] * np.cos(alpha)  # lowest corners below centre
    high = -half[0] * np.sin(alpha) + half[1] * np.cos(alpha)  # other bottom corners
    c = run(
        [plane(), box(0, (0.0, 0.0, 0.0), q, tuple(half))],
        [(0, 1)],
        body_pos=[[0.0, low - 0.002, 0.0]],
        margin=0.01,
    )
    assert len(c.depth) == 2  # the raised corners are 2·h_x·sin α ≈ 0.04 m up
    assert_close(c.depth, 0.002, atol=ROUND)
    assert (low - high) > 0.01 + 0.002


# --- closed forms: spheres and capsules --------------------------------------------------


def test_sphere_sphere():
    ca, cb = np.array([0.1, 0.2, -0.3]), np.array([0.25, 0.3, -0.2])
    d = np.linalg.norm(cb - ca)
    c = run(
        [sphere(0, (0, 0, 0), 0.1), sphere(1, (0, 0, 0), 0.12)],
        [(0, 1)],
        body_pos=[ca, cb],
        margin=0.0,
    )
    n = (cb - ca) / d
    assert len(c.depth) == 1
    assert_close(c.depth, [0.22 - d], atol=ROUND)
    assert_close(c.normal[0], n, atol=ROUND)
    assert_close(c.point[0], ca + n * (0.1 + d - 0.12) / 2, atol=ROUND)


@pytest.mark.parametrize("gap", [0.03, -0.02])
def test_crossed_capsules_at_known_distance(gap):
    ra, rb = 0.05, 0.04
    h = ra + rb + gap  # axis-to-axis distance
    qa = rot((0, 0, 1), np.pi / 2)  # along x
    qb = rot((1, 0, 0), np.pi / 2)  # along z
    c = run(
        [capsule(0, (0, 0, 0), qa, ra, 0.3), capsule(1, (0, 0, 0), qb, rb, 0.2)],
        [(0, 1)],
        body_pos=[[0.0, 0.0, 0.0], [0.05, h, -0.07]],
        margin=0.05,
    )
    assert len(c.depth) == 1
    assert_close(c.depth, [-gap], atol=ROUND)
    assert_close(c.normal[0], [0.0, 1.0, 0.0], atol=ROUND)
    assert_close(c.point[0], [0.05, (ra + h - rb) / 2, 0.0], atol=ROUND)


def test_parallel_capsule_resting_on_another_gets_overlap_end_contacts():
    q = rot((0, 0, 1), np.pi / 2)  # both along x
    r, depth = 0.05, 0.001
    c = run(
        [capsule(0, (0, 0, 0), q, r, 0.2), capsule(1, (0, 0, 0), q, r, 0.2)],
        [(0, 1)],
        body_pos=[[0.0, 0.0, 0.0], [0.1, 2 * r - depth, 0.0]],
        margin=0.01,
    )
    # b spans x ∈ [−0.1, 0.3], a spans [−0.2, 0.2]: supports at the overlap's ends.
    assert len(c.depth) == 2
    assert_close(np.sort(c.point[:, 0]), [-0.1, 0.2], atol=ROUND)
    assert_close(c.depth, depth, atol=ROUND)
    assert_close(c.normal, [[0.0, 1.0, 0.0]] * 2, atol=ROUND)


def test_skewed_capsules_keep_closest_point_between_overlap_ends():
    # b crosses a at a small angle φ in the horizontal plane, h above it: the closest
    # point is the crossing (feature 0), and the overlap's ends u = ±l·cos φ are
    # h² + u² sin² φ apart from b, still within the margin (features 1, 2).
    phi, h, half_len = 0.1, 0.099, 0.2
    qa = rot((0, 0, 1), np.pi / 2)
    qb = Rotation.from_rotvec([0, phi, 0]) * Rotation.from_rotvec([0, 0, np.pi / 2])
    c = run(
        [
            capsule(0, (0, 0, 0), qa, 0.05, half_len),
            capsule(1, (0, 0, 0), qb.as_quat(scalar_first=True), 0.05, half_len),
        ],
        [(0, 1)],
        body_pos=[[0, 0, 0], [0.0, h, 0.0]],
        margin=0.01,
    )
    u = half_len * np.cos(phi)
    end_depth = 0.1 - np.sqrt(h**2 + (u * np.sin(phi)) ** 2)
    assert c.key.tolist() == [0, 1, 2]
    assert_close(c.depth, [0.1 - h, end_depth, end_depth], atol=ROUND)
    # Equal radii: midway between a's axis point x = u and b's closest, x = u·cos² φ.
    # (a's +y axis points along world −x, so its lower overlap end is at world +x.)
    x_mid = u * (1.0 + np.cos(phi) ** 2) / 2
    assert_close(c.point[:, 0], [0.0, x_mid, -x_mid], atol=ROUND)


# --- closed forms: boxes -----------------------------------------------------------------

BOX_Q = rot((1.0, -2.0, 0.5), 0.9)
BOX_C = np.array([0.2, 0.7, -0.4])
BOX_H = np.array([0.15, 0.1, 0.25])


def box_to_world(p_local):
    return BOX_C + Rotation.from_quat(BOX_Q, scalar_first=True).apply(p_local)


@pytest.mark.parametrize(
    ("local", "surface"),
    [
        ((0.15 + 0.03, 0.04, -0.1), (0.15, 0.04, -0.1)),  # face +x
        ((0.02, -0.1 - 0.05, 0.2), (0.02, -0.1, 0.2)),  # face −y
        ((0.15 + 0.02, 0.1 + 0.03, 0.1), (0.15, 0.1, 0.1)),  # edge along z
        ((-0.15 - 0.01, 0.1 + 0.02, -0.25 - 0.03), (-0.15, 0.1, -0.25)),  # corner
        ((0.15 - 0.01, 0.02, 0.0), (0.15, 0.02, 0.0)),  # centre inside, nearest face +x
    ],
)
def test_sphere_near_rotated_box_face_edge_corner(local, surface):
    r = 0.06
    centre, surf = box_to_world(local), box_to_world(surface)
    inside = local[0] < 0.15 and np.all(np.abs(local) <= BOX_H)
    dist = -np.linalg.norm(centre - surf) if inside else np.linalg.norm(centre - surf)
    n = (centre - surf) / dist
    c = run(
        [box(-1, tuple(BOX_C), BOX_Q, tuple(BOX_H)), sphere(0, (0, 0, 0), r)],
        [(0, 1)],
        body_pos=[centre],
        margin=0.1,
    )
    assert len(c.depth) == 1
    assert_close(c.depth, [r - dist], atol=ROUND)
    assert_close(c.normal[0], n, atol=ROUND)
    assert_close(c.point[0], (surf + centre - r * n) / 2, atol=ROUND)


def test_box_capsule_order_only_flips_the_normal():
    shapes = [box(-1, tuple(BOX_C), BOX_Q, tuple(BOX_H)), capsule(0, (0, 0, 0), Q0, 0.05, 0.2)]
    pose = dict(body_pos=[box_to_world((0.2, 0.1, 0.0))], body_quat=[rot((1, 1, 0), 0.7)])
    ab, ba = run(shapes, [(0, 1)], **pose, margin=0.1), run(shapes, [(1, 0)], **pose, margin=0.1)
    assert len(ab.depth) >= 1
    assert_close(ab.normal, -ba.normal, atol=1e-14)
    assert_close(ab.depth, ba.depth, atol=1e-14)
    assert_close(ab.point, ba.point, atol=1e-14)
    assert ab.body_a.tolist() == ba.body_b.tolist()


def test_capsule_lying_on_box_face_gets_two_end_contacts():
    q = rot((0, 0, 1), np.pi / 2)  # along x, over a 0.3 × 0.5 top face
    r, sink = 0.05, 0.002
    c = run(
        [box(-1, (0.0, 0.0, 0.0), Q0, (0.3, 0.1, 0.5)), capsule(0, (0, 0, 0), q, r, 0.2)],
        [(0, 1)],
        body_pos=[[0.05, 0.1 + r - sink, 0.1]],
        margin=0.01,
    )
    assert len(c.depth) == 2
    assert_close(np.sort(c.point[:, 0]), [-0.15, 0.25], atol=ROUND)
    assert_close(c.point[:, 1], 0.1 - sink / 2, atol=ROUND)
    assert_close(c.depth, sink, atol=ROUND)
    assert_close(c.normal, [[0.0, 1.0, 0.0]] * 2, atol=ROUND)


def test_capsule_across_a_box_edge_touches_at_the_edge():
    # A cube turned 45° about z has a ridge along z at height h·√2; a capsule along x
    # passes over it at axis height y: nearest at its middle, its ends far away.
    h, r, y = 0.1, 0.05, 0.1 * S2 + 0.05 + 0.004
    qc = rot((0, 0, 1), np.pi / 2)
    c = run(
        [
            box(-1, (0, 0, 0), rot((0, 0, 1), np.pi / 4), (h, h, h)),
            capsule(0, (0, 0, 0), qc, r, 0.3),
        ],
        [(0, 1)],
        body_pos=[[0.01, y, 0.03]],
        margin=0.01,
    )
    assert c.key.tolist() == [0]
    assert_close(c.depth, [r - (y - h * S2)], atol=ROUND)
    assert_close(c.point[0], [0.0, h * S2 + (y - h * S2 - r) / 2, 0.03], atol=ROUND)


def test_capsule_piercing_a_plate_is_deepest_in_its_mid_plane():
    # Box 0.3 × 0.1 × 0.3 (half): a vertical capsule through it at (0.05, ·, 0.02) is
    # deepest where |y| is least, y = 0: φ = max(0.05 − 0.3, 0 − 0.1, 0.02 − 0.3) = −0.1.
    q = rot((1.0, 2.0, 3.0), 0.7)
    shift = np.array([0.3, -0.2, 1.0])
    to_world = Rotation.from_quat(q, scalar_first=True)
    c = run(
        [box(-1, tuple(shift), q, (0.3, 0.1, 0.3)), capsule(0, (0, 0, 0), q, 0.02, 0.5)],
        [(0, 1)],
        body_pos=[shift + to_world.apply([0.05, 0.013, 0.02])],
        margin=0.01,
    )
    assert c.key.tolist() == [0]
    assert_close(c.depth, [0.02 + 0.1], atol=ROUND)
    assert abs(c.normal[0] @ to_world.apply([0.0, 1.0, 0.0])) == pytest.approx(1.0, abs=ROUND)


def test_capsule_through_a_box_is_deepest_between_two_faces():
    # Square section 0.2 × 0.2 (half): the axis (t, t + 0.1) is deepest where it is
    # equally far inside the faces x = −0.2 and y = 0.2, at t = −0.05: φ = −0.15.
    # The ends (±0.212, 0.1 ± 0.212) are 0.012 m and more outside: beyond r.
    qc = rot((0.0, 0.0, 1.0), -np.pi / 4)  # capsule axis (1, 1, 0)/√2
    c = run(
        [box(-1, (0, 0, 0), Q0, (0.2, 0.2, 1.0)), capsule(0, (0, 0, 0), qc, 0.01, 0.3)],
        [(0, 1)],
        body_pos=[[0.0, 0.1, 0.0]],
        margin=0.0,
    )
    assert c.key.tolist() == [0]
    assert_close(c.depth, [0.01 + 0.15], atol=ROUND)
    normal = c.normal[0]  # either face: measured exact
    assert np.abs(normal - [-1, 0, 0]).max() < ROUND or np.abs(normal - [0, 1, 0]).max() < ROUND


def test_capsule_passing_a_box_corner():
    # The axis passes the corner (h, h, h) at distance g along n ∝ (1, 2, 3), in a
    # direction d ⊥ n: nearest to the corner alone, 0.02 m before its middle.  (n is
    # not (1, 1, 1)/√3, where the corner's point would also be a switch of max_i q_i.)
    h, g, r = 0.1, 0.04, 0.05
    n = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    d = np.array([1.0, 1.0, -1.0]) / np.sqrt(3.0)
    q = Rotation.align_vectors([d], [[0.0, 1.0, 0.0]])[0].as_quat(scalar_first=True)
    centre = h + g * n + 0.02 * d
    c = run(
        [box(-1, (0, 0, 0), Q0, (h, h, h)), capsule(0, (0, 0, 0), q, r, 0.3)],
        [(0, 1)],
        body_pos=[centre],
        margin=0.01,
    )
    assert c.key.tolist() == [0]
    assert_close(c.depth, [r - g], atol=ROUND)
    assert_close(c.normal[0], n, atol=ROUND)
    # Midway between the corner and the capsule's surface, g − r along n from it.
    assert_close(c.point[0], h + n * (g - r) / 2, atol=ROUND)


def test_box_on_box_face_to_face():
    h, sink = 0.1, 0.004
    c = run(
        [box(-1, (0, 0, 0), Q0, (h, h, h)), box(0, (0, 0, 0), Q0, (h, h, h))],
        [(0, 1)],
        body_pos=[[0.0, 2 * h - sink, 0.0]],
        margin=0.01,
    )
    # Identical aligned faces: the 4 shared corners, once each.
    assert len(c.depth) == 4
    assert_close(c.depth, sink, atol=ROUND)
    assert_close(c.normal, [[0.0, 1.0, 0.0]] * 4, atol=ROUND)
    assert_close(np.abs(c.point[:, [0, 2]]), h, atol=ROUND)
    assert_close(c.point[:, 1], h - sink / 2, atol=ROUND)


def test_yawed_box_on_box_gives_the_eight_octagon_vertices():
    h, gap = 0.1, 0.003
    c = run(
        [
            box(-1, (0, 0, 0), Q0, (h, h, h)),
            box(0, (0, 0, 0), rot((0, 1, 0), np.pi / 4), (h, h, h)),
        ],
        [(0, 1)],
        body_pos=[[0.0, 2 * h + gap, 0.0]],
        margin=0.01,
    )
    # Square ∩ diamond |x| + |z| ≤ h√2: vertices (±h, ±h(√2−1)) and (±h(√2−1), ±h).
    a, b = h, h * (S2 - 1)
    expect = {(sx * u, sz * v) for u, v in ((a, b), (b, a)) for sx in (-1, 1) for sz in (-1, 1)}
    got = {tuple(np.round(p, 12) + 0.0) for p in c.point[:, [0, 2]]}
    assert got == {tuple(np.round(e, 12) + 0.0) for e in expect}
    assert_close(c.depth, -gap, atol=ROUND)


def test_boxes_apart_diagonally_keep_one_conservative_contact():
    # Aligned cubes offset along (1, 1, 0): no axis of the 15 is diagonal, the best
    # (a's +x face, gap 0.05) has faces that miss each other; the deepest vertex of b
    # is kept with that gap, below the true distance 0.05·√2.
    c = run(
        [box(-1, (0, 0, 0), Q0, (0.1, 0.1, 0.1)), box(0, (0, 0, 0), Q0, (0.1, 0.1, 0.1))],
        [(0, 1)],
        body_pos=[[0.25, 0.25, 0.0]],
        margin=0.1,
    )
    assert len(c.depth) == 1
    assert_close(c.depth, [-0.05], atol=ROUND)
    assert_close(c.normal[0], [1.0, 0.0, 0.0], atol=ROUND)


def test_large_box_on_small_box_touches_at_the_small_faces_corners():
    c = run(
        [box(-1, (0, 0, 0), Q0, (0.1, 0.1, 0.1)), box(0, (0, 0, 0), Q0, (0.4, 0.05, 0.3))],
        [(0, 1)],
        body_pos=[[0.02, 0.15 - 0.001, 0.0]],
        margin=0.01,
    )
    assert len(c.depth) == 4
    assert_close(np.abs(c.point[:, [0, 2]]), 0.1, atol=ROUND)
    assert_close(c.depth, 0.001, atol=ROUND)


def test_tilted_small_box_on_a_big_one_uses_the_big_face():
    # a (a cube turned 30° about z) rests an edge on b's top face: b's face is the
    # reference even though b is second; the normal points from a to b, down.
    h, sink = 0.05, 0.003
    reach = h * (np.cos(np.pi / 6) + np.sin(np.pi / 6))  # lowest edge below a's centre
    c = run(
        [
            box(0, (0, 0, 0), rot((0, 0, 1), np.pi / 6), (h, h, h)),
            box(1, (0, 0, 0), Q0, (0.5, 0.1, 0.5)),
        ],
        [(0, 1)],
        body_pos=[[0.1, 0.1 + reach - sink, 0.05], [0.0, 0.0, 0.0]],
        margin=0.005,
    )
    assert len(c.depth) == 2
    assert_close(c.depth, sink, atol=ROUND)
    assert_close(c.normal, [[0.0, -1.0, 0.0]] * 2, atol=ROUND)
    assert_close(np.sort(c.point[:, 2]), [0.0, 0.1], atol=ROUND)


@pytest.mark.parametrize("gap", [0.004, -0.003])
def test_crossed_box_edges(gap):
    # Cube a turned 45° about z has a ridge along z; cube b turned 45° about x has
    # its lowest edge along x: they cross, axis y, at distance gap.
    h = 0.1
    c = run(
        [
            box(-1, (0, 0, 0), rot((0, 0, 1), np.pi / 4), (h, h, h)),
            box(0, (0, 0, 0), rot((1, 0, 0), np.pi / 4), (h, h, h)),
        ],
        [(0, 1)],
        body_pos=[[0.0, 2 * h * S2 + gap, 0.0]],
        margin=0.01,
    )
    assert len(c.depth) == 1
    assert_close(c.depth, [-gap], atol=ROUND)
    assert_close(c.normal[0], [0.0, 1.0, 0.0], atol=ROUND)
    assert_close(c.point[0], [0.0, h * S2 + gap / 2, 0.0], atol=ROUND)


# --- brute force: dense samples and a k-d tree -------------------------------------------

KINDS = {"sphere": 1, "capsule": 2, "box": 3}


def random_shape(rng, kind: str, body: int):
    """A shape of ``kind`` on ``body`` with a random local pose and size."""
    pos = tuple(rng.uniform(-0.1, 0.1, 3))
    q = Rotation.random(random_state=rng).as_quat(scalar_first=True)
    if kind == "box":
        return box(body, pos, q, tuple(rng.uniform(0.04, 0.2, 3)))
    r = rng.uniform(0.03, 0.1)
    return (
        capsule(body, pos, q, r, rng.uniform(0.05, 0.2))
        if kind == "capsule"
        else (sphere(body, pos, r, q))
    )


def box_surface(half, n: int = 61) -> np.ndarray:
    """Grid points (6n², 3) on the faces of a box of half extents ``half`` (box frame)."""
    u, v = (g.ravel() for g in np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n)))
    faces = []
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        for s in (-1.0, 1.0):
            p = np.empty((n * n, 3))
            p[:, k], p[:, i], p[:, j] = s * half[k], u * half[i], v * half[j]
            faces.append(p)
    return np.concatenate(faces)


def core(shape, body_pos, body_rot: Rotation, n: int = 61):
    """World sample points of a shape's core (segment or box surface) and its radius."""
    kind, _, pos, q, r, half = shape
    rot = body_rot * Rotation.from_quat(q, scalar_first=True)
    centre = body_pos + body_rot.apply(pos)
    if kind == 3:
        return centre + rot.apply(box_surface(np.asarray(half), n)), 0.0
    u = np.linspace(-half[1], half[1], 66 * n - 25 if half[1] > 0 else 1)
    return centre + np.outer(u, rot.apply([0.0, 1.0, 0.0])), r


def brute_distance(shapes, body_pos, body_rots, n: int = 61) -> float:
    """Distance between the surfaces of two separated shapes, from samples."""
    (pa, ra), (pb, rb) = (
        core(s, p, q, n) for s, p, q in zip(shapes, body_pos, body_rots, strict=True)
    )
    small, large = sorted((pa, pb), key=len)
    return float(cKDTree(large).query(small)[0].min()) - ra - rb


def random_separated_pair(rng, kind_a: str, kind_b: str, n: int = 61):
    """Shapes a (body 0) and b (body 1) with random poses, 0.02–0.3 m apart (n: samples)."""
    while True:
        shapes = [random_shape(rng, kind_a, 0), random_shape(rng, kind_b, 1)]
        rots = [Rotation.random(random_state=rng) for _ in range(2)]
        direction = rng.normal(size=3)
        pos = [rng.uniform(-1, 1, 3)]
        pos.append(pos[0] + direction / np.linalg.norm(direction) * rng.uniform(0.1, 0.7))
        # Coarse samples first: they only overestimate the distance.
        if brute_distance(shapes, pos, rots, n=9) < 0.02:
            continue
        dist = brute_distance(shapes, pos, rots, n)
        if 0.02 <= dist <= 0.3:
            return shapes, pos, rots, dist


def collide_poses(shapes, pos, rots, margin: float) -> Contacts:
    quats = [r.as_quat(scalar_first=True) for r in rots]
    return run(shapes, [(0, 1)], body_pos=pos, body_quat=quats, margin=margin)


ROUND_KINDS = [
    ("sphere", "sphere"),
    ("sphere", "capsule"),
    ("capsule", "sphere"),
    ("capsule", "capsule"),
    ("capsule", "box"),
    ("box", "sphere"),
    ("sphere", "box"),
    ("box", "capsule"),
]


@pytest.mark.parametrize(("kind_a", "kind_b"), ROUND_KINDS)
def test_distance_and_normal_match_brute_force(kind_a, kind_b):
    rng = np.random.default_rng(sum(map(ord, kind_a + kind_b)))
    # The samples' own error sets these: measured 3.4e-5 and 8.8e-6 m with a box (its
    # surface grid, 61²), 6.3e-9 and 1.5e-9 m without (segments of 4001 points).
    tol, tol_eps = (1.7e-4, 4.4e-5) if "box" in (kind_a, kind_b) else (3e-8, 7.5e-9)
    eps = 0.05
    for _ in range(12):
        shapes, pos, rots, dist = random_separated_pair(rng, kind_a, kind_b)
        c = collide_poses(shapes, pos, rots, margin=0.5)
        deepest = int(np.argmax(c.depth))
        assert -c.depth[deepest] == pytest.approx(dist, abs=tol)
        assert np.all(c.depth <= -dist + tol)  # no contact claims more than the truth
        # Distance grows at rate 1 along the normal of a convex pair: exactly eps.
        moved = [pos[0], pos[1] + eps * c.normal[deepest]]
        assert brute_distance(shapes, moved, rots) - dist == pytest.approx(eps, abs=tol_eps)


def test_penetrating_segments_and_boxes_match_brute_force():
    # Inside a box φ = −(distance to the surface): sampled surface + an inside test.
    rng = np.random.default_rng(5)
    overlapping = 0
    for kind in ("sphere", "capsule") * 8:
        half = rng.uniform(0.05, 0.2, 3)
        shapes = [box(-1, (0, 0, 0), Q0, tuple(half)), random_shape(rng, kind, 0)]
        rots = [Rotation.identity(), Rotation.random(random_state=rng)]
        # The shape's centre (offset in its body) lands inside the box's inner half.
        pos = [np.zeros(3), rng.uniform(-0.5, 0.5, 3) * half - rots[1].apply(shapes[1][2])]
        seg, r = core(shapes[1], pos[1], rots[1])
        dist = cKDTree(box_surface(half, 81)).query(seg)[0]
        phi = np.where(np.all(np.abs(seg) <= half, axis=1), -dist, dist)
        c = collide_poses(shapes, pos[1:], rots[1:], margin=1.0)
        assert c.depth.max() == pytest.approx(r - phi.min(), abs=1e-4)  # measured 2.0e-5 m
        overlapping += phi.min() < 0.0
    assert overlapping == 16


def test_segment_closest_params_match_a_dense_grid():
    rng = np.random.default_rng(2)
    p1, e1, p2, e2 = rng.normal(size=(4, 40, 3))
    e2[:10] = 0.7 * e1[:10]  # parallel
    e2[10:15] = 0.0  # a point
    e1[15:18] = 0.0
    s, t = segment_params(p1, e1, p2, e2)
    assert np.all((s >= 0) & (s <= 1) & (t >= 0) & (t <= 1))
    found = np.linalg.norm(p1 + s[:, None] * e1 - p2 - t[:, None] * e2, axis=1)
    g = np.linspace(0.0, 1.0, 801)
    a = p1[:, None, :] + g[None, :, None] * e1[:, None, :]
    b = p2[:, None, :] + g[None, :, None] * e2[:, None, :]
    brute = np.array([cKDTree(bi).query(ai)[0].min() for ai, bi in zip(a, b, strict=True)])
    assert_close(found, brute, atol=5e-5)  # the grid's error: measured 1.1e-5
    assert np.all(found <= brute + ROUND)


def on_box_surface(x, centre, rot: Rotation, half) -> np.ndarray:
    """|max_i(|p_i| − h_i)| (m): zero for points on the box surface."""
    p = np.abs(rot.inv().apply(x - centre)) - np.asarray(half)
    return np.abs(p.max(axis=-1))


def test_tilted_box_above_a_box_face_matches_brute_force():
    rng = np.random.default_rng(7)
    for _ in range(10):
        ha = rng.uniform(0.25, 0.4, 3)
        hb = rng.uniform(0.04, 0.1, 3)
        shapes = [box(-1, (0, 0, 0), Q0, tuple(ha)), box(0, (0, 0, 0), Q0, tuple(hb))]
        rots = [Rotation.identity(), Rotation.from_rotvec(rng.uniform(-0.4, 0.4, 3))]
        low = np.min(box_surface(hb, 3) @ rots[1].as_matrix().T, axis=0)[1]
        pos = [np.zeros(3), np.array([*rng.uniform(-0.1, 0.1, 1), 0.0, *rng.uniform(-0.1, 0.1, 1)])]
        pos[1][1] = ha[1] - low + rng.uniform(0.02, 0.05)
        dist = brute_distance(shapes, pos, rots)
        c = run(
            shapes,
            [(0, 1)],
            body_pos=[pos[1]],
            body_quat=[rots[1].as_quat(scalar_first=True)],
            margin=0.5,
        )
        assert len(c.depth) == 4  # b's bottom face lies wholly over a's top face
        # the brute force's grid on a's face (spacing ≤ 13 mm): measured 7.3e-4 m
        assert -c.depth.max() == pytest.approx(dist, abs=1e-3)
        assert_close(c.normal, [[0.0, 1.0, 0.0]] * len(c.depth), atol=ROUND)
        # Each point lies midway between b's surface and a's top face, over that face.
        on_b = c.point - c.normal * (c.depth / 2)[:, None]
        assert np.all(on_box_surface(on_b, pos[1], rots[1], hb) < ROUND)
        assert_close(on_b[:, 1] - ha[1], -c.depth, atol=ROUND)
        assert np.all(np.abs(on_b[:, [0, 2]]) <= ha[[0, 2]] + ROUND)


def test_box_manifold_spans_the_overlap_of_the_faces():
    # A yawed and offset box on a wide one: the contacts' hull is the overlap of the two
    # footprints, whose area a Monte-Carlo estimate gives independently.
    rng = np.random.default_rng(3)
    for _ in range(5):
        hb = np.array([rng.uniform(0.1, 0.2), 0.05, rng.uniform(0.1, 0.2)])
        yaw = Rotation.from_rotvec([0.0, rng.uniform(0, np.pi), 0.0])
        offset = np.array([rng.uniform(-0.2, 0.2), 0.2 + 0.05 - 0.002, rng.uniform(-0.2, 0.2)])
        c = run(
            [box(-1, (0, 0, 0), Q0, (0.2, 0.2, 0.2)), box(0, (0, 0, 0), Q0, tuple(hb))],
            [(0, 1)],
            body_pos=[offset],
            body_quat=[yaw.as_quat(scalar_first=True)],
            margin=0.01,
        )
        xz = rng.uniform(-0.2, 0.2, (200_000, 2))
        local = yaw.inv().apply(np.column_stack((xz[:, 0], np.zeros(len(xz)), xz[:, 1])) - offset)
        inside_b = (np.abs(local[:, 0]) <= hb[0]) & (np.abs(local[:, 2]) <= hb[2])
        area = inside_b.mean() * 0.4 * 0.4
        assert 3 <= len(c.depth) <= 8
        # 5 standard errors of the 200,000-sample estimate (≤ 3.9e-3): measured 8.0e-3
        assert ConvexHull(c.point[:, [0, 2]]).volume == pytest.approx(area, rel=0.02)
        assert_close(c.depth, 0.002, atol=ROUND)


def test_random_separated_boxes_never_report_overlap_and_never_miss():
    rng = np.random.default_rng(11)
    for _ in range(15):
        shapes, pos, rots, _ = random_separated_pair(rng, "box", "box", n=31)
        c = collide_poses(shapes, pos, rots, margin=0.35)
        assert len(c.depth) >= 1  # within the margin: a speculative contact exists
        assert np.all(c.depth < 0.0)
        (pa, _), (pb, _) = (core(s, p, q, 21) for s, p, q in zip(shapes, pos, rots, strict=True))
        # A contact's gap is at least the shapes' separation along its normal (the
        # corners are among the samples, so the sampled extremes are exact).
        support_gap = (pb @ c.normal.T).min(axis=0) - (pa @ c.normal.T).max(axis=0)
        assert np.all(-c.depth >= support_gap - ROUND)  # measured: equal at worst


# --- candidate pairs ---------------------------------------------------------------------


def rig_shapes():
    """A small rig: root 0 ← 1 ← {2, 3}, ground, table and lamp (static), 8 shapes.

    Bone capsules along y overlap their neighbours at the joints; shape 6 (body 2)
    and shape 7 (body 3) are siblings overlapping at rest; shape 3 (body 0) sits
    0.01 m into the ground.
    """
    return [
        plane(),  # 0 ground
        box(-1, (2.0, 0.5, 0.0), Q0, (0.5, 0.05, 0.5)),  # 1 table
        sphere(-1, (2.0, 0.6, 0.0), 0.05),  # 2 lamp, on the table (static–static)
        sphere(0, (0.0, -0.49, 0.0), 0.5),  # 3 body 0, into the ground
        capsule(0, (0.0, 0.3, 0.0), Q0, 0.05, 0.2),  # 4 body 0 again
        capsule(1, (0.0, 0.0, 0.0), Q0, 0.05, 0.2),  # 5 body 1, overlaps 4 (parent)
        capsule(2, (0.0, 0.0, 0.0), Q0, 0.05, 0.2),  # 6 body 2
        capsule(3, (0.0, 0.0, 0.0), Q0, 0.05, 0.2),  # 7 body 3, overlaps 6 (sibling)
    ]


def rig_pairs(exclude_rest_overlap: bool):
    kind, body, pos, q, radius, half = (np.array(v) for v in zip(*rig_shapes(), strict=True))
    body_pos = np.array([[0.0, 0.0, 0.0], [0.0, 0.6, 0.0], [0.04, 0.9, 0.0], [-0.04, 0.9, 0.0]])
    return candidate_pairs(
        body,
        kind,
        pos.astype(float),
        q.astype(float),
        radius.astype(float),
        half.astype(float),
        np.array([-1, 0, 1, 1]),
        body_pos,
        np.tile(Q0, (4, 1)),
        exclude_rest_overlap=exclude_rest_overlap,
    )


def test_candidate_pairs_exclusions_and_order():
    a, b = rig_pairs(exclude_rest_overlap=False)
    statics = [(s, d) for s in (0, 1, 2) for d in range(3, 8)]
    # 3–4 same body; 3/4–5 and 5–6/7 parent–child; 0–1, 0–2, 1–2 static–static.
    bodies = [(3, 6), (3, 7), (4, 6), (4, 7), (6, 7)]
    assert list(zip(a.tolist(), b.tolist(), strict=True)) == sorted(statics + bodies)
    assert a.dtype == np.int64 and b.dtype == np.int64


def test_candidate_pairs_drop_body_pairs_overlapping_at_rest_but_keep_the_ground():
    full = set(zip(*(v.tolist() for v in rig_pairs(False)), strict=True))
    kept = set(zip(*(v.tolist() for v in rig_pairs(True)), strict=True))
    assert full - kept == {(6, 7)}
    assert (0, 3) in kept  # sunk into the ground, still collides with it


def test_candidate_pairs_put_the_static_shape_first():
    shapes = [sphere(0, (0, 0, 0), 0.1), box(-1, (1.0, 0.0, 0.0), Q0, (0.1, 0.1, 0.1)), plane()]
    kind, body, pos, q, radius, half = (np.array(v) for v in zip(*shapes, strict=True))
    a, b = candidate_pairs(
        body,
        kind,
        pos.astype(float),
        q.astype(float),
        radius.astype(float),
        half.astype(float),
        np.array([-1]),
        np.zeros((1, 3)),
        np.array([Q0]),
    )
    assert a.tolist() == [1, 2] and b.tolist() == [0, 0]


# --- keys, order, friction ---------------------------------------------------------------

SCENE = [
    plane(),
    capsule(0, (0, 0, 0), rot((0, 0, 1), np.pi / 2), 0.05, 0.2),
    box(1, (0, 0, 0), rot((0, 1, 0), 0.3), (0.15, 0.1, 0.15)),
    box(2, (0, 0, 0), rot((0, 1, 0), 0.8), (0.1, 0.05, 0.1)),
    capsule(3, (0, 0, 0), rot((0, 0, 1), np.pi / 2 + 0.02), 0.05, 0.2),
    sphere(4, (0, 0, 0), 0.08),
]
SCENE_PAIRS = [(0, 1), (0, 2), (0, 3), (1, 4), (2, 3), (2, 5), (0, 5), (1, 2)]
# Sphere 5 against box 2's +x face (0.229 m out along the face normal), off the ground.
SCENE_POS = np.array(
    [
        [0.0, 0.048, 0.0],
        [1.0, 0.099, 0.0],
        [1.05, 0.249, 0.03],
        [0.02, 0.146, 0.01],
        [1.0 + 0.229 * np.cos(0.3), 0.099, -0.229 * np.sin(0.3)],
    ]
)


def scene(shift=0.0, turn=0.0, friction=None) -> Contacts:
    quats = [rot((0.3, 1.0, 0.2), turn)] * len(SCENE_POS)
    return run(
        SCENE,
        SCENE_PAIRS,
        body_pos=SCENE_POS + shift,
        body_quat=quats,
        margin=0.01,
        friction=friction,
    )


def test_keys_are_stable_under_a_small_motion():
    before, after = scene(), scene(shift=np.array([2e-4, -1e-4, 1e-4]), turn=2e-4)
    assert len(before.key) >= 12  # lying capsules, resting boxes, stacked capsules
    np.testing.assert_array_equal(before.key, after.key)
    assert np.abs(after.point - before.point).max() < 1e-3  # measured 2.4e-4 m


def test_contacts_are_sorted_by_unique_key_and_reproducible():
    c = scene()
    assert np.all(np.diff(c.key) > 0)
    assert set((c.key // 16).tolist()) <= set(range(len(SCENE_PAIRS)))
    again = scene()
    for name in ("body_a", "body_b", "point", "normal", "depth", "friction", "key"):
        np.testing.assert_array_equal(getattr(c, name), getattr(again, name))


def test_every_scene_pair_touching_is_reported_with_its_bodies():
    c = scene()
    touching = sorted(set((c.key // 16).tolist()))
    # Not touching: (0, 3) the top box and the ground, (0, 5) the sphere and the
    # ground, (1, 2) a capsule and a box 1 m apart.
    assert touching == [0, 1, 3, 4, 5]
    pair_bodies = [(SCENE[a][1], SCENE[b][1]) for a, b in SCENE_PAIRS]
    for key, ba, bb in zip(c.key, c.body_a, c.body_b, strict=True):
        assert (ba, bb) == pair_bodies[key // 16]


def test_friction_is_the_geometric_mean():
    mu = np.array([0.9, 0.4, 0.1, 0.6, 0.25, 0.5])
    c = scene(friction=mu)
    for key, f in zip(c.key, c.friction, strict=True):
        a, b = SCENE_PAIRS[key // 16]
        assert f == pytest.approx(np.sqrt(mu[a] * mu[b]), rel=1e-15)


@pytest.mark.parametrize("k", [2, 3, 15])
def test_box_pairs_in_one_batch_match_one_at_a_time(k):
    # Regression: the separating-axis test broadcast (k,3) against (k,15,3), which
    # raised for most k and was silently wrong for k = 15.
    from solver.collide.boxbox import separating_axis

    rng = np.random.default_rng(k)
    ca, cb = rng.normal(size=(k, 3)), rng.normal(size=(k, 3))
    ra = np.stack([Rotation.random(random_state=i).as_matrix() for i in range(k)])
    rb = np.stack([Rotation.random(random_state=100 + i).as_matrix() for i in range(k)])
    ha, hb = rng.uniform(0.1, 0.5, (k, 3)), rng.uniform(0.1, 0.5, (k, 3))
    batch = separating_axis(ca, ra, ha, cb, rb, hb)
    for i in range(k):
        one = separating_axis(
            ca[i : i + 1], ra[i : i + 1], ha[i : i + 1], cb[i : i + 1], rb[i : i + 1], hb[i : i + 1]
        )
        for got, want in zip(batch, one, strict=True):
            assert np.array_equal(got[i], want[0])  # measured: bit for bit
