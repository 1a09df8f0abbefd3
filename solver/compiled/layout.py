"""Every packed structure of the compiled step, each written once, here.

A structure is a named tuple of arrays (and of other structures): its fields in order,
each with the kind of its leaf, a buffer of ``solver.compiled.flat`` (its dtype and the
shape after the first axis: ``"f3"`` is (n, 3) float64, ``"i"`` (n,) int64, ``"b"`` (n,)
bool).  ``solver.compiled.pack`` builds them by field name, ``flat.flatten`` copies
their leaves into a few buffers in this order, the kernels read them by field name
(``rw.jac_a``, ``m.body_inv_mass``), and ``solver.compiled.views`` (generated from this
module: ``python -m solver.compiled.layout``) rebuilds them from the buffers in compiled
code.  Adding a field to the model is: one line in ``ModelArrays`` below, its array in
``pack.pack``, then regenerating the views.

The small vectors the kernels take (options, the pointer, the coupling, flags, the
report) are arrays with named offsets (``IntEnum``s, constants to numba):
``opt[Opt.h]``, ``pvec[Pointer.radius]``.

``NAMES`` of a structure are the names the kernels give it; tests/solver/test_packed_layout.py
rejects a positional index (``rw[6]``) into any of them outside this module and the
generated views.
"""

from __future__ import annotations

from collections import namedtuple
from enum import IntEnum
from pathlib import Path

import numpy as np

BUFFERS = {
    "f": (np.float64, ()), "f3": (np.float64, (3,)), "f4": (np.float64, (4,)),
    "f6": (np.float64, (6,)), "f33": (np.float64, (3, 3)), "f66": (np.float64, (6, 6)),
    "i": (np.int64, ()), "i6": (np.int64, (6,)), "b": (np.bool_, ()),
}  # fmt: skip
"""Leaf kinds, in the order of flat's buffers: dtype and the shape after the first axis."""
FLAT = (*BUFFERS, "layout")
"""The flat buffers in order (solver.compiled.flat): one per kind, then the leaves' layout."""


def structure(name: str, names: tuple[str, ...], fields: list[tuple[str, object]]) -> type:
    """A named tuple class ``name`` with ``fields`` [(field, kind)] (a kind is a buffer
    name or another structure); ``names``: what kernels call an instance of it."""
    cls = namedtuple(name, [f for f, _ in fields], module=__name__)
    cls.KINDS = tuple(kind for _, kind in fields)
    cls.NAMES = names
    return cls


def offsets(name: str, sizes: list[tuple[str, int]]) -> type[IntEnum]:
    """An IntEnum of the offsets of the entries ``sizes`` [(entry, length)] in a vector;
    ``SIZE`` is the vector's length."""
    at, members = 0, {}
    for entry, size in sizes:
        members[entry] = at
        at += size
    members["SIZE"] = at
    return IntEnum(name, members, module=__name__)


# -- the model (pack.pack) ---------------------------------------------------------------

ModelArrays = structure("ModelArrays", ("m",), [
    ("joint_parent", "i"), ("joint_bone", "i"),
    ("joint_anchor_parent", "f3"), ("joint_anchor_child", "f3"),
    ("joint_kf", "f3"), ("joint_df", "f3"), ("joint_dd", "f3"),
    ("joint_rheology", "b"), ("joint_axis", "f3"), ("joint_swing", "f"),
    ("joint_twist_lo", "f"), ("joint_twist_hi", "f"), ("joint_yield", "f"),
    ("joint_plastic", "b"),  # every D_d finite
    ("joint_finite_yield", "b"),
    ("body_mass", "f"), ("body_inv_mass", "f"), ("body_inertia", "f33"),
    ("body_inv_inertia", "f33"),
    ("body_island", "i"),  # solver.advance.sleep.body_islands
    ("joint_levers", "f6"),  # solver.advance.substep.tension_levers
    ("joint_limit_thresholds", "f3"),  # solver.rows.joints_kernel.limit_thresholds
])  # fmt: skip

