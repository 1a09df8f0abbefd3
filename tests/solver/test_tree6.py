"""The written-out 6×6 kernels (solver.solve.tree6) against the loops of solver.solve.direct_kernel
they replace for 6×6 blocks: bitwise equal on random blocks (the split elimination on
blocks with its zero corner); and tree6.py is current."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.solve import direct_kernel as tree
from solver.solve import tree6, unroll

NODES = 3  # node 0 the block, node 1 its parent, node 2 spare


def _spd(rng, sign: float) -> np.ndarray:
    a = rng.normal(size=(6, 6))
    return sign * (a @ a.T + 6.0 * np.eye(6))


def _factored(rng, sign: float):
    """(dm (NODES, 6, 6) with node 0 factored by the loops and node 1 a parent block,
    the block node 0 was before)."""
    dm = np.zeros((NODES, 6, 6))
    dm[0], dm[1] = _spd(rng, sign), _spd(rng, 1.0)
    block = dm[0].copy()
    assert tree._chol_block(dm, 0, 6, sign)
    return dm, block


def test_the_generated_file_is_current():
    path = Path(tree6.__file__)
    assert path == unroll.TARGET
    assert path.read_text() == unroll.source(), "run: python -m solver.solve.unroll"


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_chol6_is_the_loop_factor_bitwise(sign):
    rng = np.random.default_rng(1)
    for _ in range(50):
        dm = np.zeros((NODES, 6, 6))
        dm[0] = _spd(rng, sign)
        loops = dm.copy()
        assert tree6.chol6(dm, 0, sign) and tree._chol_block(loops, 0, 6, sign)
        assert np.array_equal(dm, loops)
    indefinite = np.zeros((NODES, 6, 6))
    indefinite[0] = np.diag([1.0, 1.0, -1.0, 1.0, 1.0, 1.0])
    assert not tree6.chol6(indefinite, 0, 1.0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_eliminate6_is_the_loop_elimination_bitwise(sign):
    rng = np.random.default_rng(2)
    for _ in range(50):
        dm, block = _factored(rng, sign)
        parent = dm[1].copy()
        g = rng.normal(size=(6, 6))
        y = np.zeros((NODES, 6, 6))
        dm2, y2 = dm.copy(), y.copy()
        tree6.eliminate6(0, 1, sign, dm, y, g)
        tree._eliminate(0, 1, 6, 6, sign, dm2, y2, g)
        assert np.array_equal(dm, dm2) and np.array_equal(y, y2)
        # and it is the elimination: D_p −= sign·Gᵀ (sign·D_i)⁻¹ G, on the lower triangle
        expected = parent - sign * g.T @ np.linalg.solve(sign * block, g)
        # measured 3.6e-15 on entries up to 28
        assert np.allclose(np.tril(dm[1]), np.tril(expected), rtol=0.0, atol=2e-14)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_split_elimination_is_the_loop_elimination_where_it_applies(sign):
    # A G with a zero upper-left 3×3 block (both zeros' signs, as −J makes them): the
    # split kernel equals the loop everywhere (== counts −0 and 0 as equal), and the
    # factorisation picks it exactly for such blocks.
    rng = np.random.default_rng(4)
    for k in range(50):
        dm, _ = _factored(rng, sign)
        g = rng.normal(size=(6, 6))
        g[:3, :3] = 0.0 if k % 2 else -0.0
        assert tree._upper_left_zero(g)
        y = np.zeros((NODES, 6, 6))
        dm2, y2 = dm.copy(), y.copy()
        tree6.eliminate6_split(0, 1, sign, dm, y, g)
        tree._eliminate(0, 1, 6, 6, sign, dm2, y2, g)
        assert np.array_equal(dm, dm2) and np.array_equal(y, y2)
        g[rng.integers(3), rng.integers(3)] = 1e-300
        assert not tree._upper_left_zero(g)


def _same_in_place(x: np.ndarray, written, written_args: tuple, loops, loop_args: tuple) -> bool:
    """Both kernels applied in place to copies of x (their last argument) agree bitwise."""
    a, b = x.copy(), x.copy()
    written(*written_args, a)
    loops(*loop_args, b)
    return np.array_equal(a, b)


def test_substitution_kernels_are_the_loops_bitwise():
    rng = np.random.default_rng(3)
    for _ in range(50):
        sign = rng.choice([1.0, -1.0])
        dm, _ = _factored(rng, sign)
        y = np.zeros((NODES, 6, 6))
        y[0] = rng.normal(size=(6, 6))
        x = rng.normal(size=(NODES, 6))
        assert _same_in_place(x, tree6.forward6, (dm, 0), tree._forward_block, (dm, 0, 6))
        assert _same_in_place(x, tree6.backward6, (dm, 0), tree._backward_block, (dm, 0, 6))
        fold = (0, 1, sign, dm, y)
        loops = (0, 1, 6, 6, sign, dm, y)
        assert _same_in_place(x, tree6.fold_up6, fold, tree._fold_up, loops)
        assert _same_in_place(x, tree6.take_down6, (0, 1, y), tree._take_down, (0, 1, 6, 6, y))
