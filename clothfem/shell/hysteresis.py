"""Yarn friction: a rate-independent Dahl element per yarn direction (load-unload loops).

Woven fabrics dissipate energy in a load-unload cycle through friction between and within
yarns (Man & Swan 2007, Sec. 3.1.2 and Fig. 2; KES-F curves, Kawabata 1980). Here each yarn
direction i carries, in parallel with the elastic law (:class:`FabricMaterial` or
:class:`DecrimpingFabric`), a friction stress s_i obeying Dahl's rate-independent law

    ds_i = k_i (1 - sgn(dE_ii) s_i / S_i) dE_ii,        |s_i| <= S_i,

k_i the initial (sticking) stiffness [Pa] and S_i the sliding stress [Pa]. Read as a spring
k_i in series with a slip e_p (s = k_i (E_ii - e_p)), the stored energy is s^2 / (2 k_i) and
the dissipation rate s de_p = |dE_ii| s^2 / S_i >= 0. Over a step in which E_ii changes
monotonically by d (sign g, size a = |d|) the law integrates exactly:

    s_new = g S + (s - g S) q,      q = exp(-k a / S),
    work  = int s dE = S a + (g s - S) (S / k) (1 - q),
    dissipation = work - (s_new^2 - s^2) / (2 k)  >= 0.

The work, as a function of d with the step's start fixed, is the incremental potential
phi(d) whose derivative is the friction stress at the end of the step; the shell model adds
t phi(E_ii - E_ii,n) + t s_n^2 / (2 k) (the stored part, constant within a step) to the
membrane energy, with the history (E_ii,n, s_n) at the points of the reduced membrane rule
(:class:`YarnFriction`). :meth:`YarnFriction.commit` advances the history after a converged
(static) or completed (explicit) step: in a static run call it from ``solve_static``'s
``on_step``, in an explicit one from ``integrate_explicit``'s ``on_step``.

Energy bookkeeping: ``ShellModel.strain_energy()`` includes the stored friction energy at
committed states; the dissipated energy is :meth:`YarnFriction.dissipated` (so in the
dynamics records it appears inside the numerical dissipation until the integrators report
it separately).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import dolfinx
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from .point_history import PointHistory

__all__ = [
    "COTTON_FRICTION",
    "DahlFriction",
    "YarnFriction",
    "dahl_update",
    "dahl_cycle_area",
    "dahl_increment_energy",
]


@dataclass(frozen=True, kw_only=True)
class DahlFriction:
    """Dahl friction in each yarn direction (1 = warp, 2 = weft), in parallel with the
    elastic law.

    Attributes
    ----------
    stiffness1, stiffness2: initial (sticking) stiffness k_i of the friction stress [Pa].
    stress1, stress2: sliding friction stress S_i [Pa] (the loop's half-height at large
        amplitude: the hysteresis band is 2 S_i wide in stress).
    """

    stiffness1: float
    stiffness2: float
    stress1: float
    stress2: float

    def __post_init__(self) -> None:
        for name in ("stiffness1", "stiffness2", "stress1", "stress2"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"friction {name} must be a finite number > 0 Pa, got {v!r}")

    def parameters(self) -> np.ndarray:
        """[[k_1, S_1], [k_2, S_2]] [Pa]."""
        return np.array([[self.stiffness1, self.stress1], [self.stiffness2, self.stress2]])


# Illustrative (not fitted to a measured curve): k = the crimped cotton modulus 1.2 MPa, so
# the friction branch doubles the initial stiffness, S = 30 kPa, a hysteresis band 60 kPa
# wide at large amplitude. With the crimped cotton of Man & Swan, a tensile cycle 0 -> 5 %
# (or 10 %) -> zero stress recovers 58 % of the work of loading and leaves a residual strain
# of 1.4 % (2.3 %): a loop of the shape of KES-F tensile curves (Kawabata 1980; Man & Swan
# 2007, Fig. 2).
COTTON_FRICTION = DahlFriction(stiffness1=1.2e6, stiffness2=1.2e6, stress1=3.0e4, stress2=3.0e4)


def dahl_update(
    d: np.ndarray, s: np.ndarray, *, k: float, S: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact Dahl step for monotone strain increments ``d`` from friction stresses ``s``:
    (new stress [Pa], work int s dE [J/m^3], dissipation [J/m^3] >= 0)."""
    d, s = np.asarray(d, dtype=float), np.asarray(s, dtype=float)
    a, g = np.abs(d), np.sign(d)
    q = np.exp(-k * a / S)
    s_new = g * S + (s - g * S) * q
    work = S * a + (g * s - S) * (S / k) * (1.0 - q)
    diss = work - (s_new**2 - s**2) / (2.0 * k)
    return s_new, work, diss


