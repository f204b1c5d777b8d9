"""The particle fabric: springs, masses, supports, damping, strain limit and contact.

Forces (vectorised NumPy over springs). Spring s from node i to j, ``n = (x_j - x_i) / L``:
the axial force ``T`` (tension > 0) acts as ``+T n`` on i and ``-T n`` on j,

* linear spring: ``T = k (L - L0)``;
* Choi & Ko (2002) spring in compression: ``T = -P``, the smooth minimum of ``k (L0 - L)``
  and the buckled column's ``f_b(L)`` (:func:`clothfem.particle.rule.compressive_force`);
  a spring without tension (Choi &
  Ko flexion) has ``T = 0`` for ``L > L0``;
* axial damping ``T += beta k (v_j - v_i) . n`` (stiffness-proportional along the spring
  axis: removes stretching vibrations, not rigid motions);
* mass-proportional damping ``-alpha m v`` (also damps rigid motions: a drag);
* gravity ``m g``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from .network import KIND_NAMES, SpringNetwork
from .rule import ParticleFabric, column_energy, compressive_force

__all__ = [
    "Damping",
    "Energies",
    "ParticleModel",
    "ParticleState",
    "StrainLimit",
    "energies",
    "internal_forces",
    "stable_time_step",
    "support_reaction",
    "tangent",
]

FloatArray = NDArray[np.float64]
BodiesAt = Callable[[float], tuple[Sequence, Sequence]]


@dataclass(frozen=True, kw_only=True)
class Damping:
    """alpha: mass-proportional damping [1/s] (>= 0); beta: spring-axis damping, as a
    fraction of each spring's stiffness [s] (>= 0)."""

    alpha: float = 0.0
    beta: float = 0.0

    def __post_init__(self) -> None:
        for name in ("alpha", "beta"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"Damping {name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True, kw_only=True)
class StrainLimit:
    """Provot's (1995) inverse-dynamics correction: after each step the springs of ``kinds``
    stretched beyond ``(1 + max_stretch) L0`` are shortened to that length by moving their
    end nodes (in inverse proportion to their masses; supported nodes do not move).

    max_stretch: allowed stretch [-] > 0 (Provot: 0.1); kinds: spring kinds limited;
    iterations: at most this many sweeps (>= 1); tol: stop when every limited spring is
    within ``(1 + max_stretch)(1 + tol)`` [-] (>= 0).
    """

    max_stretch: float = 0.1
    kinds: tuple[str, ...] = ("structural", "shear")
    iterations: int = 100
    tol: float = 1e-6

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_stretch) and self.max_stretch > 0.0):
            raise ValueError(f"StrainLimit max_stretch must be > 0, got {self.max_stretch!r}")
        for k in self.kinds:
            if k not in KIND_NAMES:
                raise ValueError(f"StrainLimit kinds must be in {sorted(KIND_NAMES)}, got {k!r}")
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise ValueError(
                f"StrainLimit iterations must be an integer >= 1, got {self.iterations!r}"
            )
        if not (math.isfinite(self.tol) and self.tol >= 0.0):
            raise ValueError(f"StrainLimit tol must be >= 0, got {self.tol!r}")


