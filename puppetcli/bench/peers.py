"""MuJoCo as a peer: the same rigs and scenes, its steps/s and its error, in the same run.

The rig is translated and compiled by ``puppetcli.bench.mjcf`` (same world frame,
masses, inertias, joint anchors, contact pairs and friction; see there for what MuJoCo
cannot express: the series damper D_d, yield and swing/twist limits); this module
drives the scenes and measures them.  MuJoCo keeps its default
solver settings; only the timestep, gravity and integrator are set.  ``mujoco`` is
imported lazily, so nothing here costs anything unless a peer is asked for.

Scenes
------
* ``doll``: rigs/doll.yaml (hips fixed on the stand, feet 1 cm above the ground, ground
  contacts), a position-only grip (K = 2000 N/m, D = 40 N·s/m, ±300 N per axis: our
  bench's GRIP) at the tail of ``forearm_l`` whose pointer follows the minimum-jerk
  path ``Motion(0, lift, tail, identity, LIFT, 0)``.  Each step gets the pointer's pose
  at the step's end and its mean velocity over the step, as our ``StepInput`` does;
  the mocap/ctrl inputs of every step are computed before the clock starts.
* ``chain``: rigs/chain.yaml without ground or self-collision, released at rest.

Errors are against MuJoCo's *own* converged reference (the same scene at a tiny step),
since its joints are Voigt elements and ours three-element: the two engines do not
converge to the same motion.  ``ref_error`` is the distance between the references at
the tiny step and at twice it (for a first-order integrator ≈ the reference's own
error; RK4 converges far faster).  A run that
goes non-finite or trips one of MuJoCo's bad-state warnings (after which MuJoCo resets
the state) is reported as diverged, with error = nan.
"""

from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import replace
from functools import lru_cache

import numpy as np

from puppetcli.bench.mjcf import (
    Peer,
    PeerGrip,
    anchor_gaps,
    build_peer,
    import_mujoco,
    peer_heads,
    peer_tails,
)
from puppetcli.bench.scenes import (
    CHAIN_TIMES,
    DOLL_LIFT,
    DOLL_TIMES,
    GRIP,
    GRIP_BONE,
    LIFT,
    chain_model,
    doll_model,
)
from puppetcli.spidar import pointer
from puppetcli.spidar.pointer import Motion
from solver import quat

GRIP_K, GRIP_D, GRIP_LIMIT = GRIP["stiffness"], GRIP["damping"], GRIP["force_limit"]
WARMUP_STEPS = 5
REFERENCE_H = 5e-5
_BAD_STATE = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")


def mujoco_version() -> str | None:
    """MuJoCo's version string, or None when it is not installed."""
    try:
        import mujoco
    except ImportError:
        return None
    return mujoco.__version__


@contextmanager
def quiet(mujoco):
    """MuJoCo's warnings go to its counters (``warnings``) only, not to stdout."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def pointer_path(motion: Motion, h: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(position (n,3) at each step's end, mean velocity (n,3) over it) of a pure
    translation ``motion`` (puppetcli.spidar.pointer.pointer_path; ``pointer_over_step`` costs
    ~0.4 ms a step in Python, more than the MuJoCo step)."""
    _, (end, _, vel, _) = pointer.pointer_path(motion, h * np.arange(steps + 1), h)
    return end, vel


def drive(peer: Peer, motion: Motion, grip: PeerGrip, steps: int) -> Peer:
    """The peer with per-step grip inputs along ``motion`` (a translation): the mocap
    at the pointer's end-of-step position and ctrl = (D/K)·u, u its mean velocity over
    the step, which turns the actuators' −K·e − D·v into −K·e − D·(v − u) (see
    puppetcli.bench.mjcf)."""
    h = float(peer.mj_model.opt.timestep)
    mocap, vel = pointer_path(motion, h, steps)
    return replace(peer, mocap_pos=mocap, ctrl=vel * (grip.damping / grip.stiffness))


def reset(peer: Peer) -> None:
    mujoco = import_mujoco()
    mujoco.mj_resetData(peer.mj_model, peer.mj_data)
    mujoco.mj_forward(peer.mj_model, peer.mj_data)


def warnings(peer: Peer) -> dict[str, int]:
    """MuJoCo's warning counters that are non-zero, by name (e.g. mjWARN_BADQACC)."""
    mujoco = import_mujoco()
    out = {}
    for name, w in mujoco.mjtWarning.__members__.items():
        if name != "mjNWARNING" and peer.mj_data.warning[int(w)].number:
            out[name] = int(peer.mj_data.warning[int(w)].number)
    return out


