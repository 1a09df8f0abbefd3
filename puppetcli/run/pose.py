"""What ``pose`` does, for the command and for ``batch``: a rig and a script (or a
recorded session) in, the keys' files and the trace out.

``plan_pose`` reads the script or session for the rig and sets up the model;
``run_pose`` runs it, writing trace.mcap as it goes; ``write_pose`` writes the keys'
files (puppetcli.run.outputs).  The command adds its checks, progress bar and report
around them; a batch job runs them unchanged, so its outputs are ``pose``'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from puppetcli.mcap.replay import Replay, load_replay
from puppetcli.render.camera import View
from puppetcli.run.outputs import write_key_outputs
from puppetcli.run.runner import Runner, RunResult, script_model
from puppetcli.run.trace import RunTrace
from puppetcli.script.load import Script, load_script
from solver.model import Model, build_model
from solver.spec import RigSpec

__all__ = ["OUTPUTS", "Planned", "PoseOptions", "plan_pose", "run_pose", "write_pose"]

OUTPUTS = ["keyframes.json", "keyframes.bvh", "keyframes.glb", "trace.mcap", "sheet.png", "keys"]


@dataclass(frozen=True)
class PoseOptions:
    """``pose``'s options (its command-line flags, the same defaults)."""

    trace_every: int = 1
    no_trace: bool = False
    step: float | None = None
    no_render: bool = False
    order: str = "ZXY"
    fps: float = 30.0
    interpolate: str | None = None
    scale: float = 1.0
    gltf: bool = False
    view: View | str = "iso"

    def outputs(self) -> list[str]:
        """The names ``pose`` writes into its folder with these options."""
        skipped = {"trace.mcap"} if self.no_trace else set()
        skipped |= {"sheet.png", "keys"} if self.no_render else set()
        skipped |= set() if self.gltf else {"keyframes.glb"}
        return [name for name in OUTPUTS if name not in skipped]


@dataclass
class Planned:
    """A run set up: the rig, its model (the script's settings applied), the script, and
    the session's replay when the script is a recording."""

    spec: RigSpec
    model: Model
    plan: Script
    replay: Replay | None


def plan_pose(spec: RigSpec, script: Path, step: float | None) -> Planned:
    """Read ``script`` (YAML, or a session .mcap) for ``spec``: the run set up."""
    replay = load_replay(script, spec) if script.suffix.lower() == ".mcap" else None
    plan = replay.script if replay is not None else load_script(script, spec)
    model = script_model(build_model(spec), plan)
    if step is not None:
        model = model.with_options(h=step)
    return Planned(spec, model, plan, replay)


def run_pose(
    planned: Planned, outdir: Path, options: PoseOptions, upgrade=None, progress=None
) -> RunResult:
    """Run it on ``planned.model``, writing ``outdir``/trace.mcap unless ``no_trace``."""
    model, plan, replay = planned.model, planned.plan, planned.replay
    if replay is not None:
        runner = replay.runner(model, progress=progress)
    else:
        runner = Runner(model, plan, progress=progress)
    runner.upgrade = upgrade
    if options.no_trace:
        return runner.run()
    path, spidar = outdir / "trace.mcap", replay is not None
    with RunTrace(path, model, plan, options.trace_every, runner.pointer_on, spidar) as trace:
        runner.trace = trace
        return runner.run()


def write_pose(
    outdir: Path, planned: Planned, result: RunResult, options: PoseOptions
) -> list[Path]:
    """The keys' files (and the trace, already written): the paths."""
    written = write_key_outputs(
        outdir, planned.spec, planned.model.name, list(result.keys),
        render=not options.no_render, order=options.order.upper(), fps=options.fps,
        scale=options.scale, interpolate=options.interpolate, view=options.view,
        gltf=options.gltf,
    )  # fmt: skip
    return written + ([] if options.no_trace else [outdir / "trace.mcap"])