@dataclass(frozen=True, eq=False, kw_only=True)
class ParticleModel:
    """A particle fabric ready to integrate.

    network, fabric: the springs and their constants (:func:`fabric_from_material`).
    gravity: acceleration [m/s^2].
    fixed: (n,) bool, nodes whose positions are prescribed (supports).
    prescribed: None (supported nodes stay at ``x0``) or ``t -> (n_fixed, 3)`` positions [m]
    of the supported nodes at time t [s].
    damping, strain_limit (None: off).
    bodies: None, or ``t -> (ellipsoids, velocities)`` as for :mod:`clothfem.contact.film`
    (see :func:`clothfem.particle.bodies`); contact: its FILM parameters
    (:class:`clothfem.contact.film.FilmParameters`).
    """

    network: SpringNetwork
    fabric: ParticleFabric
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    fixed: NDArray[np.bool_] | None = None
    prescribed: Callable[[float], ArrayLike] | None = None
    damping: Damping = Damping()
    strain_limit: StrainLimit | None = None
    bodies: BodiesAt | None = None
    contact: object | None = None

    def __post_init__(self) -> None:
        n = self.network.n_nodes
        fixed = np.zeros(n, bool) if self.fixed is None else np.asarray(self.fixed)
        if fixed.dtype != bool and fixed.ndim == 1:
            idx = fixed.astype(np.int64)
            fixed = np.zeros(n, bool)
            fixed[idx] = True
        if fixed.shape != (n,):
            raise ValueError(f"fixed must be a bool mask of shape ({n},) or node indices")
        object.__setattr__(self, "fixed", fixed)
        g = np.asarray(self.gravity, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"gravity must be a finite 3-vector in m/s^2, got {self.gravity!r}")
        object.__setattr__(self, "gravity", tuple(float(c) for c in g))
        if self.fabric.stiffness.shape != (self.network.n_springs,):
            raise ValueError("fabric must be built for this network (one stiffness per spring)")
        if self.contact is None and self.bodies is not None:
            from clothfem.contact.film import FilmParameters

            object.__setattr__(self, "contact", FilmParameters())

    @property
    def mass(self) -> FloatArray:
        return self.fabric.mass

    def fixed_positions(self, t: float) -> FloatArray:
        """Positions [m] of the supported nodes at time ``t`` [s]."""
        if self.prescribed is None:
            return self.network.x0[self.fixed]
        return np.asarray(self.prescribed(t), dtype=float).reshape(-1, 3)


@dataclass(frozen=True, eq=False, kw_only=True)
class ParticleState:
    """Positions x [m], velocities v [m/s] and accelerations a [m/s^2] (n, 3) at time t [s]."""

    t: float
    x: FloatArray
    v: FloatArray
    a: FloatArray

    @classmethod
    def at_rest(cls, model: ParticleModel, *, t: float = 0.0) -> ParticleState:
        """The reference configuration at rest, with the accelerations of its forces."""
        x = model.network.x0.copy()
        v = np.zeros_like(x)
        return cls(t=t, x=x, v=v, a=accelerations(model, x, v))


@dataclass(frozen=True)
class Energies:
    """kinetic, spring (strain) and gravity (potential, 0 at x0) energies [J]."""

    kinetic: float
    spring: float
    gravity: float

    @property
    def total(self) -> float:
        return self.kinetic + self.spring + self.gravity


def _axial(model: ParticleModel, x: FloatArray) -> tuple[FloatArray, ...]:
    """Lengths, unit vectors, tensions T and dT/dL of all springs at positions x."""
    net, fab = model.network, model.fabric
    i, j = net.pairs[:, 0], net.pairs[:, 1]
    d = x[j] - x[i]
    L = np.sqrt(np.einsum("ij,ij->i", d, d))
    n = d / L[:, None]
    k, L0 = fab.stiffness, net.rest
    T = k * (L - L0)
    dT = k.copy()
    slack = (L > L0) & ~fab.tension
    T[slack], dT[slack] = 0.0, 0.0
    b = np.flatnonzero(fab.buckling & (L < L0))
    if b.size:
        P, dP = compressive_force(L[b], L0[b], k[b], fab.rigidity[b])
        T[b], dT[b] = -P, -dP
    return L, n, T, dT


def _gather(n_nodes: int, pairs: np.ndarray, fvec: FloatArray) -> FloatArray:
    """Nodal sums of ``+fvec`` at the first end of each spring and ``-fvec`` at the second."""
    out = np.empty((n_nodes, 3))
    for c in range(3):
        out[:, c] = np.bincount(pairs[:, 0], fvec[:, c], n_nodes) - np.bincount(
            pairs[:, 1], fvec[:, c], n_nodes
        )
    return out


def internal_forces(model: ParticleModel, x: FloatArray, v: FloatArray | None = None) -> FloatArray:
    """Spring (and, with ``v``, damping) forces on the nodes [N], (n, 3)."""
    net = model.network
    L, n, T, _ = _axial(model, x)
    if v is not None and model.damping.beta > 0.0:
        dv = v[net.pairs[:, 1]] - v[net.pairs[:, 0]]
        T = T + model.damping.beta * model.fabric.stiffness * np.einsum("ij,ij->i", dv, n)
    f = _gather(net.n_nodes, net.pairs, T[:, None] * n)
    if v is not None and model.damping.alpha > 0.0:
        f -= model.damping.alpha * model.mass[:, None] * v
    return f


