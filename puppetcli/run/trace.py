"""The trace of a run: the simulator's step channels plus the device, haptics and keys.

Channels added to trace.mcap's step channels (see puppetcli.mcap.trace):
`/device/pose` (puppetcli.DevicePose), `/haptic/wrench` (puppetcli.HapticWrench),
`/puppet/keyframe` (puppetcli.KeyframeEvent, when a key is taken) and
`/puppet/pointer` (foxglove.SceneUpdate: the pointer and, in grip mode, the
coupling line to the grip point).  Device channels exist only for scripts that
use the pointer.  A run's first pin adds `/puppet/pins`, `/puppet/pin_force` and `/log`
(puppetcli.run.pin_trace).  Session replays (``spidar=True``) add `/spidar/tensions`
(puppetcli.SpidarTensions: string tensions and the displayed wrench Aᵀt) and
`/spidar/estimate` (puppetcli.SpidarEstimate: the estimated grip pose).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from puppetcli.mcap.template import MessageTemplate, Slot, slots
from puppetcli.mcap.trace import (
    TIME_SLOTS,
    TraceWriter,
    clock,
    load_schema,
    ns_from_seconds,
    scene_update,
)
from puppetcli.run.pin_trace import CHANNELS as PIN_CHANNELS
from puppetcli.run.pin_trace import PinMessages
from puppetcli.script.load import Script
from puppetcli.spidar.pointer import device_from_world
from solver import quat
from solver.model import Model
from solver.observe import points_on_bones, relative_rotations
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


BATCH = 64  # steps whose frames are computed together: numpy's cost per call, amortised


@dataclass
class _Step:
    """What a trace keeps of a step until it writes it (``RunTrace.flush``)."""

    t: float
    body_pos: np.ndarray
    body_quat: np.ndarray
    elastic: np.ndarray
    torque: np.ndarray
    stats: dict
    device: tuple | None  # (pointer position, orientation, coupling, requested, displayed)


class RunTrace:
    """Writes every ``every``-th step (and every key) of a run.

    Steps are kept and written ``BATCH`` at a time (their frames computed together), in
    the order they came with the other messages; everything is written by ``flush``,
    which closing the trace calls, also when the run fails."""

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
        self._pins = PinMessages(model, script.source)
        channels = (CHANNELS if pointer else {}) | (SPIDAR_CHANNELS if spidar else {})
        for topic, name in channels.items():
            self.writer.add_channel(topic, name, load_schema(name))
        self._pending: list[_Step | tuple[str, float, dict]] = []
        self._steps = 0
        self._device = DeviceMessages(model.bone_names, script)

    def __enter__(self) -> RunTrace:
        self.writer.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.flush()
        finally:
            self.writer.__exit__(*exc)

    def keyframe(self, t: float, label: str, line: int, index: int, undo: bool = False) -> None:
        """A key taken (``index`` from 1), or with ``undo`` the key ``index`` dropped."""
        event = {"t": t, "label": label, "line": line, "index": index}
        self._pending.append(("/puppet/keyframe", t, event | ({"undo": True} if undo else {})))

    def step(self, s: State, report: StepReport, inp: StepInput, coupling: Coupling | None,
             requested: tuple, displayed: tuple) -> None:  # fmt: skip
        pinned = self._pinned(inp)
        if pinned:
            self._pending.extend(self._pins.slips(s.time, inp, report))
        if s.step % self.every:
            return
        device = None
        if self.pointer and inp.pointer is not None:
            ptr = inp.pointer
            device = (ptr.pos.copy(), ptr.quat.copy(), coupling, requested, displayed)
        self._pending.append(_Step(
            s.time, s.body_pos.copy(), s.body_quat.copy(), s.joint_q_sf.copy(),
            s.joint_torque.copy(),
            dict(rows=report.rows, contacts=report.contacts, iterations=report.iterations,
                 residual=report.residual, solver=report.solver),
            device,
        ))  # fmt: skip
        if pinned:
            self._pending.extend(self._pins.step(s.time, inp, report))
        self._steps += 1
        if self._steps >= BATCH:
            self.flush()

    def _pinned(self, inp: StepInput) -> bool:
        """True once the run has pinned (its first pin adds the pin channels)."""
        if inp.pins and not self._pins.started:
            self._pins.started = True
            for topic, name in PIN_CHANNELS.items():
                self.writer.add_channel(topic, name, load_schema(name))
        return self._pins.started

    def spidar(self, s: State, track, k: int, shown, wanted: tuple) -> None:
        """The device's side of a replayed step: estimate at tick k, tensions, Aᵀt."""
        if s.step % self.every:
            return
        self._pending.append(("/spidar/estimate", s.time, {
            "t": s.time,
            "device": {"position": track.device_pos[k], "orientation": track.device_quat[k]},
            "world": {"position": track.world_pos[k], "orientation": track.world_quat[k]},
        }))  # fmt: skip
        message = tensions_message(s.time, shown, wanted)
        self._pending.append(("/spidar/tensions", s.time, message))

    def flush(self) -> None:
        """Write everything kept, in order."""
        pending, self._pending, self._steps = self._pending, [], 0
        lead, steps, after = [], [], []  # messages before the first step; steps; after each
        for item in pending:
            if isinstance(item, _Step):
                steps.append(item)
                after.append([])
            else:
                (after[-1] if after else lead).append(item)
        for item in lead:
            self.writer.write(*item)
        if not steps:
            return
        m, nb = self.model, len(self.model.bone_names)
        pos = np.stack([step.body_pos for step in steps])
        quats = np.stack([step.body_quat for step in steps])

        def then(i: int) -> None:
            if steps[i].device is not None:
                self._device.write(self.writer, steps[i].t, pos[i], quats[i], steps[i].device)
            for item in after[i]:
                self.writer.write(*item)

        self.writer.write_steps(
            [step.t for step in steps],
            quat.log(relative_rotations(m, quats)),
            np.stack([step.elastic for step in steps]),
            np.stack([step.torque for step in steps]),
            points_on_bones(m, pos, quats, m.bone_head0),
            points_on_bones(m, pos, quats, m.bone_tail0),
            quats[:, :nb],
            [step.stats for step in steps],
            then,
        )


