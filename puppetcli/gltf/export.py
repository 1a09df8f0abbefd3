"""keyframes.glb of a rig: its own character's file animated when the rig was made from one
(``rig from-gltf``), else the doll drawn from the rig's shapes."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from puppetcli.gltf.character import write_character_glb
from puppetcli.gltf.write import write_keys_glb
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe
from solver.spec import RigSpec

__all__ = ["write_glb"]


def write_glb(
    path: Path,
    spec: RigSpec,
    keys: Sequence[Keyframe],
    fps: float = 30.0,
    interpolation: str = "STEP",
) -> None:
    """Write ``keys`` of ``spec``'s rig as a .glb file, atomically."""
    skel = Skeleton.from_spec(spec)
    if spec.character is not None:
        write_character_glb(path, spec.character, skel, keys, fps, interpolation)
    else:
        write_keys_glb(path, skel, keys, spec.name, fps, interpolation)
