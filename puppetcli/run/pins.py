"""The pins a run holds (script ``pin``/``unpin`` actions, a session's pin events, the live
page's modifier-clicks): made where the bone is, kept until unpinned, moved to where the
point is when they slip (solver.rows.pin)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver import quat
from solver.model import Model
from solver.observe import bone_points
from solver.rows.pin import Pin, make_pin, retarget
from solver.state import State, StepReport


@dataclass
class PinBoard:
    """The run's pins, in the order they were made: ``pins`` is what a step takes
    (StepInput.pins, one tuple kept while nothing changes, so the compiled step packs it
    once)."""

    model: Model
    pins: tuple[Pin, ...] = ()
    names: tuple[str, ...] = field(default=())

    def __bool__(self) -> bool:
        return bool(self.pins)

    def pin(
        self, state: State, bone: str, world: np.ndarray | None = None, orient: bool = False,
        force_limit: float = np.inf, torque_limit: float = np.inf,
    ) -> Pin:  # fmt: skip
        """Pin ``bone`` where it is in ``state``: the point at ``world`` (m; None: the
        bone's centre of mass), its orientation too when ``orient``.  A bone pinned already
        is pinned again (its old pin goes)."""
        self.unpin(bone)
        b = self.model.bone_names.index(bone)
        point = None
        if world is not None:
            point = quat.rotate(quat.conj(state.body_quat[b]), world - state.body_pos[b])
        new = make_pin(state, b, point, orient, force_limit, torque_limit)
        self.pins, self.names = (*self.pins, new), (*self.names, bone)
        return new

    def pin_rest_point(self, state: State, bone: str, rest_offset: np.ndarray | None,
                       **options) -> Pin:  # fmt: skip
        """``pin`` at the point ``rest_offset`` from the bone's head in its rest pose (a
        script's ``point``; None: the centre of mass)."""
        world = None
        if rest_offset is not None:
            b = self.model.bone_names.index(bone)
            rest = self.model.bone_head0[b] + rest_offset
            world = bone_points(self.model, state, rest[None], bones=np.array([b]))[0]
        return self.pin(state, bone, world, **options)

    def unpin(self, bone: str | None = None) -> bool:
        """Drop the pin on ``bone`` (None: every pin); False when there was none."""
        keep = [i for i, name in enumerate(self.names) if bone is not None and name != bone]
        if len(keep) == len(self.names):
            return False
        self.pins = tuple(self.pins[i] for i in keep)
        self.names = tuple(self.names[i] for i in keep)
        return True

    def after_step(self, state: State, report: StepReport) -> tuple[str, ...]:
        """Move the pins that slipped in the step that made ``state`` to where their points
        now are; returns their bones."""
        slip = report.pin_slip
        if len(slip) != len(self.pins) or not slip.any():
            return ()
        self.pins = retarget(self.pins, state, slip)
        return tuple(name for name, s in zip(self.names, slip, strict=True) if s)
