"""Nodal finite rotations of the fibre director (Man & Swan 2007, Eqs. 6-9).

Each node A carries a fibre basis (e1, e2, e3) with e3 = the reference director X^_A, and
two rotation parameters (theta1, theta2): the rotation vector theta = theta1 e1 + theta2 e2
(no drilling about e3). Euler's formula (Eq. 7) applied to e3 gives the current director

    x^_A = cos|theta| e3 + sin|theta|/|theta| (theta2 e1 - theta1 e2).        (Eq. 8)

The paper prints ``+ (1 - cos|theta|) e3`` for the last term of Eq. 8; applying Eq. 7 to
e3 gives ``- (1 - cos|theta|) e3`` (Omega^2 e3 = -|theta|^2 e3), i.e. the unit vector above.

All functions are vectorised over nodes (leading axis) and exact to round-off as
|theta| -> 0 (series expansions below |theta| < 0.3). The first and second derivatives are
the nodal chain rule H of Eq. 10 that maps director variations to rotation variations.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "fibre_basis",
    "director",
    "director_derivatives",
    "director_tangent",
    "rotation_from_director",
    "rotation_matrix",
]

_SMALL = 0.3


def _coefficients(phi: np.ndarray, upto: int = 3):
    """s = sin(phi)/phi, q = s'(phi)/phi, p = q'(phi)/phi, robust near phi = 0; the first
    ``upto`` of them (the others are None)."""
    small = phi < _SMALL
    ps = np.where(small, 1.0, phi)  # safe denominator
    sin = np.sin(ps)
    cos = np.cos(ps) if upto > 1 else None
    x = phi * phi  # Taylor series in x = phi^2, truncation error < 1e-15 for phi < 0.3
    s = np.where(small, 1 - x / 6 + x**2 / 120 - x**3 / 5040 + x**4 / 362880, sin / ps)
    q = p = None
    if upto > 1:
        q = np.where(
            small,
            -1 / 3 + x / 30 - x**2 / 840 + x**3 / 45360 - x**4 / 3991680,
            (ps * cos - sin) / ps**3,
        )
    if upto > 2:
        p = np.where(
            small,
            1 / 15 - x / 210 + x**2 / 7560 - x**3 / 498960 + x**4 / 51891840,
            (3.0 * sin - 3.0 * ps * cos - ps * ps * sin) / ps**5,
        )
    return s, q, p


def fibre_basis(director: np.ndarray, preferred: np.ndarray | None = None) -> np.ndarray:
    """Nodal fibre bases (Hughes 1987): returns (N, 3, 3) with rows e1, e2, e3.

    e3 is the normalised director. Without ``preferred``, e1 is the unit projection on the
    plane normal to e3 of the global axis least aligned with e3 (never degenerate). Where
    ``preferred`` (N, 3) is given and not parallel to e3, e1 is its unit projection instead
    (used to align theta2 = 0 with a symmetry plane). e2 = e3 x e1.
    """
    d = np.asarray(director, dtype=float)
    e3 = d / np.linalg.norm(d, axis=1)[:, None]
    axis = np.eye(3)[np.argmin(np.abs(e3), axis=1)]
    if preferred is not None:
        pref = np.asarray(preferred, dtype=float)
        tang = pref - np.sum(pref * e3, axis=1)[:, None] * e3
        ok = np.linalg.norm(tang, axis=1) > 1e-8 * np.maximum(np.linalg.norm(pref, axis=1), 1)
        axis = np.where(ok[:, None], pref, axis)
    e1 = axis - np.sum(axis * e3, axis=1)[:, None] * e3
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(e3, e1)
    return np.stack([e1, e2, e3], axis=1)


def director(basis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Current directors (N, 3) from fibre bases (N, 3, 3) and rotations (N, 2)  (Eq. 8)."""
    e1, e2, e3 = basis[:, 0], basis[:, 1], basis[:, 2]
    t1, t2 = theta[:, 0:1], theta[:, 1:2]
    phi = np.hypot(t1, t2)
    s, _, _ = _coefficients(phi, upto=1)
    return np.cos(phi) * e3 + s * (t2 * e1 - t1 * e2)


