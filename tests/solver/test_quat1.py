"""solver.quat1 (one quaternion in Python floats) gives numpy's solver.quat results bit for bit."""

from __future__ import annotations

import numpy as np

from solver import quat, quat1


def test_the_same_floats_as_solver_quat():
    rng = np.random.default_rng(11)
    for i in range(3000):
        a, b, v = quat.normalize(rng.normal(size=4)), rng.normal(size=4), rng.normal(size=3)
        if i % 5 == 0:  # log's small-angle branch
            a = quat.normalize(np.array([1.0, 1e-14 * rng.normal(), 0.0, 0.0]))
        if i % 3 == 0:  # log's shortest arc
            a = -a
        pairs = [
            (quat.mul(a, b), quat1.mul(tuple(a), tuple(b))),
            (quat.conj(b), quat1.conj(tuple(b))),
            (quat.cross(v, b[1:]), quat1.cross(tuple(v), tuple(b[1:]))),
            (quat.rotate(a, v), quat1.rotate(tuple(a), tuple(v))),
            (quat.normalize(b[None])[0], quat1.normalize(tuple(b))),
            (quat.log(a), quat1.log(tuple(a))),
        ]
        for expected, got in pairs:
            assert np.array_equal(expected, np.array(got)), (i, expected, got)
