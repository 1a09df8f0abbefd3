"""Stress scenes built in code: a rig, a start state, an input and the bounds it must keep.

A ``Scene`` is simulated for ``duration`` seconds by ``puppetcli.bench.stress``.  Its
input (``Drive``) is pushes (a force and torque on a body over a time window)
and optionally a grip: a pointer following a piecewise-linear path, coupled to a
bone by ``solver.rows.grip.make_coupling`` at t = 0.  After the last step in which the
input is ``active`` nothing does work on the scene (the pushes are over, the
pointer is still), so its total energy

    E = kinetic + gravity potential + Σ ½ K_f q_sf² (joint springs) + U_grip

can only fall; U_grip per coupling row is the potential of a spring K whose force
saturates at the row's limit F (Huber: ½ K e² for |e| ≤ F/K, F |e| − F²/(2K)
beyond).  Nothing here touches files; the named cases are in puppetcli.bench.stress.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from solver import quat
from solver.massprops import shape_volume
from solver.model import Model, build_model
from solver.observe import kinetic_energy, potential_energy
from solver.rows.grip import Coupling, Pointer, make_coupling
from solver.spec import (
    BoneSpec,
    GroundSpec,
    LimitSpec,
    RheologySpec,
    RigSpec,
    ShapeSpec,
    SolverSpec,
)
from solver.state import State, StepInput, initial_state

GRIP_GAINS = dict(  # the script's default grip (puppetcli.script.actions)
    stiffness=2000.0, damping=40.0, rot_stiffness=50.0, rot_damping=2.0,
    force_limit=300.0, torque_limit=30.0,
)  # fmt: skip


@dataclass(frozen=True)
class Push:
    """force (3,) N and torque (3,) N·m, world frame, on ``body`` for start ≤ t < stop (s)."""

    body: int
    force: np.ndarray
    torque: np.ndarray
    start: float
    stop: float


@dataclass(frozen=True)
class Path:
    """Pointer positions (k,3) m at times (k,) s, linear in between, still after the last."""

    times: np.ndarray
    points: np.ndarray

    def at(self, t: float) -> np.ndarray:
        return np.array([np.interp(t, self.times, self.points[:, k]) for k in range(3)])


@dataclass(frozen=True)
class Drive:
    """A scene's input: pushes, and a grip (a coupling and the path of its pointer)."""

    pushes: tuple[Push, ...] = ()
    path: Path | None = None
    coupling: Coupling | None = None

    def active(self, t: float, h: float) -> bool:
        """True when the input may do work over the step [t, t + h]: a push is on or
        the pointer moves."""
        if any(p.start <= t < p.stop for p in self.pushes):
            return True
        return self.path is not None and bool(np.any(self.path.at(t) != self.path.at(t + h)))

    def pointer(self, t: float, h: float) -> Pointer:
        """The pointer over the step [t, t + h]: pose at its end, mean velocity over it."""
        p0, p1 = self.path.at(t), self.path.at(t + h)
        return Pointer(p1, quat.IDENTITY.copy(), (p1 - p0) / h, np.zeros(3))

    def input(self, model: Model, state: State) -> StepInput:
        """The StepInput for the step starting at ``state``."""
        force = np.zeros((model.nbody, 3))
        torque = np.zeros((model.nbody, 3))
        for p in self.pushes:
            if p.start <= state.time < p.stop:
                force[p.body] += p.force
                torque[p.body] += p.torque
        if self.path is None:
            return StepInput(force, torque)
        return StepInput(force, torque, self.pointer(state.time, model.options.h), self.coupling)


@dataclass(frozen=True)
class Scene:
    """A stress scene and its bounds.

    duration (s) simulated.  Energy: E may rise over its value E₀ after the input's
    last active step by at most energy_rel·(fall energy + E₀ − gravity part of
    E₀) + energy_extra (J), the fall energy being movable mass·|g|·extent of the
    rest pose (``fall_energy``).  penetration_bound (m): deepest contact allowed
    from penetration_from (s) on; None = slop + 2·h·(fastest surface point speed
    seen), i.e. one step of missed approach.  check_momentum: no external load,
    so linear and angular momentum must be kept.  ``why`` justifies the bounds.
    """

    name: str
    model: Model
    start: State
    duration: float
    why: str
    drive: Drive = field(default_factory=Drive)
    energy_rel: float = 0.02
    energy_extra: float = 0.0
    penetration_bound: float | None = 0.002
    penetration_from: float = 0.0
    check_momentum: bool = False