def director_tangent(basis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``T`` (N, 3, 2), T[:, :, a] = dd/dtheta_a of :func:`director` (the first part of
    :func:`director_derivatives`, the same numbers, without the second derivatives)."""
    return _derivatives(basis, theta, second=False)[0]


def director_derivatives(basis: np.ndarray, theta: np.ndarray):
    """First and second derivatives of :func:`director` w.r.t. (theta1, theta2).

    Returns ``T`` (N, 3, 2) with T[:, :, a] = dd/dtheta_a and ``H`` (N, 3, 2, 2) with
    H[:, :, a, b] = d2d/dtheta_a dtheta_b.
    """
    return _derivatives(basis, theta, second=True)


def _derivatives(basis: np.ndarray, theta: np.ndarray, *, second: bool):
    e1, e2, e3 = basis[:, 0], basis[:, 1], basis[:, 2]
    th = theta
    phi = np.hypot(th[:, 0], th[:, 1])[:, None]
    s, q, p = _coefficients(phi, upto=3 if second else 2)
    w = th[:, 1:2] * e1 - th[:, 0:1] * e2  # |w| = phi
    wa = (-e2, e1)  # dw/dtheta_a
    n = len(th)
    T = np.empty((n, 3, 2))
    H = np.empty((n, 3, 2, 2)) if second else None
    for a in range(2):
        ta = th[:, a : a + 1]
        T[:, :, a] = -s * ta * e3 + q * ta * w + s * wa[a]
        for b in range(2 if second else 0):
            tb = th[:, b : b + 1]
            dab = 1.0 if a == b else 0.0
            H[:, :, a, b] = (
                -(q * tb) * ta * e3
                - s * dab * e3
                + (p * tb) * ta * w
                + q * dab * w
                + q * ta * wa[b]
                + (q * tb) * wa[a]
            )
    return T, H


def rotation_from_director(basis: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotations (N, 2) that turn each e3 into the unit vector ``target`` (N, 3).

    Inverse of :func:`director` on |theta| < pi (the shortest rotation, no drilling).
    """
    t = np.asarray(target, dtype=float)
    t = t / np.linalg.norm(t, axis=1)[:, None]
    e1, e2, e3 = basis[:, 0], basis[:, 1], basis[:, 2]
    c = np.clip(np.sum(t * e3, axis=1), -1.0, 1.0)
    a1, a2 = np.sum(t * e1, axis=1), np.sum(t * e2, axis=1)
    sin = np.hypot(a1, a2)
    phi = np.arctan2(sin, c)
    scale = np.where(sin > 1e-300, phi / np.where(sin > 1e-300, sin, 1.0), 1.0)
    return np.stack([-a2 * scale, a1 * scale], axis=1)


def rotation_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Euler's formula (Eq. 7): rotation matrices (N, 3, 3) from rotation vectors (N, 3)."""
    rv = np.atleast_2d(np.asarray(rotvec, dtype=float))
    phi = np.linalg.norm(rv, axis=1)
    s, _, _ = _coefficients(phi[:, None], upto=1)
    safe = np.where(phi < _SMALL, 1.0, phi)
    x = phi * phi
    c2 = np.where(
        phi < _SMALL,
        1 / 2 - x / 24 + x**2 / 720 - x**3 / 40320 + x**4 / 3628800,
        (1 - np.cos(safe)) / safe**2,
    )
    W = np.zeros((len(rv), 3, 3))
    W[:, 0, 1], W[:, 0, 2], W[:, 1, 2] = -rv[:, 2], rv[:, 1], -rv[:, 0]
    W[:, 1, 0], W[:, 2, 0], W[:, 2, 1] = rv[:, 2], -rv[:, 1], rv[:, 0]
    return np.eye(3) + s[:, :, None] * W + c2[:, None, None] * (W @ W)
