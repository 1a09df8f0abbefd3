"""The live device's ticks: the scalar pose algebra against solver.quat and the session's
Workspace (numpy), bit for bit; the pointer filter against its exact recursion."""

from __future__ import annotations

import math

import numpy as np

from puppetcli.live import track
from puppetcli.live.track import LiveTrack, PointerFilter, device_from_world
from puppetcli.mcap.replay import DeviceTrack
from puppetcli.mcap.session import TICK, Workspace
from solver import quat


def random_workspace(rng) -> Workspace:
    return Workspace(
        rng.normal(size=3), float(rng.uniform(1, 60)), quat.normalize(rng.normal(size=4))
    )


def test_scalar_poses_equal_the_readers_numpy_bit_for_bit():
    """A replay computes world poses from the recorded device poses with numpy; the live run
    with scalars.  Equal floats, so the live run and its replay step on the same inputs."""
    rng = np.random.default_rng(7)
    for _ in range(500):
        ws = random_workspace(rng)
        p, q = rng.normal(size=3), rng.normal(size=4) * rng.uniform(0.5, 2.0)
        q_read = quat.normalize(q[None])
        world = ws.world_from_device(p[None], q_read)
        got = track._world_from_device(ws, tuple(p), tuple(q_read[0]))
        assert np.array_equal(got[0], world[0][0]) and np.array_equal(got[1], world[1][0])
        device = ws.device_from_world(p, q_read[0])
        got = device_from_world(ws, tuple(p), tuple(q_read[0]))
        assert np.array_equal(got[0], device[0]) and np.array_equal(got[1], device[1])


def test_live_track_looks_up_like_a_device_track():
    rng = np.random.default_rng(3)
    ws = random_workspace(rng)
    live = LiveTrack(ws, capacity=4)  # grows several times
    pos, q = rng.normal(size=(50, 3)), quat.normalize(rng.normal(size=(50, 4)))
    for k in range(50):
        live.append(k * TICK, tuple(pos[k]), tuple(q[k]))
    world = ws.world_from_device(pos, quat.normalize(q))
    ref = DeviceTrack(np.arange(50) * TICK, pos, quat.normalize(q), *world)
    for t in (-1.0, 0.0, 0.0004, 0.0105, 0.049, 3.0):
        assert live.index(t) == ref.index(t)
        for a, b in zip(live.pose(t), ref.pose(t), strict=True):
            assert np.array_equal(a, b)


def test_filter_follows_its_exact_recursion():
    """Towards a fixed target: e_n = (1 − α)^n e_0 for the position and the rotation angle."""
    f = PointerFilter((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), tau=0.01)
    alpha = 1.0 - math.exp(-TICK / 0.01)
    target_q = quat.exp(np.array([0.0, 0.0, 1.2]))
    for n in range(1, 41):
        f.tick((0.3, -0.1, 0.2), tuple(target_q))
        decay = (1.0 - alpha) ** n
        np.testing.assert_allclose(f.pos, np.array([0.3, -0.1, 0.2]) * (1 - decay), atol=1e-15)
        left = np.linalg.norm(quat.log(quat.mul(target_q, quat.conj(np.array(f.quat)))))
        assert abs(left - 1.2 * decay) < 1e-12  # measured ~1e-16
    f.jump((1.0, 2.0, 3.0), (0.0, 1.0, 0.0, 0.0))
    assert f.pos == (1.0, 2.0, 3.0) and f.quat == (0.0, 1.0, 0.0, 0.0)
