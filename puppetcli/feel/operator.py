"""The built-in operator of ``feel --task``: a hand on the device that poses the doll from
where it is to a target pose, the way a practised person does (docs/feel.md).

It knows the rig (its coefficients) and feels each joint's *set*, the orientation the
joint springs back to when let go: exp(−q_sf) ⊗ q_rel, the joint's rotation less its
elastic deflection (the anchor; while the joint flows, the anchor it will take when it
stops).  To pose a key it works joint by joint, the deepest first (bending a joint
loads the joints between it and the stand, never the ones beyond it), in passes:

1. *Place* each joint further than ``FIX`` from its target: reach its bone (a straight
   path, touching nothing, the wrist unwinding), grip it ``GRIP_AT`` along, turn it
   about the joint on a minimum-jerk arc, hold until the joint stops flowing, read the
   set; repeat until the set is within ``SET_TOLERANCE`` of the aim.  A turn goes past
   the aim by what the joint will give back: the model's τ_y Σ 1/k (``_give``) on the
   first turn each way, then what the last turn that made the joint flow showed; a
   turn that did not make it flow is pushed further by ``GAIN`` × the set's error.
   The turn is slow enough that the flow's torque stays at the yield torque
   (``_speed``), so the joints up the chain are not bent with it.  Let go.
2. *Settle* ``SETTLE`` s, and aim each placed joint past its target by what it moved
   after being let go (elastic sag under gravity, creep, what its neighbours did).
   A joint a pass did not bring closer is left alone from then on.

A 3-DOF device holds the bone by a point (``position_only``): it can swing a joint but
not twist it, so it aims at the swing part of the error only and reports the twist it
could not correct.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from puppetcli.run.runner import Runner, TouchMode, script_model
from puppetcli.script.actions import GRIP_DEFAULTS, Grip, Release
from puppetcli.script.load import Script
from puppetcli.spidar.pointer import Motion
from solver import quat
from solver.model import Model
from solver.observe import bone_heads, bone_points, relative_rotations

__all__ = ["Hand", "KeyResult", "Operator", "joint_errors", "run_task"]

FIX = math.radians(1.0)  # a joint further than this from its target is placed again
SET_TOLERANCE = math.radians(0.5)  # a placed joint's set is this close to its aim
GAIN = 0.6  # of the set's remaining error added to a turn that did not make it flow
LEARN = 0.25  # a turn that moved the set by this share of its error teaches the give
ATTEMPTS = 8  # turns per placing at most
PASSES = 6  # passes per key at most
PROGRESS = math.radians(0.1)  # a pass that brings a joint less closer than this gives up on it
TICK = 0.05  # s: the operator looks at the doll this often
HOLD = 1.5  # s: the longest hold waiting for a joint to stop flowing
STILL = 0.05  # rad/s: a bone turning slower than this is still
SETTLE = 1.0  # s after letting go before the pose is read
RETAIN = 2.0  # s after the last release: the pose kept
REACHED = math.radians(2.0)  # "reached": every joint within this of the target
TURN_SPEED = 1.0  # rad/s: the hand's mean turning speed at most
PEAK_SPEED = 1.875  # the minimum-jerk profile's peak speed over its mean
MOVE_SPEED = 0.5  # m/s: the hand's mean speed reaching a bone
SHORTEST = 0.1  # s: the shortest motion
GRIP_AT = 0.8  # along the bone from its head: where the hand holds it


@dataclass(frozen=True)
class Hand:
    """The hand on the device: degrees of freedom (3: position only, 6: position and
    rotation), the coupling's clamps (N, N·m) and stiffness, and the device's display
    capacity (N, N·m; inf: no device given), what the person can feel."""

    dof: int = 6
    capacity: tuple[float, float] = (math.inf, math.inf)
    force_limit: float = GRIP_DEFAULTS["force_limit"]
    torque_limit: float = GRIP_DEFAULTS["torque_limit"]
    stiffness: float = 20000.0  # N/m: a firm hold (scripts' default grip: 2000)
    damping: float = 400.0  # N·s/m
    rot_stiffness: float = 500.0  # N·m/rad
    rot_damping: float = 20.0  # N·m·s/rad


@dataclass
class KeyResult:
    """One target key posed.

    reached: s from the key's start until every joint was within 2° (NaN: never);
    duration: s until the operator was done (the ``RETAIN`` s watched after are not
    counted); grips taken; the hand's path (m) and turn (rad); peak force (N) and
    torque (N·m) on the doll; held, final: errors per joint (rad) when done (the last
    release) and ``RETAIN`` s after; kept: the share of the key's bend (from the pose
    it started from) there after release; beyond: the share of the time the hand
    pushed harder than the device can display (NaN without a device); pose: the joint
    rotations (nj,4) at the end; unreachable: per joint, the part of the final error
    (rad) the hand cannot correct (the twist, held by a point; NaN at 6 DOF); trace:
    (s, worst joint error in rad) per look.
    """

    label: str
    reached: float
    grips: int
    path: float
    turn: float
    peak_force: float
    peak_torque: float
    held: np.ndarray
    final: np.ndarray
    kept: float
    duration: float
    beyond: float = math.nan
    pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)
    unreachable: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    trace: list[tuple[float, float]] = field(default_factory=list, repr=False)


def joint_errors(model: Model, body_quat: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Angle (rad) between each joint's rotation and its target (nj,4)."""
    rel = relative_rotations(model, body_quat)
    return np.linalg.norm(quat.log(quat.mul(target, quat.conj(rel))), axis=1)


