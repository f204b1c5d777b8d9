"""Nodal contact forces, pressures, resultants, the joint torque of Eq. 28, and diagnostics.

Sign conventions (see also :mod:`clothfem.contact.geometry`):

* ``lam_n >= 0`` (N) is the magnitude of the compressive normal contact force; the normal force
  **on the fabric node** is ``+lam_n * n`` (``n`` the body's outward normal, pushing the fabric
  out), the force **on the body** is ``-lam_n * n``.
* Friction forces passed in are forces on the fabric (as returned by
  :mod:`clothfem.contact.friction`).
* Eq. 28 uses ``lambda_i`` = "the nodal contact force vector acting on the human body", so
  :func:`joint_torque` takes forces on the body; pass ``-contact_forces(...)``.
* ``gap`` is the signed distance in m, ``< 0`` penetration; complementarity
  ``gap >= 0, lam_n >= 0, lam_n gap = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import check_vectors as _vec

__all__ = [
    "ContactDiagnostics",
    "contact_forces",
    "contact_pressure",
    "diagnostics",
    "joint_torque",
    "node_selection",
    "resultant_force",
]

FloatArray = NDArray[np.float64]


def _field(x: ArrayLike, name: str, n: int) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return a


def node_selection(nodes: ArrayLike | None, n: int, *, name: str = "nodes") -> NDArray[np.intp]:
    """Normalise a node set (index array, boolean mask of length ``n``, or None = all) to indices.

    Raises ``ValueError`` for out-of-range indices or a mask of the wrong length.
    """
    if nodes is None:
        return np.arange(n)
    a = np.asarray(nodes)
    if a.dtype == bool:
        if a.shape != (n,):
            raise ValueError(f"{name} as a boolean mask must have shape ({n},), got {a.shape}")
        return np.flatnonzero(a)
    if a.size == 0:
        return np.zeros(0, dtype=np.intp)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name} must be a 1-D integer index array or a boolean mask")
    if a.min() < -n or a.max() >= n:
        raise ValueError(f"{name} must index nodes in [0, {n}), got range [{a.min()}, {a.max()}]")
    return np.asarray(a % n, dtype=np.intp)


def contact_forces(
    lam_n: ArrayLike, normal: ArrayLike, *, friction: ArrayLike | None = None
) -> FloatArray:
    """Nodal contact force on the fabric, ``lam_n n + f_t`` in N, (N, 3).

    Parameters
    ----------
    lam_n : (N,) array
        Normal force magnitudes ``>= 0`` in N (not checked for sign; see :func:`diagnostics`).
    normal : (N, 3) array
        Outward unit normals of the body at the contact points.
    friction : (N, 3) array, optional
        Tangential friction forces on the fabric in N.
    """
    nrm = _vec(normal, "normal")
    lam = _field(lam_n, "lam_n", nrm.shape[0])
    f = lam[:, None] * nrm
    if friction is not None:
        f = f + _vec(friction, "friction", nrm.shape[0])
    return f


def contact_pressure(force: ArrayLike, normal: ArrayLike, area: ArrayLike) -> FloatArray:
    """Nodal contact pressure ``(f_i . n_i) / A_i`` in Pa (N,), from forces on the fabric.

    ``area`` are lumped (tributary) nodal areas in m^2, all > 0.  Compressive contact gives a
    positive pressure.
    """
    f = _vec(force, "force")
    nrm = _vec(normal, "normal", f.shape[0])
    a = _field(area, "area", f.shape[0])
    if np.any(a <= 0.0):
        raise ValueError(f"area must be > 0 m^2 (lumped nodal areas), got min {a.min():g}")
    return np.einsum("ij,ij->i", f, nrm) / a


def resultant_force(force: ArrayLike, *, nodes: ArrayLike | None = None) -> FloatArray:
    """Sum of nodal force vectors (N) over ``nodes`` (indices or mask; all if None), (3,)."""
    f = _vec(force, "force")
    return f[node_selection(nodes, f.shape[0])].sum(axis=0)


def joint_torque(
    x: ArrayLike,
    force_on_body: ArrayLike,
    joint: ArrayLike,
    *,
    nodes: ArrayLike | None = None,
) -> FloatArray:
    """Torque about a joint centre, Eq. 28: ``tau = sum_{i in AJ} (x_i - J) x lambda_i`` in N m.

    Parameters
    ----------
    x : (N, 3) array
        Fabric node positions in m.
    force_on_body : (N, 3) array
        ``lambda_i``: contact force the fabric exerts **on the body** at node ``i`` in N
        (the negative of the force on the fabric, e.g. ``-contact_forces(lam_n, n)``).
    joint : (3,) array
        Joint centre ``J`` in m.
    nodes : index array or boolean mask, optional
        The set ``AJ`` of nodes that load this joint (all nodes if None).

    Returns
    -------
    (3,) array
        Torque the clothing exerts on the body about ``J``.
    """
    xx = _vec(x, "x")
    f = _vec(force_on_body, "force_on_body", xx.shape[0])
    j = np.asarray(joint, dtype=float)
    if j.shape != (3,) or not np.all(np.isfinite(j)):
        raise ValueError(f"joint must be a finite (3,) position in m, got shape {j.shape}")
    idx = node_selection(nodes, xx.shape[0])
    return np.cross(xx[idx] - j, f[idx]).sum(axis=0)


@dataclass(frozen=True)
class ContactDiagnostics:
    """Summary of a contact state.

    Attributes
    ----------
    n_active : int
        Number of active contact nodes.
    max_penetration : float
        ``max(0, -min gap)`` over all nodes, in m.
    min_multiplier : float
        Smallest ``lam_n`` over the active nodes in N (``0.0`` if none); must be ``>= 0``.
    complementarity : float
        ``max |lam_n * gap|`` over all nodes in N m (0 for an exact KKT point).
    """

    n_active: int
    max_penetration: float
    min_multiplier: float
    complementarity: float


def diagnostics(
    gap: ArrayLike, lam_n: ArrayLike, *, active: ArrayLike | None = None
) -> ContactDiagnostics:
    """Check the Kuhn-Tucker conditions ``gap >= 0, lam_n >= 0, lam_n gap = 0``.

    Parameters
    ----------
    gap : (N,) array
        Signed gaps in m (``< 0`` penetration), evaluated at the final positions.
    lam_n : (N,) array
        Normal multipliers in N.
    active : index array or boolean mask, optional
        Active set; default: nodes with ``lam_n != 0``.
    """
    g = np.asarray(gap, dtype=float)
    if g.ndim != 1:
        raise ValueError(f"gap must have shape (N,), got {g.shape}")
    n = g.shape[0]
    g = _field(g, "gap", n)
    lam = _field(lam_n, "lam_n", n)
    idx = np.flatnonzero(lam != 0.0) if active is None else node_selection(active, n, name="active")
    return ContactDiagnostics(
        n_active=int(idx.size),
        max_penetration=float(max(0.0, -g.min())) if n else 0.0,
        min_multiplier=float(lam[idx].min()) if idx.size else 0.0,
        complementarity=float(np.max(np.abs(lam * g))) if n else 0.0,
    )