def device_pose_message(t, position, orientation, device_position, bone: str | None) -> dict:
    """``/device/pose``: the pointer in the world and the device, and the grip mode."""
    return {
        "t": t, "position": position, "orientation": orientation,
        "device_position": device_position,
        "mode": "free" if bone is None else "grip", "bone": bone,
    }  # fmt: skip


class DeviceMessages:
    """``/device/pose``, ``/haptic/wrench`` and ``/puppet/pointer`` of a step, written with
    message templates (puppetcli.mcap.template), made for each grip mode when first met."""

    def __init__(self, bone_names: list[str], script: Script) -> None:
        self.bone_names, self.script = bone_names, script
        self._poses: dict[str | None, MessageTemplate] = {}
        self._pointers: dict[int, MessageTemplate] = {}
        pair = (slots("force", (3,)), slots("torque", (3,)))
        pair_shown = (slots("force_shown", (3,)), slots("torque_shown", (3,)))
        self._wrench = MessageTemplate(
            wrench_message(Slot("t"), pair, pair_shown),
            [("t", 1), ("force", 3), ("torque", 3), ("force_shown", 3), ("torque_shown", 3)],
        )

    def write(self, writer: TraceWriter, t: float, body_pos, body_quat, device) -> None:
        """The three messages at ``t``; ``device``: as ``_Step.device``."""
        ptr_pos, ptr_quat, coupling, requested, displayed = device
        sc = self.script
        bone = None if coupling is None else self.bone_names[coupling.body]
        where = device_from_world(ptr_pos, sc.workspace_offset, sc.workspace_scale)
        position = ptr_pos.tolist()
        writer.write_encoded("/device/pose", t, self._pose(bone).fill(
            [t, *position, *ptr_quat.tolist(), *where.tolist()]))  # fmt: skip
        writer.write_encoded("/haptic/wrench", t, self._wrench.fill(
            [t, *requested[0], *requested[1], *displayed[0], *displayed[1]]))  # fmt: skip
        segment = []
        if coupling is not None:
            b = coupling.body
            grip = body_pos[b] + quat.rotate(body_quat[b], coupling.anchor)
            segment = [*position, *grip.tolist()]
        fill = [*clock(ns_from_seconds(t)), *position, *segment]
        writer.write_encoded("/puppet/pointer", t, self._pointer(len(segment) // 6).fill(fill))

    def _pose(self, bone: str | None) -> MessageTemplate:
        """The ``/device/pose`` template with ``bone`` gripped (None: free mode)."""
        if bone not in self._poses:
            shape = device_pose_message(Slot("t"), slots("position", (3,)).tolist(),
                                        slots("orientation", (4,)).tolist(),
                                        slots("device", (3,)).tolist(), bone)  # fmt: skip
            groups = [("t", 1), ("position", 3), ("orientation", 4), ("device", 3)]
            self._poses[bone] = MessageTemplate(shape, groups)
        return self._poses[bone]

    def _pointer(self, segments: int) -> MessageTemplate:
        """The ``/puppet/pointer`` template with ``segments`` coupling lines (0 or 1)."""
        if segments not in self._pointers:
            stamp, time_groups = TIME_SLOTS
            shape = pointer_scene(stamp, slots("segment", (segments, 2, 3)),
                                  slots("centre", (1, 3)), self.script)  # fmt: skip
            groups = [*time_groups, ("centre", 3), ("segment", 6 * segments)]
            self._pointers[segments] = MessageTemplate(shape, groups)
        return self._pointers[segments]


def pointer_scene(stamp: dict, segments, centres, script: Script) -> dict:
    """``/puppet/pointer``: the pointer's ball and, in grip mode, the coupling line."""
    diameter = max(2.0 * script.pointer_radius, 0.01)
    return scene_update(stamp, "pointer", segments, centres, COUPLING_COLOR, POINTER_COLOR,
                        diameter)  # fmt: skip