def _chains(model: Model) -> list[list[int]]:
    """Per joint: itself and the joints between it and the root, nearest first."""
    on_bone = {int(b): j for j, b in enumerate(model.joint_bone)}
    chains = []
    for j in range(model.njoint):
        chain = [j]
        while (k := on_bone.get(int(model.joint_parent[chain[-1]]))) is not None:
            chain.append(k)
        chains.append(chain)
    return chains


class Operator:
    """A hand posing ``model`` from rest (gravity on), key after key."""

    def __init__(self, model: Model, hand: Hand) -> None:
        script = Script(source="<operator>", h=None, duration=None, gravity=True, actions=())
        self.model, self.hand = script_model(model, script), hand
        self.runner = Runner(self.model, script)
        self.runner.pointer_on = True
        self.runner.act(TouchMode(on=False))
        self.chains = _chains(self.model)
        along = self.model.bone_tail0 - self.model.bone_head0
        along = along[self.model.joint_bone]
        self.along = along / np.linalg.norm(along, axis=1)[:, None]  # (nj,3) bone axes at rest
        self.order = np.argsort([-len(c) for c in self.chains], kind="stable")
        self.grips = self.looks = self.over = 0
        self.path = self.turn = self.peak_torque = 0.0
        self.target: np.ndarray | None = None
        self.t_key = 0.0
        self.reached = math.nan
        self.trace: list[tuple[float, float]] = []

    # --- what the operator sees ---------------------------------------------------------

    def relative(self) -> np.ndarray:
        return relative_rotations(self.model, self.runner.sim.view().body_quat)

    def set_of(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(joint ``j``'s set exp(−q_sf) ⊗ q_rel, its rotation q_rel)."""
        rel = self.relative()[j]
        return quat.mul(quat.exp(-self.runner.sim.view().joint_q_sf[j]), rel), rel

    def set_error(self, j: int, aim: np.ndarray) -> np.ndarray:
        """What joint ``j``'s set lacks to be at ``aim`` (rotation vector, parent frame) and
        the hand can correct."""
        q_set, rel = self.set_of(j)
        e = quat.log(quat.mul(aim, quat.conj(q_set)))
        return self._free(e[None], rel[None], self.along[j][None])[0]

    def _look(self) -> None:
        """Record the pose's largest error now; the first time it is within 2°: reached."""
        state = self.runner.sim.view()
        worst = float(joint_errors(self.model, state.body_quat, self.target).max())
        self.trace.append((state.time - self.t_key, worst))
        if worst <= REACHED and math.isnan(self.reached):
            self.reached = state.time - self.t_key
        force, torque = (float(np.linalg.norm(w)) for w in self.runner.sim.wrench()[:2])
        self.peak_torque = max(self.peak_torque, torque)
        self.looks += 1
        self.over += force > self.hand.capacity[0] or torque > self.hand.capacity[1]

    def _advance(self, duration: float, look: bool = True) -> None:
        """Step ``duration`` s, looking every TICK."""
        end = self.runner.sim.time + duration
        while self.runner.sim.time < end - 0.5 * self.model.options.h:
            self.runner.advance(min(TICK, end - self.runner.sim.time))
            if look:
                self._look()

    def settle(self) -> None:
        """Leave the doll alone SETTLE s (from rest: it sags under gravity)."""
        self._advance(SETTLE, look=False)

    # --- what the hand does -------------------------------------------------------------

    def _reach(self, point: np.ndarray) -> None:
        """Move the free hand in a straight line to ``point``, turning it back to its home
        orientation on the way (a hand lets its wrist unwind between grips)."""
        pos, q = self.runner.motion.pose(self.runner.sim.time)
        distance = float(np.linalg.norm(point - pos))
        duration = max(SHORTEST, distance / MOVE_SPEED)
        self.runner.motion = Motion(self.runner.sim.time, duration, pos, q, point - pos,
                                    -quat.log(q))  # fmt: skip
        self.path += distance
        self._advance(duration)

    def _grip_point(self, b: int) -> np.ndarray:
        """Bone-local grip point (from the head, rest frame): GRIP_AT along the bone."""
        return GRIP_AT * (self.model.bone_tail0[b] - self.model.bone_head0[b])

    def _grip(self, b: int) -> None:
        local = self._grip_point(b)
        state = self.runner.sim.view()
        world = bone_points(self.model, state, (self.model.bone_head0[b] + local)[None],
                            bones=np.array([b]))[0]  # fmt: skip
        self._reach(world)
        self.runner.act(Grip(
            bone=self.model.bone_names[b], point=local, reach=GRIP_DEFAULTS["reach"],
            stiffness=self.hand.stiffness, damping=self.hand.damping,
            rot_stiffness=self.hand.rot_stiffness, rot_damping=self.hand.rot_damping,
            force_limit=self.hand.force_limit, torque_limit=self.hand.torque_limit,
            position_only=self.hand.dof == 3, line=0,
        ))  # fmt: skip
        self.grips += 1

    def _turn(self, j: int, goal: np.ndarray) -> None:
        """Turn the gripped bone of joint ``j`` about the joint so that its rotation
        becomes ``goal`` (parent frame)."""
        b, p = int(self.model.joint_bone[j]), int(self.model.joint_parent[j])
        state = self.runner.sim.view()
        q_parent = state.body_quat[p] if p < self.model.nbody else quat.IDENTITY
        change = quat.log(quat.mul(goal, quat.conj(self.relative()[j])))
        rotvec = quat.rotate(q_parent, change)
        pivot = bone_heads(self.model, state)[b]
        pos, q = self.runner.motion.pose(state.time)
        angle = float(np.linalg.norm(rotvec))
        duration = max(SHORTEST, angle / self._speed(j, change / max(angle, 1e-12)))
        self.runner.motion = Motion(state.time, duration, pos, q, np.zeros(3), rotvec, pivot)
        self.path += angle * float(np.linalg.norm(pos - pivot))
        self.turn += angle
        self._advance(duration)

    def _speed(self, j: int, u: np.ndarray) -> float:
        """The mean turning speed (rad/s) for joint ``j`` along ``u``: at most TURN_SPEED,
        and slow enough that the flow's torque, D_d times the joint's speed, stays at the
        yield torque at the minimum-jerk profile's peak (1.875 × the mean): a joint bent
        faster carries more than its yield torque to the joints up the chain, which then
        flow too."""
        dd = float(u * u @ self.model.joint_dd[j])
        tau = float(self.model.joint_yield[j])
        if not (math.isfinite(dd) and math.isfinite(tau)) or dd <= 0.0:
            return TURN_SPEED
        return min(TURN_SPEED, tau / dd / PEAK_SPEED)

    def _hold(self, j: int) -> None:
        """Hold still until joint ``j`` stops flowing and its bone is still (HOLD s at most)."""
        pos, q = self.runner.motion.pose(self.runner.sim.time)
        self.runner.motion = Motion(self.runner.sim.time, 0.0, pos, q, np.zeros(3), np.zeros(3))
        b = int(self.model.joint_bone[j])
        waited = 0.0
        while waited < HOLD:
            self._advance(TICK)
            waited += TICK
            state = self.runner.sim.view()
            spin = float(np.linalg.norm(state.body_vel[b, 3:]))
            if not state.joint_yielded[j] and spin < STILL:
                return

    # --- planning -----------------------------------------------------------------------

    def _free(self, e: np.ndarray, rel: np.ndarray, along: np.ndarray) -> np.ndarray:
        """The part of errors ``e`` (k,3, parent frames) of joints at rotations ``rel`` (k,4)
        with rest bone axes ``along`` (k,3) the hand can correct: all of it at 6 DOF, the
        swing (across the bone) at 3."""
        if self.hand.dof == 6:
            return e
        axis = quat.rotate(rel, along)
        return e - np.sum(e * axis, axis=1)[:, None] * axis

    def _split(self, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per joint, the error (rad) to ``target`` the hand can correct and the rest."""
        rel = self.relative()
        e = quat.log(quat.mul(target, quat.conj(rel)))
        free = self._free(e, rel, self.along)
        return np.linalg.norm(free, axis=1), np.linalg.norm(e - free, axis=1)

    def _give(self, j: int, u: np.ndarray) -> float:
        """How far (rad) past its aim a joint must be turned along ``u`` for its set to end
        at the aim, by the model: what it gives back (τ_y / K_f), and what the yield torque
        τ_y takes from the turn on the way, in the coupling (τ_y / its stiffness about the
        joint) and in the joints between the bone and the stand (Σ τ_y / K_f).  (Held by a
        point, the joints up the chain carry the grip's force on longer levers and give
        more; the operator learns that from the first turn.)"""
        tau = float(self.model.joint_yield[j])
        if not math.isfinite(tau):
            return 0.0
        chain = [float(u * u @ self.model.joint_kf[a]) for a in self.chains[j]]
        b = int(self.model.joint_bone[j])
        local = self._grip_point(b)
        arm = float(np.linalg.norm(local))
        across = math.sqrt(max(0.0, 1.0 - float(u @ local / max(arm, 1e-9)) ** 2))
        grip = self.hand.stiffness * (arm * across) ** 2  # about the joint
        grip += self.hand.rot_stiffness if self.hand.dof == 6 else 0.0
        return tau * sum(1.0 / k for k in (*chain, grip) if k > 0.0)

    def place(self, j: int, aim: np.ndarray) -> np.ndarray:
        """Grip joint ``j``'s bone and turn it until the joint's set is at ``aim``; let go.
        The joint's set when let go."""
        gripped, push, before = False, np.zeros(3), math.inf
        gives: dict[bool, float] = {}  # learnt, per side of the first turn
        first = None
        for _ in range(ATTEMPTS):
            e = self.set_error(j, aim)
            size = float(np.linalg.norm(e))
            if size < SET_TOLERANCE or size > before + PROGRESS:
                break  # placed, or going the wrong way: let go and look again
            if not gripped:
                self._grip(int(self.model.joint_bone[j]))
                gripped = True
            u = e / size
            first = u if first is None else first
            side = bool(u @ first > 0.0)
            if float(u @ push) > 0.0 and side not in gives:  # it did not flow: further
                push = push + GAIN * e
            else:  # past the aim by what it gives back this way (learnt, else the model's)
                push = u * gives.get(side, self._give(j, u))
            was = self.set_of(j)[0]
            self._turn(j, quat.mul(quat.exp(push), aim))
            self._hold(j)
            after = self.set_error(j, aim)
            moved = float(np.linalg.norm(quat.log(quat.mul(self.set_of(j)[0], quat.conj(was)))))
            if moved > LEARN * size:  # it flowed: what it gives back this way
                gives[side] = max(0.0, float((push + after) @ u))
            before = size
        kept = self.set_of(j)[0]
        if gripped:
            self.runner.act(Release(line=0))
        return kept

    def pose_key(self, label: str, target: np.ndarray) -> KeyResult:
        """Pose the doll from where it is to ``target`` (nj,4 joint rotations)."""
        self.target, self.t_key = target, self.runner.sim.time
        self.reached, self.trace = math.nan, []
        self.grips = self.looks = self.over = 0
        self.path = self.turn = self.peak_torque = 0.0
        self.runner.peak = 0.0
        start = self.relative()
        aim = target.copy()
        self._look()
        stuck: set[int] = set()  # joints a pass did not bring closer: left alone
        err = self._split(target)[0]
        for _ in range(PASSES):
            todo = [int(j) for j in self.order if err[j] > FIX and int(j) not in stuck]
            if not todo:
                break
            placed = self.relative()
            for j in todo:
                placed[j] = self.place(j, aim[j])
            self._advance(SETTLE)
            shift = quat.mul(self.relative(), quat.conj(placed))  # since let go: sag, creep
            for j in todo:
                aim[j] = quat.mul(quat.conj(shift[j]), target[j])
            now = self._split(target)[0]
            stuck |= {j for j in todo if now[j] > err[j] - PROGRESS}
            err = now
        held = joint_errors(self.model, self.runner.sim.view().body_quat, target)
        duration = self.runner.sim.time - self.t_key
        self._advance(RETAIN)
        final = joint_errors(self.model, self.runner.sim.view().body_quat, target)
        wanted = quat.log(quat.mul(target, quat.conj(start)))
        got = quat.log(quat.mul(self.relative(), quat.conj(start)))
        size = float(np.sum(wanted * wanted))
        kept = float(np.sum(wanted * got)) / size if size > 0.0 else math.nan
        unreachable = self._split(target)[1] if self.hand.dof == 3 else np.full(len(final), np.nan)
        beyond = self.over / self.looks if math.isfinite(sum(self.hand.capacity)) else math.nan
        return KeyResult(label, self.reached, self.grips, self.path, self.turn, self.runner.peak,
                         self.peak_torque, held, final, kept, duration, beyond,
                         self.relative(), unreachable, self.trace)  # fmt: skip


def run_task(model: Model, keys: list[tuple[str, np.ndarray]], hand: Hand) -> list[KeyResult]:
    """Pose ``keys`` ((label, joint rotations (nj,4)) in order) from rest, once the doll has
    settled under gravity."""
    operator = Operator(model, hand)
    operator.settle()
    return [operator.pose_key(label, target) for label, target in keys]
