"""Sleeping: parts of the scene at rest and untouched are not simulated.

An *island* is a set of movable bodies joined by joints (immovable bodies, such as the
doll's clamped hips, do not join islands: each leg hanging from them is an island of
its own).  Contacts do not join islands; instead a contact that could form between an
awake body and a sleeping one wakes the sleeper.

An awake island falls asleep when for ``Options.sleep_time`` seconds running every body
in it moved slower than ``sleep_speed`` (m/s, at its centre of mass) and spun slower
than ``sleep_spin`` (rad/s), no joint in it was flowing (yielded, or plastic without a
yield torque: a creeping joint must keep creeping), and nothing touched it: no external
force or torque on its bodies, no grip on them, no free-mode pointer within contact
reach of its shapes.  It is then frozen exactly at rest: velocities zero, joint states
unchanged.  A sleeping island wakes, before the step is built, as soon as one of those
touches happens or a *moving* body of another island (faster than the thresholds)
comes within contact reach of its shapes; a resting neighbour does not wake it, so two
islands at rest against each other sleep together.

While an island sleeps its bodies get no free velocity and no integration, its joints
no rows (the compiled step keeps their row slots empty), its shape pairs with static
shapes and other sleepers no collision work, and its joints' rheology and yield state is
frozen.  What this changes: an island's state when it falls asleep is within the
thresholds of rest, so the sleeping run departs from the awake one by at most what
those residual speeds would have moved over the sleep (``puppetcli bench --skips``
measures it on the doll).

The functions below are compiled (numba) and shared by the numpy step and the compiled
one, so both sleep and wake identically.
"""

from __future__ import annotations

import math

import numpy as np

from solver.collide import scene as collide
from solver.jit import kernel
from solver.model import Model, kept_with
from solver.state import State, StepInput

_ISLANDS: dict[int, np.ndarray] = {}


def body_islands(model: Model) -> np.ndarray:
    """(nb,) int64: each movable body's island (0, 1, …), −1 for immovable bodies; kept
    while ``model`` lives."""
    return kept_with(model, _ISLANDS, lambda: _components(model))


def _components(model: Model) -> np.ndarray:
    """Connected components of the movable bodies over the joints (union–find)."""
    nb = model.nbody
    root = np.arange(nb)

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    movable = model.body_inv_mass > 0.0
    for p, c in zip(model.joint_parent, model.joint_bone, strict=True):
        if p >= 0 and movable[p] and movable[c]:
            root[find(int(c))] = find(int(p))
    out = np.full(nb, -1, dtype=np.int64)
    labels: dict[int, int] = {}
    for b in range(nb):
        if movable[b]:
            out[b] = labels.setdefault(find(b), len(labels))
    return out


@kernel(error_model="numpy")
def _wake(island, asleep, still, fresh, isl):
    """Wake island ``isl``, restart its rest timer and mark it touched (fresh); True when
    it was asleep."""
    if isl < 0:
        return False
    was = False
    for b in range(len(island)):
        if island[b] == isl:
            was = was or asleep[b]
            asleep[b], still[b], fresh[b] = False, 0.0, True
    return was


@kernel(error_model="numpy")
def _norm(x, b):
    return math.sqrt(x[b, 0] ** 2 + x[b, 1] ** 2 + x[b, 2] ** 2)


@kernel(error_model="numpy")
def _near(centre, bound, i, k, margin):
    """Bounding spheres of shapes i and k within ``margin``."""
    d = 0.0
    for c in range(3):
        d += (centre[i, c] - centre[k, c]) ** 2
    return math.sqrt(d) - bound[i] - bound[k] <= margin


