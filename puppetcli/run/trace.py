"""The trace of a run: the simulator's step channels plus the device, haptics and keys.

Channels added to trace.mcap's step channels (see puppetcli.mcap.trace):
`/device/pose` (puppetcli.DevicePose), `/haptic/wrench` (puppetcli.HapticWrench),
`/puppet/keyframe` (puppetcli.KeyframeEvent, when a key is taken) and
`/puppet/pointer` (foxglove.SceneUpdate: the pointer and, in grip mode, the
coupling line to the grip point).  Device channels exist only for scripts that
use the pointer.  Session replays (``spidar=True``) add `/spidar/tensions`
(puppetcli.SpidarTensions: string tensions and the displayed wrench Aᵀt) and
`/spidar/estimate` (puppetcli.SpidarEstimate: the estimated grip pose).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from puppetcli.mcap.trace import TraceWriter, line_scene, load_schema
from puppetcli.script.load import Script
from puppetcli.spidar.pointer import device_from_world
from solver import quat
from solver.model import Model
from solver.observe import bone_heads, bone_tails, joint_rotations
from solver.rows.grip import Coupling
from solver.state import State, StepInput, StepReport

POINTER_COLOR = {"r": 1.0, "g": 0.3, "b": 0.2, "a": 1.0}
COUPLING_COLOR = {"r": 1.0, "g": 0.8, "b": 0.1, "a": 1.0}
CHANNELS = {
    "/device/pose": "puppetcli.DevicePose",
    "/haptic/wrench": "puppetcli.HapticWrench",
    "/puppet/pointer": "foxglove.SceneUpdate",
}
SPIDAR_CHANNELS = {
    "/spidar/tensions": "puppetcli.SpidarTensions",
    "/spidar/estimate": "puppetcli.SpidarEstimate",
}


def wrench_message(t: float, requested: tuple, displayed: tuple) -> dict:
    """``/haptic/wrench``: the (force, torque) the hand should feel and what it was shown."""
    return {
        "t": t,
        "requested": {"force": _list(requested[0]), "torque": _list(requested[1])},
        "displayed": {"force": _list(displayed[0]), "torque": _list(displayed[1])},
    }


def _list(v) -> list[float]:
    """A vector as the list JSON writes (cheaper than the encoders' numpy fallback)."""
    return v.tolist() if isinstance(v, np.ndarray) else list(v)


def tensions_message(t: float, shown, wanted: tuple) -> dict:
    """``/spidar/tensions``: the tension programme's tensions and displayed wrench Aᵀt for
    the wanted (force, torque) in the device frame."""
    return {
        "t": t, "tensions": _list(shown.tensions),
        "displayed": {"force": _list(shown.force), "torque": _list(shown.torque)},
        "wanted": {"force": _list(wanted[0]), "torque": _list(wanted[1])},
        "converged": bool(shown.converged),
    }  # fmt: skip


class RunTrace:
    """Writes every ``every``-th step (and every key) of a run."""

    def __init__(
        self, path: Path, model: Model, script: Script, every: int, pointer: bool,
        spidar: bool = False,
    ) -> None:  # fmt: skip
        self.model, self.script, self.every, self.pointer = model, script, every, pointer
        self.writer = TraceWriter(
            path, model.bone_names, list(model.bone_parent), model.joint_names
        )
        self.writer.add_channel(
            "/puppet/keyframe", "puppetcli.KeyframeEvent", load_schema("puppetcli.KeyframeEvent")
        )
        channels = (CHANNELS if pointer else {}) | (SPIDAR_CHANNELS if spidar else {})
        for topic, name in channels.items():
            self.writer.add_channel(topic, name, load_schema(name))

    def __enter__(self) -> RunTrace:
        self.writer.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.writer.__exit__(*exc)

    def keyframe(self, t: float, label: str, line: int, index: int, undo: bool = False) -> None:
        """A key taken (``index`` from 1), or with ``undo`` the key ``index`` dropped."""
        event = {"t": t, "label": label, "line": line, "index": index}
        self.writer.write("/puppet/keyframe", t, event | ({"undo": True} if undo else {}))

    def step(self, s: State, report: StepReport, inp: StepInput, coupling: Coupling | None,
             requested: tuple, displayed: tuple) -> None:  # fmt: skip
        if s.step % self.every:
            return
        m = self.model
        self.writer.write_step(
            s.time, joint_rotation=joint_rotations(m, s), joint_elastic=s.joint_q_sf,
            joint_torque=s.joint_torque, bone_head=bone_heads(m, s), bone_tail=bone_tails(m, s),
            bone_quat=s.body_quat[: len(m.bone_names)],
            stats=dict(rows=report.rows, contacts=report.contacts, iterations=report.iterations,
                       residual=report.residual, solver=report.solver),
        )  # fmt: skip
        if self.pointer and inp.pointer is not None:
            self._device(s, inp.pointer, coupling, requested, displayed)

    def spidar(self, s: State, track, k: int, shown, wanted: tuple) -> None:
        """The device's side of a replayed step: estimate at tick k, tensions, Aᵀt."""
        if s.step % self.every:
            return
        self.writer.write("/spidar/estimate", s.time, {
            "t": s.time,
            "device": {"position": track.device_pos[k], "orientation": track.device_quat[k]},
            "world": {"position": track.world_pos[k], "orientation": track.world_quat[k]},
        })  # fmt: skip
        self.writer.write("/spidar/tensions", s.time, tensions_message(s.time, shown, wanted))

    def _device(
        self, s: State, ptr, coupling: Coupling | None, requested: tuple, displayed: tuple
    ) -> None:
        sc = self.script
        bone = None if coupling is None else self.model.bone_names[coupling.body]
        self.writer.write("/device/pose", s.time, {
            "t": s.time, "position": ptr.pos, "orientation": ptr.quat,
            "device_position": device_from_world(ptr.pos, sc.workspace_offset, sc.workspace_scale),
            "mode": "free" if coupling is None else "grip", "bone": bone,
        })  # fmt: skip
        self.writer.write("/haptic/wrench", s.time, wrench_message(s.time, requested, displayed))
        segments = np.zeros((0, 2, 3))
        if coupling is not None:
            b = coupling.body
            grip = s.body_pos[b] + quat.rotate(s.body_quat[b], coupling.anchor)
            segments = np.array([[ptr.pos, grip]])
        scene = line_scene(_ns(s.time), "pointer", segments, ptr.pos[None], COUPLING_COLOR,
                           POINTER_COLOR, max(2.0 * sc.pointer_radius, 0.01))  # fmt: skip
        self.writer.write("/puppet/pointer", s.time, scene)


def _ns(t: float) -> int:
    return round(t * 1e9)