Geometry = structure("Geometry", ("g",), [
    ("shape_body", "i"), ("shape_pos", "f3"), ("shape_quat", "f4"), ("shape_kind", "i"),
    ("shape_radius", "f"), ("shape_half", "f3"), ("shape_bound", "f"),
    ("pair_first", "i"), ("pair_second", "i"),  # candidate pairs, lower shape class first
    ("pair_group", "i"), ("pair_sign", "f"),  # kind of pair (pack.FEATURES), normal sign
    ("pair_body_a", "i"), ("pair_body_b", "i"), ("pair_friction", "f"),
    ("touchable", "i"), ("touch_friction", "f"),  # shapes the pointer touches, their μ
])  # fmt: skip

TreeWork = structure("TreeWork", ("tw",), [
    ("block", "f66"),  # D_i, factored in place
    ("coupling", "f66"),  # Y_i = L⁻¹ K_ip
    ("rhs", "f6"),  # right-hand sides, then solutions
    ("gather", "f6"),  # one 6×6 block of scratch
])  # fmt: skip

Tree = structure("Tree", ("tree",), [
    ("order", "i"),  # static elimination order, children first
    ("parent", "i"), ("rheo_start", "i"),  # this step's node parents; first rheology row a joint
    ("forest_parent", "i"),  # the packed forest's node parents (ptree's: never written)
    ("no_rheo", "i"), ("sequence", "i"),  # −1 per joint; this step's order
    ("node_rows", "i6"), ("node_size", "i"), ("work", TreeWork),
])  # fmt: skip

ProjectionTree = structure("ProjectionTree", ("ptree",), [
    ("order", "i"), ("parent", "i"), ("no_rheo", "i"), ("node_rows", "i6"),
    ("node_size", "i"), ("work", TreeWork),
])  # fmt: skip

Rows = structure("Rows", ("rw", "prw"), [  # solver.rows.table.Rows
    ("body_a", "i"), ("body_b", "i"), ("jac_a", "f6"), ("jac_b", "f6"),
    ("lo", "f"), ("hi", "f"), ("comp", "f"), ("bias", "f"), ("fric_of", "i"), ("mu", "f"),
    ("key", "i"), ("kind", "i"),
])  # fmt: skip

Contacts = structure("Contacts", ("cb",), [
    ("body_a", "i"), ("body_b", "i"), ("point", "f3"), ("normal", "f3"), ("depth", "f"),
    ("friction", "f"), ("key", "i"),
])  # fmt: skip

Workspace = structure("Workspace", ("ws",), [
    ("rows", Rows), ("resp_a", "f6"), ("resp_b", "f6"),  # the rows' responses M⁻¹Jᵀ
    ("rheo_joint", "i"),  # joint of each rheology row
    ("contacts", Contacts),
    ("rot", "f33"), ("inv_inertia", "f33"), ("inertia", "f33"),  # bodies' world frames
    ("shape_centre", "f3"), ("shape_rot", "f33"),  # shapes' world frames
    ("cycles", "i"),  # per stage (solver.compiled.clock)
])  # fmt: skip

ProjectionWorkspace = structure("ProjectionWorkspace", ("pws",), [
    ("rows", Rows), ("resp_a", "f6"), ("resp_b", "f6"), ("rot", "f33"),
    ("inv_inertia", "f33"), ("inertia", "f33"), ("lam", "f"),
])  # fmt: skip

Packed = structure("Packed", ("packed",), [
    ("m", ModelArrays), ("g", Geometry), ("tree", Tree), ("ptree", ProjectionTree),
    ("ws", Workspace), ("pws", ProjectionWorkspace), ("opt", "f"), ("iopt", "i"),
])  # fmt: skip

Opt = offsets("Opt", [
    ("h", 1), ("joint_erp", 1), ("contact_erp", 1), ("contact_slop", 1),
    ("contact_margin", 1), ("limit_margin", 1), ("regularization", 1),
    ("yield_filter_time", 1), ("max_speed", 1), ("max_angular_speed", 1),
    ("max_joint_gap", 1), ("warm_start_factor", 1), ("gravity", 3), ("sleep_speed", 1),
    ("sleep_spin", 1), ("sleep_time", 1),
])  # fmt: skip
"""opt: the float options (solver.model.Options' fields of the same names)."""