def fall_energy(model: Model) -> float:
    """Movable mass × |g| × the rest pose's largest extent (J): what a fall can free."""
    ends = np.vstack((model.bone_head0, model.bone_tail0, model.body_pos0))
    mass = float(model.body_mass[model.body_inv_mass > 0.0].sum())
    return mass * float(np.linalg.norm(model.options.gravity)) * float(np.ptp(ends, axis=0).max())


def energy_bound(scene: Scene, state: State) -> float:
    """The allowed energy rise (J) over E at ``state`` (the passive start)."""
    free = total_energy(scene, state) - potential_energy(scene.model, state)
    return scene.energy_rel * (fall_energy(scene.model) + free) + scene.energy_extra


def huber(e: np.ndarray, k: float, limit: float) -> float:
    """Potential (J) of springs k with force saturating at ``limit``, deflections e."""
    a = np.abs(e)
    knee = limit / k
    return float(np.sum(np.where(a <= knee, 0.5 * k * a * a, limit * a - 0.5 * limit * knee)))


def grip_energy(drive: Drive, state: State) -> float:
    """U_grip (J) of the drive's coupling at ``state`` (0 without one)."""
    c = drive.coupling
    if c is None:
        return 0.0
    ptr = drive.path.at(state.time)
    point = state.body_pos[c.body] + quat.rotate(state.body_quat[c.body], c.anchor)
    energy = huber(point - (ptr + c.offset), c.stiffness, c.force_limit)
    if not c.position_only:
        e_rot = quat.log(quat.mul(state.body_quat[c.body], quat.conj(c.rest)))
        energy += huber(e_rot, c.rot_stiffness, c.torque_limit)
    return energy


def total_energy(scene: Scene, state: State) -> float:
    """E (J): kinetic, gravity, joint springs ½ K_f q_sf² and the grip's spring."""
    m = scene.model
    kf = np.where(m.joint_rheology[:, None], m.joint_kf, 0.0)
    springs = 0.5 * float(np.sum(kf * state.joint_q_sf**2))
    grip = grip_energy(scene.drive, state)
    return kinetic_energy(m, state) + potential_energy(m, state) + springs + grip


# ---- rigs ------------------------------------------------------------------------------


def rheology(kf: float, df: float, dd: float, yield_torque: float = np.inf) -> RheologySpec:
    return RheologySpec(np.full(3, kf), np.full(3, df), np.full(3, dd), yield_torque)


CHAIN_RHEOLOGY = rheology(0.5, 0.02, 2.0)  # rigs/chain.yaml


def chain_rig(
    n: int,
    h: float,
    *,
    link: float = 0.1,
    masses: list[float] | None = None,
    radius: float = 0.015,
    rheo: RheologySpec | None = CHAIN_RHEOLOGY,
    ground: float | None = None,
) -> RigSpec:
    """A horizontal chain of n capsule links along +x from a fixed stand at (0, 1.5, 0).

    Defaults are the links of rigs/chain.yaml (10 cm, 0.2 kg, r 1.5 cm).
    """
    bones = []
    for i in range(n):
        head = np.array([i * link, 1.5, 0.0])
        bones.append(
            BoneSpec(
                name=f"link{i}", parent=f"link{i - 1}" if i else None, head=head,
                tail=head + [link, 0.0, 0.0], shape=ShapeSpec("capsule", radius=radius),
                mass=0.2 if masses is None else masses[i], rheology=rheo,
                collide=ground is not None,
            )
        )  # fmt: skip
    return RigSpec(
        name=f"chain{n}",
        bones=tuple(bones),
        root_mode="fixed",
        ground=None if ground is None else GroundSpec(height=ground, friction=0.8),
        solver=SolverSpec(h=h),
    )


def free_bodies(
    shapes: list[tuple[ShapeSpec, np.ndarray, np.ndarray]],
    h: float,
    gravity: bool,
    ground: bool,
) -> Model:
    """Unjoined free bodies, each a root (shape, head, tail) of density 1000 kg/m³."""
    bones = tuple(
        BoneSpec(
            name=f"body{i}", parent=None, head=head, tail=tail, shape=shape,
            mass=1000.0 * shape_volume(shape, float(np.linalg.norm(tail - head))),
        )
        for i, (shape, head, tail) in enumerate(shapes)
    )  # fmt: skip
    spec = RigSpec(
        name="free",
        bones=bones,
        root_mode="free",
        gravity=np.array([0.0, -9.81, 0.0]) if gravity else np.zeros(3),
        ground=GroundSpec() if ground else None,
        solver=SolverSpec(h=h),
    )
    return build_model(spec)


