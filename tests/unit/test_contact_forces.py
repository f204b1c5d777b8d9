"""Nodal forces, pressure, resultant, joint torque (Eq. 28) and diagnostics."""

from __future__ import annotations

import numpy as np
import pytest

from clothfem.contact import (
    closest_point_ellipsoid,
    contact_forces,
    contact_pressure,
    diagnostics,
    joint_torque,
    resultant_force,
)


def test_contact_forces_pressure_resultant() -> None:
    n = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])
    lam = np.array([2.0, 0.0, 3.0])
    fric = np.array([[0.5, 0, 0], [0, 0, 0], [0, 0, -1.0]])
    f = contact_forces(lam, n, friction=fric)
    np.testing.assert_allclose(f, [[0.5, 0, 2.0], [0, 0, 0], [0, 3.0, -1.0]])
    area = np.array([0.01, 0.02, 0.5])
    np.testing.assert_allclose(contact_pressure(f, n, area), [200.0, 0.0, 6.0])
    np.testing.assert_allclose(resultant_force(f), [0.5, 3.0, 1.0])
    np.testing.assert_allclose(resultant_force(f, nodes=np.array([True, False, False])), f[0])
    np.testing.assert_allclose(resultant_force(f, nodes=np.array([2])), f[2])


def test_joint_torque_hand_computed() -> None:
    # Eq. 28 with J = (1, 1, 0); lambda_i are forces ON the body
    J = np.array([1.0, 1.0, 0.0])
    x = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 0.0], [5.0, 5.0, 5.0]])
    f_body = np.array([[0.0, 4.0, 0.0], [0.0, 0.0, 3.0], [1.0, 2.0, 3.0]])
    # (1,0,0) x (0,4,0) = (0,0,4);  (0,2,0) x (0,0,3) = (6,0,0)
    np.testing.assert_allclose(joint_torque(x, f_body, J, nodes=np.array([0, 1])), [6.0, 0, 4.0])
    np.testing.assert_allclose(
        joint_torque(x, f_body, J, nodes=np.array([True, False, False])), [0, 0, 4.0]
    )
    # node 2: (4,4,5) x (1,2,3) = (4*3-5*2, 5*1-4*3, 4*2-4*1) = (2, -7, 4)
    np.testing.assert_allclose(joint_torque(x, f_body, J), [8.0, -7.0, 8.0])
    np.testing.assert_allclose(joint_torque(x, f_body, J, nodes=np.array([], int)), 0.0)


def test_joint_torque_sleeve_band_on_forearm() -> None:
    """A sleeve band pressing uniformly on a forearm cross-section gives zero torque; a band
    pulling the forearm (fabric pressing on its top side) toward extension gives the lever arm
    times the resultant."""
    J = np.zeros(3)
    d = 0.25  # band position along the forearm (x axis), m
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    x = np.stack([np.full_like(t, d), 0.06 * np.cos(t), 0.06 * np.sin(t)], axis=1)
    n = x - [d, 0, 0]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    f_on_body = -contact_forces(np.full(64, 0.1), n)  # uniform squeeze
    np.testing.assert_allclose(joint_torque(x, f_on_body, J), 0.0, atol=1e-15)
    top = n[:, 2] > 0.9  # fabric pushes down on the top nodes only
    tau = joint_torque(x, f_on_body, J, nodes=top)
    F = resultant_force(f_on_body, nodes=top)
    assert F[2] < 0
    np.testing.assert_allclose(
        tau, np.cross([d, 0, 0], F) + np.cross(x[top] - [d, 0, 0], f_on_body[top]).sum(0)
    )
    assert tau[1] == pytest.approx(-d * F[2], rel=1e-12)


def test_diagnostics() -> None:
    gap = np.array([0.0, -1e-3, 0.02, 1e-6])
    lam = np.array([5.0, 2.0, 0.0, 1.0])
    d = diagnostics(gap, lam)
    assert d.n_active == 3
    assert d.max_penetration == pytest.approx(1e-3)
    assert d.min_multiplier == 1.0
    assert d.complementarity == pytest.approx(2e-3)
    d = diagnostics(gap, lam, active=np.array([0, 1]))
    assert d.n_active == 2 and d.min_multiplier == 2.0
    # a KKT point built with the exact projection
    c, Q, r = np.zeros(3), np.eye(3), np.array([0.2, 0.06, 0.06])
    x = np.array([[0.3, 0.0, 0.0], [0.1, 0.05, 0.0]])
    p = closest_point_ellipsoid(x, c, Q, r).point
    g = closest_point_ellipsoid(np.vstack([x[:1], p[1:]]), c, Q, r).gap
    d = diagnostics(g, np.array([0.0, 3.0]))
    assert d.max_penetration <= 1e-15 and d.complementarity <= 1e-14


def test_bad_input_raises() -> None:
    n = np.tile([0, 0, 1.0], (2, 1))
    with pytest.raises(ValueError, match=r"lam_n must have shape \(2,\)"):
        contact_forces(np.ones(3), n)
    with pytest.raises(ValueError, match="area must be > 0"):
        contact_pressure(n, n, np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match=r"force_on_body must have shape \(2, 3\)"):
        joint_torque(n, np.ones((3, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="joint must be a finite"):
        joint_torque(n, n, np.zeros(2))
    with pytest.raises(ValueError, match=r"nodes must index nodes in \[0, 2\)"):
        joint_torque(n, n, np.zeros(3), nodes=np.array([0, 5]))
    with pytest.raises(ValueError, match=r"nodes as a boolean mask must have shape \(2,\)"):
        joint_torque(n, n, np.zeros(3), nodes=np.array([True]))
