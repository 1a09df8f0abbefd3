"""Compiled collision driver (solver.collide.scene's twin): the scene's shapes in world
coordinates and their contacts, pair group by pair group.
"""

from __future__ import annotations

from solver.collide.box_kernel import plane_box, segment_box
from solver.collide.boxbox_kernel import box_box
from solver.collide.segment_kernel import plane_segment, segment_segment
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    column,
    dot,
    put,
    qmatrix,
    qmul,
    qrotate,
    quat_at,
    sub,
    vec,
)

PLANE, BOX = 0, 3


GROUP_PLANE_SEGMENT, GROUP_PLANE_BOX, GROUP_SEGMENT_SEGMENT, GROUP_SEGMENT_BOX, GROUP_BOX_BOX = (
    range(5)
)


Y_AXIS = (0.0, 1.0, 0.0)


@kernel(error_model="numpy")
def world_shapes(g, body_pos, body_quat, centre, rot):
    """World centres (ns,3) and rotations (ns,3,3) of all shapes into centre, rot."""
    shape_body, shape_pos, shape_quat = g.shape_body, g.shape_pos, g.shape_quat
    for k in range(len(shape_body)):
        b = shape_body[k]
        if b >= 0:
            bq = quat_at(body_quat, b)
            put(centre, k, add(vec(body_pos, b), qrotate(bq, vec(shape_pos, k))))
            qmatrix(qmul(bq, quat_at(shape_quat, k)), rot, k)
        else:
            put(centre, k, vec(shape_pos, k))
            qmatrix(quat_at(shape_quat, k), rot, k)


@kernel(error_model="numpy", _nrt=False)
def collide_scene(g, centre, rot, margin, cb, cull, awake):
    """Contacts of the scene's candidate pairs into cb; returns the count, or −1 for a
    pair of a group it does not know (the caller falls back to numpy).  With
    ``cull``, pairs whose bounding spheres are farther apart than the margin are skipped
    before the narrow phase (which would find nothing there either); pairs with no
    awake movable body (awake (nb,) bool: solver.advance.sleep) are skipped altogether."""
    kind, radius, half, bound = g.shape_kind, g.shape_radius, g.shape_half, g.shape_bound
    pair_f, pair_s, group, sign, body_a, body_b, mu = (
        g.pair_first,
        g.pair_second,
        g.pair_group,
        g.pair_sign,
        g.pair_body_a,
        g.pair_body_b,
        g.pair_friction,
    )
    n = 0
    for p in range(len(pair_f)):
        f, s = pair_f[p], pair_s[p]
        if not ((body_a[p] >= 0 and awake[body_a[p]]) or (body_b[p] >= 0 and awake[body_b[p]])):
            continue
        if cull and not within_reach(kind[f] == PLANE, centre, rot, f, s, bound, margin):
            continue
        ctx = (body_a[p], body_b[p], mu[p], sign[p], p * 16)
        grp = group[p]
        cf, cs = vec(centre, f), vec(centre, s)
        af, as_ = column(rot, f, 1), column(rot, s, 1)  # axes: plane normal, segment axis
        if grp == GROUP_PLANE_SEGMENT:
            n = plane_segment(cf, af, cs, as_, half[s, 1], radius[s], margin, ctx, cb, n)
        elif grp == GROUP_PLANE_BOX:
            n = plane_box(cf, af, cs, rot, s, vec(half, s), margin, ctx, cb, n)
        elif grp == GROUP_SEGMENT_SEGMENT:
            seg_f, seg_s = (cf, af, half[f, 1], radius[f]), (cs, as_, half[s, 1], radius[s])
            n = segment_segment(*seg_f, *seg_s, margin, ctx, cb, n)
        elif grp == GROUP_SEGMENT_BOX:
            seg_f = (cf, af, half[f, 1], radius[f])
            n = segment_box(cs, rot, s, vec(half, s), *seg_f, margin, ctx, cb, n)
        elif grp == GROUP_BOX_BOX:
            n = box_box(centre, rot, half, f, s, margin, ctx, cb, n)
        else:
            return -1
    return n


@kernel(error_model="numpy")
def within_reach(plane, centre, rot, f, s, bound, margin):
    """Shape s's bounding sphere within the margin of shape f's (or of f's plane): for
    two spheres |offset| ≤ r_f + r_s + margin, compared squared (no square root)."""
    offset = sub(vec(centre, s), vec(centre, f))
    if plane:
        return dot(offset, column(rot, f, 1)) - bound[s] <= margin
    reach = bound[f] + bound[s] + margin
    return dot(offset, offset) <= reach * reach
