"""Loads and supports of a fabric shell (frozen dataclasses, SI units).

Every load is multiplied by the model's load factor ``lam`` (quasi-static load stepping, or
time for dynamics); prescribed displacements and rotations too. ``where`` selects nodes
either by a boundary name of the mesh (``"root"``) or by a function of the node
coordinates ``x`` (shape (N, 3)) returning a boolean mask (a located point or line).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass

import numpy as np

__all__ = [
    "Where",
    "Gravity",
    "Pressure",
    "EdgeTraction",
    "EdgeMoment",
    "PointForce",
    "Clamp",
    "Pin",
    "Symmetry",
    "Prescribed",
    "PointPin",
    "Load",
    "Support",
]

Where = str | Callable[[np.ndarray], np.ndarray]


def _vector(owner: str, field: str, value) -> tuple[float, float, float]:
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{owner} {field} must be 3 finite numbers, got {value!r}")
    return tuple(float(c) for c in v)


def _where(owner: str, where) -> None:
    if not (isinstance(where, str) or callable(where)):
        raise ValueError(f"{owner} where must be a boundary name or a callable, got {where!r}")


def _on(owner: str, on) -> None:
    if on is not None and not isinstance(on, str):
        raise ValueError(f"{owner} on must be a boundary name or None, got {on!r}")


@dataclass(frozen=True)
class Gravity:
    """Body force rho * t * acceleration per unit area; acceleration in m/s^2."""

    acceleration: tuple[float, float, float] = (0.0, 0.0, -9.81)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "acceleration", _vector("Gravity", "acceleration", self.acceleration)
        )


@dataclass(frozen=True)
class Pressure:
    """Uniform pressure [Pa] on the whole surface, along the cell normal.

    ``follower=True``: along the current normal on the current area (non-conservative);
    otherwise along the reference normal (dead load).
    """

    value: float
    follower: bool = True

    def __post_init__(self) -> None:
        if not math.isfinite(self.value):
            raise ValueError(f"Pressure value must be finite (Pa), got {self.value!r}")


@dataclass(frozen=True)
class EdgeTraction:
    """Dead force per unit reference edge length [N/m] on a named boundary."""

    where: str
    traction: tuple[float, float, float]

    def __post_init__(self) -> None:
        _where("EdgeTraction", self.where)
        object.__setattr__(self, "traction", _vector("EdgeTraction", "traction", self.traction))


@dataclass(frozen=True)
class EdgeMoment:
    """Moment per unit reference edge length [N m/m] on a named boundary.

    Its work is m . theta with theta the nodal rotation vector: exact (conservative) for
    rotations about a fixed axis, as in the rolled-up strip.
    """

    where: str
    moment: tuple[float, float, float]

    def __post_init__(self) -> None:
        _where("EdgeMoment", self.where)
        object.__setattr__(self, "moment", _vector("EdgeMoment", "moment", self.moment))


@dataclass(frozen=True)
class PointForce:
    """Dead force [N] at the mesh node nearest to ``point`` [m].

    ``on`` (keyword only): a boundary name; only the nodes of that boundary are candidates.
    Where nodes coincide (the two lips of a slit) it selects the side; without it the choice
    among coincident nodes is arbitrary.
    """

    point: tuple[float, float, float]
    force: tuple[float, float, float]
    _: KW_ONLY
    on: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vector("PointForce", "point", self.point))
        object.__setattr__(self, "force", _vector("PointForce", "force", self.force))
        _on("PointForce", self.on)


@dataclass(frozen=True)
class Clamp:
    """u = 0 and director fixed on ``where``."""

    where: Where

    def __post_init__(self) -> None:
        _where("Clamp", self.where)


@dataclass(frozen=True)
class Pin:
    """u = 0 on ``where``; the director is free."""

    where: Where

    def __post_init__(self) -> None:
        _where("Pin", self.where)


@dataclass(frozen=True)
class Symmetry:
    """Symmetry about the plane of normal ``axis`` (0 = x, 1 = y, 2 = z) through ``where``:
    u_axis = 0 and the director stays in the plane (it rotates only about the normal).

    At a node on two symmetry planes (e.g. the centre node of a quarter model) the director
    must stay in both, i.e. on their intersection line: both of its rotations are fixed.
    """

    where: Where
    axis: int

    def __post_init__(self) -> None:
        _where("Symmetry", self.where)
        if self.axis not in (0, 1, 2):
            raise ValueError(f"Symmetry axis must be 0, 1 or 2, got {self.axis!r}")


@dataclass(frozen=True)
class Prescribed:
    """Prescribed displacement and/or rotation on ``where``, scaled by the load factor.

    displacement: a 3-vector [m] (times lam) or a function ``f(x, lam) -> (N, 3)`` of the
    reference node coordinates; ``components`` picks which of x, y, z are constrained.
    rotation: a global rotation vector [rad] (times lam) applied to the reference director
    (|lam * rotation| < pi); None leaves the director free.
    """

    where: Where
    displacement: tuple[float, float, float] | Callable | None = None
    components: tuple[int, ...] = (0, 1, 2)
    rotation: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        _where("Prescribed", self.where)
        if self.displacement is not None and not callable(self.displacement):
            object.__setattr__(
                self, "displacement", _vector("Prescribed", "displacement", self.displacement)
            )
        if self.rotation is not None:
            object.__setattr__(self, "rotation", _vector("Prescribed", "rotation", self.rotation))
        if not self.components or any(c not in (0, 1, 2) for c in self.components):
            raise ValueError(
                f"Prescribed components must be among 0, 1, 2, got {self.components!r}"
            )
        if self.displacement is None and self.rotation is None:
            raise ValueError("Prescribed needs a displacement or a rotation, got neither")


@dataclass(frozen=True, kw_only=True)
class PointPin:
    """u_i = 0 for i in ``components`` (0 = x, 1 = y, 2 = z) at the one mesh node nearest to
    ``point`` [m]; the other components and the director stay free.

    It removes rigid-body modes that the other supports leave, e.g. of a free model cut by
    symmetry planes: under a self-equilibrated load its reactions are zero, so it changes
    nothing but the singularity. ``on``: a boundary name whose nodes are the only candidates
    (selects one side where nodes coincide, as at a slit).
    """

    point: tuple[float, float, float]
    components: tuple[int, ...] = (0, 1, 2)
    on: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vector("PointPin", "point", self.point))
        comps = tuple(self.components)
        if not comps or len(set(comps)) != len(comps) or any(c not in (0, 1, 2) for c in comps):
            raise ValueError(
                f"PointPin components must be distinct among 0, 1, 2, got {self.components!r}"
            )
        object.__setattr__(self, "components", comps)
        _on("PointPin", self.on)


Load = Gravity | Pressure | EdgeTraction | EdgeMoment | PointForce
Support = Clamp | Pin | Symmetry | Prescribed | PointPin
