"""Stress cases (issue 6): extreme rigs and inputs, each simulated for a fixed time.

Each case is a ``puppetcli.bench.stress_scenes.Scene``: a rig built in code (or an example
rig at an extreme setting), a start state, an input, and the bounds it must keep.
``run_scene`` steps it and measures, over every State the solver returns:

* non-finite values anywhere in the State (pose, velocities, rheology state,
  warm-start forces);
* energy growth: max of E(t) − E(t₀) over t ≥ t₀, t₀ = when the input stops doing
  work (E and its bound: puppetcli.bench.stress_scenes);
* the worst joint separation (solver.observe.joint_gaps), bounded by
  Options.max_joint_gap;
* the worst penetration (deepest solver.collide.scene.collide depth) from the scene's
  ``penetration_from`` on;
* for scenes without external loads, the drift of linear and angular momentum.

A case is *stable* when no SimulationError is raised, nothing is non-finite and
every figure is within its bound.  Any other exception is a crash, reported as such.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from puppetcli.bench import stress_scenes as sc
from puppetcli.bench.scenes import RIGS
from puppetcli.rig.load import load_rig
from solver.collide.scene import collide
from solver.engine import Engine
from solver.errors import SimulationError
from solver.model import build_model
from solver.observe import joint_gaps, momentum
from solver.spec import ShapeSpec
from solver.state import State, initial_state

MOMENTUM_TOL = 1e-9
"""Relative: without loads the step conserves momentum to round-off (tests/solver)."""


@dataclass
class CaseResult:
    """What one case did.  Lengths in m, energies in J, wall time in s."""

    name: str
    steps: int = 0
    wall: float = 0.0
    energy_growth: float = 0.0
    energy_bound: float = np.inf
    joint_gap: float = 0.0
    gap_limit: float = np.inf
    penetration: float = 0.0
    penetration_bound: float = np.inf
    momentum_drift: float = 0.0
    nonfinite: bool = False
    error: str = ""
    crash: str = ""
    problems: list[str] = field(default_factory=list)

    @property
    def stable(self) -> bool:
        return not self.problems


def state_finite(state: State) -> bool:
    """True when every number in the State is finite."""
    arrays = (
        state.body_pos, state.body_quat, state.body_vel, state.body_omega, state.joint_q_sf,
        state.joint_anchor, state.joint_torque_avg, state.joint_torque, state.warm_lam,
    )  # fmt: skip
    return bool(np.isfinite(state.time)) and all(np.isfinite(a).all() for a in arrays)


def penetration(scene: sc.Scene, state: State) -> float:
    """Deepest overlap (m) of the scene's candidate shape pairs (0 when none)."""
    if not scene.model.has_collision:
        return 0.0
    con = collide(scene.model.geometry, state.body_pos, state.body_quat, 0.0)
    return float(con.depth.max(initial=0.0))


def body_reach(scene: sc.Scene) -> np.ndarray:
    """(nb,) farthest a body's shapes reach from its centre of mass (m)."""
    g = scene.model.geometry
    reach = np.zeros(scene.model.nbody)
    own = g.shape_body >= 0
    size = np.where(g.shape_kind == 3, np.linalg.norm(g.shape_half, axis=1), g.shape_radius)
    extent = np.linalg.norm(g.shape_pos, axis=1) + g.shape_half[:, 1] + size
    np.maximum.at(reach, g.shape_body[own], extent[own])
    return reach