IOpt = offsets("IOpt", [
    ("method", 1),  # pack.METHODS
    ("bdf2", 1),  # integrator: bdf2
    ("iterations", 1), ("warm_start", 1), ("has_rheology", 1), ("has_limits", 1),
    ("has_collision", 1), ("max_substeps", 1), ("profiling", 1), ("cull_pairs", 1),
    ("dormant_rows", 1), ("leaf_contacts", 1), ("sleep", 1),
])  # fmt: skip
"""iopt: the integer and boolean options and the model's features."""

# -- a step's state and input ------------------------------------------------------------

StateSet = structure("StateSet", ("out", "prev"), [
    ("x", "f3"), ("q", "f4"), ("v", "f3"), ("omega", "f3"), ("q_sf", "f3"),
    ("yielded", "b"), ("anchor", "f4"), ("torque_avg", "f"), ("torque", "f3"),
    ("asleep", "b"), ("still", "f"),
    ("prev_x", "f3"), ("prev_q", "f4"), ("prev_v", "f3"), ("prev_omega", "f3"),
    ("prev_q_sf", "f3"), ("hist", "f"),
])  # fmt: skip
"""A step's new state (out; a Sim's two sets, one read, one written; prev, a previous out).
prev_* and hist (3,: prev_h, prev_mark, prev_load): the history of the BDF2 step
(State.prev_*), written only under ``integrator: bdf2``."""

StepState = namedtuple("StepState", [
    "x", "q", "v", "omega", "q_sf", "yielded", "anchor", "torque_avg", "warm_key",
    "warm_lam", "asleep", "still", "prev_x", "prev_q", "prev_v", "prev_omega", "prev_q_sf",
    "hist",
], module=__name__)  # fmt: skip
StepState.NAMES = ("st",)
"""The state a step reads (st): a StateSet's fields but τ, with the warm keys and λ."""

Input = namedtuple("Input", ["force", "torque", "pointer", "coupling", "flags", "pins",
                             "pin_bone"], module=__name__)  # fmt: skip
Input.NAMES = ("inp",)
"""A step's input (inp): force, torque (nb, 3), pointer (Pointer), coupling (Coupling),
flags (Flags), pins (npin, PinVec.SIZE) and their bones pin_bone (npin,) int."""

Pointer = offsets("Pointer", [("pos", 3), ("quat", 4), ("vel", 3), ("omega", 3), ("radius", 1)])
"""pvec: the pointer's pose, velocity, angular velocity and touch radius."""

Coupling = offsets("Coupling", [
    ("anchor", 3), ("offset", 3), ("rest", 4), ("stiffness", 1), ("damping", 1),
    ("rot_stiffness", 1), ("rot_damping", 1), ("force_limit", 1), ("torque_limit", 1),
])  # fmt: skip
"""cvec: the grip's coupling (solver.rows.grip.Coupling's fields)."""

PinVec = offsets("PinVec", [
    ("point", 3), ("target", 3), ("target_quat", 4), ("force_limit", 1), ("torque_limit", 1),
    ("orient", 1),
])  # fmt: skip
"""A row of inp.pins: solver.rows.pin.Pin's fields of the same names (orient 1.0 or 0.0)."""

Flags = offsets("Flags", [
    ("mode", 1), ("body", 1), ("position_only", 1), ("has_force", 1), ("has_torque", 1),
])  # fmt: skip
"""ivec: the pointer's mode (solver.rows.grip_kernel), gripped body, the loads given."""

ReportInt = offsets("ReportInt", [
    ("rows", 1), ("contacts", 1), ("iterations", 1), ("solver", 1), ("substeps", 1),
])  # fmt: skip
"""rep_i: a step's rows (on SUBSTEP: the substeps asked for), contacts, iterations, solver,
and the parts it was taken in (StepReport.substeps)."""

ReportFloat = offsets("ReportFloat", [
    ("residual", 1), ("grip_force", 3), ("grip_torque", 3), ("touch_force", 3),
])  # fmt: skip
"""rep_f: a step's residual, grip force and torque, and pointer touch force."""

# -- a step's scratch arrays (kernel.step_arrays) ----------------------------------------

SolverFlags = structure("SolverFlags", ("flags",), [
    ("at_lo", "b"), ("at_hi", "b"), ("dormant", "b"), ("leaf", "b"), ("sliding", "b"),
])  # fmt: skip

