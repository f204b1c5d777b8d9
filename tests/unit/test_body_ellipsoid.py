"""Ellipsoid (Eq. 26), Segment and Body: analytic values and input validation."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfem.body import Body, Ellipsoid, FixedMotion, HingeMotion, Segment

Q = Rotation.from_euler("zyx", [30.0, -20.0, 50.0], degrees=True).as_matrix()
C = np.array([0.1, -0.2, 0.9])
R = np.array([0.2, 0.06, 0.04])


def make() -> Ellipsoid:
    return Ellipsoid(centre=C, axes=Q.T, radii=R, name="forearm")


def test_f_on_axes_and_centre():
    e = make()
    # Points c + s r_i e_i: f = s^2 - 1 exactly.
    for i in range(3):
        for s in (0.0, 0.5, 1.0, 2.0):
            x = C + s * R[i] * Q[:, i]
            assert e.f(x) == pytest.approx(s**2 - 1.0, abs=1e-12)
    assert e.f(C) == pytest.approx(-1.0)


def test_f_vectorised_and_surface_grid_zero():
    e = make()
    x, y, z = e.surface_grid(n_u=9, n_v=7)
    pts = np.stack([x, y, z], axis=-1)
    assert pts.shape == (7, 9, 3)
    np.testing.assert_allclose(e.f(pts), 0.0, atol=1e-12)
    np.testing.assert_allclose(e.f(pts.reshape(-1, 3)).shape, (63,))


def test_gradient_analytic_and_finite_difference():
    e = make()
    rng = np.random.default_rng(1)
    x = C + rng.normal(scale=0.1, size=(5, 3))
    g = e.gradient(x)
    # Analytic: 2 sum_i ((x-c).e_i / r_i^2) e_i.
    y = (x - C) @ Q
    np.testing.assert_allclose(g, (2 * y / R**2) @ Q.T, rtol=1e-12)
    h = 1e-6
    fd = np.stack([(e.f(x + h * d) - e.f(x - h * d)) / (2 * h) for d in np.eye(3)], axis=-1)
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_contains_and_local_round_trip():
    e = make()
    inside = C + 0.9 * R[1] * Q[:, 1]
    outside = C + 1.1 * R[1] * Q[:, 1]
    np.testing.assert_array_equal(e.contains(np.array([inside, outside])), [True, False])
    y = np.array([[0.1, 0.02, -0.03], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(e.transform_to_local(e.transform_from_local(y)), y, atol=1e-15)
    np.testing.assert_allclose(e.transform_from_local([R[0], 0, 0]), C + R[0] * Q[:, 0])


@pytest.mark.parametrize("bad", [(0.06, 0.0, 0.2), (0.06, -0.1, 0.2), (np.nan, 0.06, 0.2)])
def test_segment_radii_error(bad):
    motion = FixedMotion(centre=C, rotation=Q)
    with pytest.raises(ValueError, match=r"^segment 'forearm': radii must be finite and > 0 m"):
        Segment(name="forearm", radii=bad, motion=motion)
    with pytest.raises(ValueError, match=r"^ellipsoid 'e': radii must be finite and > 0 m, got"):
        Ellipsoid(centre=C, axes=Q.T, radii=bad, name="e")


def test_radii_shape_and_axes_errors():
    with pytest.raises(ValueError, match="radii must have shape"):
        Ellipsoid(centre=C, axes=Q.T, radii=(0.1, 0.1))
    with pytest.raises(ValueError, match="axes: must be orthonormal"):
        Ellipsoid(centre=C, axes=2 * Q.T, radii=R)
    with pytest.raises(ValueError, match="axes: must be right-handed"):
        Ellipsoid(centre=C, axes=-Q.T, radii=R)
    with pytest.raises(ValueError, match="centre: must be finite"):
        Ellipsoid(centre=(0.0, np.nan, 0.0), axes=Q.T, radii=R)


def test_body_union_names_and_point_velocity():
    hinge = HingeMotion(
        joint=(0.0, 0.0, 0.0),
        axis=(0.0, 0.0, 1.0),
        omega=2.0,
        angle_max=1.0,
        centre0=(0.2, 0.0, 0.0),
        rotation0=np.eye(3),
    )
    a = Segment(name="a", radii=(0.2, 0.05, 0.05), motion=hinge)
    b = Segment(
        name="b", radii=(0.1, 0.1, 0.1), motion=FixedMotion(centre=(-1, 0, 0), rotation=np.eye(3))
    )
    body = Body(segments=(a, b))
    assert body.names == ("a", "b")
    x = np.array([[-1.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    np.testing.assert_allclose(body.f(x, 0.0), [-1.0, 26.0 / 0.01 - 1.0])
    np.testing.assert_array_equal(body.contains(x, 0.0), [True, False])
    # Rigid rotation about the z axis through the origin: v = omega z x p.
    p = np.array([[0.3, 0.1, 0.0]])
    np.testing.assert_allclose(a.point_velocity(p, 0.25), [[-0.2, 0.6, 0.0]], atol=1e-14)
    with pytest.raises(ValueError, match="segment names must be unique"):
        Body(segments=(a, a))
    with pytest.raises(KeyError, match="no segment 'c'"):
        body.segment("c")


def test_body_package_imports_no_fem_code():
    """clothfem.body is numpy/scipy only: no dolfinx/ufl/petsc4py, and ezc3d only on demand."""
    code = (
        "import sys, clothfem.body; "
        "bad = [m for m in ('dolfinx', 'ufl', 'petsc4py', 'mpi4py', 'ezc3d') if m in sys.modules]; "
        "print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
