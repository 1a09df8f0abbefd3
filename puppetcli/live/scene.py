"""What the page needs to draw a rig: bodies, shapes, joints, ground, colours, camera.

Shapes are the rig's visual shapes, one per bone (``solver.model``'s collision shapes,
also for bones that do not collide) and one per prop, in their body's frame (static
props: the world), so that the page places them with the streamed body poses.  Colours
are the OpenCV renders' (``puppetcli.render.scene``), so the page looks like the pictures.
"""

from __future__ import annotations

import numpy as np

from puppetcli.render import picture as render_module
from puppetcli.render import scene as look
from solver import quat
from solver.massprops import shape_frame
from solver.model import Model
from solver.spec import RigSpec

__all__ = ["scene_bounds", "scene_description"]

KINDS = {"sphere": "sphere", "capsule": "capsule", "box": "box"}


def _hex(bgr: tuple[int, int, int]) -> str:
    b, g, r = bgr
    return f"#{r:02x}{g:02x}{b:02x}"


def _shape(body: int, kind: str, pos, q, radius: float, half, role: str, bone: str | None):
    return {
        "body": body, "kind": kind, "pos": [float(x) for x in pos],
        "quat": [float(x) for x in q], "radius": float(radius),
        "half": [float(x) for x in half], "role": role, "bone": bone,
    }  # fmt: skip


def _bone_shapes(model: Model, spec: RigSpec) -> list[dict]:
    shapes = []
    for i, b in enumerate(spec.bones):
        length = float(np.linalg.norm(b.tail - b.head))
        kind = b.shape.kind
        half = (0.0, 0.5 * length, 0.0) if kind == "capsule" else tuple(b.shape.half_extents)
        centre = 0.5 * (b.head + b.tail) if kind != "sphere" or b.com is None else b.com
        q_rest = quat.conj(model.body_quat0[i])
        pos = quat.rotate(q_rest, centre - model.body_pos0[i])
        q = quat.mul(q_rest, shape_frame(b.head, b.tail))
        shapes.append(_shape(i, KINDS[kind], pos, q, b.shape.radius, half, "bone", b.name))
    return shapes


def _prop_shapes(spec: RigSpec, nbone: int) -> list[dict]:
    shapes, body = [], nbone
    for p in spec.props:
        q = quat.normalize(np.asarray(p.rotation, dtype=float))
        kind, half = KINDS[p.shape.kind], tuple(p.shape.half_extents)
        if p.dynamic:
            shapes.append(_shape(body, kind, np.zeros(3), quat.IDENTITY, p.shape.radius, half,
                                 "prop", None))  # fmt: skip
            body += 1
        else:
            shapes.append(_shape(-1, kind, p.position, q, p.shape.radius, half, "prop", None))
    return shapes


def scene_bounds(model: Model, spec: RigSpec) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) corners (3,) of the rig at rest: bone heads and tails, props."""
    points = [b.head for b in spec.bones] + [b.tail for b in spec.bones]
    points += [np.asarray(p.position, float) for p in spec.props]
    pts = np.array(points, dtype=float)
    return pts.min(axis=0), pts.max(axis=0)


def scene_description(model: Model, spec: RigSpec) -> dict:
    """The static part of the page's ``hello``: bones, shapes, joints, ground, colours, camera."""
    nbone = len(model.bone_names)
    lo, hi = scene_bounds(model, spec)
    joints = [
        {"bone": model.bone_names[i], "body": i,
         "pos": [float(x) for x in quat.rotate(quat.conj(model.body_quat0[i]),
                                               model.bone_head0[i] - model.body_pos0[i])]}
        for i in range(nbone) if model.bone_parent[i] >= 0
    ]  # fmt: skip
    return {
        "rig": model.name,
        "bodies": int(model.nbody),
        "bones": [
            {"name": n, "body": i, "parent": int(model.bone_parent[i])}
            for i, n in enumerate(model.bone_names)
        ],
        "shapes": _bone_shapes(model, spec) + _prop_shapes(spec, nbone),
        "ground": None if spec.ground is None else {"height": float(spec.ground.height)},
        "joints": joints,
        "camera": {
            "target": [float(x) for x in 0.5 * (lo + hi)],
            "distance": float(2.2 * max(np.linalg.norm(hi - lo), 0.5)),
        },
        "colors": _colors(),
    }


def _colors() -> dict[str, str]:
    """The OpenCV renders' colours as CSS hex."""
    return {
        "background": _hex(render_module.BACKGROUND), "bone": _hex(look.BONE_COLOR),
        "joint": _hex(look.JOINT_COLOR), "prop": _hex(look.PROP_COLOR),
        "pointer": _hex(look.POINTER_COLOR), "coupling": _hex(look.COUPLING_COLOR),
        "ground": _hex(look.GROUND_COLOR), "grid": _hex(look.GRID_COLOR),
    }  # fmt: skip