def dahl_cycle_area(amplitude: float, *, k: float, S: float) -> float:
    """Closed form: area [J/m^3] of the steady loop of a strain cycle between -amplitude and
    +amplitude (the turning stresses are +-s*, s* = S (1 - q) / (1 + q), q = exp(-2 k A / S))."""
    q = math.exp(-2.0 * k * amplitude / S)
    s_star = S * (1.0 - q) / (1.0 + q)
    return 2.0 * (2.0 * amplitude * S - (s_star + S) * (S / k) * (1.0 - q))


def dahl_increment_energy(
    d: ufl.core.expr.Expr, s: ufl.core.expr.Expr, k: ufl.core.expr.Expr, S: ufl.core.expr.Expr
) -> ufl.core.expr.Expr:
    """phi(d) = int_0^d s dE of the Dahl law from stress ``s`` (UFL), by branch so that
    phi'(0) = s (the loading branch at d = 0)."""
    up = S * d + (s - S) * (S / k) * (1.0 - ufl.exp(-k * d / S))
    down = -S * d + (-s - S) * (S / k) * (1.0 - ufl.exp(k * d / S))
    return ufl.conditional(ufl.ge(d, 0.0), up, down)


class YarnFriction(PointHistory):
    """History and forms of :class:`DahlFriction` on a shell model (built by ShellModel).

    Per quadrature point of the reduced membrane rule (degree ``degree``, measure ``dx``):
    (E11_n, E22_n, s1_n, s2_n) of the last committed state, and the cumulated dissipation
    density [J/m^3]. ``energy``: the UFL energy added to the membrane term.

    The friction term is integrated with the reduced rule only, not blended with the full
    one as the elastic membrane energy is: the fully integrated share of the elastic energy
    already removes the reduced rule's spurious modes, and an added term can only stiffen
    them. (Blending would need the history at the full rule's points too, and FFCx 0.5
    cannot compile a form holding two Quadrature elements with different numbers of points:
    its element comparison calls numpy.allclose on point arrays of different shapes.)
    """

    PREFIX = "friction"

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        friction: DahlFriction,
        eps: ufl.core.expr.Expr,
        t: fem.Constant,
        *,
        degree: int,
        dx: ufl.Measure,
        point_strains: Callable[[], np.ndarray] | None = None,
    ) -> None:
        self.friction, self.t = friction, t
        self.k = fem.Constant(mesh, friction.parameters())
        strains = ufl.as_vector([eps[0, 0], eps[1, 1]])
        self._build(
            mesh,
            degree=degree,
            dim=4,
            strains=strains,
            t=t,
            dx=dx,
            point_strains=point_strains,
            names=("yarn_friction", "yarn_dissipation"),
        )
        H = self.history
        dens = 0
        psi = 0
        for i in range(2):
            k, S = self.k[i, 0], self.k[i, 1]
            dens += dahl_increment_energy(eps[i, i] - H[i], H[2 + i], k, S)
            psi += H[2 + i] ** 2 / (2.0 * k)
        self.energy = t * (dens + psi) * dx
        self._stored_form = fem.form(t * psi * dx)
        self.last_min_dissipation = 0.0

    def commit(self) -> float:
        """Advance the history to the model's current state (:meth:`advance`); returns the
        energy [J] dissipated in the step (collective). ``last_min_dissipation`` keeps the
        smallest dissipation density [J/m^3] of a point in the step (>= 0 up to round-off)."""
        before = self.dissipated()
        lowest = self.advance()
        self.last_min_dissipation = self.mesh.comm.allreduce(lowest, op=MPI.MIN)
        return self.dissipated() - before

    def advance(self) -> float:
        """Advance the history to the model's current state without any collective call
        (an explicit run does this every step and measures :meth:`dissipated` per history
        row); returns this rank's smallest dissipation density [J/m^3] of the step."""
        par = self.friction.parameters()
        lowest = math.inf
        e, dofs = self._point_strains()
        H, D = self.history, self.dissipation
        h = H.x.array.reshape(-1, 4)
        for i in range(2):
            s_new, _, diss = dahl_update(
                e[:, :, i] - h[dofs, i], h[dofs, 2 + i], k=par[i, 0], S=par[i, 1]
            )
            h[dofs, i] = e[:, :, i]
            h[dofs, 2 + i] = s_new
            D.x.array[dofs] += diss
            if diss.size:
                lowest = min(lowest, float(diss.min()))
        return lowest

    def stored(self) -> float:
        """Energy [J] stored in the friction springs at the last committed state."""
        return self.mesh.comm.allreduce(fem.assemble_scalar(self._stored_form), op=MPI.SUM)