class _Meter:
    """Running figures of one case."""

    def __init__(self, scene: sc.Scene) -> None:
        self.scene, self.res = scene, CaseResult(scene.name)
        self.e_ref: float | None = None
        self.reach = body_reach(scene)
        self.speed = 0.0  # fastest surface point seen (m/s)
        self.p0, self.l0 = momentum(scene.model, scene.start)
        self.see(scene.start)

    def see(self, state: State, driven: bool = False) -> None:
        """Take in a State; ``driven``: the input did work in the step that produced it."""
        s, r = self.scene, self.res
        if not state_finite(state):
            r.nonfinite = True
            return
        if driven:  # energy growth counts from the end of the input on
            self.e_ref, r.energy_growth = None, 0.0
        elif self.e_ref is None:
            self.e_ref = sc.total_energy(s, state)
            r.energy_bound = sc.energy_bound(s, state)
        else:
            r.energy_growth = max(r.energy_growth, sc.total_energy(s, state) - self.e_ref)
        if s.model.njoint:
            gaps = joint_gaps(s.model, state.body_pos, state.body_quat)
            r.joint_gap = max(r.joint_gap, float(gaps.max()))
        spin = np.linalg.norm(state.body_omega, axis=1) * self.reach
        self.speed = max(self.speed, float(np.max(np.linalg.norm(state.body_vel, axis=1) + spin)))
        if state.time >= s.penetration_from - 0.5 * s.model.options.h:
            r.penetration = max(r.penetration, penetration(s, state))
        if s.check_momentum:
            p, ang = momentum(s.model, state)
            r.momentum_drift = max(r.momentum_drift, _rel(p, self.p0), _rel(ang, self.l0))

    def finish(self) -> CaseResult:
        s, r = self.scene, self.res
        opt = s.model.options
        r.gap_limit = opt.max_joint_gap
        r.penetration_bound = s.penetration_bound
        if r.penetration_bound is None:
            r.penetration_bound = opt.contact_slop + 2.0 * opt.h * self.speed
        r.problems = _problems(r, s)
        return r


def _rel(x: np.ndarray, x0: np.ndarray) -> float:
    scale = float(np.linalg.norm(x0))
    return float(np.linalg.norm(x - x0)) / scale if scale > 0.0 else float(np.linalg.norm(x))


def run_scene(scene: sc.Scene, method: str | None = None) -> CaseResult:
    """Simulate a scene for its duration and measure it (see the module docstring);
    ``method``: a solver method instead of the scene's own."""
    if method is not None:
        scene = replace(scene, model=scene.model.with_options(method=method))
    model = scene.model
    meter = _Meter(scene)
    state, engine = scene.start, Engine(model)
    start = time.perf_counter()
    h = model.options.h
    try:
        for _ in range(round(scene.duration / h)):
            driven = scene.drive.active(state.time, h)
            state, _ = engine.step(state, scene.drive.input(model, state))
            meter.res.steps += 1
            meter.see(state, driven)
    except SimulationError as exc:
        meter.res.error = str(exc)
    except Exception as exc:  # a crash is a finding: report it, keep the table going
        meter.res.crash = f"{type(exc).__name__}: {exc}"
    meter.res.wall = time.perf_counter() - start
    return meter.finish()


def _problems(r: CaseResult, scene: sc.Scene) -> list[str]:
    """Why the case is not stable (empty when it is)."""
    out = [f"crash: {r.crash}"] if r.crash else []
    out += [r.error] if r.error else []
    if r.nonfinite:
        out.append("non-finite value in a State")
    if r.energy_growth > r.energy_bound:
        out.append(f"energy grew {r.energy_growth:.3g} J > {r.energy_bound:.3g} J")
    if r.joint_gap > r.gap_limit:
        out.append(f"joint gap {r.joint_gap:.3g} m > {r.gap_limit:.3g} m")
    if r.penetration > r.penetration_bound:
        out.append(f"penetration {r.penetration:.3g} m > {r.penetration_bound:.3g} m")
    if scene.check_momentum and r.momentum_drift > MOMENTUM_TOL:
        out.append(f"momentum drift {r.momentum_drift:.3g} > {MOMENTUM_TOL:g}")
    return out


