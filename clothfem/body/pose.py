"""Rigid-body pose of one body segment at one instant, and the ``Motion`` protocol.

Conventions (used throughout :mod:`clothfem.body`)
--------------------------------------------------
* Global frame: right-handed, metres, **Z up** (gravity along -Z).
* ``rotation`` is the 3x3 matrix ``Q`` whose **columns** are the segment's body axes
  ``e1, e2, e3`` expressed in the global frame (Eq. 27 of Man & Swan 2007: ``e1`` runs from
  joint centre ``J1`` to ``J2``).  A body-fixed point with local coordinates ``y`` sits at
  ``x = c + Q @ y``.
* ``angular_velocity`` is the spatial (global-frame) angular velocity ``omega`` in rad/s, so
  that ``dQ/dt = skew(omega) @ Q`` and the velocity of a body-fixed material point ``x`` is
  ``v = c'(t) + omega x (x - c)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Motion", "Pose", "check_rotation"]


def check_rotation(q: ArrayLike, *, what: str, tol: float = 1e-6) -> NDArray[np.float64]:
    """Return ``q`` as a float (3, 3) array after checking it is a proper rotation.

    Raises ``ValueError`` (one line, naming ``what``) unless ``q`` is finite, orthonormal
    within ``tol`` and has determinant +1 (right-handed).
    """
    a = np.asarray(q, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"{what}: must have shape (3, 3), got {a.shape}")
    # on the nine Python floats: a few NumPy calls on a 3x3 cost more than the arithmetic
    rows = a.tolist()
    if not all(math.isfinite(x) for row in rows for x in row):
        raise ValueError(f"{what}: must be finite, got NaN/inf entries")
    cols = list(zip(*rows, strict=True))
    err = max(
        abs(sum(p * q for p, q in zip(cols[i], cols[j], strict=True)) - (i == j))
        for i in range(3)
        for j in range(i, 3)
    )
    if err > tol:
        raise ValueError(f"{what}: must be orthonormal (|Q^T Q - I| <= {tol:g}), got {err:.3g}")
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = rows
    det = (
        a00 * (a11 * a22 - a12 * a21)
        - a01 * (a10 * a22 - a12 * a20)
        + a02 * (a10 * a21 - a11 * a20)
    )
    if det < 0.0:
        raise ValueError(f"{what}: must be right-handed (det = +1), got det = {det:.6g}")
    return a


def _vec3(v: ArrayLike, *, what: str) -> NDArray[np.float64]:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,):
        raise ValueError(f"{what}: must have shape (3,), got {a.shape}")
    if not all(math.isfinite(x) for x in a.tolist()):
        raise ValueError(f"{what}: must be finite, got {tuple(float(x) for x in a)}")
    return a


@dataclass(frozen=True, eq=False, kw_only=True)
class Pose:
    """Pose and rigid-body velocity of a segment at time ``time``.

    Attributes
    ----------
    time : float
        Time in s.
    centre : (3,) array
        Segment centre ``c`` (the ellipsoid centroid, Eq. 27a) in m.
    rotation : (3, 3) array
        ``Q``; columns are the body axes ``e1, e2, e3`` in global coordinates (dimensionless).
    velocity : (3,) array
        ``c'(t)`` in m/s.
    angular_velocity : (3,) array
        Spatial angular velocity ``omega`` in rad/s.
    """

    time: float
    centre: NDArray[np.float64]
    rotation: NDArray[np.float64]
    velocity: NDArray[np.float64]
    angular_velocity: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", float(self.time))
        object.__setattr__(self, "centre", _vec3(self.centre, what="pose centre"))
        object.__setattr__(self, "rotation", check_rotation(self.rotation, what="pose rotation"))
        object.__setattr__(self, "velocity", _vec3(self.velocity, what="pose velocity"))
        object.__setattr__(
            self, "angular_velocity", _vec3(self.angular_velocity, what="pose angular_velocity")
        )

    @property
    def axes(self) -> NDArray[np.float64]:
        """Body axes as **rows** (``axes[i] = e_{i+1}``), i.e. ``rotation.T``."""
        return self.rotation.T

    def point_velocity(self, x: ArrayLike) -> NDArray[np.float64]:
        """Velocity (m/s) of body-fixed material points ``x`` (N, 3) or (3,) in m."""
        p = np.asarray(x, dtype=float)
        return self.velocity + np.cross(self.angular_velocity, p - self.centre)

    def to_global(self, y: ArrayLike) -> NDArray[np.float64]:
        """Map body-local coordinates ``y`` (N, 3) in m to global positions ``c + Q y``."""
        return self.centre + np.asarray(y, dtype=float) @ self.rotation.T


@runtime_checkable
class Motion(Protocol):
    """Anything that gives a segment's :class:`Pose` at a time ``t`` (s)."""

    def pose(self, t: float) -> Pose:
        """Pose at time ``t`` in s."""
        ...
