"""The pins in a run's trace (puppetcli.run.trace), for runs that pin:

- ``/puppet/pins`` (foxglove.SceneUpdate): a ball where each pin holds its point and a
  line along the force it puts on the bone (PIN_METRES_PER_NEWTON);
- ``/puppet/pin_force`` (puppetcli.Pins): each pin's bone, target, force, torque, slip;
- ``/log`` (foxglove.Log): a warning when a pin starts slipping (its force reached its limit).
"""

from __future__ import annotations

import numpy as np

from puppetcli.mcap.trace import foxglove_time, ns_from_seconds, scene_update
from solver.model import Model
from solver.state import StepInput, StepReport

PIN_COLOR = {"r": 0.2, "g": 0.6, "b": 1.0, "a": 1.0}
FORCE_COLOR = {"r": 0.2, "g": 0.9, "b": 0.9, "a": 1.0}
PIN_DIAMETER = 0.03  # m
PIN_METRES_PER_NEWTON = 0.005  # the force line's length per newton
WARNING = 3  # foxglove.LogLevel
CHANNELS = {
    "/puppet/pins": "foxglove.SceneUpdate",
    "/puppet/pin_force": "puppetcli.Pins",
    "/log": "foxglove.Log",
}


class PinMessages:
    """The pin messages of the steps a trace writes, and a log line per slip that starts."""

    def __init__(self, model: Model, source: str) -> None:
        self.model, self.source = model, source
        self.started = False  # the run has pinned: its trace has the pin channels
        self._slipping: set[int] = set()  # bones whose pin slipped last step

    def slips(self, t: float, inp: StepInput, report: StepReport) -> list[tuple]:
        """(topic, t, message) of a log line for each pin that started slipping this step."""
        out = []
        now = {p.bone for p, s in zip(inp.pins, report.pin_slip, strict=False) if s}
        for k, pin in enumerate(inp.pins):
            if pin.bone in now and pin.bone not in self._slipping:
                force = float(np.linalg.norm(report.pin_force[k]))
                text = (f"pin on '{self.model.bone_names[pin.bone]}' slipped at t = {t:.3f} s "
                        f"({force:.3g} N): its force reached its limit")  # fmt: skip
                out.append(("/log", t, self._log(t, text)))
        self._slipping = now
        return out

    def step(self, t: float, inp: StepInput, report: StepReport) -> list[tuple]:
        """(topic, t, message) of ``/puppet/pins`` and ``/puppet/pin_force`` for a step."""
        pins = inp.pins
        force = report.pin_force if len(report.pin_force) == len(pins) else np.zeros((len(pins), 3))
        torque = report.pin_torque if len(report.pin_torque) == len(pins) else np.zeros_like(force)
        slip = report.pin_slip if len(report.pin_slip) == len(pins) else np.zeros(len(pins), bool)
        targets = np.array([p.target for p in pins]).reshape(-1, 3)
        ends = targets + PIN_METRES_PER_NEWTON * force
        scene = scene_update(
            foxglove_time(ns_from_seconds(t)), "pins", np.stack((targets, ends), axis=1),
            targets, FORCE_COLOR, PIN_COLOR, PIN_DIAMETER,
        )  # fmt: skip
        listed = [
            {"bone": self.model.bone_names[p.bone], "target": targets[k].tolist(),
             "orient": bool(p.orient), "force": force[k].tolist(), "torque": torque[k].tolist(),
             "slipped": bool(slip[k])}
            for k, p in enumerate(pins)
        ]  # fmt: skip
        return [("/puppet/pins", t, scene), ("/puppet/pin_force", t, {"t": t, "pins": listed})]

    def _log(self, t: float, text: str) -> dict:
        return {
            "timestamp": foxglove_time(ns_from_seconds(t)), "level": WARNING, "message": text,
            "name": "puppetcli.pins", "file": self.source, "line": 0,
        }  # fmt: skip