def run_random(seed: int, method: str | None = None) -> CaseResult:
    """One random rig (puppetcli.bench.stress_scenes.random_scene); building it may crash too."""
    try:
        scene = sc.random_scene(seed)
    except Exception as exc:
        res = CaseResult(f"random-{seed}", crash=f"{type(exc).__name__}: {exc} (building)")
        res.problems = [f"crash: {res.crash}"]
        return res
    return run_scene(scene, method)


def summarize(name: str, results: list[CaseResult]) -> CaseResult:
    """One row for many runs: each figure from the run worst against its bound."""

    def worst(value: str, bound: str) -> CaseResult:
        return max(results, key=lambda r: getattr(r, value) / max(getattr(r, bound), 1e-300))

    out = CaseResult(name, steps=sum(r.steps for r in results), wall=sum(r.wall for r in results))
    for value, bound in (("energy_growth", "energy_bound"), ("penetration", "penetration_bound")):
        w = worst(value, bound)
        setattr(out, value, getattr(w, value))
        setattr(out, bound, getattr(w, bound))
    out.joint_gap = max(r.joint_gap for r in results)
    out.gap_limit = min(r.gap_limit for r in results)
    out.nonfinite = any(r.nonfinite for r in results)
    bad = [r for r in results if not r.stable]
    if bad:
        seeds = ", ".join(r.name.rsplit("-", 1)[-1] for r in bad)
        out.problems = [f"{len(bad)} of {len(results)} unstable (seeds {seeds})"]
    return out


# ---- the cases ---------------------------------------------------------------------------

CHAIN_WHY = (
    "passive: energy may not rise by more than 2 % of the fall energy (the README's bound "
    "for semi-implicit Euler on an undamped pendulum chain, 0.86 % measured); rheology "
    "only dissipates"
)
CONTACT_WHY = (
    "; penetration ≤ 2 mm, the README's bound for resting contact (slop 0.5 mm, "
    "speculative contacts within 1 cm)"
)


def _alternating() -> list[float]:
    return [0.01 if i % 2 == 0 else 10.0 for i in range(10)]


def mass_ratio() -> sc.Scene:
    """Ten 10 cm links alternating 0.01 and 10 kg, no rheology, falling from horizontal."""
    model = build_model(sc.chain_rig(10, 0.005, masses=_alternating(), rheo=None))
    return sc.Scene("mass-ratio", model, initial_state(model), 1.0, CHAIN_WHY)


def mass_ratio_ground() -> sc.Scene:
    """The same chain landing on the ground 0.7 m below the stand (PGS, contacts)."""
    rig = sc.chain_rig(10, 0.005, masses=_alternating(), rheo=None, ground=0.8)
    model = build_model(rig)
    return sc.Scene("mass-ratio-ground", model, initial_state(model), 1.0, CHAIN_WHY + CONTACT_WHY)


def chain_100() -> sc.Scene:
    """100 links of rigs/chain.yaml (10 cm, 0.2 kg, plastic joints) falling from horizontal."""
    model = build_model(sc.chain_rig(100, 0.005))
    return sc.Scene("chain-100", model, initial_state(model), 0.2, CHAIN_WHY)


def chain_100_rope() -> sc.Scene:
    """100 bare ball-jointed links of 2 cm and 20 g (a 2 m rope) falling from horizontal."""
    rig = sc.chain_rig(100, 0.005, link=0.02, radius=0.005, masses=[0.02] * 100, rheo=None)
    model = build_model(rig)
    return sc.Scene("chain-100-rope", model, initial_state(model), 0.3, CHAIN_WHY)


def h50_doll() -> sc.Scene:
    """rigs/doll.yaml at h = 50 ms: scripts/arm_push.yaml's push (60 N up, 0.5 s), then 1.5 s."""
    model = build_model(load_rig(RIGS / "doll.yaml")).with_options(h=0.05)
    b = model.bone_names.index("forearm_l")
    arm = model.bone_head0[b] + [0.25, 0.0, 0.0] - model.body_pos0[b]
    force = np.array([0.0, 60.0, 0.0])
    drive = sc.Drive(pushes=(sc.Push(b, force, np.cross(arm, force), 0.0, 0.5),))
    return sc.Scene("h50-doll", model, initial_state(model), 2.0, CHAIN_WHY + CONTACT_WHY, drive)


