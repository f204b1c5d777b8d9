"""Inertia of the fabric shell in UFL (Man & Swan 2007, Eq. 13: the term M . a).

The kinetic energy of the continuum-degenerated shell x = xbar + z d (Eqs. 4-5), integrated
over the thickness z in [-t/2, t/2] with a uniform reference density rho, is

    T = 1/2 int_A rho t |du/dt|^2 dA + 1/2 int_A rho t^3/12 |dd/dt|^2 dA,

(the cross term vanishes because the midsurface is the mid-plane), so the consistent mass in
the (u, d) block layout of the shell model is block diagonal:

    M_uu = rho t int N_A N_B I dA,       M_dd = rho t^3/12 int N_A N_B I dA.

The forms below are bilinear forms on the 3-vector space of u and d; they are constant in a
total-Lagrangian description (reference area, reference density). The map to the (u, theta)
unknowns of the model is done by the nodal transfer P = diag(I, dd_A/dtheta_A) in
:mod:`clothfem.dynamics`. No solver, mesh or assembly here.
"""

from __future__ import annotations

import ufl

__all__ = ["translational_mass", "rotary_mass", "mass_density", "director_mass_density"]


def translational_mass(V, rho, thickness, dx) -> ufl.Form:
    """Consistent midsurface mass rho t int du . v dA on the 3-vector space ``V`` [kg]."""
    du, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    return rho * thickness * ufl.inner(du, v) * dx


def rotary_mass(V, rho, thickness, dx, scale=1.0) -> ufl.Form:
    """Consistent rotary inertia of the director rho t^3/12 int dd . w dA [kg m^2].

    ``scale`` multiplies it (rotary-inertia scaling for explicit steps; 1 is physical).
    """
    dd, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    return scale * (rho * thickness**3) / 12.0 * ufl.inner(dd, w) * dx


def mass_density(rho, thickness, dx) -> ufl.Form:
    """Total midsurface mass rho t int dA [kg] (a functional, for lumping)."""
    return rho * thickness * dx


def director_mass_density(rho, thickness, dx, scale=1.0) -> ufl.Form:
    """Total rotary inertia scale rho t^3/12 int dA [kg m^2] (a functional, for lumping)."""
    return scale * (rho * thickness**3) / 12.0 * dx
