"""What a run's keys become on disk: keyframes.json, keyframes.bvh, keyframes.glb (when asked),
keys/NNN.png, sheet.png.

One function for every command that captures keys (``pose`` and ``live``), so their
output folders have the same layout and the same contents for the same keys.  Every file is
made in a staging folder inside the output folder first and moved into place only when all
of them are made: a failure on the way (a render, a BVH) leaves the outputs of an earlier
run exactly as they were.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from puppetcli.bvh.write import write_keys_bvh
from puppetcli.gltf.export import write_glb
from puppetcli.outputs import OutputError
from puppetcli.render.camera import View
from puppetcli.render.picture import remove_stale_keys, render_keys
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import Keyframe, write_keyframes
from solver.spec import RigSpec

__all__ = ["KEY_OUTPUTS", "write_key_outputs"]

KEY_OUTPUTS = ["keyframes.json", "keyframes.bvh", "keyframes.glb", "sheet.png", "keys"]


def write_key_outputs(
    outdir: Path, spec: RigSpec, rig_name: str, keys: list[Keyframe], *, render: bool = True,
    order: str = "ZXY", fps: float = 30.0, scale: float = 1.0, interpolate: str | None = None,
    view: View | str = "iso", gltf: bool = False,
) -> list[Path]:  # fmt: skip
    """Write the keys' files into ``outdir``, all or none of them; the paths written.

    keyframes.glb (``gltf``) holds the keys as STEP keys at 1/fps apart, or, with
    ``interpolate="slerp"``, at their own times for viewers to interpolate."""
    outdir = Path(outdir)
    stage = _staging_folder(outdir)
    try:
        names = ["keyframes.json"]
        write_keyframes(stage / "keyframes.json", rig_name, keys)
        if keys:
            write_keys_bvh(
                stage / "keyframes.bvh", Skeleton.from_spec(spec), keys, order,
                scale=scale, fps=fps, interpolate=interpolate,
            )  # fmt: skip
            names.append("keyframes.bvh")
        if keys and gltf:
            interpolation = "STEP" if interpolate is None else "LINEAR"
            write_glb(stage / "keyframes.glb", spec, keys, fps, interpolation)
            names.append("keyframes.glb")
        if keys and render:
            render_keys(stage, Skeleton.from_spec(spec), keys, spec, view=view)
            names += ["sheet.png", "keys"]
        _commit(stage, outdir, names)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return [outdir / name for name in names]


def _staging_folder(outdir: Path) -> Path:
    try:
        return Path(tempfile.mkdtemp(prefix=".staging-", dir=outdir))
    except OSError as exc:
        raise OutputError(f"{outdir}: cannot write: {exc.strerror or exc}") from None


def _commit(stage: Path, outdir: Path, names: list[str]) -> None:
    """Move the staged outputs into ``outdir`` (renames within one file system)."""
    for name in names:
        if name == "keys":
            (outdir / "keys").mkdir(exist_ok=True)
            pictures = sorted(p.name for p in (stage / "keys").iterdir())
            for picture in pictures:
                _move(stage / "keys" / picture, outdir / "keys" / picture)
            remove_stale_keys(outdir / "keys", pictures)
        else:
            _move(stage / name, outdir / name)


def _move(source: Path, target: Path) -> None:
    try:
        os.replace(source, target)
    except OSError as exc:
        raise OutputError(f"{target}: cannot write: {exc.strerror or exc}") from None