def diverged(peer: Peer) -> bool:
    """True after a non-finite state or a bad-state warning (MuJoCo then resets)."""
    d = peer.mj_data
    bad = any(name in _BAD_STATE for name in warnings(peer))
    return bad or not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))


def run(peer: Peer, steps: int, record=None, at=()) -> tuple[float, float, list]:
    """Take ``steps`` steps (with the grip inputs if any): (wall s, mean ncon, records).

    ``record(peer)`` is called after each step whose 1-based number is in ``at``; the
    clock runs only around mj_step and the inputs (the bench's convention)."""
    mujoco = import_mujoco()
    m, d = peer.mj_model, peer.mj_data
    mocap, ctrl = peer.mocap_pos, peer.ctrl
    grip = len(mocap) > 0
    marks, out, ncon, wall = set(at), [], 0, 0.0
    with quiet(mujoco):
        start = time.perf_counter()
        for k in range(steps):
            if grip:
                d.mocap_pos[0] = mocap[k]
                d.ctrl[:] = ctrl[k]
            mujoco.mj_step(m, d)
            ncon += d.ncon
            if k + 1 in marks:
                wall += time.perf_counter() - start
                out.append(record(peer))
                start = time.perf_counter()
    wall += time.perf_counter() - start
    return wall, ncon / max(steps, 1), out


def doll_grip_peer(
    h: float, lift: float, steps: int, integrator: str = "Euler", offset=(0.0, 0.0, 0.0)
) -> Peer:
    """The doll with the grip on forearm_l's tail, driven along the lift for ``steps``.

    The pointer's path starts at the tail.  offset (3,): the coupling's rest offset,
    grip point − pointer at gripping (m): the grip pulls the tail towards pointer +
    offset; 0 = nothing jumps."""
    model = doll_model()
    b = model.bone_names.index(GRIP_BONE)
    tail = model.bone_tail0[b]
    gripped_at = tail - np.asarray(offset, dtype=float)
    grip = PeerGrip(b, tail - model.body_pos0[b], gripped_at, GRIP_K, GRIP_D, GRIP_LIMIT)
    motion = Motion(0.0, lift, tail, quat.IDENTITY, LIFT, np.zeros(3))
    return drive(build_peer(model, h, integrator, grip), motion, grip, steps)


def doll_timer(h: float, seconds: float, integrator: str = "Euler", offset=(0.0, 0.0, 0.0)):
    """A function that times one run of the bench's doll scene (``puppetcli.bench.solvers.
    run_timer``: the grip lifts forearm_l's end over ``seconds``) from rest and returns
    its figures, steps/s among them; only the mj_step loop is timed.  The peer is built
    and takes a few untimed steps once, here."""
    n = max(1, round(seconds / h))
    peer = doll_grip_peer(h, seconds, n, integrator, offset)
    run(peer, WARMUP_STEPS)

    def timed() -> dict:
        reset(peer)
        wall, contacts, _ = run(peer, n)
        return dict(
            h=h,
            integrator=integrator,
            steps=n,
            seconds=wall,
            steps_per_s=n / wall,
            contacts=contacts,
            diverged=diverged(peer),
        )

    return timed


def _checkpoints(h: float, times) -> list[int]:
    return [max(1, round(t / h)) for t in times]


def _chain_tips(h: float, integrator: str) -> tuple[list[np.ndarray], float, bool]:
    """Tip (link9's tail) after each of CHAIN_TIMES, wall seconds, diverged."""
    peer = build_peer(chain_model(), h, integrator)
    marks = _checkpoints(h, CHAIN_TIMES)
    wall, _, tips = run(peer, marks[-1], lambda p: peer_tails(p)[-1:].copy(), marks)
    return tips, wall, diverged(peer)


def _doll_heads(h: float, integrator: str) -> tuple[list[np.ndarray], float, bool]:
    """Bone heads at each of DOLL_TIMES in the grip scene, wall seconds, diverged."""
    marks = _checkpoints(h, DOLL_TIMES)
    peer = doll_grip_peer(h, DOLL_LIFT, marks[-1], integrator)
    wall, _, heads = run(peer, marks[-1], lambda p: peer_heads(p).copy(), marks)
    return heads, wall, diverged(peer)


