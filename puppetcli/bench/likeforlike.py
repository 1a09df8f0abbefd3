"""Accuracy at equal time against MuJoCo, on the same continuous physics (``puppetcli bench
--accuracy``).

Both engines get the same bodies, inertias and ball joints with the same Voigt springs
(``plastic: false``: K_f and D_f about the rest pose, equal on the three axes, no limits,
no contacts but the floor of ``chain-floor``), so they approximate the same ODE; the truth
is that ODE integrated to 1e-12 by DOP853 in joint coordinates (``puppetcli.bench.truth``),
independent of both.  Scenes:

- ``chain-bent``: 5 links of rigs/chain.yaml (10 cm, 0.2 kg; K = 0.5 N·m/rad,
  D = 0.005 N·m·s/rad) released from a 3-D bend under gravity;
- ``chain-hanging``: 4 such links hanging straight down from the fixed root, released
  (their springs' rest is the horizontal T-pose);
- ``doll-bent``: rigs/doll.yaml's bones and joints (its K_f, D_f) released from a bent
  pose under gravity, no input;
- ``doll-pull``: the same doll at rest, its left hand (forearm_l's tail) pulled 0.21 m
  over 0.5 s along a minimum-jerk path by a 2,000 N/m, 40 N·s/m spring-damper.  Both
  engines get the pointer's pose and velocity at the end of each step;
- ``chain-floor``: the 4 links of ``chain-hanging`` with their last link's capsule
  (radius 1.5 cm) on a frictionless floor 25 cm below the root, which is above where
  the chain would hang: its tail end presses on the floor all along (the truth's
  normal force stays between 0.75 and 3.5 N over 2 s), and, released from a pose swung and
  twisted out of its plane, slides on it.  Our contact is a hard row with no slop
  (``contact_slop: 0``); MuJoCo's is its default soft contact, frictionless (condim 1).

The error is the RMS (and the largest) distance of every bone's tail from the truth's at
t = 0.04, 0.08, … 1 s; the time is the wall time of the stepping loop per simulated
second (ours: the in-place compiled stepper, solver.compiled.sim.Sim; MuJoCo: mj_step),
the best of ``repeats`` runs.  ``equal_time`` reads off each engine's time to reach an
error level by log-log interpolation between its steps.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import os
import tempfile
import time
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np
import scipy.optimize
from scipy.spatial.transform import Rotation

from puppetcli.bench import mjcf
from puppetcli.bench import truth as ode
from puppetcli.bench.peers import quiet
from puppetcli.bench.scenes import RIGS
from puppetcli.rig.load import load_rig
from puppetcli.spidar.pointer import min_jerk
from solver import quat
from solver.engine import Engine
from solver.model import Model, build_model
from solver.observe import points_on_bones, relative_rotations
from solver.rows.grip import Coupling, Pointer
from solver.spec import GroundSpec, LimitSpec, RheologySpec
from solver.state import State, StepInput, initial_state

SCENES = ("chain-bent", "chain-hanging", "doll-bent", "doll-pull", "chain-floor")
DURATION, SAMPLE = 1.0, 0.04  # s: every step below divides SAMPLE
STEPS = (0.0005, 0.001, 0.002, 0.004, 0.005, 0.01, 0.02, 0.04)
LARGE_STEPS = (0.02, 0.04, 0.05, 0.1, 0.2, 0.25)
OURS = ("bdf2", "euler")
PEERS = ("Euler", "implicitfast", "RK4")
PULL = dict(bone="forearm_l", delta=np.array([0.0, 0.15, 0.15]), duration=0.5,
            stiffness=2000.0, damping=40.0)  # fmt: skip
CHAIN_K, CHAIN_D = 0.5, 0.005
BEND_SEED = 3
FLOOR = dict(below_root=0.25, swing=0.3, twist=-0.2)
"""chain-floor: the floor's top (where the last link's tail stays) below the root's
tail (m), and the start's turns of the first joint about y and the second's (rad)."""


def voigt_model(rig: str, links: int | None = None, k: float | None = None,
                d: float | None = None, ground: GroundSpec | None = None) -> Model:  # fmt: skip
    """A rig with spring-damper joints only: K_f and D_f (their axes' mean, or k and d)
    equal on all axes, no series damper, limits, props or collisions; the first
    ``links`` + 1 bones when given.  With ``ground``, that ground, which the last bone
    touches (its only collision shape), with no contact slop."""
    spec = load_rig(RIGS / rig)
    bones = spec.bones if links is None else spec.bones[: links + 1]
    out = []
    for b in bones:
        if b.rheology is None:  # the fixed root
            out.append(replace(b, collide=False))
            continue
        kf = float(np.mean(b.rheology.kf)) if k is None else k
        df = float(np.mean(b.rheology.df)) if d is None else d
        rheology = RheologySpec(np.full(3, kf), np.full(3, df), np.full(3, math.inf))
        last = ground is not None and len(out) == len(bones) - 1
        out.append(replace(b, rheology=rheology, limits=LimitSpec(), collide=last))
    solver = spec.solver if ground is None else replace(spec.solver, contact_slop=0.0)
    return build_model(replace(spec, bones=tuple(out), ground=ground, props=(), solver=solver))


def posed(model: Model, rotvecs: np.ndarray) -> State:
    """The rest state with every joint turned by its rotation vector (parent frame, rad)
    and the bodies placed by the joints (at rest: the springs' deflection)."""
    tree = ode.make_tree(model)
    q = Rotation.from_rotvec(rotvecs[: len(tree.joint)]).as_quat(scalar_first=True)
    kin = ode.kinematics(tree, q, np.zeros((len(tree.joint), 3)))
    state = initial_state(model)
    q_sf = np.zeros((model.njoint, 3))
    q_sf[tree.joint] = rotvecs[: len(tree.joint)]
    body_q = Rotation.from_matrix(kin.rot).as_quat(scalar_first=True)
    return replace(state, body_pos=kin.pos, body_quat=body_q, joint_q_sf=q_sf)


@dataclass(frozen=True)
class Scene:
    """A like-for-like scene: the model (its options' h is set per run), the start, and
    the pull (None: no input)."""

    name: str
    model: Model
    start: State
    pull: ode.Pull | None
    floor: ode.Floor | None = None


def _bend(n: int, scale: float) -> np.ndarray:
    return np.random.default_rng(BEND_SEED).normal(size=(n, 3)) * scale


@cache
def scene(name: str) -> Scene:
    """The scene ``name`` (module docstring)."""
    if name == "chain-floor":
        return _floor_scene()
    if name.startswith("chain"):
        links = 5 if name == "chain-bent" else 4
        model = voigt_model("chain.yaml", links, CHAIN_K, CHAIN_D)
        if name == "chain-bent":
            turns = _bend(links, 0.4)
        else:
            turns = np.zeros((links, 3))
            turns[0, 2] = -math.pi / 2  # straight down
        return Scene(name, model, posed(model, turns), None)
    model = voigt_model("doll.yaml")
    if name == "doll-bent":
        return Scene(name, model, posed(model, _bend(model.njoint, 0.3)), None)
    if name == "doll-pull":
        return Scene(name, model, initial_state(model), _pull(model))
    raise ValueError(f"unknown scene {name!r}")


def _floor_scene() -> Scene:
    """chain-floor (module docstring): the chain turned by ``_floor_turns``, its first
    joint's downward turn chosen so that the last link's tail is on the floor."""
    links = last = 4
    bones = load_rig(RIGS / "chain.yaml").bones
    top = float(bones[0].tail[1]) - FLOOR["below_root"]
    ground = GroundSpec(height=top - bones[last].shape.radius, friction=0.0)  # its capsule's
    model = voigt_model("chain.yaml", links, CHAIN_K, CHAIN_D, ground)

    def tail_height(extra: float) -> float:
        s = posed(model, _floor_turns(links, extra))
        tails = points_on_bones(model, s.body_pos, s.body_quat, model.bone_tail0)
        return float(tails[last, 1]) - top

    extra = scipy.optimize.brentq(tail_height, 0.0, 1.0, xtol=1e-15)
    start = posed(model, _floor_turns(links, extra))
    point = model.bone_tail0[last] - model.body_pos0[last]
    return Scene("chain-floor", model, start, None, ode.Floor(last, point, top))


def _floor_turns(links: int, extra: float) -> np.ndarray:
    """chain-floor's start turns: straight down, the first joint raised by ``extra`` about
    z, swung about y, the second turned back about y (FLOOR)."""
    turns = np.zeros((links, 3))
    turns[0] = (0.0, FLOOR["swing"], -math.pi / 2 + extra)
    turns[1, 1] = FLOOR["twist"]
    return turns


def _pull(model: Model) -> ode.Pull:
    b = model.bone_names.index(PULL["bone"])
    tail = model.bone_tail0[b]
    delta, duration = PULL["delta"], PULL["duration"]

    def target(t: float) -> tuple[np.ndarray, np.ndarray]:
        tau = min(max(t / duration, 0.0), 1.0)
        rate = 30.0 * tau**2 * (1.0 - tau) ** 2 / duration  # d(min_jerk)/dt
        return tail + delta * min_jerk(tau), delta * rate

    return ode.Pull(b, tail - model.body_pos0[b], PULL["stiffness"], PULL["damping"], target)


@dataclass(frozen=True)
class Samples:
    """When a run is compared with the truth: every ``every`` s until ``until`` s."""

    every: float = SAMPLE
    until: float = DURATION

    def times(self) -> np.ndarray:
        return np.arange(1, round(self.until / self.every) + 1) * self.every


SMALL, LARGE = Samples(), Samples(1.0, 2.0)
"""The study's samples (steps up to 40 ms), and the large steps' (20–250 ms, all on one window)."""


@cache
def true_tails(name: str, samples: Samples = SMALL) -> np.ndarray:
    """(ntimes, nbone, 3) the bones' tails at the sample times by the truth; kept in
    ``truth_cache()`` under a hash of the scene's model, start, samples and the truth's
    source (the released doll's takes ~2 minutes)."""
    sc = scene(name)
    key = _truth_key(sc, samples)
    path = truth_cache() / f"{name}-{key}.npy"
    if path.exists():
        return np.load(path)
    tree = ode.make_tree(sc.model)
    y0 = ode.joint_state(tree, sc.start.body_quat, sc.start.body_omega)
    ys = ode.integrate(tree, y0, samples.times(), sc.pull, sc.floor)
    pos, q = ode.body_poses(tree, ys)
    tails = points_on_bones(sc.model, pos, q, sc.model.bone_tail0)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npy", delete=False) as f:
        np.save(f, tails)
    os.replace(f.name, path)
    return tails


def truth_cache() -> Path:
    """Where computed truths are kept: $PUPPETCLI_CACHE or ~/.cache/puppetcli, /truth."""
    base = os.environ.get("PUPPETCLI_CACHE") or Path.home() / ".cache" / "puppetcli"
    return Path(base) / "truth"


def _truth_key(sc: Scene, samples: Samples) -> str:
    digest = hashlib.sha256()
    m = sc.model
    arrays = (m.body_mass, m.body_inertia, m.body_pos0, m.joint_parent, m.joint_bone,
              m.joint_anchor_parent, m.joint_anchor_child, m.joint_kf, m.joint_df,
              m.options.gravity, sc.start.body_pos, sc.start.body_quat,
              samples.times())  # fmt: skip
    for a in arrays:
        digest.update(np.ascontiguousarray(a).tobytes())
    digest.update(Path(ode.__file__).read_bytes())
    digest.update(repr(PULL if sc.pull else None).encode())
    digest.update(repr(FLOOR if sc.floor else None).encode())
    return digest.hexdigest()[:16]


def _coupling(sc: Scene) -> Coupling:
    p = sc.pull
    return Coupling(
        p.body, p.point, np.zeros(3), quat.IDENTITY, p.stiffness, p.damping,
        0.0, 0.0, math.inf, math.inf, position_only=True,
    )  # fmt: skip


def our_inputs(sc: Scene, h: float, steps: int) -> list[StepInput | None]:
    """Each step's input: the pointer's pose and velocity at the step's end."""
    if sc.pull is None:
        return [None] * steps
    coupling, ident = _coupling(sc), quat.IDENTITY
    out = []
    for k in range(1, steps + 1):
        pos, vel = sc.pull.target(k * h)
        out.append(StepInput(pointer=Pointer(pos, ident, vel, np.zeros(3)), coupling=coupling))
    return out


@dataclass(frozen=True)
class Run:
    """One engine's run of a scene at one step: errors (m), seconds of stepping per
    simulated second, a note (empty, or why it has no result), and the solver steps per
    simulated second (ours: each part of a subdivided step counts; MuJoCo's: 1/h)."""

    scene: str
    engine: str
    h: float
    rms: float
    worst: float
    cost: float
    note: str = ""
    steps: float = math.nan


def _errors(tails: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    d = np.linalg.norm(tails - truth, axis=-1)
    if not np.all(np.isfinite(d)):
        return math.inf, math.inf
    return float(np.sqrt(np.mean(d**2))), float(d.max())


def run_ours(
    name: str,
    integrator: str,
    h: float,
    repeats: int = 3,
    samples: Samples = SMALL,
    count_parts: bool = False,
) -> Run:
    """Our compiled stepper on scene ``name`` at step h with ``integrator`` (with
    ``count_parts``, Run.steps too)."""
    sc = scene(name)
    model = sc.model.with_options(h=h, integrator=integrator)
    steps, every = round(samples.until / h), round(samples.every / h)
    inputs = our_inputs(sc, h, steps)
    engine, best, tails = Engine(model), math.inf, []
    for _ in range(repeats):
        sim, tails, wall = engine.stepper(sc.start), [], 0.0
        try:
            start = time.perf_counter()
            for k in range(steps):
                sim.advance(inputs[k])
                if (k + 1) % every == 0:  # reading the result is not simulating
                    wall += time.perf_counter() - start
                    s = sim.view()
                    tails.append(points_on_bones(model, s.body_pos, s.body_quat, model.bone_tail0))
                    start = time.perf_counter()
        except Exception as exc:  # a SimulationError: the step has no answer
            return Run(name, integrator, h, math.inf, math.inf, math.inf, str(exc).split(":")[0])
        best = min(best, wall)
    rms, worst = _errors(np.array(tails), true_tails(name, samples))
    parts = _parts(engine, sc.start, inputs) if count_parts else math.nan
    return Run(name, integrator, h, rms, worst, best / samples.until, "", parts / samples.until)


def _parts(engine: Engine, start: State, inputs: list) -> int:
    """The solver steps a run takes, each part of a subdivided step counted (an untimed
    run of its own: reading it every step would cost the timed loop ~1 %)."""
    sim, parts = engine.stepper(start), 0
    for inp in inputs:
        sim.advance(inp)
        parts += sim.substeps
    return parts


def _peer(sc: Scene, h: float, integrator: str) -> mjcf.Peer:
    """MuJoCo's model of the scene at step h, at the scene's start."""
    mujoco = mjcf.import_mujoco()
    grip = None
    if sc.pull is not None:
        p = sc.pull
        start, _ = p.target(0.0)
        grip = mjcf.PeerGrip(p.body, p.point, start, p.stiffness, p.damping)
    peer = mjcf.build_peer(sc.model, h, integrator, grip)
    m, d, model = peer.mj_model, peer.mj_data, sc.model
    q_rel = relative_rotations(model, sc.start.body_quat)  # a ball joint's qpos (mjcf.py)
    for j in range(model.njoint):
        adr = m.jnt_qposadr[m.joint(model.joint_names[j]).id]
        d.qpos[adr : adr + 4] = q_rel[j]
    mujoco.mj_forward(m, d)
    return peer


def run_peer(
    name: str, integrator: str, h: float, repeats: int = 3, samples: Samples = SMALL
) -> Run:
    """MuJoCo (``integrator``) on scene ``name`` at step h."""
    mujoco = mjcf.import_mujoco()
    sc = scene(name)
    steps, every = round(samples.until / h), round(samples.every / h)
    mocap = ctrl = None
    if sc.pull is not None:
        ends = [sc.pull.target(k * h) for k in range(1, steps + 1)]
        mocap = np.array([p for p, _ in ends])
        ctrl = np.array([u for _, u in ends]) * (sc.pull.damping / sc.pull.stiffness)
    best, tails = math.inf, []
    for _ in range(repeats):
        peer = _peer(sc, h, integrator)
        m, d, tails, wall = peer.mj_model, peer.mj_data, [], 0.0
        with quiet(mujoco):
            start = time.perf_counter()
            for k in range(steps):
                if mocap is not None:
                    d.mocap_pos[0] = mocap[k]
                    d.ctrl[:] = ctrl[k]
                mujoco.mj_step(m, d)
                if (k + 1) % every == 0:
                    wall += time.perf_counter() - start
                    tails.append(mjcf.peer_tails(peer))
                    start = time.perf_counter()
        best = min(best, wall)
    rms, worst = _errors(np.array(tails), true_tails(name, samples))
    note = "" if math.isfinite(rms) and rms < 1.0 else "diverged"
    return Run(name, f"MuJoCo {integrator}", h, rms, worst, best / samples.until, note, 1.0 / h)


def study(names=SCENES, steps=STEPS, peers: bool = True, repeats: int = 3) -> list[Run]:
    """Every engine on every scene at every step (MuJoCo's only with ``peers``)."""
    runs = []
    for name in names:
        for h in steps:
            runs += [run_ours(name, integrator, h, repeats) for integrator in OURS]
            if peers:
                runs += [run_peer(name, integrator, h, repeats) for integrator in PEERS]
    return runs


def large_steps(names=SCENES, steps=LARGE_STEPS) -> list[Run]:
    """Ours at the large steps (errors at t = 1 and 2 s)."""
    return [run_ours(n, i, h, 3, LARGE, True) for n in names for h in steps for i in OURS]


LEVELS = (3e-3, 1e-3, 3e-4, 1e-4)
"""The error levels (m) the equal-time table reads each engine's cost at."""


def cost_at(runs: list[Run], level: float) -> float:
    """Seconds per simulated second an engine's runs (one scene, its steps) need for an
    RMS error of at most ``level``: the cheapest of its runs that reach it and of the
    log-log interpolations between consecutive steps whose errors straddle it; inf if
    none reaches it."""
    ok = sorted((r for r in runs if math.isfinite(r.rms) and r.rms > 0), key=lambda r: r.h)
    best = min((r.cost for r in ok if r.rms <= level), default=math.inf)
    for small, large in itertools.pairwise(ok):
        lo, hi = sorted((small.rms, large.rms))
        if not lo < level < hi:
            continue
        f = math.log(level / small.rms) / math.log(large.rms / small.rms)
        best = min(best, math.exp(math.log(small.cost) + f * math.log(large.cost / small.cost)))
    return best


@dataclass(frozen=True)
class EqualTime:
    """At one error level on one scene: each engine's cost (s per simulated s) and ours
    (bdf2) ÷ the cheapest MuJoCo integrator's."""

    scene: str
    level: float
    costs: dict
    ratio: float


def equal_time(runs: list[Run], levels=LEVELS) -> list[EqualTime]:
    out = []
    for name in dict.fromkeys(r.scene for r in runs):
        engines = dict.fromkeys(r.engine for r in runs if r.scene == name)
        for level in levels:
            costs = {e: cost_at([r for r in runs if r.scene == name and r.engine == e], level)
                     for e in engines}  # fmt: skip
            peers = [c for e, c in costs.items() if e.startswith("MuJoCo")]
            ratio = costs["bdf2"] / min(peers) if peers and min(peers) < math.inf else math.nan
            out.append(EqualTime(name, level, costs, ratio))
    return out


def format_runs(runs: list[Run]) -> str:
    """RMS error (mm) and cost (ms per simulated s) per scene, step and engine, and the
    solver steps per simulated second where they were counted."""
    engines = list(dict.fromkeys(r.engine for r in runs))
    counted = any(math.isfinite(r.steps) for r in runs)
    head = "RMS tail error, mm / stepping time, ms per simulated second"
    lines = [head + (" / solver steps per simulated second" if counted else "")]
    for name in dict.fromkeys(r.scene for r in runs):
        lines += ["", f"{name}:", "h ms     " + "".join(f"{e:>26}" for e in engines)]
        for h in sorted({r.h for r in runs if r.scene == name}):
            cells = []
            for e in engines:
                got = [r for r in runs if r.scene == name and r.engine == e and r.h == h]
                cells.append(f" {_cell(got[0]) if got else '':>25}")
            lines.append(f"{h * 1e3:<9g}" + "".join(cells))
    return "\n".join(lines)


def _cell(r: Run) -> str:
    if not math.isfinite(r.rms) or r.note:
        return r.note or "no answer"
    steps = f" / {r.steps:.3g}" if math.isfinite(r.steps) else ""
    return f"{r.rms * 1e3:.3g} / {r.cost * 1e3:.3g}{steps}"


def format_equal_time(table: list[EqualTime]) -> str:
    """Each engine's cost at each error level, and ours ÷ MuJoCo's best."""
    if not table:
        return ""
    engines = list(table[0].costs)
    names = "".join(f"{e:>20}" for e in engines)
    head = f"scene          error mm{names}   bdf2 ÷ best MuJoCo"
    lines = ["ms per simulated second to reach an RMS error", head]
    for r in table:
        cells = "".join(f"{c * 1e3:>20.3g}" if math.isfinite(c) else f"{'-':>20}"
                        for c in r.costs.values())  # fmt: skip
        lines.append(f"{r.scene:<15}{r.level * 1e3:<9g}{cells}   {_ratio_cell(r)}")
    return "\n".join(lines)


def _ratio_cell(row: EqualTime) -> str:
    """ours ÷ MuJoCo's best, or which side reaches the level alone ("-": neither)."""
    if math.isfinite(row.ratio):
        return f"{row.ratio:.2f}"
    if row.ratio == math.inf:
        return "only MuJoCo reaches it"
    return "only bdf2 reaches it" if math.isfinite(row.costs["bdf2"]) else "-"


def csv_text(runs: list[Run]) -> str:
    lines = ["scene,engine,h_s,rms_m,max_m,seconds_per_simulated_second,note,"
             "steps_per_simulated_second"]  # fmt: skip
    lines += [f"{r.scene},{r.engine},{r.h!r},{r.rms!r},{r.worst!r},{r.cost!r},{r.note},{r.steps!r}"
              for r in runs]  # fmt: skip
    return "\n".join(lines) + "\n"