def moved(model: Model, offsets: np.ndarray) -> State:
    """The rest state with every body shifted by offsets (nb,3) m."""
    s = initial_state(model)
    return replace(s, body_pos=s.body_pos + offsets)


def tip_grip(model: Model, state: State, path: Path, **gains) -> Drive:
    """A grip on the last body's centre, its pointer on ``path`` (starting at that centre)."""
    b = model.nbody - 1
    start = Pointer(path.at(0.0), quat.IDENTITY.copy(), np.zeros(3), np.zeros(3))
    coupling = make_coupling(state, start, b, state.body_pos[b], **{**GRIP_GAINS, **gains})
    return Drive(path=path, coupling=coupling)


# ---- random rigs -----------------------------------------------------------------------
#
# A random rig has one length scale s, log-uniform over 0.01–10 m; its bones are
# s·(0.46–2.15) long (a factor 4.6 apart at most) with radii 5–15 % of their length,
# so neighbours differ in mass by at most ~900× (the mass-ratio case's 1:1000).
# Rheology is drawn in the joint's natural units, τ = (mass it carries)·g·(length)
# and T = sqrt(length/g), over several decades around them: from a joint that
# barely holds its load to one 1000× stiffer.  Density 1000 kg/m³.


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(10.0 ** rng.uniform(np.log10(lo), np.log10(hi)))


def _random_shape(rng: np.random.Generator, length: float) -> ShapeSpec:
    r = length * rng.uniform(0.05, 0.15)
    kind = str(rng.choice(["capsule", "capsule", "sphere", "box"]))
    if kind == "box":
        return ShapeSpec("box", half_extents=(r, 0.5 * length, r * rng.uniform(0.5, 1.0)))
    if kind == "sphere":
        r = length * rng.uniform(0.1, 0.25)
    return ShapeSpec(kind, radius=r)


def _random_rheology(
    rng: np.random.Generator, carried: float, length: float
) -> RheologySpec | None:
    """None (a free ball joint), or coefficients around the joint's natural units."""
    if rng.random() < 0.15:
        return None
    tau = carried * 9.81 * length
    t = np.sqrt(length / 9.81)
    kf = tau * _log_uniform(rng, 0.1, 1e3)
    df = kf * t * _log_uniform(rng, 1e-2, 1.0)
    dd = np.inf if rng.random() < 0.2 else tau * t * _log_uniform(rng, 0.1, 1e3)
    yield_torque = np.inf if rng.random() < 0.3 else tau * _log_uniform(rng, 0.3, 10.0)
    return rheology(kf, df, dd, yield_torque)


def _random_limits(rng: np.random.Generator) -> LimitSpec:
    if rng.random() < 0.5:
        return LimitSpec()
    swing = np.radians(rng.uniform(20.0, 170.0)) if rng.random() < 0.7 else np.inf
    twist = np.radians(rng.uniform(10.0, 170.0)) if rng.random() < 0.7 else np.inf
    return LimitSpec(swing, (-twist, twist))


def _random_tree(rng: np.random.Generator, n: int, scale: float) -> list[dict]:
    """Geometry of a random tree: each bone hangs from an earlier one, at a point along it."""
    bones: list[dict] = []
    for i in range(n):
        length = scale * _log_uniform(rng, 10 ** (-1 / 3), 10 ** (1 / 3))
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        parent, head = None, np.array([0.0, 2.0 * scale, 0.0])
        if i:
            parent = int(rng.integers(0, i))
            p = bones[parent]
            head = p["head"] + rng.uniform(0.3, 1.0) * (p["tail"] - p["head"])
        shape = _random_shape(rng, length)
        mass = 1000.0 * shape_volume(shape, length)
        bones.append(dict(parent=parent, head=head, tail=head + length * axis, shape=shape,
                          mass=mass, length=length))  # fmt: skip
    carried = [b["mass"] for b in bones]
    for i in reversed(range(1, n)):
        carried[bones[i]["parent"]] += carried[i]
    for b, c in zip(bones, carried, strict=True):
        b["carried"] = c
    return bones


