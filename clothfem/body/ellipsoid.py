"""Rigid ellipsoids (Eq. 26 of Man & Swan 2007) and a body made of moving ellipsoid segments.

The ellipsoid with centre ``c``, orientation vectors ``e1, e2, e3`` and radii ``r1, r2, r3``
is the zero set of

    f(x) = sum_i [(x - c) . e_i]^2 / r_i^2 - 1            (Eq. 26)

``f < 0`` inside (a fabric point there has penetrated), ``f = 0`` on the surface, ``f > 0``
outside.  Radius ``r_i`` is measured along ``e_i``; with poses from Eq. 27, ``e1`` runs along the
limb (joint centre ``J1`` -> ``J2``), so ``r1`` is the half-length of a limb segment.  (The paper's
Sec. 4.1 lists the long radius last, ``(0.06, 0.06, 0.20)``; in clothfem's order that forearm is
``(0.20, 0.06, 0.06)``.)
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from clothfem.body.pose import Motion, Pose, _vec3, check_rotation

__all__ = ["Body", "Ellipsoid", "Segment", "check_radii"]


def check_radii(radii: ArrayLike, *, owner: str) -> NDArray[np.float64]:
    """Return ``radii`` as a (3,) float array, or raise a one-line ``ValueError``.

    ``owner`` names the object in the message, e.g. ``"segment 'forearm'"``.
    """
    r = np.asarray(radii, dtype=float)
    if r.shape != (3,):
        raise ValueError(f"{owner}: radii must have shape (3,) (r1, r2, r3 in m), got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0.0):
        shown = tuple(float(v) for v in r)
        raise ValueError(f"{owner}: radii must be finite and > 0 m, got {shown}")
    return r


def _points(x: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(x, dtype=float)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points x: last axis must have length 3, got shape {p.shape}")
    return p


@dataclass(frozen=True, eq=False, kw_only=True)
class Ellipsoid:
    """An ellipsoid at a fixed placement (Eq. 26).

    Attributes
    ----------
    centre : (3,) array
        Centroid ``x^c`` in m.
    axes : (3, 3) array
        Orientation vectors as **rows**: ``axes[i]`` is ``e_{i+1}`` in global coordinates.
        Must be orthonormal and right-handed (``e3 = e1 x e2``).  ``axes.T`` is the rotation
        ``Q`` of :class:`~clothfem.body.pose.Pose`.
    radii : (3,) array
        ``(r1, r2, r3)`` in m along ``e1, e2, e3``; finite and > 0.
    name : str
        Label used in error messages.
    """

    centre: NDArray[np.float64]
    axes: NDArray[np.float64]
    radii: NDArray[np.float64]
    name: str = "ellipsoid"

    def __post_init__(self) -> None:
        owner = f"ellipsoid '{self.name}'"
        object.__setattr__(self, "centre", _vec3(self.centre, what=f"{owner}: centre"))
        object.__setattr__(self, "axes", check_rotation(self.axes, what=f"{owner}: axes"))
        object.__setattr__(self, "radii", check_radii(self.radii, owner=owner))

    @classmethod
    def from_pose(cls, *, pose: Pose, radii: ArrayLike, name: str = "ellipsoid") -> Ellipsoid:
        """Ellipsoid placed at ``pose`` (its rotation columns become the rows of ``axes``)."""
        return cls(centre=pose.centre, axes=pose.rotation.T, radii=radii, name=name)

    def transform_to_local(self, x: ArrayLike) -> NDArray[np.float64]:
        """Local coordinates ``y_i = (x - c) . e_i`` (m) of points ``x`` (..., 3) in m."""
        return (_points(x) - self.centre) @ self.axes.T

    def transform_from_local(self, y: ArrayLike) -> NDArray[np.float64]:
        """Global positions ``x = c + sum_i y_i e_i`` (m) of local coordinates ``y`` (..., 3)."""
        return self.centre + _points(y) @ self.axes

    def f(self, x: ArrayLike) -> NDArray[np.float64]:
        """Implicit function of Eq. 26 at points ``x`` (..., 3) in m; shape ``x.shape[:-1]``."""
        y = self.transform_to_local(x)
        return np.sum((y / self.radii) ** 2, axis=-1) - 1.0

    def gradient(self, x: ArrayLike) -> NDArray[np.float64]:
        """Gradient of ``f`` (1/m), ``2 sum_i y_i / r_i^2 e_i``; same shape as ``x``."""
        y = self.transform_to_local(x)
        return (2.0 * y / self.radii**2) @ self.axes

    def contains(self, x: ArrayLike) -> NDArray[np.bool_]:
        """True where ``f(x) < 0`` (strictly inside: the paper's penetration test)."""
        return self.f(x) < 0.0

    def surface_grid(
        self, *, n_u: int = 24, n_v: int = 12
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Surface sample for plotting: three (n_v, n_u) arrays X, Y, Z in m.

        ``u`` is the azimuth about ``e1`` and ``v`` the polar angle from ``+e1``.
        """
        u = np.linspace(0.0, 2.0 * np.pi, n_u)
        v = np.linspace(0.0, np.pi, n_v)
        vv, uu = np.meshgrid(v, u, indexing="ij")
        y = (
            np.stack([np.cos(vv), np.sin(vv) * np.cos(uu), np.sin(vv) * np.sin(uu)], axis=-1)
            * self.radii
        )
        x = self.transform_from_local(y)
        return x[..., 0], x[..., 1], x[..., 2]


@dataclass(frozen=True, eq=False, kw_only=True)
class Segment:
    """A named rigid ellipsoid segment moving with ``motion``.

    Attributes
    ----------
    name : str
        Segment name, e.g. ``"forearm"``.
    radii : (3,) array
        ``(r1, r2, r3)`` in m along the body axes ``e1, e2, e3`` (``e1`` along the limb).
    motion : Motion
        Gives the :class:`Pose` (centre, rotation, velocities) at any time in s.
    """

    name: str
    radii: NDArray[np.float64]
    motion: Motion

    def __post_init__(self) -> None:
        object.__setattr__(self, "radii", check_radii(self.radii, owner=f"segment '{self.name}'"))
        if not isinstance(self.motion, Motion):
            raise ValueError(
                f"segment '{self.name}': motion must have a pose(t) method, "
                f"got {type(self.motion).__name__}"
            )

    def pose(self, t: float) -> Pose:
        """Pose at time ``t`` (s)."""
        return self.motion.pose(t)

    def ellipsoid(self, t: float) -> Ellipsoid:
        """The segment's ellipsoid at time ``t`` (s)."""
        return Ellipsoid.from_pose(pose=self.pose(t), radii=self.radii, name=self.name)

    def point_velocity(self, x: ArrayLike, t: float) -> NDArray[np.float64]:
        """Velocity (m/s) at time ``t`` of body-fixed points currently at ``x`` (N, 3) m."""
        return self.pose(t).point_velocity(x)


@dataclass(frozen=True, eq=False, kw_only=True)
class Body:
    """An assemblage of named, possibly overlapping ellipsoid segments (Fig. 5 of the paper).

    Attributes
    ----------
    segments : tuple of Segment
        Segments with unique names.
    """

    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        segs = tuple(self.segments)
        if not segs:
            raise ValueError("body: segments must contain at least one Segment, got none")
        for s in segs:
            if not isinstance(s, Segment):
                raise ValueError(f"body: segments must be Segment objects, got {type(s).__name__}")
        names = [s.name for s in segs]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"body: segment names must be unique, got duplicates {dup}")
        object.__setattr__(self, "segments", segs)

    @classmethod
    def from_segments(cls, *, segments: Iterable[Segment]) -> Body:
        """Build a body from any iterable of segments."""
        return cls(segments=tuple(segments))

    @property
    def names(self) -> tuple[str, ...]:
        """Segment names in order."""
        return tuple(s.name for s in self.segments)

    def segment(self, name: str) -> Segment:
        """The segment called ``name``; ``KeyError`` naming the available ones otherwise."""
        for s in self.segments:
            if s.name == name:
                return s
        raise KeyError(f"body: no segment {name!r}; available: {list(self.names)}")

    def ellipsoids(self, t: float) -> dict[str, Ellipsoid]:
        """All segment ellipsoids at time ``t`` (s), by name."""
        return {s.name: s.ellipsoid(t) for s in self.segments}

    def poses(self, t: float) -> dict[str, Pose]:
        """All segment poses at time ``t`` (s), by name."""
        return {s.name: s.pose(t) for s in self.segments}

    def f(self, x: ArrayLike, t: float) -> NDArray[np.float64]:
        """Union implicit function ``min_k f_k(x)`` over the segments at time ``t``.

        Negative where ``x`` is inside at least one ellipsoid (dimensionless, shape
        ``x.shape[:-1]``).
        """
        return np.min(np.stack([e.f(x) for e in self.ellipsoids(t).values()]), axis=0)

    def contains(self, x: ArrayLike, t: float) -> NDArray[np.bool_]:
        """True where ``x`` is strictly inside any segment at time ``t``."""
        return self.f(x, t) < 0.0
