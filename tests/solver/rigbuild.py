"""Rig specs built in code for solver tests (no YAML involved)."""

from __future__ import annotations

import numpy as np

from solver.spec import (
    BoneSpec,
    GroundSpec,
    LimitSpec,
    RheologySpec,
    RigSpec,
    ShapeSpec,
    SolverSpec,
)


def rheology(kf: float, df: float, dd: float, yield_torque: float = np.inf) -> RheologySpec:
    return RheologySpec(np.full(3, kf), np.full(3, df), np.full(3, dd), yield_torque)


def one_bone(h: float, kf=1.0, df=10.0, dd=100.0, inertia=0.1, method="auto") -> RigSpec:
    """The paper's experiment, rotational form: a body centred on its joint anchor."""
    head = np.zeros(3)
    bone = BoneSpec(
        name="bone",
        parent=None,
        head=head,
        tail=np.array([0.0, 0.1, 0.0]),
        shape=ShapeSpec("sphere", radius=0.05),
        mass=1.0,
        com=head,
        inertia=np.eye(3) * inertia,
        rheology=rheology(kf, df, dd),
    )
    return RigSpec(
        name="one_bone",
        bones=(bone,),
        root_mode="ball",
        gravity=np.zeros(3),
        solver=SolverSpec(h=h, method=method),
    )


def chain(
    n: int,
    h: float,
    *,
    rheo: RheologySpec | None = None,
    root_mode: str = "fixed",
    link: float = 0.1,
    gravity=(0.0, -9.81, 0.0),
    method: str = "auto",
    limits: LimitSpec | None = None,
    masses=None,
    lengths=None,
    radius: float = 0.02,
    shape: str = "capsule",
    collide: bool = False,
    ground: float | None = None,
) -> RigSpec:
    """A horizontal chain of n capsule links along +x from a stand at the origin."""
    bones = []
    lengths = [link] * n if lengths is None else lengths
    x = np.concatenate(([0.0], np.cumsum(lengths)))
    for i in range(n):
        head = np.array([x[i], 1.0, 0.0])
        bones.append(
            BoneSpec(
                name=f"link{i}",
                parent=f"link{i - 1}" if i else None,
                head=head,
                tail=head + [lengths[i], 0.0, 0.0],
                shape=ShapeSpec(shape, radius=radius),
                mass=1.0 if masses is None else masses[i],
                rheology=rheo,
                limits=limits or LimitSpec(),
                collide=collide,
            )
        )
    return RigSpec(
        name="chain",
        bones=tuple(bones),
        root_mode=root_mode,
        gravity=np.array(gravity, dtype=float),
        ground=None if ground is None else GroundSpec(height=ground, friction=0.7),
        solver=SolverSpec(h=h, method=method),
    )
