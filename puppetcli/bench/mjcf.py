"""Our rig as a MuJoCo model: the MJCF, the compiled peer and its read-back (for
``puppetcli.bench.peers``, which runs and measures the scenes).

Frames
------
World frames are identical: Y up, gravity = the model's (``<option gravity>``), so no
coordinate conversion is needed anywhere.  Each of our bodies becomes one MuJoCo body
whose frame *is* ours: world-aligned at rest, origin at the centre of mass.  So
``data.xpos`` is our ``body_pos`` and ``data.xquat`` our ``body_quat``, and a rest-pose
point p of bone b is at ``xpos + R(xquat)·(p − body_pos0[b])``.  A child body sits at
``body_pos0[child] − body_pos0[parent]`` in its parent's frame.

Masses and inertias
-------------------
``inertiafromgeom="false"`` and an explicit ``<inertial mass fullinertia>`` at the body
origin (our centre of mass), so MuJoCo's mass matrix is built from exactly our
``body_mass`` and ``body_inertia``; geoms only collide.

Joints
------
Every non-root bone hangs from its parent by a ball joint at its head; a "ball" root
hangs from the world, a "fixed" root has no joint (welded), a "free" root and dynamic
props get a free joint.  MuJoCo's ball joints are generalised coordinates, so the anchor
gap is zero by construction (ours is a constraint row).  Joint stiffness = K_f and
damping = D_f: the peer's joints are Voigt spring-dampers about the rest pose.
MuJoCo cannot express the series (plastic) damper D_d of our three-element model, nor
the yield switch (MuJoCo 4's ``springyield`` is rate-independent ideal plasticity, a
different law), nor our swing/twist limits (a MuJoCo ball limit is one cone on the
total rotation angle).  Those are dropped and listed in ``PeerMJCF.approximations``;
a peer's error is therefore measured against its own converged reference, not ours.

Contacts
--------
Every geom has contype = conaffinity = 0, and each of our candidate pairs
(``Geometry.pair_a/pair_b``: no parent–child pairs, no pairs overlapping at rest,
static shapes only against bodies) is one explicit ``<pair>``, condim 3, friction
sqrt(μ_a·μ_b) (condim 1 where that is 0: frictionless); so MuJoCo tests exactly the
pairs we test.  MuJoCo's capsule and plane
axis is local z, ours local y: their geom orientation is ours ⊗ R_x(−90°).
Contact solver parameters stay MuJoCo's defaults (soft: solref 0.02 1, solimp
0.9 0.95 0.001; margin 0, no speculative contacts; pyramidal cone).

Grip
----
A mocap body follows the pointer; three ``<position>`` actuators with a site
transmission from a site at the grip point to a ``refsite`` on the mocap body, one per
world axis, with kp = K, kv = D and forcerange ±force_limit (our per-row clamp).  Their
length is the grip point's offset from the pointer, so the force is −K·e − D·v per world
axis: a 3-D Voigt spring-damper, like our coupling's three rows.  A mocap body has no
velocity in MuJoCo, so the damper sees the bone's absolute velocity; setting the
actuators' ctrl to (D/K)·u (u the pointer's velocity) gives exactly
K·(ctrl − e) − D·v = −K·e − D·(v − u).  Why not the alternatives:

* an equality ``connect`` with solref "−K −D" is implicit, but MuJoCo's k and b are
  *acceleration*-space (a_ref = −b·v − k·r, scaled by the impedance and the
  qpos0-frozen diagonal inertia estimate), so its force per metre depends on the
  effective mass at the grip point: not K N/m;
* a spatial tendon spring of zero rest length gives K·e but damps only the radial
  velocity and has no direction at e = 0 (where every grip starts).

The actuator's kv is integrated implicitly by ``implicitfast``/``implicit`` and folded
into the metric by ``discrete``; under ``Euler`` (implicit in joint damping only) it is
explicit.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from solver import quat
from solver.model import Model

INTEGRATORS = ("Euler", "implicitfast", "implicit", "discrete", "RK4")
_Z_TO_Y = np.array([np.sqrt(0.5), -np.sqrt(0.5), 0.0, 0.0])  # R_x(−90°): local z → y
_GEOM_TYPE = {0: "plane", 1: "sphere", 2: "capsule", 3: "box"}
_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class PeerGrip:
    """A position-only grip: ``body`` (our body index), ``point`` (3,) in its body frame
    (m), ``pointer_start`` (3,) the pointer's world position at gripping (m; the
    coupling's rest offset is the grip point minus it, as in ``make_coupling``),
    stiffness K (N/m), damping D (N·s/m) and the per-axis force limit (N, inf = none)."""

    body: int
    point: np.ndarray
    pointer_start: np.ndarray
    stiffness: float
    damping: float
    force_limit: float = float("inf")


@dataclass(frozen=True)
class PeerMJCF:
    """The MJCF text and what it could not represent.

    xml: the model.  body_names: MuJoCo body name of each of our bodies, in order.
    approximations: human-readable notes on what of our rig MuJoCo lacks.
    grip_actuators: actuator names (x, y, z) of the grip, empty without one.
    """

    xml: str
    body_names: tuple[str, ...]
    approximations: tuple[str, ...]
    grip_actuators: tuple[str, ...] = ()


def _fmt(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.atleast_1d(values))


def _root_kinds(model: Model) -> dict[int, str]:
    """Root bodies (and dynamic props) → "fixed" | "ball" | "free"."""
    nbone = len(model.bone_names)
    world_joint = {
        int(b) for b, p in zip(model.joint_bone, model.joint_parent, strict=True) if p < 0
    }
    kinds = {}
    for b in range(model.nbody):
        if b < nbone and model.bone_parent[b] >= 0:
            continue
        if b in world_joint:
            kinds[b] = "ball"
        elif model.body_inv_mass[b] == 0.0:
            kinds[b] = "fixed"
        else:
            kinds[b] = "free"
    return kinds


def _add_body(parent_el: ET.Element, model: Model, b: int, parent: int) -> ET.Element:
    """A body with its explicit inertial at the origin (our centre of mass)."""
    pos = model.body_pos0[b] - (model.body_pos0[parent] if parent >= 0 else 0.0)
    attrs = {"name": model.body_names[b], "pos": _fmt(pos)}
    if parent < 0:
        attrs["quat"] = _fmt(model.body_quat0[b])
    el = ET.SubElement(parent_el, "body", attrs)
    i = model.body_inertia[b]
    full = (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])
    ET.SubElement(
        el, "inertial", pos="0 0 0", mass=_fmt(model.body_mass[b]), fullinertia=_fmt(full)
    )
    return el


def _add_joint(el: ET.Element, model: Model, b: int, kind: str, notes: list[str]) -> None:
    if kind == "free":
        ET.SubElement(el, "freejoint", name=f"{model.body_names[b]}_free")
        return
    if kind == "fixed":
        return
    j = int(np.flatnonzero(model.joint_bone == b)[0])
    kf, df = model.joint_kf[j], model.joint_df[j]
    if np.ptp(kf) > 0.0 or np.ptp(df) > 0.0:
        notes.append(f"{model.joint_names[j]}: per-axis K_f/D_f averaged (MuJoCo: one per joint)")
    ET.SubElement(
        el,
        "joint",
        name=model.joint_names[j],
        type="ball",
        pos=_fmt(model.joint_anchor_child[j]),
        stiffness=_fmt(float(np.mean(kf))),
        damping=_fmt(float(np.mean(df))),
    )


def _add_geom(el: ET.Element, model: Model, s: int) -> None:
    g = model.geometry
    kind = int(g.shape_kind[s])
    q = g.shape_quat[s]
    if kind in (0, 2):
        q = quat.mul(q, _Z_TO_Y)
    size = {
        0: (0.0, 0.0, 1.0),
        1: (g.shape_radius[s],),
        2: (g.shape_radius[s], g.shape_half[s, 1]),
        3: tuple(g.shape_half[s]),
    }[kind]
    ET.SubElement(
        el,
        "geom",
        name=f"shape{s}",
        type=_GEOM_TYPE[kind],
        size=_fmt(size),
        pos=_fmt(g.shape_pos[s]),
        quat=_fmt(q),
        contype="0",
        conaffinity="0",
    )


def _add_grip(world: ET.Element, bodies: dict, model: Model, grip: PeerGrip) -> tuple:
    """Mocap pointer, the grip site and three position actuators (see the module doc)."""
    ET.SubElement(bodies[grip.body], "site", name="grip", pos=_fmt(grip.point))
    mocap = ET.SubElement(world, "body", name="pointer", mocap="true", pos=_fmt(grip.pointer_start))
    point_w = model.body_pos0[grip.body] + quat.rotate(model.body_quat0[grip.body], grip.point)
    ET.SubElement(mocap, "site", name="pointer_ref", pos=_fmt(point_w - grip.pointer_start))
    act = ET.Element("actuator")
    names = []
    for k, axis in enumerate(_AXES):
        attrs = {
            "name": f"grip_{axis}",
            "site": "grip",
            "refsite": "pointer_ref",
            "gear": _fmt(np.eye(6)[k]),
            "kp": _fmt(grip.stiffness),
            "kv": _fmt(grip.damping),
        }
        if np.isfinite(grip.force_limit):
            attrs["forcerange"] = _fmt((-grip.force_limit, grip.force_limit))
        ET.SubElement(act, "position", attrs)
        names.append(attrs["name"])
    return act, tuple(names)


def _notes(model: Model) -> list[str]:
    notes = []
    if np.any(np.isfinite(model.joint_dd)):
        notes.append("series damper D_d dropped: joints are Voigt (K_f ∥ D_f) about rest")
    if np.any(np.isfinite(model.joint_yield)):
        notes.append("yield torque dropped (no switch between Voigt and three-element flow)")
    if model.has_limits:
        notes.append("swing/twist limits dropped (MuJoCo ball limit: one cone on total angle)")
    if model.has_collision:
        notes.append(
            "contacts: MuJoCo soft contacts (default solref/solimp, margin 0, pyramidal);"
            f" ours hard rows, {model.options.contact_margin * 100:g} cm speculative margin,"
            f" {model.options.contact_slop * 1000:g} mm slop,"
            f" {model.options.contact_erp * 100:g} % correction"
        )
    return notes


def mjcf_from_model(
    model: Model, h: float, integrator: str = "Euler", grip: PeerGrip | None = None
) -> PeerMJCF:
    """The MJCF of ``model`` at step ``h`` (s) with MuJoCo's ``integrator``.

    Only the timestep, gravity and integrator are set in ``<option>``; everything else
    keeps MuJoCo's defaults: Newton solver, 100 iterations, tolerance 1e-8, warm start,
    pyramidal friction cone, impratio 1, dense/sparse Jacobian chosen automatically.
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator: expected one of {', '.join(INTEGRATORS)}, got {integrator}")
    notes = _notes(model)
    root = ET.Element("mujoco", model=model.name)
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    ET.SubElement(
        root,
        "option",
        timestep=_fmt(h),
        gravity=_fmt(model.options.gravity),
        integrator=integrator,
    )
    world = ET.SubElement(root, "worldbody")
    kinds = _root_kinds(model)
    nbone = len(model.bone_names)
    bodies: dict[int, ET.Element] = {}
    for b in range(model.nbody):
        parent = int(model.bone_parent[b]) if b < nbone else -1
        bodies[b] = _add_body(world if parent < 0 else bodies[parent], model, b, parent)
        _add_joint(bodies[b], model, b, kinds.get(b, "ball"), notes)
    g = model.geometry
    for s in range(len(g.shape_body)):
        b = int(g.shape_body[s])
        _add_geom(world if b < 0 else bodies[b], model, s)
    contact = ET.SubElement(root, "contact")
    for a, b in zip(g.pair_a, g.pair_b, strict=True):
        mu = float(np.sqrt(g.shape_friction[a] * g.shape_friction[b]))
        ET.SubElement(
            contact,
            "pair",
            geom1=f"shape{a}",
            geom2=f"shape{b}",
            condim="3" if mu > 0.0 else "1",  # frictionless: normal force only
            friction=_fmt((mu, mu, 0.005, 0.0001, 0.0001)),
        )
    actuators: tuple[str, ...] = ()
    if grip is not None:
        act, actuators = _add_grip(world, bodies, model, grip)
        root.append(act)
        notes.append(
            "grip: actuator spring explicit in position (implicit only under discrete);"
            f" its damper {'explicit' if integrator in ('Euler', 'RK4') else 'implicit'};"
            " ours is backward Euler in both"
        )
    return PeerMJCF(
        ET.tostring(root, encoding="unicode"), model.body_names, tuple(notes), actuators
    )


