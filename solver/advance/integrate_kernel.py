"""Compiled semi-implicit Euler (solver.advance.integrate's twin), momentum form."""

from __future__ import annotations

from solver.advance.integrate import MIDPOINT_PASSES
from solver.compiled.layout import Flags, Opt
from solver.jit import kernel
from solver.kin_kernel import (
    add,
    matvec,
    put,
    qexp,
    qmatrix,
    qmul,
    qnormalize,
    quat_at,
    scale,
    tmatvec,
    vec,
)


@kernel(error_model="numpy")
def _omega_from_momentum(q, mom, inv_inertia, b, rot):
    """ω = I_w(q)⁻¹ L = R (I⁻¹ (Rᵀ L)) of body b; rot (nb,3,3) scratch."""
    qmatrix(q, rot, b)
    return matvec(rot, b, matvec(inv_inertia, b, tmatvec(rot, b, mom)))


@kernel(error_model="numpy", _nrt=False)
def integrate(inertia, inv_inertia, h, pos, quat, vel, rot, asleep, out_pos, out_quat, out_omega,
              scratch):  # fmt: skip
    """Semi-implicit Euler in momentum form with the implicit midpoint rotation rate.
    rot (nb,3,3) holds R(q[t]) on entry and R(q[t+1]) on return.  Sleeping bodies
    (asleep (nb,) bool) keep their pose, at rest.  scratch: (rates (nb,3), momenta
    (nb,3), done (nb,) bool).

    The midpoint passes run pass by pass over all bodies (the bodies' chains are
    independent, so the processor overlaps them; body by body it waits on each pass's
    latency), and a body's passes stop once one returns its rate unchanged: every later
    pass would repeat it exactly, so the result is bit for bit that of all passes."""
    nb = len(pos)
    rates, moms, done = scratch
    for b in range(nb):
        done[b] = asleep[b]
        if asleep[b]:
            for k in range(3):
                out_pos[b, k], out_omega[b, k] = pos[b, k], 0.0
            for k in range(4):
                out_quat[b, k] = quat[b, k]
            continue
        put(out_pos, b, add(vec(pos, b), scale(h, (vel[b, 0], vel[b, 1], vel[b, 2]))))
        rate = (vel[b, 3], vel[b, 4], vel[b, 5])
        put(moms, b, matvec(rot, b, matvec(inertia, b, tmatvec(rot, b, rate))))  # L = R I Rᵀ ω
        put(rates, b, rate)
    for _ in range(MIDPOINT_PASSES):
        for b in range(nb):
            if done[b]:
                continue
            rate = vec(rates, b)
            mid = qmul(qexp(scale(0.5 * h, rate)), quat_at(quat, b))
            new = _omega_from_momentum(mid, vec(moms, b), inv_inertia, b, rot)
            done[b] = new[0] == rate[0] and new[1] == rate[1] and new[2] == rate[2]
            put(rates, b, new)
    for b in range(nb):
        if asleep[b]:
            continue
        q0 = quat_at(quat, b)
        q = qnormalize(qmul(qexp(scale(h, vec(rates, b))), q0))
        for k in range(4):
            out_quat[b, k] = q[k]
        put(out_omega, b, _omega_from_momentum(q, vec(moms, b), inv_inertia, b, rot))


@kernel(error_model="numpy", _nrt=False)
def free_velocity(inv_mass, opt, vel, omega, inv_i, loads, out):
    """(nb,6) velocities after gravity and external loads (force, torque, flags: the
    input's inp.force, inp.torque, inp.flags), before constraints."""
    force, torque, ivec = loads
    h = opt[Opt.h]
    for b in range(len(vel)):
        tau = matvec(inv_i, b, (torque[b, 0], torque[b, 1], torque[b, 2]))
        for k in range(3):
            acc = opt[Opt.gravity + k] if inv_mass[b] > 0.0 else 0.0
            if ivec[Flags.has_force]:
                acc = acc + force[b, k] * inv_mass[b]
            out[b, k] = vel[b, k] + h * acc
            out[b, 3 + k] = omega[b, k] + h * tau[k] if ivec[Flags.has_torque] else omega[b, k]
