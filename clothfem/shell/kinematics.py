"""Shell kinematics in UFL (Man & Swan 2007, Eqs. 3-6; Hughes 1987).

The continuum-degenerated shell places a material point at

    x(xi, eta, z) = xbar(xi, eta) + z d(xi, eta),     X = Xbar + z D,        (Eqs. 4-5)

with xbar = Xbar + u the midsurface and d the fibre director, both interpolated from nodal
values (d from the nodal rotated directors of :mod:`clothfem.shell.rotation`). Expanding the
Green-Lagrange strain E = (C - I)/2 of this map to first order in z in the reference lamina
basis (e1, e2, n) gives, for alpha, beta in {1, 2},

    E_ab(z) = eps_ab + z kappa_ab,     2 E_a3 = gamma_a,

    eps_ab   = (a_a . a_b - delta_ab) / 2                      membrane
    kappa_ab = (a_a . d,b + a_b . d,a - e_a . D,b - e_b . D,a) / 2   bending
    gamma_a  = a_a . d - e_a . D                               transverse shear

where a_a = d xbar / d s_a is the derivative of the deformed midsurface along e_a and
(.),a the derivative along e_a. The z^2 terms and the change of the metric through the
thickness (the shifter) are O(t/R) and dropped: the fabric is thin (t/R <= 1/30 in the
paper's scenes). All functions return UFL expressions; no solver, mesh or I/O here.
"""

from __future__ import annotations

import ufl

__all__ = ["lamina_frame", "shell_strains", "tangent_projector"]


def tangent_projector(mesh) -> ufl.core.expr.Expr:
    """Projector on the reference tangent plane, J (J^T J)^-1 J^T (3x3).

    On a manifold ``grad(SpatialCoordinate)`` is the full identity; this is the surface
    identity.
    """
    J = ufl.Jacobian(mesh)
    return J * ufl.inv(J.T * J) * J.T


def lamina_frame(mesh, warp) -> tuple:
    """Orthonormal lamina basis (e1, e2, n) of the reference surface at each point.

    ``n`` is the unit cell normal (the orientation of the mesh), ``e1`` the unit projection
    of the warp direction ``warp`` (a 3-vector UFL expression) on the tangent plane, and
    ``e2 = n x e1`` the weft direction. ``warp`` must not be normal to the surface.
    """
    J = ufl.Jacobian(mesh)
    t1, t2 = ufl.as_vector([J[i, 0] for i in range(3)]), ufl.as_vector([J[i, 1] for i in range(3)])
    n = ufl.cross(t1, t2)
    n = n / ufl.sqrt(ufl.dot(n, n))
    w = warp - ufl.dot(warp, n) * n
    e1 = w / ufl.sqrt(ufl.dot(w, w))
    e2 = ufl.cross(n, e1)
    return e1, e2, n


def shell_strains(u, d, D, frame) -> tuple:
    """Membrane, bending and shear strains (eps 2x2, kappa 2x2, gamma 2) in the lamina frame.

    u: midsurface displacement (3-vector), d: current director, D: reference director,
    frame: (e1, e2, n) from :func:`lamina_frame`.
    """
    e = frame[:2]
    Fu, Fd, FD = ufl.grad(u), ufl.grad(d), ufl.grad(D)
    a = [e[i] + Fu * e[i] for i in range(2)]
    d_s = [Fd * e[i] for i in range(2)]
    D_s = [FD * e[i] for i in range(2)]
    eps = ufl.as_matrix(
        [
            [0.5 * (ufl.dot(a[i], a[j]) - (1.0 if i == j else 0.0)) for j in range(2)]
            for i in range(2)
        ]
    )
    kappa = ufl.as_matrix(
        [
            [
                0.5
                * (
                    ufl.dot(a[i], d_s[j])
                    + ufl.dot(a[j], d_s[i])
                    - ufl.dot(e[i], D_s[j])
                    - ufl.dot(e[j], D_s[i])
                )
                for j in range(2)
            ]
            for i in range(2)
        ]
    )
    gamma = ufl.as_vector([ufl.dot(a[i], d) - ufl.dot(e[i], D) for i in range(2)])
    return eps, kappa, gamma
