"""Coulomb friction as a return mapping, and the sliding kinematics it needs (pure NumPy).

NumPy twin of what the FEM layer does at its contact nodes.  Conventions:

* ``force`` is the tangential friction force **on the fabric node** in N (the body receives the
  opposite force).  It opposes the slip of the node relative to the body surface.
* Coulomb's law: ``|f_t| <= mu * lambda_N`` with ``lambda_N >= 0`` the normal contact force
  magnitude (N); stick if the trial force is inside the cone, slip otherwise, in which case
  ``|f_t| = mu * lambda_N`` exactly.
* The tangential regularisation ("penalty") ``k_t`` in N/m turns force into elastic slip,
  ``f_t = -k_t u_e``; the plastic (true) slip increment is ``du_p = du - du_e``.  The frictional
  dissipation increment ``mu * lambda_N * |du_p|`` in J is >= 0.
* ``mu = 0`` gives exact zeros, the ``slip`` state and no dissipation.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import check_vectors as _vec

__all__ = [
    "FrictionResult",
    "body_point_velocity",
    "coulomb_return_map",
    "coulomb_slip_update",
    "relative_tangential_velocity",
    "tangential_part",
]

FloatArray = NDArray[np.float64]


class FrictionResult(NamedTuple):
    """Outcome of the Coulomb return mapping for N nodes.

    Attributes
    ----------
    force : (N, 3) float array
        Tangential friction force on the fabric node in N.
    stick : (N,) bool array
        True where the trial force is admissible (``|f_trial| <= mu lambda_N``).  ``mu = 0`` nodes
        are slipping.
    slip : (N, 3) float array
        Plastic slip increment ``du_p`` in m (zero when sticking); ``force`` is antiparallel to
        it when slipping.
    dissipation : (N,) float array
        Frictional dissipation increment ``mu lambda_N |du_p| >= 0`` in J.
    """

    force: FloatArray
    stick: NDArray[np.bool_]
    slip: FloatArray
    dissipation: FloatArray


def _scalar_field(x: ArrayLike, name: str, n: int, *, what: str) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError(f"{name} must be finite and >= 0 ({what}), got min {np.min(a):g}")
    return a


def _check_penalty(penalty: ArrayLike, n: int) -> FloatArray:
    k = np.asarray(penalty, dtype=float)
    if k.ndim == 0:
        k = np.full(n, float(k))
    if k.shape != (n,) or not np.all(np.isfinite(k)) or np.any(k <= 0.0):
        raise ValueError(f"penalty must be finite and > 0 N/m (scalar or ({n},)), got {penalty!r}")
    return k


def tangential_part(v: ArrayLike, normal: ArrayLike) -> FloatArray:
    """Projection ``(I - n n^T) v`` of vectors ``v`` (N, 3) onto the planes of unit ``normal``."""
    v = _vec(v, "v")
    n = _vec(normal, "normal", v.shape[0])
    return v - np.einsum("ij,ij->i", v, n)[:, None] * n


def body_point_velocity(p: ArrayLike, c: ArrayLike, v_c: ArrayLike, omega: ArrayLike) -> FloatArray:
    """Velocity in m/s of the rigid-body material point at ``p``: ``v_b = v_c + omega x (p - c)``.

    ``p`` (N, 3) m; ``c`` (3,) m centre; ``v_c`` (3,) m/s centre velocity; ``omega`` (3,) rad/s.
    """
    p = _vec(p, "p")
    c, v_c, omega = (np.asarray(a, dtype=float) for a in (c, v_c, omega))
    for name, a in (("c", c), ("v_c", v_c), ("omega", omega)):
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be a finite (3,) vector, got shape {a.shape}")
    return v_c + np.cross(omega, p - c)


def relative_tangential_velocity(
    v_node: ArrayLike,
    p: ArrayLike,
    normal: ArrayLike,
    c: ArrayLike,
    v_c: ArrayLike,
    omega: ArrayLike,
) -> FloatArray:
    """Slip velocity of fabric nodes over a rigid body surface, in m/s, (N, 3).

    ``(I - n n^T) (v_node - v_b(p))`` with ``v_b = v_c + omega x (p - c)`` the velocity of the
    body point ``p`` at which the node touches (its closest point) and ``n`` the outward normal.
    Multiply by the time step for the slip increment ``du`` in m.
    """
    v_node = _vec(v_node, "v_node")
    vb = body_point_velocity(p, c, v_c, omega)
    if vb.shape != v_node.shape:
        raise ValueError(f"p must have shape {v_node.shape} like v_node, got {vb.shape}")
    return tangential_part(v_node - vb, normal)


def coulomb_return_map(
    lam_n: ArrayLike, trial_force: ArrayLike, mu: float, *, penalty: ArrayLike
) -> FrictionResult:
    """Project trial tangential forces onto the Coulomb disc ``|f_t| <= mu lambda_N``.

    ``f = f_trial`` (stick) if ``|f_trial| <= mu lambda_N``, else
    ``f = mu lambda_N f_trial / |f_trial|`` (slip); the plastic slip is
    ``du_p = -(|f_trial| - mu lambda_N)/k_t * f_trial/|f_trial|`` and the dissipation
    ``mu lambda_N |du_p|``.

    Parameters
    ----------
    lam_n : (N,) array or scalar
        Normal contact force magnitudes ``lambda_N >= 0`` in N.
    trial_force : (N, 3) array
        Trial tangential force on the fabric in N (already in the tangent plane).
    mu : float
        Coulomb coefficient, ``>= 0``.
    penalty : (N,) array or scalar
        Tangential regularisation ``k_t > 0`` in N/m used to convert the excess force into slip
        (in the explicit step ``k_t = m / dt^2``).

    Returns
    -------
    FrictionResult
    """
    f_tr = _vec(trial_force, "trial_force")
    n = f_tr.shape[0]
    lam = _scalar_field(lam_n, "lam_n", n, what="normal force in N")
    mu = _check_mu(mu)
    k = _check_penalty(penalty, n)
    if mu == 0.0:
        z = np.zeros((n, 3))
        return FrictionResult(z, np.zeros(n, dtype=bool), -f_tr / k[:, None], np.zeros(n))
    cap = mu * lam
    mag = np.linalg.norm(f_tr, axis=1)
    stick = mag <= cap
    scale = np.ones(n)
    slip_mask = ~stick
    scale[slip_mask] = cap[slip_mask] / mag[slip_mask]
    force = f_tr * scale[:, None]
    slip = -(f_tr - force) / k[:, None]
    dissipation = cap * np.linalg.norm(slip, axis=1)
    return FrictionResult(force, stick, slip, dissipation)


def coulomb_slip_update(
    lam_n: ArrayLike,
    slip_increment: ArrayLike,
    mu: float,
    *,
    penalty: ArrayLike,
    normal: ArrayLike,
    force_old: ArrayLike | None = None,
) -> FrictionResult:
    """Regularised Coulomb update from a slip increment (elastic predictor, plastic corrector).

    ``f_trial = P_t f_old - k_t P_t du``, ``P_t = I - n n^T``, then :func:`coulomb_return_map`.
    The old force is projected onto the current tangent plane (a simple "rotation" of the
    history for a curved, moving surface).

    Parameters
    ----------
    lam_n : (N,) array or scalar
        Normal force magnitude ``lambda_N >= 0`` in N.
    slip_increment : (N, 3) array
        Relative tangential displacement ``du`` of node vs body point over the step, in m
        (e.g. ``dt *`` :func:`relative_tangential_velocity`).
    mu : float
        Coulomb coefficient ``>= 0``.
    penalty : (N,) array or scalar
        Tangential stiffness ``k_t > 0`` in N/m.
    normal : (N, 3) array
        Outward unit normals of the body at the contact points.
    force_old : (N, 3) array, optional
        Friction force on the fabric at the end of the previous step, in N (zeros if omitted).
    """
    du = _vec(slip_increment, "slip_increment")
    n = du.shape[0]
    k = _check_penalty(penalty, n)
    nrm = _vec(normal, "normal", n)
    f_old = np.zeros((n, 3)) if force_old is None else _vec(force_old, "force_old", n)
    trial = tangential_part(f_old - k[:, None] * du, nrm)
    return coulomb_return_map(lam_n, trial, mu, penalty=k)


def _check_mu(mu: float) -> float:
    m = float(mu)
    if not np.isfinite(m) or m < 0.0:
        raise ValueError(f"mu must be a finite friction coefficient >= 0, got {mu}")
    return m