def import_mujoco():
    """The ``mujoco`` module, imported on first use (so the CLI never pays for it)."""
    try:
        import mujoco
    except ImportError as exc:
        raise ImportError("MuJoCo peer: `pip install mujoco` first") from exc
    return mujoco


@dataclass
class Peer:
    """A compiled MuJoCo model of one of ours, with its data.

    body_ids (nb,): MuJoCo body id of each of our bodies.  mocap_pos (n,3) and ctrl
    (n,3): the grip's inputs per step (empty without a grip).
    """

    model: Model
    mjcf: PeerMJCF
    mj_model: object
    mj_data: object
    body_ids: np.ndarray
    mocap_pos: np.ndarray
    ctrl: np.ndarray


def build_peer(
    model: Model, h: float, integrator: str = "Euler", grip: PeerGrip | None = None
) -> Peer:
    """Compile ``model`` for MuJoCo at step h (s); no inputs yet (see ``drive``)."""
    mujoco = import_mujoco()
    mjcf = mjcf_from_model(model, h, integrator, grip)
    mj_model = mujoco.MjModel.from_xml_string(mjcf.xml)
    ids = np.array([mj_model.body(name).id for name in mjcf.body_names], dtype=np.int64)
    empty = np.zeros((0, 3))
    return Peer(model, mjcf, mj_model, mujoco.MjData(mj_model), ids, empty, empty)


