"""Nodal finite rotations (Eqs. 7-9): Euler's formula, derivatives, inverse, theta -> 0."""

import numpy as np
import pytest

from clothfem.shell import rotation as R


@pytest.fixture
def basis():
    rng = np.random.default_rng(0)
    return R.fibre_basis(rng.normal(size=(64, 3)))


def test_fibre_basis_orthonormal_right_handed(basis):
    assert np.allclose(np.einsum("nij,nkj->nik", basis, basis), np.eye(3), atol=1e-14)
    assert np.allclose(np.linalg.det(basis), 1.0, atol=1e-14)
    # a normal along a global axis is not degenerate
    b = R.fibre_basis(np.eye(3))
    assert np.allclose(np.linalg.det(b), 1.0)


@pytest.mark.parametrize("scale", [0.0, 1e-9, 1e-3, 0.2999, 0.3001, 1.0, 3.0])
def test_director_is_euler_rotation_of_e3(basis, scale):
    rng = np.random.default_rng(1)
    th = rng.normal(size=(len(basis), 2)) * scale
    d = R.director(basis, th)
    rotvec = th[:, :1] * basis[:, 0] + th[:, 1:] * basis[:, 1]
    Rm = R.rotation_matrix(rotvec)
    assert np.allclose(np.einsum("nij,nj->ni", Rm, basis[:, 2]), d, atol=1e-14)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-14)
    assert np.allclose(np.einsum("nij,nkj->nik", Rm, Rm), np.eye(3), atol=1e-13)


@pytest.mark.parametrize("scale", [1e-6, 0.29, 0.31, 2.0])
def test_derivatives_against_central_differences(basis, scale):
    rng = np.random.default_rng(2)
    th = rng.normal(size=(len(basis), 2)) * scale
    T, H = R.director_derivatives(basis, th)
    h = 1e-6
    for a in range(2):
        dth = np.zeros_like(th)
        dth[:, a] = h
        fd = (R.director(basis, th + dth) - R.director(basis, th - dth)) / (2 * h)
        assert np.allclose(fd, T[:, :, a], atol=1e-8)
        Tp, _ = R.director_derivatives(basis, th + dth)
        Tm, _ = R.director_derivatives(basis, th - dth)
        assert np.allclose((Tp - Tm) / (2 * h), H[:, :, :, a], atol=1e-7)


def test_small_rotation_limit_is_hughes_infinitesimal(basis):
    """Eq. 9 as theta -> 0: u^ = theta2 e1 - theta1 e2."""
    th = np.full((len(basis), 2), 1e-9)
    d = R.director(basis, th)
    lin = basis[:, 2] + th[:, 1:] * basis[:, 0] - th[:, :1] * basis[:, 1]
    assert np.allclose(d, lin, atol=1e-17)


def test_inverse(basis):
    rng = np.random.default_rng(3)
    th = rng.normal(size=(len(basis), 2))
    th *= (3.0 * rng.random(len(basis)) / np.linalg.norm(th, axis=1))[:, None]  # |theta| < pi
    assert np.allclose(R.rotation_from_director(basis, R.director(basis, th)), th, atol=1e-12)
