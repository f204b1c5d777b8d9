"""Orthotropic St. Venant-Kirchhoff fabric with the plane-stress condition S33 = 0.

Man & Swan (2007), Eqs. 11-12: S = D : E with D constant (St. Venant-Kirchhoff), written in
the reference lamina basis (e1 = warp, e2 = weft, n). For an orthotropic solid the condition
S33 = 0 condenses the 3-D stiffness; the condensed in-plane stiffness is the inverse of the
in-plane block of the compliance, i.e. the classical reduced stiffness

    Q11 = E1/(1 - nu12 nu21),  Q22 = E2/(1 - nu12 nu21),  Q12 = nu12 E2/(1 - nu12 nu21),
    Q66 = G12,                  nu21 = nu12 E2/E1,

acting on (E11, E22, 2 E12). The transverse shear stresses are S13 = G13 2E13,
S23 = G23 2E23, with the shear correction factor k. Integrating the strain energy of
E(z) = eps + z kappa over z in [-t/2, t/2] gives the energy per unit reference area below.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ufl

__all__ = ["FabricMaterial", "membrane_energy", "bending_energy", "shear_energy"]


def _check_positive(name: str, value: float, unit: str) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ValueError(f"material {name} must be a finite number > 0 {unit}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class FabricMaterial:
    """Orthotropic fabric (1 = warp, 2 = weft), St. Venant-Kirchhoff, plane stress.

    Attributes
    ----------
    E1, E2: Young's moduli in the warp and weft directions [Pa].
    G12: in-plane shear modulus [Pa].
    nu12: major Poisson ratio [-]; admissible while nu12^2 < E1/E2.
    rho: mass density [kg/m^3] (0 for a massless static analysis).
    G13, G23: transverse shear moduli [Pa]; default G12.
    shear_factor: transverse shear correction factor k [-], default 5/6.
    """

    E1: float
    E2: float
    G12: float
    nu12: float = 0.0
    rho: float = 0.0
    G13: float | None = None
    G23: float | None = None
    shear_factor: float = 5.0 / 6.0

    def __post_init__(self) -> None:
        for name in ("E1", "E2", "G12"):
            _check_positive(name, getattr(self, name), "Pa")
        for name in ("G13", "G23"):
            if getattr(self, name) is not None:
                _check_positive(name, getattr(self, name), "Pa")
        _check_positive("shear_factor", self.shear_factor, "")
        if not (math.isfinite(self.rho) and self.rho >= 0):
            raise ValueError(f"material rho must be >= 0 kg/m^3, got {self.rho!r}")
        limit = math.sqrt(self.E1 / self.E2)
        if not (math.isfinite(self.nu12) and -limit < self.nu12 < limit):
            raise ValueError(
                f"material nu12 must be in (-{limit:.4g}, {limit:.4g}) = +-sqrt(E1/E2), "
                f"got {self.nu12!r}"
            )

    @classmethod
    def isotropic(cls, *, E: float, nu: float, rho: float = 0.0) -> FabricMaterial:
        """Isotropic material: E1 = E2 = E, G12 = G13 = G23 = E / (2 (1 + nu))."""
        if not (math.isfinite(nu) and -1.0 < nu < 0.5):
            raise ValueError(f"material nu must be in (-1, 0.5), got {nu!r}")
        _check_positive("E", E, "Pa")
        return cls(E1=E, E2=E, G12=E / (2 * (1 + nu)), nu12=nu, rho=rho)

    @property
    def nu21(self) -> float:
        return self.nu12 * self.E2 / self.E1

    def plane_stress_stiffness(self) -> np.ndarray:
        """Reduced stiffness Q (3x3, Pa) on (E11, E22, 2 E12) in the warp/weft basis."""
        den = 1.0 - self.nu12 * self.nu21
        q11, q22, q12 = self.E1 / den, self.E2 / den, self.nu12 * self.E2 / den
        return np.array([[q11, q12, 0.0], [q12, q22, 0.0], [0.0, 0.0, self.G12]])

    def transverse_shear(self) -> np.ndarray:
        """(k G13, k G23) [Pa]."""
        g13 = self.G13 if self.G13 is not None else self.G12
        g23 = self.G23 if self.G23 is not None else self.G12
        return self.shear_factor * np.array([g13, g23])


def _voigt(e) -> ufl.core.expr.Expr:
    return ufl.as_vector([e[0, 0], e[1, 1], 2 * e[0, 1]])


def membrane_energy(eps, Q, t) -> ufl.core.expr.Expr:
    """t/2 eps : Q : eps, per unit reference area [J/m^2]."""
    v = _voigt(eps)
    return 0.5 * t * ufl.dot(v, Q * v)


def bending_energy(kappa, Q, t) -> ufl.core.expr.Expr:
    """t^3/24 kappa : Q : kappa, per unit reference area [J/m^2]."""
    v = _voigt(kappa)
    return t**3 / 24.0 * ufl.dot(v, Q * v)


def shear_energy(gamma, kG, t) -> ufl.core.expr.Expr:
    """t/2 (k G13 gamma1^2 + k G23 gamma2^2), per unit reference area [J/m^2]."""
    return 0.5 * t * (kG[0] * gamma[0] ** 2 + kG[1] * gamma[1] ** 2)
