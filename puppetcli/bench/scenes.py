"""The work-precision study's scenes: models, inputs, sample times and references.

Each scene is run as one sequence of precomputed step inputs (made before the clock
starts, so a timing is the step's) with states kept at its sample steps ("marks");
what is read off those states and compared with a reference gives the error rows:

- ``creep``: the paper's experiment (rigs/one_bone.yaml: τ = 1 N·m about z for 2 s,
  then free until 6 s); error = max over all steps of |θ − θ_exact| (rad), θ_exact the
  continuous model's solution by the matrix exponential (``creep_exact``, no solver).
- ``chain-1s``, ``chain-3s``: rigs/chain.yaml without ground (10 links, equality rows
  only) released under gravity; error = |tip − tip_ref| (m) after 1 s and after 3 s of
  one run (two rows: each with the wall time up to its sample), tip_ref from the direct
  solver at a tiny step.
- ``doll``: rigs/doll.yaml (ground contacts, limits, yield) with a position-only grip
  on forearm_l's tail (``grip_inputs``) lifting it over 1 s, then held
  still until 1.5 s; error = max over t = 0.5, 1.0, 1.5 s and over bones of
  |head − head_ref| (m), head_ref from ``hybrid`` with 200 sweeps at a tiny step.  This is
  the scene ``puppetcli.bench.peers.doll_error`` measures for MuJoCo.

A reference's own error is estimated as its distance to the same reference at twice
its step (first order: about its error); the study reports it as ``ref_error``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache, lru_cache
from pathlib import Path

import numpy as np
import scipy.linalg

from puppetcli.rig.load import load_rig
from puppetcli.spidar.pointer import Motion, pointer_over_step, still
from solver import quat
from solver.engine import Engine
from solver.model import Model, build_model
from solver.observe import bone_heads, bone_tails, joint_rotations
from solver.rows.grip import make_coupling
from solver.state import State, StepInput, initial_state

ROOT = Path(__file__).resolve().parents[2]  # the checkout (the install is editable: README)
RIGS = ROOT / "rigs"

# The creep experiment (rigs/one_bone.yaml; digest §5.1, rotational form).
KF, DF, DD, INERTIA, TAU = 1.0, 10.0, 100.0, 0.1, 1.0
T_LOAD, T_END = 2.0, 6.0
CHAIN_TIMES = (1.0, 3.0)
DOLL_LIFT, DOLL_TIMES = 1.0, (0.5, 1.0, 1.5)
DOLL_REFERENCE = dict(method="hybrid", iterations=200, warm_start=True, warm_start_factor=1.0)
CHAIN_REFERENCE = dict(method="direct", iterations=15, warm_start=True, warm_start_factor=1.0)
KINDS = ("creep", "chain", "doll")


@dataclass(frozen=True)
class Scene:
    """One scene at one configured model.

    inputs: one StepInput (or None) per step; marks: 1-based step numbers whose states
    are kept; sample(model, state) (k,3): the points compared with the reference;
    rows: (row name, indices into marks whose worst distance is that row's error)."""

    model: Model
    inputs: list[StepInput | None]
    marks: list[int]
    sample: Callable[[Model, State], np.ndarray]
    rows: tuple[tuple[str, tuple[int, ...]], ...]
    unit: str


def key_steps(h: float, times) -> list[int]:
    """The 1-based step numbers that end exactly at ``times`` (s) for step h; a time
    that is not a whole number of steps is an error (its sample would be off by up
    to h, an error of its own)."""
    steps = [round(t / h) for t in times]
    for t, k in zip(times, steps, strict=True):
        if k < 1 or not math.isclose(k * h, t, rel_tol=1e-9, abs_tol=1e-12):
            raise ValueError(f"t = {t:g} s is not a step boundary for h = {h:g} s")
    return steps


def creep_exact(times: np.ndarray) -> np.ndarray:
    """Angle θ(t) (rad) of the continuous creep model, exact by the matrix exponential.

    State (θ, ω, q_sf):  I ω̇ = τ + λ,  λ = −D_d (ω − q̇_sf) = −K_f q_sf − D_f q̇_sf
    ⇒ q̇_sf = (D_d ω − K_f q_sf)/(D_d + D_f); τ = TAU for t < T_LOAD, then 0.
    The constant input enters as a fourth, constant state of the augmented matrix.
    """
    s = DD + DF
    aug = np.zeros((4, 4))
    aug[:3, :3] = [
        [0.0, 1.0, 0.0],
        [0.0, -DD / INERTIA * (1 - DD / s), -DD * KF / (s * INERTIA)],
        [0.0, DD / s, -KF / s],
    ]

    def advance(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
        a = aug.copy()
        a[1, 3] = tau / INERTIA
        return (scipy.linalg.expm(a * dt) @ np.append(x, 1.0))[:3]

    x_load = advance(np.zeros(3), TAU, T_LOAD)
    times = np.asarray(times, dtype=float)
    return np.array(
        [
            advance(np.zeros(3), TAU, t)[0] if t <= T_LOAD else advance(x_load, 0.0, t - T_LOAD)[0]
            for t in times
        ]
    )


def creep_model() -> Model:
    return build_model(load_rig(RIGS / "one_bone.yaml"))


def chain_model() -> Model:
    """rigs/chain.yaml without ground or self-collision: equality rows only."""
    spec = load_rig(RIGS / "chain.yaml")
    bones = tuple(replace(b, collide=False) for b in spec.bones)
    return build_model(replace(spec, ground=None, bones=bones))


def doll_model() -> Model:
    """rigs/doll.yaml as it is: ground contacts, limits, yield, the side table."""
    return build_model(load_rig(RIGS / "doll.yaml"))


@cache
def base_model(kind: str) -> Model:
    """The scene's model with the rig's own options (built once: models are frozen)."""
    return {"creep": creep_model, "chain": chain_model, "doll": doll_model}[kind]()


def _creep_angle(model: Model, state: State) -> np.ndarray:
    return np.array([[joint_rotations(model, state)[0, 2], 0.0, 0.0]])


def _chain_tip(model: Model, state: State) -> np.ndarray:
    return bone_tails(model, state)[-1:]


def scene(kind: str, model: Model) -> Scene:
    """The scene ``kind`` ("creep" | "chain" | "doll") on ``model`` (configured: h, solver)."""
    h = model.options.h
    if kind == "creep":
        n, n_load = key_steps(h, (T_END, T_LOAD))
        loaded = StepInput(body_torque=np.array([[0.0, 0.0, TAU]]))
        inputs = [loaded] * n_load + [None] * (n - n_load)
        marks = list(range(1, n + 1))
        return Scene(model, inputs, marks, _creep_angle, (("creep", tuple(range(n))),), "rad")
    if kind == "chain":
        marks = key_steps(h, CHAIN_TIMES)
        rows = tuple((f"chain-{t:g}s", (i,)) for i, t in enumerate(CHAIN_TIMES))
        return Scene(model, [None] * marks[-1], marks, _chain_tip, rows, "m")
    if kind == "doll":
        marks = key_steps(h, DOLL_TIMES)
        inputs = grip_inputs(model, DOLL_LIFT, marks[-1])
        return Scene(model, inputs, marks, bone_heads, (("doll", tuple(range(len(marks)))),), "m")
    raise ValueError(f"unknown scene {kind!r}")


def run_scene(sc: Scene) -> tuple[list[np.ndarray], list[float], float]:
    """(samples at the marks, wall seconds of the steps up to each mark, mean substeps).

    The steps run in place (solver.compiled.sim.Sim: the same kernel and states as
    fast_step, bit for bit, without a new State object a step), so a time is the
    simulation's, as the MuJoCo rows' are mj_step's (puppetcli.bench.peers): fast_step's own
    Python (~20 µs a step) would add the same to every setting and hide their
    differences.  Reading a mark's sample (Sim.state, then sc.sample) is reading the
    result, not simulating: the clock stops for it."""
    marks, kept, walls, substeps = set(sc.marks), [], [], 0
    sim, elapsed = Engine(sc.model).stepper(), 0.0
    start = time.perf_counter()
    for k, inp in enumerate(sc.inputs, start=1):
        sim.advance(inp)
        substeps += sim.substeps
        if k in marks:
            elapsed += time.perf_counter() - start
            walls.append(elapsed)
            kept.append(sc.sample(sc.model, sim.state))
            start = time.perf_counter()
    return kept, walls, substeps / max(len(sc.inputs), 1)


def distances(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """Per mark, the largest point distance between two runs' samples."""
    return np.array([np.max(np.linalg.norm(x - y, axis=1)) for x, y in zip(a, b, strict=True)])


def reference(kind: str, h: float, reference_h: float) -> tuple[list[np.ndarray], dict[str, float]]:
    """The reference samples of ``kind``'s marks for step h, and each row's reference
    error estimate (0 for the exact creep solution)."""
    if kind == "creep":
        return _creep_reference(h), {"creep": 0.0}
    return _converged(kind, reference_h)


@lru_cache(maxsize=8)
def _creep_reference(h: float) -> list[np.ndarray]:
    t = h * np.arange(1, key_steps(h, (T_END,))[0] + 1)
    return [np.array([[th, 0.0, 0.0]]) for th in creep_exact(t)]


@lru_cache(maxsize=8)
def _converged(kind: str, reference_h: float) -> tuple[list[np.ndarray], dict[str, float]]:
    """The tight reference of chain (direct) or doll (hybrid, 200 sweeps) at reference_h,
    with its distance to the same at 2·reference_h per row; computed once per process."""
    options = CHAIN_REFERENCE if kind == "chain" else DOLL_REFERENCE
    runs = []
    for h in (reference_h, 2.0 * reference_h):
        sc = scene(kind, base_model(kind).with_options(h=h, **options))
        runs.append(run_scene(sc)[0])
    d = distances(runs[0], runs[1])
    return runs[0], {name: float(d[list(ix)].max()) for name, ix in sc.rows}


GRIP = dict(  # the script's default gains, position-only (as for pulls)
    stiffness=2000.0, damping=40.0, rot_stiffness=50.0, rot_damping=2.0,
    force_limit=300.0, torque_limit=30.0, position_only=True,
)  # fmt: skip


LIFT = np.array([0.0, 0.15, 0.15])  # m: where the grip takes the forearm's end


GRIP_BONE = "forearm_l"


def grip_inputs(model: Model, lift: float, steps: int) -> list[StepInput]:
    """The inputs of ``steps`` steps at the model's h: the grip on GRIP_BONE's tail whose
    pointer lifts by LIFT over ``lift`` s (minimum jerk), then stays still.

    The grip is made with the pointer where the motion starts, so its rest is the
    pointer-to-bone pose at t = 0 (nothing jumps), as a script's grip.  The pointer's
    path depends on time only, so the inputs are made before any clock starts and a
    timing is the step's (a script run adds ~80 µs of Python per step; see README)."""
    state = initial_state(model)
    b = model.bone_names.index(GRIP_BONE)
    end = model.bone_tail0[b]
    h = model.options.h
    at_rest = pointer_over_step(still(end, quat.IDENTITY), 0.0, h, 0.0)
    coupling = make_coupling(state, at_rest, b, end, **GRIP)
    motion = Motion(0.0, lift, end, quat.IDENTITY, LIFT, np.zeros(3))
    return [
        StepInput(pointer=pointer_over_step(motion, k * h, h, 0.0), coupling=coupling)
        for k in range(steps)
    ]