SolverIndex = structure("SolverIndex", ("ints",), [
    ("its", "i"), ("pinned", "i"), ("local", "i"), ("fric", "i"),  # rows
    ("path", "i"), ("needed", "i"),  # nodes
    ("free_grip", "i"),  # 6
    ("leaves", "i"), ("first_friction", "i"),  # rows
])  # fmt: skip

SolverValues = structure("SolverValues", ("values",), [
    ("s_vec", "f"), ("lo", "f"), ("hi", "f"), ("mu", "f"), ("start", "f"), ("lam_u", "f"),
    ("r_u", "f"),
])  # fmt: skip

SolverScratch = structure("SolverScratch", ("sv",), [
    ("flags", SolverFlags), ("ints", SolverIndex), ("values", SolverValues),
    ("vel_p", "f6"), ("pushed", "f6"),
    ("s_mat", "f"),  # hybrid.NU_CAP² entries
    ("alone", "b"),  # per body: asleep, and a row acts on it (hybrid_kernel.sleeping_sides)
])  # fmt: skip

WakeScratch = structure("WakeScratch", ("wake_scratch",), [("loaded", "b"), ("pointer", "f")])
IntegrateScratch = structure("IntegrateScratch", ("integrate_scratch",), [
    ("rates", "f3"), ("moms", "f3"), ("done", "b"),
])  # fmt: skip
LimitScratch = structure("LimitScratch", ("limit_scratch",), [("gaps", "f3"), ("turned", "f3")])
Prediction = structure("Prediction", ("pred",), [  # solver.advance.bdf2.Prediction
    ("x", "f3"), ("q", "f4"), ("v", "f3"), ("omega", "f3"), ("shift", "f6"), ("q_sf", "f3"),
])  # fmt: skip
"""The stage (x̃, q̃, its start velocities v̂ − ṽ and ω̂ − ω̃, the shift ṽ, ω̃, and q̂_sf)."""

Scratch = structure("Scratch", ("scratch",), [
    ("vel_free", "f6"), ("fresh", "b"), ("awake", "b"), ("wake", WakeScratch),
    ("lam0", "f"), ("lam", "f"), ("vel", "f6"), ("integrate", IntegrateScratch),
    ("w", "f3"),  # rheology's
    ("limit", LimitScratch), ("flows", "b"), ("solvers", SolverScratch),
    ("pred", Prediction), ("moving", "f6"),  # the BDF2 stage's
    ("stage_opt", "f"),  # Opt.SIZE: opt with the stage's h and yield filter time
    ("part_opt", "f"),  # Opt.SIZE: opt with a part's h (kernel.step_parts)
    ("part_pointer", "f"),  # Pointer.SIZE: the pointer at a part's end
    ("part_report", "f"),  # ReportFloat.SIZE: the parts' summed report
])  # fmt: skip
"""The arrays kernel._step works in: whatever they hold on entry is overwritten first."""

# -- a Sim's arrays (solver.compiled.sim) ------------------------------------------------

Warm = structure("Warm", ("warm",), [("keys", "i"), ("lam", "f"), ("n", "i")])
"""Warm-start keys and λ with room for every row, and how many are set (n (1,))."""

StepWork = structure("StepWork", ("work",), [("scratch", Scratch), ("keys", "i"), ("lam", "f")])
"""kernel.step_arrays: the scratch and the new warm keys and λ."""

SimArrays = structure("SimArrays", ("sim",), [
    ("packed", Packed),  # first: a Sim's flat buffers are also a flat packed model
    ("set0", StateSet), ("set1", StateSet), ("warm", Warm), ("rep_i", "i"),
    ("rep_f", "f"), ("work", StepWork),
    ("spare", StateSet), ("spare_keys", "i"), ("spare_lam", "f"),  # a step's parts
])  # fmt: skip

# -- ad hoc views of the model that kernels take -----------------------------------------

Joints = namedtuple("Joints", ["parent", "bone", "anchor_parent", "anchor_child"],
                    module=__name__)  # fmt: skip
Joints.NAMES = ("joints",)
"""Joints' parents, bones and anchors (ModelArrays' joint_* of those names)."""

Rheology = namedtuple("Rheology", [
    "parent", "bone", "kf", "df", "dd", "has", "yield_torque", "plastic", "finite_yield",
], module=__name__)  # fmt: skip
Rheology.NAMES = ("rheo",)
"""What the rheology rows and update read (ModelArrays' joint_*)."""