def _random_bones(rng: np.random.Generator, tree: list[dict], root_mode: str) -> tuple:
    out = []
    for i, b in enumerate(tree):
        jointed = b["parent"] is not None or root_mode == "ball"
        out.append(
            BoneSpec(
                name=f"b{i}", parent=None if b["parent"] is None else f"b{b['parent']}",
                head=b["head"], tail=b["tail"], shape=b["shape"], mass=b["mass"],
                rheology=_random_rheology(rng, b["carried"], b["length"]) if jointed else None,
                limits=_random_limits(rng) if jointed else LimitSpec(),
            )
        )  # fmt: skip
    return tuple(out)


def _lowest_point(bones: tuple[BoneSpec, ...]) -> float:
    """Lowest y (m) a bone shape reaches, from its end points and a bounding radius."""
    reach = [max(b.shape.radius, float(np.linalg.norm(b.shape.half_extents))) for b in bones]
    return min(min(b.head[1], b.tail[1]) - r for b, r in zip(bones, reach, strict=True))


def _random_pushes(rng: np.random.Generator, model: Model) -> tuple[Push, ...]:
    """1–3 pushes, 0.1–20 times the pushed bone's weight (torque: × its length), ≤ 0.15 s."""
    pushes = []
    for _ in range(int(rng.integers(1, 4))):
        b = int(rng.integers(0, len(model.bone_names)))
        weight = model.body_mass[b] * 9.81
        length = float(np.linalg.norm(model.bone_tail0[b] - model.bone_head0[b]))
        start = rng.uniform(0.0, 0.1)
        pushes.append(
            Push(
                b, _unit(rng) * weight * _log_uniform(rng, 0.1, 20.0),
                _unit(rng) * weight * length * _log_uniform(rng, 0.01, 1.0),
                start, start + rng.uniform(0.01, 0.05),
            )
        )  # fmt: skip
    return tuple(pushes)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _random_grip(rng: np.random.Generator, model: Model, start: State, scale: float) -> Drive:
    """A grip on the last bone, its pointer moved 0.1–1 scale away over 0.05–0.15 s."""
    b = model.nbody - 1
    total = float(model.body_mass.sum()) * 9.81
    k = total / scale * _log_uniform(rng, 1.0, 300.0)
    p0 = start.body_pos[b]
    path = Path(
        np.array([0.0, rng.uniform(0.05, 0.15)]),
        np.stack((p0, p0 + _unit(rng) * scale * rng.uniform(0.1, 1.0))),
    )
    limit = total * _log_uniform(rng, 1.0, 10.0)
    damping = 2.0 * np.sqrt(k * model.body_mass[b])  # critical for the gripped bone alone
    return tip_grip(
        model, start, path, stiffness=k, damping=damping, rot_stiffness=0.1 * k * scale**2,
        rot_damping=0.1 * damping * scale**2, force_limit=limit, torque_limit=limit * scale,
    )  # fmt: skip


RANDOM_WHY = (
    "energy may rise by 20 % of the fall energy after the input stops: a blow-up detector "
    "(blow-ups the monitor misses exceed it 2–450×, seeds 0–99), loose enough for the "
    "Baumgarte pushes of contacts and limits the input drove in; penetration: one step of "
    "missed approach at the fastest surface speed seen"
)


def random_scene(seed: int, duration: float = 0.25) -> Scene:
    """A random rig (2–12 bones, scale 0.01–10 m) with random pushes and, sometimes, a grip."""
    rng = np.random.default_rng(seed)
    scale = _log_uniform(rng, 0.01, 10.0)
    root_mode = str(rng.choice(["fixed", "free", "ball"]))
    tree = _random_tree(rng, int(rng.integers(2, 13)), scale)
    bones = _random_bones(rng, tree, root_mode)
    ground = None
    if rng.random() < 0.5:
        ground = GroundSpec(height=_lowest_point(bones) - scale * rng.uniform(0.0, 0.01))
    spec = RigSpec(
        name=f"random{seed}", bones=bones, root_mode=root_mode,
        gravity=np.array([0.0, -9.81, 0.0]) if rng.random() < 0.8 else np.zeros(3),
        ground=ground, solver=SolverSpec(h=float(rng.choice([0.002, 0.005, 0.01]))),
    )  # fmt: skip
    model = build_model(spec)
    start = initial_state(model)
    drive = Drive(pushes=_random_pushes(rng, model))
    if rng.random() < 0.3:
        grip = _random_grip(rng, model, start, scale)
        drive = replace(drive, path=grip.path, coupling=grip.coupling)
    return Scene(
        name=f"random-{seed}", model=model, start=start, duration=duration,
        why=RANDOM_WHY, drive=drive, energy_rel=0.2, penetration_bound=None,
    )  # fmt: skip
