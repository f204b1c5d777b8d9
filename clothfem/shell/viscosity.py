"""Membrane viscosity: a Kelvin-Voigt (rate-dependent) part in parallel with the elastic law.

Woven fabric dissipates energy when it deforms quickly (inter-fibre friction and the
viscoelasticity of the fibres; Man & Swan 2007 name damping among the fabric characteristics
the model should capture). Here the membrane carries, in parallel with the elastic law, the
viscous stresses

    tau_11 = eta1 dE11/dt,   tau_22 = eta2 dE22/dt,   tau_12 = eta12 d(2 E12)/dt,

eta_i [Pa s] per yarn direction and eta12 for in-plane shear (engineering shear strain
2 E12, the Green strains in the lamina frame). Over a step of size h from the committed
strain E_n the rate is taken as (E - E_n) / h (backward Euler), the stress of the
incremental potential

    phi(E) = t / (2 h) [eta1 (E11 - E11,n)^2 + eta2 (E22 - E22,n)^2 + 4 eta12 (E12 - E12,n)^2],

whose derivative the shell model adds to its residual (Jacobian by ``ufl.derivative``); the
step dissipates 2 phi >= 0 (the viscous stress times the strain increment). The history
E_n lives at the points of the reduced membrane rule and :meth:`MembraneViscosity.advance`
moves it after every accepted step (``ShellModel.commit_material``). ``1/h`` is a constant
the integrators set (``ShellModel.set_time_step``) before every step; it is 0 until then, so a
quasi-static run has no viscous stress.

The loss factor of a membrane mode of angular frequency omega is omega eta / E: viscous
damping grows with frequency, so it damps the fabric's high membrane modes and leaves its slow
motion (the body's) alone. In the explicit central difference it lowers the stable step of a
mode with damping ratio xi = omega eta / (2 E) by the factor sqrt(1 + xi^2) - xi (the explicit
runner applies it: ``explicit_step_factor``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import dolfinx
import numpy as np
import ufl
from dolfinx import fem

from .point_history import PointHistory

__all__ = ["FabricViscosity", "MembraneViscosity", "explicit_step_factor"]


@dataclass(frozen=True, kw_only=True)
class FabricViscosity:
    """Kelvin-Voigt viscosity of the membrane (1 = warp, 2 = weft, 12 = in-plane shear).

    Attributes
    ----------
    eta1, eta2: viscosity on the yarn strain rates [Pa s] (>= 0).
    eta12: viscosity on the engineering shear strain rate [Pa s] (>= 0).
    """

    eta1: float
    eta2: float
    eta12: float

    def __post_init__(self) -> None:
        for name in ("eta1", "eta2", "eta12"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"viscosity {name} must be a finite number >= 0 Pa s, got {v!r}")
        if self.eta1 == self.eta2 == self.eta12 == 0:
            raise ValueError("viscosity: at least one of eta1, eta2, eta12 must be > 0 Pa s")

    def weights(self) -> np.ndarray:
        """The factors on (E11 - E11,n)^2, (E22 - E22,n)^2, (E12 - E12,n)^2 [Pa s]."""
        return np.array([self.eta1, self.eta2, 4.0 * self.eta12])


def explicit_step_factor(
    *, omega: float, viscosity: FabricViscosity, E1: float, E2: float, G12: float
) -> float:
    """Factor (<= 1) on the undamped stable step 2 / omega of the central difference with the
    viscous membrane. A mode of angular frequency w and damping ratio xi is stable for
    h <= (2 / w) (sqrt(1 + xi^2) - xi) (also with the rate lagged by half a step, as here).
    A mode near the highest frequency omega may strain the membrane in any mix of the three
    components, so xi is bounded by omega max(eta1 / E1, eta2 / E2, eta12 / G12) / 2 (the
    largest relaxation time of the three): safe, and costly for a large shear viscosity
    (a bound from the shear modes' lower frequencies alone let the arm-sleeve run blow up)."""
    tau = max(viscosity.eta1 / E1, viscosity.eta2 / E2, viscosity.eta12 / G12)
    xi = 0.5 * omega * tau
    return math.sqrt(1.0 + xi * xi) - xi


class MembraneViscosity(PointHistory):
    """History and forms of :class:`FabricViscosity` on a shell model (built by ShellModel):
    the committed strains (E11, E22, E12) at the points of the reduced membrane rule
    (degree ``degree``, measure ``dx``), the cumulated dissipation density [J/m^3], the
    constant ``inv_h`` = 1 / time step [1/s] and ``energy``, the UFL potential added to the
    membrane term."""

    PREFIX = "viscous"

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        viscosity: FabricViscosity,
        eps: ufl.core.expr.Expr,
        t: fem.Constant,
        *,
        degree: int,
        dx: ufl.Measure,
        point_strains: Callable[[], np.ndarray] | None = None,
    ) -> None:
        self.viscosity = viscosity
        self.inv_h = fem.Constant(mesh, 0.0)
        self.eta = fem.Constant(mesh, viscosity.weights())
        strain = ufl.as_vector([eps[0, 0], eps[1, 1], eps[0, 1]])
        self._build(
            mesh,
            degree=degree,
            dim=3,
            strains=strain,
            t=t,
            dx=dx,
            point_strains=point_strains,
            names=("membrane_strain", "viscous_dissipation"),
        )
        H = self.history
        rate2 = sum(self.eta[i] * (strain[i] - H[i]) ** 2 for i in range(3))
        self.energy = 0.5 * t * self.inv_h * rate2 * dx

    def advance(self) -> None:
        """Add the step's dissipation eta (E - E_n)^2 / h at every point and make the current
        strains the history (no collective call)."""
        e, dofs = self._point_strains()
        h = self.history.x.array.reshape(-1, 3)
        d = e - h[dofs]
        w = self.viscosity.weights()
        self.dissipation.x.array[dofs] += float(self.inv_h.value) * (d * d) @ w
        h[dofs] = e
