"""`expect` actions: assertions on a joint's rotation or a bone's position at a moment.

Angles: the joint's rotation from rest as a rotation vector in the parent frame;
`angle` is its norm.  Positions: the bone's head in the world.  A failed
expectation does not stop the run; ``puppetcli pose`` reports every result and
exits non-zero when any failed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from puppetcli.script.actions import Expect
from solver.model import Model
from solver.observe import bone_heads, joint_rotations
from solver.state import State


@dataclass(frozen=True)
class ExpectResult:
    """passed, and a one-line message naming the script line, what was expected and found."""

    passed: bool
    message: str


def check(model: Model, state: State, exp: Expect, source: str) -> ExpectResult:
    """Evaluate one expectation on the current state."""
    where = f"{source}:{exp.line}: at t = {state.time:.3f} s"
    if exp.bone is not None:
        head = bone_heads(model, state)[model.bone_names.index(exp.bone)]
        error = float(np.linalg.norm(head - exp.head))
        return ExpectResult(
            error <= exp.tolerance,
            f"{where}: {exp.bone} head expected at {_fmt(exp.head)} ± {exp.tolerance:g} m, "
            f"got {_fmt(head)} ({error:.4f} m off)",
        )
    rot = joint_rotations(model, state)[model.joint_names.index(exp.joint)]
    angle = float(np.linalg.norm(rot))
    if exp.rotation is not None:
        error = float(np.linalg.norm(rot - exp.rotation))
        ok = error <= exp.tolerance
        wanted = f"rotation {_fmt(np.degrees(exp.rotation))}° ± {np.degrees(exp.tolerance):g}°"
        got = f"{_fmt(np.degrees(rot))}°"
    elif exp.angle is not None:
        ok = abs(angle - exp.angle) <= exp.tolerance
        wanted = f"angle {np.degrees(exp.angle):g}° ± {np.degrees(exp.tolerance):g}°"
        got = f"{np.degrees(angle):.2f}°"
    else:
        lo = exp.min_angle if exp.min_angle is not None else 0.0
        hi = exp.max_angle if exp.max_angle is not None else np.inf
        ok = lo <= angle <= hi
        wanted = f"angle in [{np.degrees(lo):g}°, {np.degrees(hi):g}°]"
        got = f"{np.degrees(angle):.2f}°"
    return ExpectResult(ok, f"{where}: joint {exp.joint} {wanted}, got {got}")


def _fmt(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in v) + "]"
