"""The skips, measured: each skip of work a scene does not need, on and off, in one run.

For each skip the grip scene of ``puppetcli.bench.solvers`` (the doll's forearm lifted along a
minimum-jerk path), or the resting chain below, runs with the skip on and off, interleaved,
best of ``repeats``; the row gives both rates, their ratio, and how far apart the two runs
end up: the largest difference over the run of any body's position (m) and orientation
(rad).  A skip must
change nothing beyond the solver's tolerance; the tests check that.

Skips (``solver.model.Options``):
- ``cull_pairs``: shape pairs whose bounding spheres are apart by more than the contact
  margin get no narrow phase (no collision work for bone pairs that cannot touch);
- ``dormant_rows``: the hybrid solve leaves out of its iteration the one-sided rows that
  neither pushed last step nor are crossed (speculative contacts, limits not reached)
  and checks them after the solve (no contact rows where nothing touches);
- ``leaf_contacts``: the hybrid solve eliminates the contacts of a bone on the ground with
  the joints while they stick instead of iterating them (solver.solve.hybrid); off = PGS
  on their Schur complement (15 sweeps).  Measured on ``chain-on-ground``: a chain of 20
  plastic capsule links (rigs/chain.yaml's) lying on the ground from its fixed stand, left
  alone and kept awake (sleep off in both runs: a resting chain would otherwise fall
  asleep and solve nothing).  Off differs by PGS's own error;
- ``direct``: ``auto`` solves a step whose rows are all two-sided exactly (the tree
  elimination) instead of iterating; off = the paper's PGS (15 sweeps), on the doll
  without ground and limits (``doll-joints``).  Off differs by PGS's own error;
- ``sleep``: islands at rest and untouched are frozen (solver.advance.sleep).  The doll first
  settles for SETTLE seconds (untimed, with sleep on: every island falls asleep), then
  both runs start from that pose, the one without sleep with every island awake; the
  grip wakes the upper body, the legs sleep on.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from puppetcli.bench.scenes import grip_inputs
from puppetcli.bench.solvers import doll_scenes
from puppetcli.bench.stress_scenes import chain_rig
from solver import quat
from solver.engine import Engine
from solver.model import Model, build_model
from solver.state import State, StepInput, initial_state


@dataclass(frozen=True)
class SkipRow:
    """One skip: steps/s on and off, on ÷ off, and the runs' largest differences."""

    skip: str
    scene: str
    on_steps_per_s: float
    off_steps_per_s: float
    speedup: float
    position_diff: float
    rotation_diff: float


CHAIN_SCENE = "chain-on-ground"  # the one scene that is not the doll's
SKIPS = {  # name: (scene, options with the skip on, options with it off)
    "cull_pairs": ("doll", {"cull_pairs": True}, {"cull_pairs": False}),
    "dormant_rows": ("doll", {"dormant_rows": True}, {"dormant_rows": False}),
    "leaf_contacts": (
        CHAIN_SCENE,
        {"leaf_contacts": True, "sleep": False},
        {"leaf_contacts": False, "sleep": False},
    ),
    "direct": ("doll-joints", {"method": "auto"}, {"method": "pgs"}),
    "sleep": ("doll", {"sleep": True}, {"sleep": False}),
}
SETTLE = 3.0  # s: the sleep skip's untimed start (the legs are asleep after ~2 s)
CHAIN_LINKS, CHAIN_RADIUS = 20, 0.015  # chain-on-ground: stress_scenes.chain_rig's links


def skip_scene(name: str) -> Model:
    """A skip's scene: CHAIN_SCENE or one of the doll's (puppetcli.bench.solvers.doll_scenes)."""
    return _chain_on_ground() if name == CHAIN_SCENE else doll_scenes()[name]


def _chain_on_ground() -> Model:
    """CHAIN_LINKS links of stress_scenes.chain_rig lying on a ground plane level with
    their undersides."""
    height = chain_rig(1, 0.001).bones[0].head[1] - CHAIN_RADIUS
    return build_model(chain_rig(CHAIN_LINKS, 0.001, radius=CHAIN_RADIUS, ground=height))


def run(model: Model, inputs: list[StepInput], start: State) -> tuple[float, list[State]]:
    """Wall seconds of the steps from ``start`` and the State after each."""
    state, states, engine = start, [], Engine(model)
    start = time.perf_counter()
    for inp in inputs:
        state, _ = engine.step(state, inp)
        states.append(state)
    return time.perf_counter() - start, states


def differences(a: list[State], b: list[State]) -> tuple[float, float]:
    """Largest position (m) and rotation (rad) difference of any body over two runs."""
    pos = max(float(np.abs(x.body_pos - y.body_pos).max()) for x, y in zip(a, b, strict=True))
    rot = max(
        float(np.linalg.norm(quat.log(quat.mul(quat.conj(y.body_quat), x.body_quat)), axis=1).max())
        for x, y in zip(a, b, strict=True)
    )
    return pos, rot


def measure_skip(name: str, h: float, seconds: float, repeats: int) -> SkipRow:
    """One skip, on and off, interleaved ``repeats`` times (module docstring)."""
    scene, on, off = SKIPS[name]
    base = skip_scene(scene).with_options(h=h)
    models = (base.with_options(**on), base.with_options(**off))
    n = max(1, round(seconds / h))
    inputs = [None] * n if scene == CHAIN_SCENE else grip_inputs(base, seconds, n)
    starts = _starts(models[0], h) if name == "sleep" else (initial_state(base),) * 2
    best, states = [math.inf, math.inf], [None, None]
    for m, start in zip(models, starts, strict=True):  # untimed: compile, warm caches
        run(m, inputs[:5], start)
    for _ in range(repeats):
        for k, m in enumerate(models):
            wall, states[k] = run(m, inputs, starts[k])
            best[k] = min(best[k], wall)
    pos, rot = differences(states[0], states[1])
    rate_on, rate_off = n / best[0], n / best[1]
    return SkipRow(name, scene, rate_on, rate_off, rate_on / rate_off, pos, rot)


def _starts(model: Model, h: float) -> tuple[State, State]:
    """The doll after SETTLE s left alone (asleep), and the same with every island awake."""
    state, engine = initial_state(model), Engine(model)
    for _ in range(round(SETTLE / h)):
        state, _ = engine.step(state)
    nb = model.nbody
    return state, replace(state, body_asleep=np.zeros(nb, bool), body_still=np.zeros(nb))


def measure_skips(h: float = 0.001, seconds: float = 0.5, repeats: int = 5) -> list[SkipRow]:
    """Every skip of SKIPS."""
    return [measure_skip(name, h, seconds, repeats) for name in SKIPS]


def format_skips(rows: list[SkipRow], h: float) -> str:
    head = (
        f"{'skip':<13} {'scene':<15} {'on (steps/s)':>12} {'off (steps/s)':>13} "
        f"{'× on/off':>8} {'Δ position (m)':>14} {'Δ rotation (rad)':>16}"
    )
    lines = [f"skips at h = {h:g} s (compiled step; on and off interleaved)",
             head, "-" * len(head)]  # fmt: skip
    for r in rows:
        lines.append(
            f"{r.skip:<13} {r.scene:<15} {r.on_steps_per_s:>12,.0f} {r.off_steps_per_s:>13,.0f} "
            f"{r.speedup:>8.2f} {r.position_diff:>14.2e} {r.rotation_diff:>16.2e}"
        )
    return "\n".join(lines)