def peer_points(peer: Peer, rest_points: np.ndarray, bones: np.ndarray | None = None):
    """World positions (k,3) of rest-pose points carried by bones (None: one per bone)."""
    m = peer.model
    b = np.arange(len(m.bone_names)) if bones is None else np.asarray(bones)
    d = peer.mj_data
    ids = peer.body_ids[b]
    rot = d.xmat[ids].reshape(-1, 3, 3)
    return d.xpos[ids] + np.einsum("kij,kj->ki", rot, rest_points - m.body_pos0[b])


def peer_heads(peer: Peer) -> np.ndarray:
    """World positions (nbone,3) of the bones' heads (their joints), m."""
    return peer_points(peer, peer.model.bone_head0)


def peer_tails(peer: Peer) -> np.ndarray:
    """World positions (nbone,3) of the bones' tails, m."""
    return peer_points(peer, peer.model.bone_tail0)


def anchor_gaps(peer: Peer) -> np.ndarray:
    """Distance (nj,) between each joint's anchor on the parent and on the child (m)."""
    m, d = peer.model, peer.mj_data
    child = peer_points(peer, m.bone_head0[m.joint_bone], m.joint_bone)
    parent = np.array(m.joint_anchor_parent, dtype=float)
    has = m.joint_parent >= 0
    if np.any(has):
        p = m.joint_parent[has]
        rot = d.xmat[peer.body_ids[p]].reshape(-1, 3, 3)
        local = m.joint_anchor_parent[has]
        parent[has] = d.xpos[peer.body_ids[p]] + np.einsum("kij,kj->ki", rot, local)
    return np.linalg.norm(child - parent, axis=1)
