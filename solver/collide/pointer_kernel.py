"""Compiled free-mode pointer contacts (solver.collide.pointer's twin)."""

from __future__ import annotations

from solver.collide.box_kernel import segment_box
from solver.collide.scene_kernel import BOX, Y_AXIS
from solver.collide.segment_kernel import segment_segment
from solver.jit import kernel
from solver.kin_kernel import (
    column,
    norm,
    sub,
    vec,
)

POINTER_KEY_OFFSET = 1 << 32


@kernel(error_model="numpy")
def collide_pointer(g, centre, rot, pc, pr, margin, cb, n):
    """Contacts of the pointer sphere (centre pc, radius pr) with every body shape."""
    shape_body, kind, radius, half, bound, shapes, mu = (
        g.shape_body,
        g.shape_kind,
        g.shape_radius,
        g.shape_half,
        g.shape_bound,
        g.touchable,
        g.touch_friction,
    )
    for rank in range(len(shapes)):
        k = shapes[rank]
        if not (norm(sub(vec(centre, k), pc)) - pr) - bound[k] <= margin:
            continue
        ctx = (-1, shape_body[k], mu[rank], 1.0, POINTER_KEY_OFFSET + rank * 16)
        ck = vec(centre, k)
        if kind[k] == BOX:
            n = segment_box(ck, rot, k, vec(half, k), pc, Y_AXIS, 0.0, pr, margin, ctx, cb, n)
        else:
            n = segment_segment(
                pc,
                Y_AXIS,
                0.0,
                pr,
                ck,
                column(rot, k, 1),
                half[k, 1],
                radius[k],
                margin,
                ctx,
                cb,
                n,
            )
    return n
