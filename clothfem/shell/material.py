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

:class:`DecrimpingFabric` adds a nonlinear, convex stiffening in each yarn direction to the
membrane energy (the crimped fabric's St. Venant-Kirchhoff energy plus the energy of the
straightened yarns): docs/material.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ufl

from .hysteresis import DahlFriction
from .viscosity import FabricViscosity

__all__ = [
    "FabricMaterial",
    "DecrimpingFabric",
    "membrane_energy",
    "bending_energy",
    "shear_energy",
    "decrimping_membrane_energy",
    "yarn_ramp",
    "transition_from_stresses",
]


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
    friction: yarn friction in parallel with the elastic law (load-unload hysteresis,
        :mod:`clothfem.shell.hysteresis`); None: elastic.
    viscosity: membrane viscosity in parallel with the elastic law (Kelvin-Voigt,
        :mod:`clothfem.shell.viscosity`); None: none.
    """

    E1: float
    E2: float
    G12: float
    nu12: float = 0.0
    rho: float = 0.0
    G13: float | None = None
    G23: float | None = None
    shear_factor: float = 5.0 / 6.0
    friction: DahlFriction | None = None
    viscosity: FabricViscosity | None = None

    def __post_init__(self) -> None:
        if self.friction is not None and not isinstance(self.friction, DahlFriction):
            raise ValueError(
                f"material friction must be a DahlFriction or None, got {self.friction!r}"
            )
        if self.viscosity is not None and not isinstance(self.viscosity, FabricViscosity):
            raise ValueError(
                f"material viscosity must be a FabricViscosity or None, got {self.viscosity!r}"
            )
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


# ---------------------------------------------------------------------------- decrimping
def yarn_ramp(s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The smoothed ramp of the decrimping law and its first two derivatives at ``s``.

    Returns (P, p, h) with h = P'' the cubic smoothstep from 0 (s <= -1) to 1 (s >= 1),

        h(s) = (2 + 3 s - s^3) / 4,                       |s| < 1
        p(s) = (3/4 + 2 s + 3/2 s^2 - 1/4 s^4) / 4        (= 0 for s <= -1, = s for s >= 1)
        P(s) = (1/5 + 3/4 s + s^2 + 1/2 s^3 - 1/20 s^5) / 4  (= 0, = s^2/2 + 1/10)

    P is C^3, p a smoothed max(s, 0), h in [0, 1] nondecreasing (NumPy; the UFL twin is
    :func:`_ramp_energy_ufl`).
    """
    s = np.asarray(s, dtype=float)
    c = np.clip(s, -1.0, 1.0)
    h = np.where(s <= -1.0, 0.0, np.where(s >= 1.0, 1.0, (2.0 + 3.0 * c - c**3) / 4.0))
    p_in = (0.75 + 2.0 * c + 1.5 * c**2 - 0.25 * c**4) / 4.0
    P_in = (0.2 + 0.75 * c + c**2 + 0.5 * c**3 - 0.05 * c**5) / 4.0
    p = np.where(s <= -1.0, 0.0, np.where(s >= 1.0, s, p_in))
    P = np.where(s <= -1.0, 0.0, np.where(s >= 1.0, 0.5 * s**2 + 0.1, P_in))
    return P, p, h


def _ramp_energy_ufl(s) -> ufl.core.expr.Expr:
    """P(s) of :func:`yarn_ramp` in UFL (Horner form of the middle piece)."""
    inner = 0.25 * (0.2 + s * (0.75 + s * (1.0 + s * (0.5 - 0.05 * s * s))))
    return ufl.conditional(
        ufl.le(s, -1.0), 0.0, ufl.conditional(ufl.ge(s, 1.0), 0.5 * s * s + 0.1, inner)
    )