Limits = namedtuple("Limits", [
    "parent", "bone", "axis", "swing", "twist_lo", "twist_hi", "thresholds",
], module=__name__)  # fmt: skip
Limits.NAMES = ("limits",)
"""What the limit rows read (ModelArrays' joint_*)."""

Bodies = namedtuple("Bodies", [
    "bone", "mass", "inv_mass", "resp_a", "resp_b", "inv_inertia", "inertia",
], module=__name__)  # fmt: skip
Bodies.NAMES = ("bw",)
"""What the solvers read of the bodies: joint bones, masses, the rows' responses, the
world inertias."""

STRUCTURES = (
    ModelArrays, Geometry, TreeWork, Tree, ProjectionTree, Rows, Contacts, Workspace,
    ProjectionWorkspace, Packed, StateSet, StepState, Input, SolverFlags, SolverIndex,
    SolverValues, SolverScratch, WakeScratch, IntegrateScratch, LimitScratch, Prediction,
    Scratch, Warm, StepWork, SimArrays, Joints, Rheology, Limits, Bodies,
)  # fmt: skip
VECTORS = {"opt": Opt, "iopt": IOpt, "pvec": Pointer, "cvec": Coupling, "ivec": Flags,
           "pins": PinVec, "rep_i": ReportInt, "rep_f": ReportFloat}  # fmt: skip
"""The vectors with named offsets, by the names kernels give them."""


def leaf_count(kind) -> int:
    """Leaves of a kind (1 for a buffer kind, the sum of its fields' for a structure)."""
    return 1 if isinstance(kind, str) else sum(leaf_count(k) for k in kind.KINDS)


def leaf_of(cls, path: str) -> int:
    """Depth-first number of the leaf ``path`` ("ws.rows.body_a") of structure ``cls``."""
    first, _, rest = path.partition(".")
    at = 0
    for name, kind in zip(cls._fields, cls.KINDS, strict=True):
        if name == first:
            return at + (leaf_of(kind, rest) if rest else 0)
        at += leaf_count(kind)
    raise KeyError(f"{cls.__name__} has no field {first!r}")


def views_source() -> str:
    """The source of solver.compiled.views: a function per structure that rebuilds it
    from the flat buffers (``<name>_view(flat, k)``, its first leaf k), and one per leaf
    kind (``leaf_<kind>(flat, k)``, leaf k)."""
    viewed = [c for c in STRUCTURES if hasattr(c, "KINDS")]
    lines = [
        '"""Generated by ``python -m solver.compiled.layout`` from solver.compiled.layout: do',
        "not edit.  Each function rebuilds a packed structure from the flat buffers",
        "(solver.compiled.flat), its first leaf k; inlined, so the views are made in the",
        'caller."""',
        "",
        "from solver.compiled.flat import leaf",
        "from solver.compiled.layout import (",
        *[f"    {name}," for name in sorted(c.__name__ for c in viewed)],
        ")",
        "from solver.jit import kernel",
    ]
    for kind in BUFFERS:
        lines += ["", "", '@kernel(inline="always")', f"def leaf_{kind}(flat, k):"]
        lines.append(f"    return leaf(flat[{FLAT.index(kind)}], flat[{FLAT.index('layout')}], k)")
    for cls in viewed:
        args, at = [], 0
        for name, kind in zip(cls._fields, cls.KINDS, strict=True):
            view = f"leaf_{kind}" if isinstance(kind, str) else f"{_snake(kind.__name__)}_view"
            args.append(f"{view}(flat, k + {at}),  # {name}")
            at += leaf_count(kind)
        lines += ["", "", '@kernel(inline="always")', f"def {_snake(cls.__name__)}_view(flat, k):"]
        lines.append(f"    return {cls.__name__}(")
        lines += [f"        {a}" for a in args]
        lines.append("    )")
    return "\n".join(lines) + "\n"


def _snake(name: str) -> str:
    return "".join("_" + c.lower() if c.isupper() else c for c in name).lstrip("_")


VIEWS = Path(__file__).with_name("views.py")

if __name__ == "__main__":
    VIEWS.write_text(views_source())