@kernel(error_model="numpy", _nrt=False)  # allocates nothing: counts nothing
def touch(island, asleep, still, fresh, loaded, grip_body, pointer, centre, bound, shape_body,
          pair_a, pair_b, margin, vel, omega, speed, spin):  # fmt: skip
    """Wake every island touched this step (module docstring), restart its timer and mark
    its bodies in fresh (nb,) bool.

    loaded (nb,) bool: bodies with an external force or torque; grip_body: the gripped
    body or −1; pointer (4,): free-mode pointer centre and radius (radius ≤ 0: none);
    centre (ns,3), bound (ns,): shapes' world centres and bounding radii; pair_a/b: the
    candidate shape pairs; vel, omega (nb,3): the velocities at the start of the step.
    Sleepers near a moving awake body wake, repeatedly, until no more do.  Returns True
    when any island woke."""
    woke = False
    for b in range(len(island)):
        if loaded[b]:
            woke = _wake(island, asleep, still, fresh, island[b]) or woke
    if grip_body >= 0:
        woke = _wake(island, asleep, still, fresh, island[grip_body]) or woke
    if pointer[3] > 0.0:
        for k in range(len(shape_body)):
            b = shape_body[k]
            if b >= 0 and island[b] >= 0:
                d = 0.0
                for c in range(3):
                    d += (centre[k, c] - pointer[c]) ** 2
                if math.sqrt(d) - pointer[3] - bound[k] <= margin:
                    woke = _wake(island, asleep, still, fresh, island[b]) or woke
    changed = False
    for b in range(len(island)):
        changed = changed or asleep[b]  # no sleeper: no pair has one to wake
    while changed:
        changed = False
        for p in range(len(pair_a)):
            ba, bb = shape_body[pair_a[p]], shape_body[pair_b[p]]
            if ba < 0 or bb < 0 or island[ba] < 0 or island[bb] < 0:
                continue  # static shapes and immovable bodies wake nothing
            if asleep[ba] == asleep[bb]:
                continue
            sleeper, waker = (ba, bb) if asleep[ba] else (bb, ba)
            moving = not (_norm(vel, waker) < speed and _norm(omega, waker) < spin)
            if moving and _near(centre, bound, pair_a[p], pair_b[p], margin):
                changed = _wake(island, asleep, still, fresh, island[sleeper]) or changed
        woke = woke or changed
    return woke


@kernel(error_model="numpy", _nrt=True)
def settle(island, asleep, still, vel, omega, joint_bone, joint_flowing, h, speed, spin,
           sleep_time, fresh):  # fmt: skip
    """After a step: advance the rest timers of awake islands and put to sleep those at
    rest for ``sleep_time``, zeroing their velocities (vel, omega (nb,3), in place).
    fresh (nb,) bool: bodies of islands touched this step (their timer restarts)."""
    nb = len(island)
    count = 0
    for b in range(nb):
        count = max(count, island[b] + 1)
    resting = np.ones(count, dtype=np.bool_)
    for b in range(nb):
        i = island[b]
        if i < 0 or asleep[b]:
            continue
        if fresh[b] or not (_norm(vel, b) < speed and _norm(omega, b) < spin):
            resting[i] = False
    for j in range(len(joint_bone)):
        i = island[joint_bone[j]]
        if i >= 0 and joint_flowing[j]:
            resting[i] = False
    for b in range(nb):
        i = island[b]
        if i < 0 or asleep[b]:
            continue
        still[b] = still[b] + h if resting[i] else 0.0
        if still[b] >= sleep_time:
            asleep[b] = True
            for c in range(3):
                vel[b, c] = 0.0
                omega[b, c] = 0.0


def wake(model: Model, state: State, inp: StepInput) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(asleep, still, touched) (nb,) after waking the islands this step's input or a
    moving neighbour touches (solver.advance.sleep.touch); all awake when sleeping is off."""
    nb, opt = model.nbody, model.options
    asleep, still = np.zeros(nb, dtype=bool), np.zeros(nb)
    fresh = np.zeros(nb, dtype=bool)
    if not opt.sleep:
        return asleep, still, fresh
    if len(state.body_asleep) == nb:
        asleep, still = state.body_asleep.copy(), state.body_still.copy()
    loaded = np.zeros(nb, dtype=bool)
    for load in (inp.body_force, inp.body_torque):
        if load is not None:
            loaded |= np.any(np.asarray(load) != 0.0, axis=1)
    ptr, cpl = inp.pointer, inp.coupling
    grip_body = cpl.body if (ptr is not None and cpl is not None) else -1
    pointer = np.zeros(4)
    if ptr is not None and cpl is None and ptr.radius > 0.0:
        pointer[:3], pointer[3] = ptr.pos - opt.h * ptr.vel, ptr.radius
    g = model.geometry
    centre, _ = collide.world_shapes(g, state.body_pos, state.body_quat)
    touch(
        body_islands(model), asleep, still, fresh, loaded, grip_body, pointer, centre,
        collide.shape_bounds(g), g.shape_body, g.pair_a, g.pair_b, opt.contact_margin,
        state.body_vel, state.body_omega, opt.sleep_speed, opt.sleep_spin,
    )  # fmt: skip
    return asleep, still, fresh