def transition_from_stresses(
    *, E_crimped: float, E_decrimped: float, crimped_below: float, decrimped_above: float
) -> tuple[float, float]:
    """(transition, width) of the decrimping law that is exactly crimped (tangent modulus
    E_crimped) for yarn stresses below ``crimped_below`` [Pa] and exactly de-crimped (tangent
    E_decrimped) above ``decrimped_above`` [Pa]:

        width = (S_d - S_c) / (E_c + E_d),      transition = S_c / E_c + width.
    """
    _check_positive("E_crimped", E_crimped, "Pa")
    _check_positive("E_decrimped", E_decrimped, "Pa")
    _check_positive("crimped_below", crimped_below, "Pa")
    if not (math.isfinite(decrimped_above) and decrimped_above > crimped_below):
        raise ValueError(
            f"decrimped_above must be a finite number > crimped_below = {crimped_below:g} Pa, "
            f"got {decrimped_above!r}"
        )
    width = (decrimped_above - crimped_below) / (E_crimped + E_decrimped)
    return crimped_below / E_crimped + width, width


@dataclass(frozen=True, kw_only=True)
class DecrimpingFabric(FabricMaterial):
    """Orthotropic fabric whose yarns stiffen as they de-crimp (1 = warp, 2 = weft).

    Strain energy per unit reference volume, in the Green-Lagrange strain E of the lamina
    basis, plane stress (S33 = 0):

        W(E) = 1/2 E : Q_c : E + sum_i (Ed_i - Ec_i) w_i^2 P((E_ii - et_i) / w_i),

    Q_c the reduced stiffness of the crimped fabric (E1, E2, G12, nu12 as in
    :class:`FabricMaterial`) and P the smoothed ramp of :func:`yarn_ramp`. The yarn-direction
    stress and tangent of the extra term are (Ed_i - Ec_i) w_i p(s_i) and (Ed_i - Ec_i) h(s_i)
    with h rising smoothly (C^1) from 0 to 1 over et_i - w_i < E_ii < et_i + w_i: in uniaxial
    tension along yarn i the tangent modulus is exactly E_i (crimped) below the transition,
    exactly Ed_i (de-crimped) above it. W is convex in each E_ii (W'' >= Ec_i > 0). Bending
    stays linear with the crimped Q_c (a fabric's bending stiffness comes from yarn bending
    and inter-yarn friction, not from yarn tension); transverse shear as FabricMaterial.

    Attributes (besides those of :class:`FabricMaterial`, where E1, E2 are the crimped
    moduli)
    ----------
    E1_decrimped, E2_decrimped: de-crimped tangent moduli [Pa], >= E1, E2.
    transition1, transition2: Green-Lagrange yarn strain at the middle of the transition [-].
    width1, width2: half-width of the transition in strain [-], in (0, transition]
        (so the fabric is exactly crimped around the reference state).
    """

    E1_decrimped: float
    E2_decrimped: float
    transition1: float
    transition2: float
    width1: float
    width2: float

    def __post_init__(self) -> None:
        super().__post_init__()
        for i in (1, 2):
            Ec, Ed = getattr(self, f"E{i}"), getattr(self, f"E{i}_decrimped")
            if not (isinstance(Ed, int | float) and math.isfinite(Ed) and Ed >= Ec):
                raise ValueError(
                    f"material E{i}_decrimped must be a finite number >= E{i} = {Ec:g} Pa, "
                    f"got {Ed!r}"
                )
            _check_positive(f"transition{i}", getattr(self, f"transition{i}"), "")
            w, et = getattr(self, f"width{i}"), getattr(self, f"transition{i}")
            if not (isinstance(w, int | float) and math.isfinite(w) and 0.0 < w <= et):
                raise ValueError(
                    f"material width{i} must be in (0, transition{i} = {et:g}], got {w!r}"
                )

    @classmethod
    def cotton(
        cls,
        *,
        crimped_below: float = 1.0e6,
        decrimped_above: float = 10.0e6,
        rho: float = 436.0,
        friction: DahlFriction | None = None,
    ) -> DecrimpingFabric:
        """Man & Swan's plain-weave cotton (Sec. 4.1) as one material: E = 1.2 MPa while
        crimped (yarn stress below ``crimped_below`` = 1 MPa), 350 MPa de-crimped (above
        ``decrimped_above`` = 10 MPa), G12 = 0.1 MPa, nu12 = 0, both yarn directions alike;
        ``friction`` e.g. :data:`clothfem.shell.hysteresis.COTTON_FRICTION`."""
        Ec, Ed = 1.2e6, 350e6
        et, w = transition_from_stresses(
            E_crimped=Ec,
            E_decrimped=Ed,
            crimped_below=crimped_below,
            decrimped_above=decrimped_above,
        )
        return cls(
            E1=Ec,
            E2=Ec,
            G12=1.0e5,
            rho=rho,
            E1_decrimped=Ed,
            E2_decrimped=Ed,
            transition1=et,
            transition2=et,
            width1=w,
            width2=w,
            friction=friction,
        )

    def yarn_parameters(self) -> np.ndarray:
        """[[Ed_1 - Ec_1, et_1, w_1], [Ed_2 - Ec_2, et_2, w_2]] (Pa, -, -), the constants of
        :func:`decrimping_membrane_energy`."""
        return np.array(
            [
                [self.E1_decrimped - self.E1, self.transition1, self.width1],
                [self.E2_decrimped - self.E2, self.transition2, self.width2],
            ]
        )

    def stress(
        self, E11: np.ndarray, E22: np.ndarray, E12: np.ndarray | float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closed form: second Piola-Kirchhoff (S11, S22, S12) [Pa] at the in-plane Green
        strains (NumPy arrays broadcast together)."""
        E11, E22, E12 = (np.asarray(a, dtype=float) for a in (E11, E22, E12))
        Q = self.plane_stress_stiffness()
        out = []
        for i, e in enumerate((E11, E22)):
            dE, et, w = self.yarn_parameters()[i]
            out.append(Q[i, 0] * E11 + Q[i, 1] * E22 + dE * w * yarn_ramp((e - et) / w)[1])
        return out[0], out[1], 2.0 * Q[2, 2] * E12

    def uniaxial_stress(self, e: np.ndarray, *, direction: int = 1) -> np.ndarray:
        """Closed form: S_ii [Pa] in uniaxial stress along yarn ``direction`` (1 or 2) at the
        yarn strain E_ii = ``e``, the other in-plane stresses zero. Exact while the lateral
        strain -nu e stays below its own transition (always for e >= 0, nu >= 0)."""
        if direction not in (1, 2):
            raise ValueError(f"direction must be 1 or 2, got {direction!r}")
        e = np.asarray(e, dtype=float)
        dE, et, w = self.yarn_parameters()[direction - 1]
        Ec = self.E1 if direction == 1 else self.E2
        return Ec * e + dE * w * yarn_ramp((e - et) / w)[1]

    def yarn_tangent(self, e: np.ndarray, *, direction: int = 1) -> np.ndarray:
        """d S_ii / d E_ii [Pa] in uniaxial stress along yarn ``direction`` (1 or 2)."""
        if direction not in (1, 2):
            raise ValueError(f"direction must be 1 or 2, got {direction!r}")
        e = np.asarray(e, dtype=float)
        dE, et, w = self.yarn_parameters()[direction - 1]
        Ec = self.E1 if direction == 1 else self.E2
        return Ec + dE * yarn_ramp((e - et) / w)[2]

    def energy_density(
        self, E11: np.ndarray, E22: np.ndarray, E12: np.ndarray | float = 0.0
    ) -> np.ndarray:
        """Closed form: W [J/m^3] at the in-plane Green strains (NumPy)."""
        E11, E22, E12 = (np.asarray(a, dtype=float) for a in (E11, E22, E12))
        Q = self.plane_stress_stiffness()
        v = (E11, E22, 2.0 * E12)
        W = 0.5 * sum(Q[i, j] * v[i] * v[j] for i in range(3) for j in range(3))
        for i, e in enumerate((E11, E22)):
            dE, et, w = self.yarn_parameters()[i]
            W = W + dE * w**2 * yarn_ramp((e - et) / w)[0]
        return W


def decrimping_membrane_energy(
    eps: ufl.core.expr.Expr, Q: ufl.core.expr.Expr, yarn: ufl.core.expr.Expr, t
) -> ufl.core.expr.Expr:
    """t W(eps) of :class:`DecrimpingFabric` per unit reference area [J/m^2]; ``yarn`` the
    2x3 constants of :meth:`DecrimpingFabric.yarn_parameters`."""
    psi = membrane_energy(eps, Q, t)
    for i in range(2):
        dE, et, w = yarn[i, 0], yarn[i, 1], yarn[i, 2]
        psi = psi + t * dE * w * w * _ramp_energy_ufl((eps[i, i] - et) / w)
    return psi
