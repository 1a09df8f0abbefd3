"""Between the simulation and the script: loads from `push`, keyframes from states."""

from __future__ import annotations

import numpy as np

from puppetcli.run.keyframes import BonePose, Keyframe
from puppetcli.script.load import Push
from solver import quat
from solver.model import Model
from solver.observe import bone_heads, relative_rotations
from solver.state import State, StepInput


def push_input(model: Model, state: State, push: Push) -> StepInput:
    """Force and torque about the bone's centre of mass for a push at a bone-local point."""
    b = model.bone_names.index(push.bone)
    local = model.bone_head0[b] - model.body_pos0[b] + push.point
    arm = quat.rotate(state.body_quat[b], local)
    force = np.zeros((model.nbody, 3))
    torque = np.zeros((model.nbody, 3))
    force[b] = push.force
    torque[b] = push.torque + quat.cross(arm, push.force)
    return StepInput(body_force=force, body_torque=torque)


def capture(model: Model, state: State, label: str, extra: dict) -> Keyframe:
    """A keyframe of every bone: head position, rotation from rest, joint rotation from rest.

    A root without a joint gets its rotation relative to the world as ``local``.
    """
    nbone = len(model.bone_names)
    heads = bone_heads(model, state)
    rotation = state.body_quat[:nbone]
    local = rotation.copy()
    local[model.joint_bone] = relative_rotations(model, state.body_quat)
    bones = {
        name: BonePose(head=heads[i], rotation=rotation[i], local=local[i])
        for i, name in enumerate(model.bone_names)
    }
    # The step grid's time, not the sum of the steps' floats: 2.0, not 1.9999999999999793.
    return Keyframe(time=round(state.time, 9), label=label, bones=bones, extra=extra)