def accelerations(model: ParticleModel, x: FloatArray, v: FloatArray) -> FloatArray:
    """M^-1 (spring + damping + gravity forces) [m/s^2]; 0 at supported nodes."""
    a = internal_forces(model, x, v) / model.mass[:, None] + np.asarray(model.gravity)
    a[model.fixed] = 0.0
    return a


def support_reaction(model: ParticleModel, state: ParticleState) -> FloatArray:
    """Total force [N] the supports exert on the fabric, quasi-statically: minus the spring,
    damping and gravity forces on the supported nodes (their inertia is not included)."""
    f = internal_forces(model, state.x, state.v)[model.fixed]
    f += model.mass[model.fixed, None] * np.asarray(model.gravity)
    return -f.sum(axis=0)


def _spring_energy(model: ParticleModel, x: FloatArray) -> float:
    """Strain energy [J]: 0.5 k (L - L0)^2, the work of the compressive force for Choi & Ko
    springs in compression (:func:`clothfem.particle.rule.column_energy`)."""
    net, fab = model.network, model.fabric
    L, _, T, _ = _axial(model, x)
    e = 0.5 * fab.stiffness * (L - net.rest) ** 2
    e[(L > net.rest) & ~fab.tension] = 0.0
    b = np.flatnonzero(fab.buckling & (L < net.rest))
    if b.size:
        e[b] = column_energy(L[b], net.rest[b], fab.stiffness[b], fab.rigidity[b])
    return float(e.sum())


def energies(model: ParticleModel, state: ParticleState) -> Energies:
    """Kinetic, spring and gravity energies [J] of ``state``."""
    m = model.mass
    kin = 0.5 * float(np.sum(m[:, None] * state.v**2))
    grav = -float(np.sum(m[:, None] * (state.x - model.network.x0) * np.asarray(model.gravity)))
    return Energies(kinetic=kin, spring=_spring_energy(model, state.x), gravity=grav)


def tangent(
    model: ParticleModel, x: FloatArray, v: FloatArray, *, definite: bool = False
) -> tuple[sparse.csr_matrix, ...]:
    """Stiffness ``K = dF/dx`` and damping ``C = dF/dv`` (3n x 3n, CSR) of the spring and
    damping forces (exact for the spring forces). ``definite``: leave out the geometric term
    ``T / L (I - n n^T)`` of compressed springs (Choi & Ko 2002), which keeps ``-K``
    positive semi-definite."""
    net = model.network
    L, n, T, dT = _axial(model, x)
    nn = n[:, :, None] * n[:, None, :]
    tg = np.maximum(T, 0.0) if definite else T
    geo = (tg / L)[:, None, None] * (np.eye(3) - nn)
    Kb = dT[:, None, None] * nn + geo
    K = _assemble(net, Kb)
    Cb = (model.damping.beta * model.fabric.stiffness)[:, None, None] * nn
    C = _assemble(net, Cb)
    if model.damping.alpha > 0.0:
        C = C - sparse.diags(np.repeat(model.damping.alpha * model.mass, 3))
    return K.tocsr(), C.tocsr()


def _assemble(net: SpringNetwork, blocks: FloatArray) -> sparse.coo_matrix:
    """Sum of ``[[-B, B], [B, -B]]`` over springs (i, j) into a 3n x 3n matrix."""
    i, j = net.pairs[:, 0], net.pairs[:, 1]
    r, c = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    rows, cols, vals = [], [], []
    for a, b, sign in ((i, i, -1.0), (j, j, -1.0), (i, j, 1.0), (j, i, 1.0)):
        rows.append((3 * a[:, None, None] + r).ravel())
        cols.append((3 * b[:, None, None] + c).ravel())
        vals.append((sign * blocks).ravel())
    size = 3 * net.n_nodes
    return sparse.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size)
    )


def stable_time_step(model: ParticleModel) -> float:
    """A lower bound [s] on the explicit central-difference limit 2 / omega_max of the linear
    springs at rest (Gershgorin bound on M^-1/2 K M^-1/2); without damping."""
    net, m = model.network, model.mass
    i, j = net.pairs[:, 0], net.pairs[:, 1]
    k = model.fabric.stiffness
    cross = k / np.sqrt(m[i] * m[j])
    row = np.bincount(i, k / m[i] + cross, net.n_nodes) + np.bincount(
        j, k / m[j] + cross, net.n_nodes
    )
    row[model.fixed] = 0.0
    return 2.0 / math.sqrt(float(row.max()))
