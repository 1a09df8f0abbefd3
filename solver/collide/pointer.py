"""Free mode: the pointer's contact sphere against the bones.

The pointer sphere is a static-side shape that moves: its contacts are found by
the ordinary collision code on a geometry of the pointer plus the bones' shapes,
and its velocity enters the contact rows' bias (a static side moving at u makes
the row's relative velocity w − n·u).  Keys are offset so they never collide
with the scene's own contact keys.
"""

from __future__ import annotations

import numpy as np

from solver.collide import scene as collide
from solver.model import Model
from solver.state import State

POINTER_KEY_OFFSET = 1 << 32


def pointer_geometry(model: Model, centre: np.ndarray, radius: float) -> collide.Geometry:
    """Shape 0 = the pointer sphere (static, at ``centre``), then every bone shape."""
    g = model.geometry
    bones = np.flatnonzero(g.shape_body >= 0)
    k = len(bones)
    return collide.Geometry(
        shape_body=np.concatenate(([-1], g.shape_body[bones])),
        shape_kind=np.concatenate(([1], g.shape_kind[bones])),
        shape_pos=np.vstack((centre, g.shape_pos[bones])),
        shape_quat=np.vstack(([1.0, 0.0, 0.0, 0.0], g.shape_quat[bones])),
        shape_radius=np.concatenate(([radius], g.shape_radius[bones])),
        shape_half=np.vstack((np.zeros(3), g.shape_half[bones])),
        shape_friction=np.concatenate(([0.5], g.shape_friction[bones])),
        pair_a=np.zeros(k, dtype=np.int64),
        pair_b=np.arange(1, k + 1, dtype=np.int64),
    )


def pointer_contacts(
    model: Model, state: State, centre: np.ndarray, radius: float
) -> collide.Contacts:
    """Contacts of the pointer sphere (at ``centre`` now) with the bones."""
    geom = pointer_geometry(model, centre, radius)
    con = collide.collide(geom, state.body_pos, state.body_quat, model.options.contact_margin)
    return collide.Contacts(
        body_a=con.body_a,
        body_b=con.body_b,
        point=con.point,
        normal=con.normal,
        depth=con.depth,
        friction=con.friction,
        key=con.key + POINTER_KEY_OFFSET,
    )
