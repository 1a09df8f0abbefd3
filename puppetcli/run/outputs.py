"""What a run's keys become on disk: keyframes.json, keyframes.bvh, keys/NNN.png, sheet.png.

One function for every command that captures keys (``pose`` and ``live``), so their
output folders have the same layout and the same contents for the same keys.
"""

from __future__ import annotations

from pathlib import Path

from puppetcli.bvh.write import write_keys_bvh
from puppetcli.render.camera import View
from puppetcli.render.picture import render_keys
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe, write_keyframes
from solver.spec import RigSpec

__all__ = ["KEY_OUTPUTS", "write_key_outputs"]

KEY_OUTPUTS = ["keyframes.json", "keyframes.bvh", "sheet.png", "keys"]


def write_key_outputs(
    outdir: Path, spec: RigSpec, rig_name: str, keys: list[Keyframe], *, render: bool = True,
    order: str = "ZXY", fps: float = 30.0, scale: float = 1.0, interpolate: str | None = None,
    view: View | str = "iso",
) -> list[Path]:  # fmt: skip
    """Write the keys' files into ``outdir`` (atomically, each); the paths written."""
    written = [outdir / "keyframes.json"]
    write_keyframes(written[0], rig_name, keys)
    if not keys:
        return written
    write_keys_bvh(
        outdir / "keyframes.bvh", Skeleton.from_spec(spec), keys, order,
        scale=scale, fps=fps, interpolate=interpolate,
    )  # fmt: skip
    written.append(outdir / "keyframes.bvh")
    if render:
        render_keys(outdir, Skeleton.from_spec(spec), keys, spec, view=view)
        written += [outdir / "sheet.png", outdir / "keys"]
    return written