def h50_chain() -> sc.Scene:
    """rigs/chain.yaml at h = 50 ms, falling from horizontal for 3 s."""
    model = build_model(load_rig(RIGS / "chain.yaml")).with_options(h=0.05)
    return sc.Scene("h50-chain", model, initial_state(model), 3.0, CHAIN_WHY + CONTACT_WHY)


def stiff_kf() -> sc.Scene:
    """K_f = 1e6 N·m/rad on every joint of a 10-link chain, yield 0.5 N·m, a 4 N tip push."""
    model = build_model(sc.chain_rig(10, 0.005, rheo=sc.rheology(1e6, 0.02, 2.0, 0.5)))
    push = sc.Push(9, np.array([0.0, 4.0, 0.0]), np.zeros(3), 0.2, 0.4)
    return sc.Scene("kf-1e6", model, initial_state(model), 1.0, CHAIN_WHY, sc.Drive((push,)))


def series_damper(dd: float, name: str) -> sc.Scene:
    """rigs/chain.yaml's joints with D_d = dd, falling from horizontal."""
    model = build_model(sc.chain_rig(10, 0.005, rheo=sc.rheology(0.5, 0.02, dd)))
    return sc.Scene(name, model, initial_state(model), 1.0, CHAIN_WHY)


def grip_stiff() -> sc.Scene:
    """A 1e5 N/m grip on a chain tip, its pointer circling (r = 0.2 m, 0.5 s), then still."""
    model = build_model(sc.chain_rig(10, 0.005))
    start = initial_state(model)
    t = np.linspace(0.0, 0.5, 51)
    turn = 2.0 * np.pi * t / 0.5
    circle = 0.2 * np.stack((np.cos(turn) - 1.0, np.sin(turn), np.zeros_like(t)), axis=1)
    drive = sc.tip_grip(model, start, sc.Path(t, start.body_pos[-1] + circle), stiffness=1e5)
    why = CHAIN_WHY + ", the grip's spring (saturating at its force limit) counted in E"
    return sc.Scene("grip-1e5", model, start, 0.8, why, drive)


def grip_yank() -> sc.Scene:
    """The script's default grip on a chain tip, its pointer jumping 1 m up in one step."""
    model = build_model(sc.chain_rig(10, 0.005))
    start = initial_state(model)
    p0 = start.body_pos[-1]
    path = sc.Path(np.array([0.0, 0.1, 0.105]), np.stack((p0, p0, p0 + [0.0, 1.0, 0.0])))
    why = CHAIN_WHY + ", the grip's spring (saturating at its force limit) counted in E"
    return sc.Scene("grip-yank", model, start, 0.6, why, sc.tip_grip(model, start, path))


def overlap_capsules() -> sc.Scene:
    """Two free capsules (r 5 cm, 30 cm, no gravity) starting r/2 deep in each other."""
    r, depth = 0.05, 0.025
    cap = ShapeSpec("capsule", radius=r)
    shapes = [(cap, np.array([-0.15, y, 0.0]), np.array([0.15, y, 0.0])) for y in (0.0, 1.0)]
    model = sc.free_bodies(shapes, 0.005, gravity=False, ground=False)
    start = sc.moved(model, np.array([[0.0, 0.0, 0.0], [0.0, 2.0 * r - depth - 1.0, 0.0]]))
    mu = 0.5 * model.body_mass[0]  # reduced mass of two equal bodies
    kick = _baumgarte_kick(model, depth, mu)
    why = (
        f"the overlap is pushed out at erp·(depth − slop)/h, so they part at that speed: E may "
        f"rise by ½μv² = {kick:.3g} J (+2 %); from 0.1 s penetration ≤ 2 mm"
    )
    return sc.Scene(
        "overlap-capsules", model, start, 0.5, why, energy_extra=1.02 * kick, penetration_from=0.1
    )


