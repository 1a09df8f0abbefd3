"""Property-based round trips (Hypothesis) of BVH files through readers that are not ours.

Written by puppetcli (``write_keys_bvh``, what ``pose`` and ``convert`` call for
keyframes.bvh): random poses of rigs/doll.yaml's skeleton and of random small skeletons, a
random root translation, every channel order, metres and centimetres.  Read back by the
``bvh`` package (its raw channel values, turned into rotations here with scipy's
``Rotation.from_euler``: upper-case axes = intrinsic, the convention of docs/bvh.md) and by
``bvhio`` (its own float32 forward kinematics).  Oracle: the rotations the test chose and a
forward kinematics written here with scipy (``scipy_fk``).

The reverse: files whose channel values the test chose (random hierarchies, channel subsets
and orders, positions on any joint, line ends, indentation), written by the fixtures' own
writer (test_bvh_fixtures.bvh_text, no puppetcli code), read by ``puppetcli.bvh.read``; its
values, rotations and joint positions are checked against the same scipy oracle.

Derandomized: the same examples on every run.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import bvh as bvh_package
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from test_bvh_fixtures import ORDERS, J, bvh_text

from puppetcli.bvh.model import CHANNEL_NAMES
from puppetcli.bvh.read import read_bvh
from puppetcli.bvh.write import write_keys_bvh
from puppetcli.rig.load import load_rig
from puppetcli.rig.skeleton import Skeleton
from puppetcli.run.keyframes import BonePose, Keyframe

with warnings.catch_warnings():  # bvhio imports PyGLM the way PyGLM now deprecates
    warnings.simplefilter("ignore", PendingDeprecationWarning)
    import bvhio

ROOT = Path(__file__).resolve().parents[3]
DOLL = Skeleton.from_spec(load_rig(ROOT / "rigs" / "doll.yaml"))
SETTINGS = settings(max_examples=8, derandomize=True, deadline=None)

# Tolerances: about 5× the worst error measured over 6,000 random examples (all six orders,
# gimbal lock included), the measured value in the comment.
ROTATION_TOL = 9e-8  # rad, channel values (6 decimals of a degree) vs the chosen rotation: 1.8e-8
POSITION_TOL = 1e-9  # file units, 9-decimal lengths vs the chosen ones: 5.0e-10 (the rounding)
BVHIO_POSITION_TOL = 3e-6  # × the figure's reach, bvhio's float32 joint positions: 6.3e-7
BVHIO_ROTATION_TOL = 6e-6  # rad, bvhio's float32 world rotations: 1.4e-6
OURS_ROTATION_TOL = 1e-15  # rad, our reader's rotations from exact channel values: 2.0e-16
OURS_POSITION_TOL = 6e-15  # × the reach, our reader's forward kinematics: 1.4e-15


# ---- the oracle: scipy rotations and a forward kinematics of its own ----


def scipy_fk(parents, translations, rotations):
    """(world positions (nj,3), world Rotations) of joints with ``parents`` (parents first):
    p_j = p_parent + R_parent t_j, R_j = R_parent R_local_j; a root has p = t, R = R_local."""
    heads, world = np.zeros((len(parents), 3)), []
    for j, p in enumerate(parents):
        if p < 0:
            heads[j], rot = translations[j], rotations[j]
        else:
            heads[j] = heads[p] + world[p].apply(translations[j])
            rot = world[p] * rotations[j]
        world.append(rot)
    return heads, world


def angle(a: Rotation, b: Rotation) -> float:
    """Radians between two rotations."""
    return float((a.inv() * b).magnitude())


# ---- strategies ----

unit = st.floats(-1.0, 1.0, allow_nan=False)
random_rotations = st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1)
# Rotations at gimbal lock of some order: the middle angle ±90°, the others anything.
locked_rotations = st.tuples(
    st.sampled_from(ORDERS),
    st.floats(-180, 180),
    st.sampled_from([90.0, -90.0]),
    st.floats(-180, 180),
)


@st.composite
def rotations(draw) -> Rotation:
    if draw(st.booleans()):
        return Rotation.from_quat(draw(random_rotations), scalar_first=True)
    order, a, b, c = draw(locked_rotations)
    return Rotation.from_euler(order, [a, b, c], degrees=True)


def vectors(bound: float, least: float = 0.0):
    """3-vectors with components in ±bound and a norm of at least ``least``."""
    comp = st.floats(-bound, bound, allow_nan=False)
    return st.tuples(comp, comp, comp).map(np.array).filter(lambda v: np.linalg.norm(v) >= least)


@st.composite
def small_skeletons(draw) -> Skeleton:
    """A random tree of 1–6 bones (parents before children) with random heads and tails."""
    n = draw(st.integers(1, 6))
    parents = [-1] + [draw(st.integers(0, i - 1)) for i in range(1, n)]
    names = draw(st.lists(st.from_regex(r"[A-Za-z][A-Za-z0-9_:.]{0,7}", fullmatch=True),
                          min_size=n, max_size=n, unique=True))  # fmt: skip
    head = np.zeros((n, 3))
    head[0] = draw(vectors(1.0))
    for i in range(1, n):
        head[i] = head[parents[i]] + draw(vectors(0.5, least=0.02))
    tail = head + np.array([draw(vectors(0.4)) for _ in range(n)])
    return Skeleton(tuple(names), np.array(parents), head, tail, ("capsule",) * n,
                    np.full(n, 0.02), np.zeros((n, 3)))  # fmt: skip


skeletons = st.one_of(st.just(DOLL), small_skeletons())


@st.composite
def motions(draw, skel: Skeleton) -> tuple[np.ndarray, list[list[Rotation]]]:
    """(root translations (nframes,3) m, local rotations [frame][bone]) of 1–3 frames."""
    nframes = draw(st.integers(1, 3))
    root = np.array([draw(vectors(3.0)) for _ in range(nframes)])
    local = [[draw(rotations()) for _ in skel.names] for _ in range(nframes)]
    return root, local


def keys_of(skel: Skeleton, root: np.ndarray, local: list[list[Rotation]]) -> list[Keyframe]:
    """Keys as a run keeps them; the BVH writer reads the root's head and every ``local``
    (the world ``rotation`` and the other heads are not written)."""
    keys = []
    for f, rots in enumerate(local):
        bones = {}
        for b, name in enumerate(skel.names):
            q = rots[b].as_quat(scalar_first=True)
            bones[name] = BonePose(head=root[f] if b == 0 else np.zeros(3), rotation=q, local=q)
        keys.append(Keyframe(time=f / 30.0, label=f"key {f}", bones=bones))
    return keys


def expected_pose(skel: Skeleton, root: np.ndarray, rots: list[Rotation]):
    """World joint positions (m) and rotations of one frame, by the scipy oracle."""
    trans = [root if p < 0 else skel.head0[b] - skel.head0[p] for b, p in enumerate(skel.parents)]
    return scipy_fk(skel.parents, np.array(trans), rots)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("bvh_roundtrip")


def write_motion(folder: Path, name: str, data, skel, order: str, scale: float):
    """(root, local, path): a drawn motion of ``skel`` written by puppetcli to folder/name."""
    root, local = data.draw(motions(skel))
    path = folder / name
    write_keys_bvh(path, skel, keys_of(skel, root, local), order=order, scale=scale)
    return root, local, path


# ---- puppetcli writes, the `bvh` package reads ----


@pytest.mark.parametrize("order", ORDERS)
@SETTINGS
@given(data=st.data(), skel=skeletons, scale=st.sampled_from([1.0, 100.0]))
def test_bvh_package_reads_the_chosen_rotations_and_root_positions(folder, order, data, skel,
                                                                   scale) -> None:  # fmt: skip
    root, local, path = write_motion(folder, "written.bvh", data, skel, order, scale)
    mocap = bvh_package.Bvh(path.read_text())
    names = mocap.get_joints_names()
    assert sorted(names) == sorted(skel.names)
    assert mocap.nframes == len(local) == len(mocap.frames)
    rotation_channels = [f"{axis}rotation" for axis in order]
    for b, name in enumerate(skel.names):
        p = skel.parents[b]
        parent = mocap.joint_parent(name)
        assert (parent is None) if p < 0 else (parent.name == skel.names[p])
        offset = np.zeros(3) if p < 0 else (skel.head0[b] - skel.head0[p]) * scale
        np.testing.assert_allclose(mocap.joint_offset(name), offset, rtol=0, atol=POSITION_TOL)
        positions = ["Xposition", "Yposition", "Zposition"] if p < 0 else []
        assert mocap.joint_channels(name) == positions + rotation_channels
        ends = list(mocap.get_joint(name).filter("End"))
        assert len(ends) == (b not in set(skel.parents))
        for end in ends:
            tip = [float(x) for x in end["OFFSET"]]
            np.testing.assert_allclose(tip, (skel.tail0[b] - skel.head0[b]) * scale,
                                       rtol=0, atol=POSITION_TOL)  # fmt: skip
    for f in range(len(local)):
        written = mocap.frame_joint_channels(f, skel.names[0], ["Xposition", "Yposition",
                                                                "Zposition"])  # fmt: skip
        np.testing.assert_allclose(written, root[f] * scale, rtol=0, atol=POSITION_TOL)
        for b, name in enumerate(skel.names):
            values = mocap.frame_joint_channels(f, name, rotation_channels)
            # scipy: upper-case axes are intrinsic, R = R_first R_second R_third
            back = Rotation.from_euler(order.upper(), values, degrees=True)
            assert angle(back, local[f][b]) <= ROTATION_TOL, (f, name, values)


# ---- puppetcli writes, bvhio computes the joints' world poses ----


@pytest.mark.parametrize("order", ORDERS)
@SETTINGS
@given(data=st.data(), skel=skeletons, scale=st.sampled_from([1.0, 100.0]))
def test_bvhio_puts_joints_where_scipy_forward_kinematics_does(folder, order, data, skel,
                                                               scale) -> None:  # fmt: skip
    root, local, path = write_motion(folder, "fk.bvh", data, skel, order, scale)
    hierarchy = bvhio.readAsHierarchy(str(path))
    joints = {joint.Name: joint for joint, _, _ in hierarchy.layout()}
    assert sorted(joints) == sorted(skel.names)
    hierarchy.loadRestPose()  # bvhio turns each joint's frame to follow its bone
    rest = {name: _rotation(joint.RotationWorld) for name, joint in joints.items()}
    reach = max(skel.size + float(np.abs(root).max()), 0.1)  # m; float32 near 0 is exact
    for f in range(len(local)):
        heads, world = expected_pose(skel, root[f], local[f])
        hierarchy.loadPose(f)
        for b, name in enumerate(skel.names):
            found = np.array(joints[name].PositionWorld) / scale
            assert np.abs(found - heads[b]).max() <= BVHIO_POSITION_TOL * reach, (f, name)
            turned = _rotation(joints[name].RotationWorld) * rest[name].inv()
            assert angle(turned, world[b]) <= BVHIO_ROTATION_TOL, (f, name)


def _rotation(q) -> Rotation:
    """A scipy Rotation of a glm quaternion."""
    return Rotation.from_quat([q.w, q.x, q.y, q.z], scalar_first=True)


# ---- the test writes channel values, puppetcli reads them ----


@st.composite
def channel_lists(draw, root: bool) -> list[str]:
    """Any subset of the six channels in any order (the root: at least one)."""
    chosen = draw(st.lists(st.sampled_from(CHANNEL_NAMES), unique=True, min_size=int(root)))
    return draw(st.permutations(chosen))


@st.composite
def files(draw):
    """(joints, channels by name, frames (nframes, nchannels)) of a random BVH file."""
    n = draw(st.integers(1, 6))
    parents = [None] + [draw(st.integers(0, i - 1)) for i in range(1, n)]
    names = [f"J{i}" for i in range(n)]
    joints = []
    for i in range(n):
        end = tuple(draw(vectors(1.0))) if draw(st.booleans()) else None
        parent = None if parents[i] is None else names[parents[i]]
        joints.append(J(names[i], parent, tuple(draw(vectors(5.0))), end))
    channels = {j.name: draw(channel_lists(j.parent is None)) for j in joints}
    nchannels = sum(len(c) for c in channels.values())
    value = st.floats(-720.0, 720.0, allow_nan=False)
    frames = draw(st.lists(st.lists(value, min_size=nchannels, max_size=nchannels),
                           min_size=0, max_size=3))  # fmt: skip
    return joints, channels, np.array(frames, dtype=float).reshape(-1, nchannels)


def file_pose(joints: list[J], channels: dict, row: np.ndarray):
    """Local translations and Rotations of one frame line, per joint in file order (depth
    first): positions replace the OFFSET's components, rotations intrinsic in listed order."""
    trans, rots, k = [], [], 0
    for j in joints:
        t, axes, angles = np.array(j.offset, dtype=float), "", []
        for c in channels[j.name]:
            if c.endswith("position"):
                t["XYZ".index(c[0])] = row[k]
            else:
                axes, angles = axes + c[0], [*angles, row[k]]
            k += 1
        trans.append(t)
        # one row of angles: a single rotation even for a single axis
        rots.append(
            Rotation.from_euler(axes, [angles], degrees=True)[0] if axes else Rotation.identity()
        )
    return np.array(trans), rots


