"""Shapes' volumes and inertias against integrals over the solid (scipy's quad).

A capsule and a sphere are solids of revolution about their local y axis with radius
profile ρ(y); per unit density their volume is ∫ π ρ² dy, their axial moment ∫ π ρ⁴/2 dy
(stacked discs) and their moment about a perpendicular axis through the centre
∫ (π ρ⁴/4 + π ρ² y²) dy (each disc's own moment plus the parallel-axis term).  A box's
moments are products of one-dimensional integrals.  None of this uses the code's
cylinder-plus-caps decomposition.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.integrate import quad

from solver.massprops import shape_inertia_local, shape_volume
from solver.model import build_model
from solver.spec import BoneSpec, RigSpec, ShapeSpec


def revolution(profile, half: float) -> tuple[float, float, float]:
    """(volume, axial moment, perpendicular moment) per unit density of the solid of
    revolution with radius ``profile(y)`` for |y| ≤ half, integrated piecewise."""
    cuts = sorted({-half, half, *getattr(profile, "cuts", ())})
    volume = axial = perp = 0.0
    for a, b in itertools.pairwise(cuts):
        volume += quad(lambda y: np.pi * profile(y) ** 2, a, b, epsabs=0, epsrel=1e-13)[0]
        axial += quad(lambda y: np.pi * profile(y) ** 4 / 2, a, b, epsabs=0, epsrel=1e-13)[0]
        perp += quad(
            lambda y: np.pi * profile(y) ** 4 / 4 + np.pi * profile(y) ** 2 * y * y,
            a, b, epsabs=0, epsrel=1e-13,
        )[0]  # fmt: skip
    return volume, axial, perp


def capsule_profile(radius: float, length: float):
    def rho(y: float) -> float:
        beyond = max(abs(y) - length / 2, 0.0)
        return np.sqrt(max(radius * radius - beyond * beyond, 0.0))

    rho.cuts = (-length / 2, length / 2)
    return rho


@pytest.mark.parametrize(("radius", "length"), [(0.02, 0.1), (0.05, 0.3), (0.04, 0.01)])
def test_capsule_volume_and_inertia_are_the_integrals_over_it(radius, length):
    mass = 0.7
    volume, axial, perp = revolution(capsule_profile(radius, length), length / 2 + radius)
    shape = ShapeSpec("capsule", radius=radius)
    inertia = shape_inertia_local(shape, length, mass)
    density = mass / volume
    # measured: 2e-16 relative on all three (quad's tolerance is 1e-13)
    assert shape_volume(shape, length) == pytest.approx(volume, rel=1e-12)
    expected = np.diag([perp, axial, perp]) * density  # local y along the bone
    np.testing.assert_allclose(inertia, expected, rtol=1e-12, atol=0.0)


def test_sphere_volume_and_inertia_are_the_integrals_over_it():
    radius, mass = 0.03, 0.4
    volume, axial, perp = revolution(capsule_profile(radius, 0.0), radius)
    shape = ShapeSpec("sphere", radius=radius)
    assert shape_volume(shape, 0.2) == pytest.approx(volume, rel=1e-12)  # measured 1e-16
    inertia = shape_inertia_local(shape, 0.2, mass)
    np.testing.assert_allclose(inertia, np.eye(3) * axial * mass / volume, rtol=1e-12)
    assert perp == pytest.approx(axial, rel=1e-12)  # the integrals agree with themselves


def test_box_volume_and_inertia_are_the_integrals_over_it():
    half = (0.03, 0.12, 0.05)
    mass = 1.3
    # ∫∫∫ x² dV = (2h_x)³/12 · (2h_y)(2h_z) etc., each factor by quad
    length = [quad(lambda _: 1.0, -h, h)[0] for h in half]
    second = [quad(lambda s: s * s, -h, h)[0] for h in half]
    volume = float(np.prod(length))
    moments = [
        (second[1] * length[2] + second[2] * length[1]) * length[0],
        (second[0] * length[2] + second[2] * length[0]) * length[1],
        (second[0] * length[1] + second[1] * length[0]) * length[2],
    ]
    shape = ShapeSpec("box", half_extents=half)
    assert shape_volume(shape, 0.24) == pytest.approx(volume, rel=1e-12)  # measured 0
    inertia = shape_inertia_local(shape, 0.24, mass)
    np.testing.assert_allclose(inertia, np.diag(moments) * mass / volume, rtol=1e-12)


@pytest.mark.parametrize("offset", [0.0, 0.04])
def test_a_sphere_centred_on_its_com_has_its_own_inertia_there(offset):
    # rig-format: "a sphere is centred on the midpoint (or on com when given)": a sphere
    # bone whose com is off the head–tail midpoint is a uniform ball about that com, so its
    # body inertia is the integral's, with no parallel-axis term (it had m·|midpoint − com|²)
    radius, mass = 0.05, 2.0
    volume, axial, _ = revolution(capsule_profile(radius, 0.0), radius)
    com = np.array([0.0, 0.05 + offset, 0.0])  # the midpoint of head and tail is y = 0.05
    spec = rig_with_sphere(com, radius, mass)
    model = build_model(spec)
    want = np.eye(3) * axial * mass / volume
    np.testing.assert_allclose(model.body_inertia[0], want, rtol=1e-12)  # measured 1e-16
    np.testing.assert_array_equal(model.body_pos0[0], com)
    assert np.abs(model.geometry.shape_pos[0]).max() == 0.0  # the ball sits on the com


def rig_with_sphere(com: np.ndarray, radius: float, mass: float):
    bone = BoneSpec("ball", None, np.zeros(3), np.array([0.0, 0.1, 0.0]),
                    ShapeSpec("sphere", radius=radius), mass, com=com)  # fmt: skip
    return RigSpec("one", (bone,), root_mode="free")