def ground_deep() -> sc.Scene:
    """A free capsule (r 5 cm, 30 cm) lying 3 cm deep in the ground, under gravity."""
    r, depth = 0.05, 0.03
    cap = ShapeSpec("capsule", radius=r)
    y = r - depth
    model = sc.free_bodies([(cap, np.array([-0.15, y, 0.0]), np.array([0.15, y, 0.0]))], 0.005,
                           gravity=True, ground=True)  # fmt: skip
    m = float(model.body_mass[0])
    lift = depth - model.options.contact_slop
    extra = _baumgarte_kick(model, depth, m) + m * 9.81 * lift
    why = (
        f"pushed out at erp·(depth − slop)/h and lifted by depth − slop: E may rise by "
        f"½mv² + mg·lift = {extra:.3g} J (+2 % of the fall energy); from 0.5 s (landed "
        f"again) penetration ≤ 2 mm"
    )
    return sc.Scene(
        "ground-deep", model, initial_state(model), 1.0, why, energy_extra=extra,
        penetration_from=0.5,
    )  # fmt: skip


def _baumgarte_kick(model, depth: float, mass: float) -> float:
    """½ m v² with v = erp·(depth − slop)/h: the speed the contact rows ask for (J)."""
    opt = model.options
    v = opt.contact_erp * (depth - opt.contact_slop) / opt.h
    return 0.5 * mass * v * v


def spin() -> sc.Scene:
    """A free box 0.6×0.4×0.2 m, no gravity, spinning at 20 rad/s about its middle axis."""
    box = ShapeSpec("box", half_extents=(0.3, 0.2, 0.1))
    model = sc.free_bodies([(box, np.array([0.0, -0.2, 0.0]), np.array([0.0, 0.2, 0.0]))], 0.005,
                           gravity=False, ground=False)  # fmt: skip
    start = replace(initial_state(model), body_omega=np.array([[1e-3, 20.0, 0.0]]))
    why = (
        "torque-free: momentum kept to 1e-9 and E (exactly conserved by the true motion, "
        "which flips every ~1 s) within 2 %"
    )
    return sc.Scene("spin", model, start, 3.0, why, check_momentum=True)


CASES = {
    "mass-ratio": mass_ratio,
    "mass-ratio-ground": mass_ratio_ground,
    "chain-100": chain_100,
    "chain-100-rope": chain_100_rope,
    "h50-doll": h50_doll,
    "h50-chain": h50_chain,
    "kf-1e6": stiff_kf,
    "dd-tiny": lambda: series_damper(1e-6, "dd-tiny"),
    "dd-huge": lambda: series_damper(1e9, "dd-huge"),
    "grip-1e5": grip_stiff,
    "grip-yank": grip_yank,
    "overlap-capsules": overlap_capsules,
    "ground-deep": ground_deep,
    "spin": spin,
}
RANDOM = "random"
RANDOM_SEEDS = 100


def run_cases(
    names: list[str],
    seeds: list[int],
    tick: Callable[[], None] | None = None,
    method: str | None = None,
) -> list[CaseResult]:
    """One result per named case, then the random rigs of ``seeds`` as one summary row
    (or as their own row for a single seed).  ``tick`` is called after every run;
    ``method``: a solver method for every scene instead of its own."""
    tick = tick or (lambda: None)
    out = []
    for name in names:
        if name != RANDOM:
            out.append(run_scene(CASES[name](), method))
            tick()
    if RANDOM in names and seeds:
        runs = []
        for seed in seeds:
            runs.append(run_random(seed, method))
            tick()
        out.append(runs[0] if len(runs) == 1 else summarize(f"random×{len(runs)}", runs))
    return out
