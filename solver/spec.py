"""Plain-data description of a rig, as the rig file states it.

A ``RigSpec`` is what ``puppetcli.rig.load`` produces after validation and what
``solver.model.build_model`` consumes.  Everything here is in SI units (metres,
kilograms, seconds, radians) in the world frame of the rest pose: right-handed,
Y up.  Nothing here is derived; derived quantities (inertia tensors, row counts)
belong to ``solver.model.Model``.

Conventions
-----------
* A bone's *body frame* is world-aligned in the rest pose, with its origin at the
  bone's centre of mass.  So a bone's world rotation relative to its rest
  orientation is simply its body quaternion.
* Every non-root bone hangs from its parent by one ball joint at the bone's head.
  A root with ``root_mode == "ball"`` hangs from the fixed stand (the world) by a
  ball joint at its head; ``"fixed"`` welds it to the stand; ``"free"`` leaves
  it unconstrained.
* Quaternions are (w, x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SHAPE_KINDS = ("capsule", "sphere", "box")
ROOT_MODES = ("fixed", "free", "ball")


@dataclass(frozen=True)
class ShapeSpec:
    """Collision and mass shape of a bone or prop.

    kind: "capsule" | "sphere" | "box".
    radius: capsule/sphere radius (m); unused for boxes.
    half_extents: box half sizes (m) along the shape's local x, y, z; for a bone
        box, local y runs from head to tail.  Unused otherwise.
    """

    kind: str = "capsule"
    radius: float = 0.0
    half_extents: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RheologySpec:
    """Three-element rheology of one ball joint, per joint axis (parent frame).

    kf: Voigt spring K_f (N·m/rad), shape (3,).
    df: Voigt damper D_f (N·m·s/rad), shape (3,).
    dd: series (plastic) damper D_d (N·m·s/rad), shape (3,); ``inf`` means the
        joint never flows (a pure Voigt spring-damper about its rest pose).
    yield_torque: torque norm (N·m) below which the joint does not flow; ``inf``
        means no yield (the three-element model always flows).
    """

    kf: np.ndarray
    df: np.ndarray
    dd: np.ndarray
    yield_torque: float = float("inf")

    @property
    def active(self) -> bool:
        """True when the joint has any rheology row at all (K_f or D_f non-zero)."""
        return bool(np.any(self.kf > 0.0) or np.any(self.df > 0.0))


@dataclass(frozen=True)
class LimitSpec:
    """Swing-twist limits of a ball joint, measured from the rest pose.

    swing: half-angle of the swing cone about the bone axis (rad); ``inf`` = none.
    twist: (lower, upper) twist about the bone axis (rad); ``(-inf, inf)`` = none.
    """

    swing: float = float("inf")
    twist: tuple[float, float] = (float("-inf"), float("inf"))


@dataclass(frozen=True)
class BoneSpec:
    """One bone.

    head, tail: rest-pose world positions (m), shape (3,).
    parent: parent bone name, or None for the root.
    shape: its shape; a capsule/box spans head to tail, a sphere is centred on
        the midpoint (or on ``com`` when given).
    mass: kg.
    com: rest-pose world centre of mass (m), shape (3,); defaults to the shape centre.
    inertia: 3x3 inertia tensor about the centre of mass in world-aligned rest
        axes (kg·m²); None = computed from the shape and mass.
    rheology, limits: of the joint at the head (ignored for a fixed/free root).
    collide: whether the bone takes part in collisions.
    """

    name: str
    parent: str | None
    head: np.ndarray
    tail: np.ndarray
    shape: ShapeSpec
    mass: float
    com: np.ndarray | None = None
    inertia: np.ndarray | None = None
    rheology: RheologySpec | None = None
    limits: LimitSpec = field(default_factory=LimitSpec)
    collide: bool = True


@dataclass(frozen=True)
class PropSpec:
    """A prop to collide with.

    position: world position of the shape centre (m); rotation: (w,x,y,z).
    dynamic: a dynamic prop is a free rigid body of ``mass``; a static one never moves.
    friction: Coulomb coefficient used against it (combined with the other side's
        by the geometric mean).
    """

    name: str
    shape: ShapeSpec
    position: np.ndarray
    rotation: np.ndarray
    dynamic: bool = False
    mass: float = 1.0
    friction: float = 0.5


@dataclass(frozen=True)
class GroundSpec:
    """Infinite ground plane y = height with Coulomb friction."""

    height: float = 0.0
    friction: float = 0.8


CONTACT_SLOP = 0.0005
"""m: how far a contact may sink before its row pushes back (quiet resting contacts; a
little error of its own where contacts drift: measurements set 0, docs/integrators.md)."""


@dataclass(frozen=True)
class SolverSpec:
    """Solver options as a rig or script states them.

    h: step (s).  method: "auto" | "pgs" | "hybrid" | "direct" | "reference"
    (auto: direct when every row is two-sided, else hybrid).
    iterations: PGS sweeps.  warm_start: reuse the previous step's impulses.
    warm_start_factor: scale on the reused impulses (1.0 = all of it; the
        reference implementation used 0.7).
    integrator: "euler" (the paper's step) or "bdf2" (second order: solver.advance.bdf2).
    contact_slop: m a contact may sink before it pushes back (CONTACT_SLOP).
    """

    h: float = 0.005
    method: str = "auto"
    iterations: int = 15
    warm_start: bool = True
    warm_start_factor: float = 1.0
    integrator: str = "euler"
    contact_slop: float = CONTACT_SLOP


@dataclass(frozen=True)
class RigSpec:
    """A whole validated rig.  Bones are ordered so that parents precede children."""

    name: str
    bones: tuple[BoneSpec, ...]
    root_mode: str = "fixed"
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, -9.81, 0.0]))
    ground: GroundSpec | None = None
    props: tuple[PropSpec, ...] = ()
    bone_friction: float = 0.6
    solver: SolverSpec = field(default_factory=SolverSpec)
    # The glTF file (path) and skin the rig was made from: exporters animate that character.
    # Not simulated.
    character: tuple[str, int] | None = None
