"""Coulomb return mapping and sliding kinematics (clothfem.contact.friction)."""

from __future__ import annotations

import numpy as np
import pytest

from clothfem.contact import (
    body_point_velocity,
    coulomb_return_map,
    coulomb_slip_update,
    relative_tangential_velocity,
    tangential_part,
)


def _trial(n: int, seed: int = 0) -> np.ndarray:
    f = np.random.default_rng(seed).normal(size=(n, 3))
    f[:, 2] = 0.0  # tangent plane z = 0
    return f


def test_stick_inside_cone() -> None:
    f = _trial(50)
    lam = np.linalg.norm(f, axis=1) / 0.5 * 1.01  # |f_trial| < mu lambda
    res = coulomb_return_map(lam, f, 0.5, penalty=1e3)
    assert np.all(res.stick)
    np.testing.assert_array_equal(res.force, f)
    np.testing.assert_array_equal(res.slip, 0.0)
    np.testing.assert_array_equal(res.dissipation, 0.0)


def test_slip_on_cone_and_dissipation() -> None:
    f = _trial(50, 1)
    mu, k = 0.3, 2e3
    lam = np.linalg.norm(f, axis=1) / mu * 0.4  # |f_trial| > mu lambda
    res = coulomb_return_map(lam, f, mu, penalty=k)
    assert not np.any(res.stick)
    np.testing.assert_allclose(np.linalg.norm(res.force, axis=1), mu * lam, rtol=1e-14)
    # force along the trial direction, antiparallel to the plastic slip
    unit = f / np.linalg.norm(f, axis=1, keepdims=True)
    np.testing.assert_allclose(res.force / (mu * lam)[:, None], unit, atol=1e-14)
    slip_dir = res.slip / np.linalg.norm(res.slip, axis=1, keepdims=True)
    np.testing.assert_allclose(slip_dir, -unit, atol=1e-14)
    # plastic slip magnitude (|f_trial| - mu lambda) / k, dissipation mu lambda |du_p| >= 0
    np.testing.assert_allclose(
        np.linalg.norm(res.slip, axis=1), (np.linalg.norm(f, axis=1) - mu * lam) / k, rtol=1e-12
    )
    assert np.all(res.dissipation > 0)
    np.testing.assert_allclose(res.dissipation, mu * lam * np.linalg.norm(res.slip, axis=1))


def test_mu_zero_exact_zeros() -> None:
    f = _trial(10, 2)
    res = coulomb_return_map(np.ones(10), f, 0.0, penalty=1.0)
    assert np.all(res.force == 0.0) and np.all(res.dissipation == 0.0)
    assert not np.any(res.stick)
    res = coulomb_slip_update(1.0, f, 0.0, penalty=5.0, normal=np.tile([0, 0, 1.0], (10, 1)))
    assert np.all(res.force == 0.0) and np.all(res.dissipation == 0.0)


def test_zero_normal_force_means_free_slip() -> None:
    f = _trial(5, 3)
    res = coulomb_return_map(0.0, f, 0.8, penalty=1.0)
    assert np.all(res.force == 0.0) and not np.any(res.stick)
    np.testing.assert_array_equal(res.dissipation, 0.0)


def test_slip_update_opposes_slip_and_accumulates() -> None:
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    du = np.array([[1e-4, 0, 0], [0, -2e-3, 5.0], [0, 0, 0]])  # normal part is discarded
    lam, mu, k = 10.0, 0.5, 1e4
    res = coulomb_slip_update(lam, du, mu, penalty=k, normal=n)
    # small slip: elastic stick, f = -k du_t
    assert res.stick[0]
    np.testing.assert_allclose(res.force[0], [-1.0, 0, 0])
    # large slip: sliding at mu lambda opposite the slip
    assert not res.stick[1]
    np.testing.assert_allclose(res.force[1], [0, mu * lam, 0])
    np.testing.assert_allclose(res.slip[1], [0, -(20.0 - 5.0) / k, 0])
    # history: the old force carries over when there is no slip
    res2 = coulomb_slip_update(lam, np.zeros((3, 3)), mu, penalty=k, normal=n, force_old=res.force)
    np.testing.assert_allclose(res2.force, res.force)
    assert np.all(res2.stick)


def test_body_point_and_relative_tangential_velocity() -> None:
    c = np.array([1.0, 0.0, 0.0])
    v_c = np.array([0.0, 0.0, 0.5])
    omega = np.array([0.0, 0.0, 2.0])
    p = np.array([[2.0, 0.0, 0.0], [1.0, 3.0, 0.0]])
    # omega x (p - c): z x x = y, z x y = -x
    np.testing.assert_allclose(
        body_point_velocity(p, c, v_c, omega), [[0, 2.0, 0.5], [-6.0, 0, 0.5]]
    )
    n = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    v_node = np.array([[7.0, 2.0, 1.5], [1.0, 9.0, 0.5]])
    vt = relative_tangential_velocity(v_node, p, n, c, v_c, omega)
    np.testing.assert_allclose(vt, [[0, 0, 1.0], [7.0, 0, 0]])
    np.testing.assert_allclose(np.einsum("ij,ij->i", vt, n), 0.0)
    np.testing.assert_allclose(tangential_part(v_node, n), [[0, 2.0, 1.5], [1.0, 0, 0.5]])


def test_bad_input_raises() -> None:
    f = _trial(2)
    with pytest.raises(ValueError, match="mu must be a finite friction coefficient >= 0"):
        coulomb_return_map(1.0, f, -0.1, penalty=1.0)
    with pytest.raises(ValueError, match="lam_n must be finite and >= 0"):
        coulomb_return_map(np.array([1.0, -1.0]), f, 0.1, penalty=1.0)
    with pytest.raises(ValueError, match=r"lam_n must be a scalar or have shape \(2,\)"):
        coulomb_return_map(np.ones(3), f, 0.1, penalty=1.0)
    with pytest.raises(ValueError, match="penalty must be finite and > 0"):
        coulomb_return_map(1.0, f, 0.1, penalty=0.0)
    with pytest.raises(ValueError, match=r"trial_force must have shape \(N, 3\)"):
        coulomb_return_map(1.0, np.ones((2, 2)), 0.1, penalty=1.0)
    with pytest.raises(ValueError, match=r"normal must have shape \(2, 3\)"):
        coulomb_slip_update(1.0, f, 0.1, penalty=1.0, normal=np.ones((3, 3)))
    with pytest.raises(ValueError, match="omega must be a finite"):
        body_point_velocity(np.zeros((1, 3)), np.zeros(3), np.zeros(3), np.zeros(2))