_SAMPLES = {"chain": _chain_tips, "doll": _doll_heads}


def _distances(a: list[np.ndarray], b) -> list[float]:
    """Per sample time, the largest point distance (m) between two runs."""
    return [float(np.max(np.linalg.norm(x - y, axis=1))) for x, y in zip(a, b, strict=True)]


@lru_cache(maxsize=8)
def reference(scene: str, integrator: str, reference_h: float) -> tuple[tuple, float]:
    """MuJoCo's own samples of ``scene`` ("chain" | "doll") at reference_h, and their
    largest distance to the samples at 2·reference_h (≈ its first-order error)."""
    fine, _, _ = _SAMPLES[scene](reference_h, integrator)
    coarse, _, _ = _SAMPLES[scene](2.0 * reference_h, integrator)
    return tuple(fine), max(_distances(fine, coarse))


def _errors(scene: str, h: float, integrator: str, reference_h: float, repeats: int) -> dict:
    ref, ref_err = reference(scene, integrator, reference_h)
    best, samples, bad = math.inf, [], False
    for _ in range(repeats):
        samples, wall, bad = _SAMPLES[scene](h, integrator)
        best = min(best, wall)
    errors = [math.nan] * len(ref) if bad else _distances(samples, ref)
    times = CHAIN_TIMES if scene == "chain" else DOLL_TIMES
    return dict(
        h=h,
        integrator=integrator,
        steps=_checkpoints(h, times)[-1],
        seconds=best,
        errors=errors,
        ref_error=ref_err,
        diverged=bad,
    )


def chain_error(
    h: float, integrator: str = "Euler", reference_h: float = REFERENCE_H, repeats: int = 1
) -> dict:
    """MuJoCo's chain tip error (m) after 1 s and 3 s at step h against its own
    reference; seconds = the best wall time of the mj_step loop over the 3 s."""
    out = _errors("chain", h, integrator, reference_h, repeats)
    out["error_1s"], out["error_3s"] = out.pop("errors")
    return out


def doll_error(
    h: float, integrator: str = "Euler", reference_h: float = REFERENCE_H, repeats: int = 1
) -> dict:
    """MuJoCo's doll grip error (m): the pointer lifts over 1 s and holds until 1.5 s;
    error = max over t = 0.5, 1.0, 1.5 s and over bones of |head − head_ref|."""
    out = _errors("doll", h, integrator, reference_h, repeats)
    out["error"] = max(out.pop("errors"))
    return out


def _health(peer: Peer) -> tuple[bool, float, float]:
    """(state finite, largest anchor gap m, largest body speed m/s) now."""
    mujoco = import_mujoco()
    d = peer.mj_data
    finite = bool(np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))
    vel, speed = np.zeros(6), 0.0
    for i in peer.body_ids:
        mujoco.mj_objectVelocity(peer.mj_model, d, mujoco.mjtObj.mjOBJ_BODY, int(i), vel, 0)
        speed = max(speed, float(np.linalg.norm(vel[3:])))
    return finite, float(np.max(anchor_gaps(peer), initial=0.0)), speed


def _grip_rise(peer: Peer) -> float:
    """How far (m) the gripped tail rose from rest: the lift did happen."""
    b = peer.model.bone_names.index(GRIP_BONE)
    return float(peer_tails(peer)[b, 1] - peer.model.bone_tail0[b, 1])


def stability(h: float, seconds: float = 1.0, integrator: str = "Euler") -> dict:
    """The doll grip scene (lift over ``seconds``) at step h: whether MuJoCo stayed
    finite, its warnings, the largest joint-anchor gap (m; zero by construction for
    MuJoCo's generalised coordinates, measured from both bodies' frames) and the
    largest body speed (m/s) seen after any step."""
    n = max(1, round(seconds / h))
    peer = doll_grip_peer(h, seconds, n, integrator)
    _, _, per_step = run(peer, n, _health, range(1, n + 1))
    finite = all(ok for ok, _, _ in per_step)
    gap = max(g for _, g, _ in per_step)
    speed = max(v for _, _, v in per_step)
    return dict(
        h=h,
        integrator=integrator,
        steps=n,
        finite=finite,
        warnings=warnings(peer),
        diverged=diverged(peer),
        max_anchor_gap=gap,
        max_speed=speed,
        grip_rise=float(_grip_rise(peer)),
    )