def depth_first(joints: list[J]) -> list[J]:
    """The joints in file order: depth first, children in list order."""
    out: list[J] = []
    stack = [j for j in joints if j.parent is None]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed([c for c in joints if c.parent == j.name]))
    return out


@SETTINGS
@given(
    spec=files(),
    newline=st.sampled_from(["\n", "\r\n", "\r"]),
    indent=st.sampled_from(["\t", "  "]),
    frame_time=st.floats(1e-4, 1.0),
)
def test_our_reader_reads_chosen_channel_values_as_scipy_does(folder, spec, newline, indent,
                                                             frame_time) -> None:  # fmt: skip
    joints, channels, frames = spec
    path = folder / "chosen.bvh"
    path.write_bytes(bvh_text(joints, channels, frames, frame_time, newline, indent).encode())
    read = read_bvh(path)
    ordered = depth_first(joints)
    names = [j.name for j in ordered]
    assert read.names == tuple(names)
    parents = [-1 if j.parent is None else names.index(j.parent) for j in ordered]
    assert read.parents.tolist() == parents
    for got, j in zip(read.joints, ordered, strict=True):
        assert got.offset.tolist() == list(j.offset)  # 17 significant digits: exact
        assert got.channels == tuple(channels[j.name])
        assert [e.tolist() for e in got.ends] == ([] if j.end is None else [list(j.end)])
    assert read.frame_time == frame_time
    # the fixtures' writer lists frame values in file order, joint by joint
    assert np.array_equal(read.frames, frames)
    trans, rot = read.poses()
    reach = 1.0 + float(np.abs(frames).max(initial=0.0)) + 5.0 * len(joints)
    for f, row in enumerate(frames):
        want_trans, want_rots = file_pose(ordered, channels, row)
        np.testing.assert_array_equal(trans[f], want_trans)
        for k, want in enumerate(want_rots):
            got = Rotation.from_quat(rot[f, k], scalar_first=True)
            assert angle(got, want) <= OURS_ROTATION_TOL, (f, names[k])
        heads, _ = read.forward_kinematics(f)
        want_heads, _ = scipy_fk(parents, want_trans, want_rots)
        assert np.abs(heads - want_heads).max() <= OURS_POSITION_TOL * reach
