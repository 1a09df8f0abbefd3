"""Compiled row response (solver.solve.response's twin): how a unit row force changes body
velocities, and applying solved forces.
"""

from __future__ import annotations

from solver.jit import kernel


@kernel(error_model="numpy", _nrt=False)
def response(rw, start, n, inv_mass, inv_i, h, resp_a, resp_b):
    """Velocity change per unit row force: h M⁻¹ jac, per side (0 for the world), of
    rows start … n − 1."""
    _response_side(rw.body_a, rw.jac_a, start, n, inv_mass, inv_i, h, resp_a)
    _response_side(rw.body_b, rw.jac_b, start, n, inv_mass, inv_i, h, resp_b)


@kernel(error_model="numpy")
def _response_side(body, jac, start, n, inv_mass, inv_i, h, out):
    for i in range(start, n):
        r = row_response(body, jac, i, inv_mass, inv_i, h)
        for k in range(6):
            out[i, k] = r[k]


@kernel(error_model="numpy")
def row_response(body, jac, i, inv_mass, inv_i, h):
    """Row i's h M⁻¹ jac on one side (zeros for the world)."""
    b = body[i]
    if b < 0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    s0 = inv_i[b, 0, 0] * jac[i, 3] + inv_i[b, 0, 1] * jac[i, 4]
    s1 = inv_i[b, 1, 0] * jac[i, 3] + inv_i[b, 1, 1] * jac[i, 4]
    s2 = inv_i[b, 2, 0] * jac[i, 3] + inv_i[b, 2, 1] * jac[i, 4]
    return (
        h * (inv_mass[b] * jac[i, 0]), h * (inv_mass[b] * jac[i, 1]),
        h * (inv_mass[b] * jac[i, 2]), h * (s0 + inv_i[b, 0, 2] * jac[i, 5]),
        h * (s1 + inv_i[b, 1, 2] * jac[i, 5]), h * (s2 + inv_i[b, 2, 2] * jac[i, 5]),
    )  # fmt: skip


@kernel(error_model="numpy")
def apply(rw, n, resp_a, resp_b, lam, vel):
    """vel += response to λ: every row's a side, then every row's b side (np.add.at order)."""
    _apply_side(rw.body_a, n, resp_a, lam, vel)
    _apply_side(rw.body_b, n, resp_b, lam, vel)


@kernel(error_model="numpy", inline="always")
def copy6(src, dst):
    """dst[:, :] ← src (nb, 6) (an array assigned to a slice needs reference counting)."""
    for b in range(len(src)):
        for k in range(6):
            dst[b, k] = src[b, k]


@kernel(error_model="numpy", _nrt=False)
def apply_listed(rw, rows, count, resp_a, resp_b, lam, vel):
    """vel += response to λ of the rows rows[:count] only (ascending: the order of
    ``apply``)."""
    for side in range(2):
        body, resp = (rw.body_a, resp_a) if side == 0 else (rw.body_b, resp_b)
        for q in range(count):
            i = rows[q]
            if body[i] >= 0:
                for k in range(6):
                    vel[body[i], k] += resp[i, k] * lam[i]


@kernel(error_model="numpy")
def _apply_side(body, n, resp, lam, vel):
    for i in range(n):
        b = body[i]
        if b >= 0:
            for k in range(6):
                vel[b, k] += resp[i, k] * lam[i]
