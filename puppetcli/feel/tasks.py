"""A posing task for ``feel --task``: a keyframes.json whose keys are the target poses.

Every key gives each bone's ``local`` rotation (its joint's rotation from rest, parent
frame); the operator poses the doll to the keys in order, starting from rest.  Any
keyframes.json of the rig will do: ``pose``'s and ``live``'s, or a shipped task
(scripts/tasks/).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from puppetcli.run.keyframes import KeyframesError, read_keyframes
from solver.model import Model

__all__ = ["read_task"]


def read_task(path: Path, model: Model) -> list[tuple[str, np.ndarray]]:
    """(label, joint rotations (nj,4)) per key of ``path``, for ``model``'s joints."""
    _, keys = read_keyframes(path)
    if not keys:
        raise KeyframesError(f"{path}:keys: expected at least one target key, got none")
    bones = [model.bone_names[b] for b in model.joint_bone]
    missing = [name for name in bones if name not in keys[0].bones]
    if missing:
        raise KeyframesError(
            f"{path}:keys[0].bones: expected the rig's bone {missing[0]!r} "
            f"(a task for rig {model.name!r}), got no such bone"
        )
    return [(key.label, np.array([key.bones[name].local for name in bones])) for key in keys]
