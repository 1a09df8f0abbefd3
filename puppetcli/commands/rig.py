"""``puppetcli rig from-bvh FILE.bvh -o RIG.yaml`` and ``rig from-gltf FILE.glb -o RIG.yaml``:
make a rig from a BVH skeleton or a skinned glTF character."""

from __future__ import annotations

import os
from pathlib import Path

import click

from puppetcli.bvh.read import read_bvh
from puppetcli.bvh.rig import check_frame, rig_text_from_bvh
from puppetcli.bvh.units import infer_unit
from puppetcli.commands.options import SCALE, force_option
from puppetcli.gltf.read import read_gltf
from puppetcli.gltf.rig import rig_text_from_gltf
from puppetcli.outputs import refuse_overwrite
from puppetcli.rig.make import write_rig

RIG_OUT = click.option(
    "-o", "--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
    help="The rig file to write (YAML).",
)  # fmt: skip


@click.group("rig")
def command() -> None:
    """Make rigs from other formats."""


@command.command("from-bvh")
@click.argument("bvh_file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@RIG_OUT
@click.option(
    "--frame",
    type=click.IntRange(min=0),
    default=None,
    help="Take the rest pose from this frame (0 = the first) instead of the OFFSETs.",
)
@click.option(
    "--scale",
    type=SCALE,
    default=None,
    help="Metres per file unit [default: inferred from the skeleton's size, see docs/bvh.md].",
)
@force_option("RIG.yaml if it exists")
def from_bvh(
    bvh_file: Path, out: Path, frame: int | None, scale: float | None, force: bool
) -> None:
    """Turn the skeleton of BVH_FILE into a rig that `puppetcli validate` accepts.

    Every joint becomes a capsule bone (a small sphere where a bone has no
    length), sized from the skeleton, with masses from a density of water, the
    example doll's joint settings (strengthened where a joint carries a heavy
    subtree) and a fixed root.  See docs/bvh.md.
    """
    refuse_overwrite(out, force)
    bvh = read_bvh(bvh_file)
    check_frame(bvh, frame)
    if scale is None:
        unit = infer_unit(bvh)
        scale = unit.scale
        click.echo(f"note: {unit.note()}", err=True)
        if unit.warning:
            click.echo(f"warning: {unit.warning}", err=True)
    pose = f"frame {frame}" if frame is not None else "its OFFSETs (rest pose)"
    note = f"Made by `puppetcli rig from-bvh` from {bvh_file.name}, {pose}, scale {scale:g} m/unit."
    text = rig_text_from_bvh(bvh, bvh_file.stem, scale, frame, note)
    _write_rig(out, text, f"{bvh_file} ({pose}, scale {scale:g})")


def _write_rig(out: Path, text: str, what: str) -> None:
    model = write_rig(out, text)
    click.echo(
        f"wrote {out}: {len(model.bone_names)} bones from {what}, {model.body_mass.sum():.3f} kg"
    )


@command.command("from-gltf")
@click.argument("gltf_file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@RIG_OUT
@click.option(
    "--skin",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="The skin (skeleton) to take, when the file has several.",
)
@force_option("RIG.yaml if it exists")
def from_gltf(gltf_file: Path, out: Path, skin: int, force: bool) -> None:
    """Turn the skeleton of a skinned glTF 2.0 character (.glb or .gltf) into a rig.

    Bones are the skin's joints at the bind pose; capsule shapes and masses
    come from the mesh vertices bound to each joint; joints and ground as `rig
    from-bvh` makes them.  The rig remembers the file: `pose --gltf` and
    `convert -o OUT.glb` then write the character itself, animated by the keys.
    See docs/gltf.md.
    """
    refuse_overwrite(out, force)
    g = read_gltf(gltf_file)
    character = os.path.relpath(gltf_file.resolve(), out.resolve().parent)
    note = f"Made by `puppetcli rig from-gltf` from {gltf_file.name}, skin {skin}, bind pose."
    text = rig_text_from_gltf(g, skin, gltf_file.stem, note, character)
    _write_rig(out, text, f"{gltf_file} (skin {skin}, bind pose)")
