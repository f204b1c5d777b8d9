"""Assumed covariant membrane and transverse-shear strains of the 9-node shell (MITC9).

Bucalem & Bathe (1993): the covariant strains in the cell's reference coordinates (r, s),

    e_rr = (x_r . x_r - X_r . X_r) / 2,   e_ss, e_rs alike,   g_r = x_r . d - X_r . D,

are sampled at tying points and interpolated back over the cell:

    e_rr, g_r   at r in the 2-point and s in the 3-point Gauss abscissae, linear in r,
                quadratic in s;
    e_ss, g_s   the same with r and s exchanged;
    e_rs        at the 2 x 2 Gauss points, bilinear.

The energy is the model's membrane and shear energy (:mod:`clothfem.shell.material`) of
these assumed strains, turned into the lamina frame (warp, weft) at the 3 x 3 Gauss
points, where it is integrated: with T_ia = G^i . e_a (G^i the contravariant reference
base vectors, e_a the lamina frame), eps_ab = T_ia T_jb e_ij and gamma_a = T_ia g_i, which
with the tying points replaced by the 3 x 3 points themselves is the fully integrated
energy of :func:`clothfem.shell.kinematics.shell_strains` (the ``"full"`` tying, a test of
the kernels).

Why hand-written kernels and not UFL: the assumed strain at one point needs the fields at
other points of the same cell, which UFL (2022.2) cannot express, and FFCx (0.5) cannot
tabulate the higher reference derivatives a Taylor shift would need
(docs/shell_element.md). The kernels below are dolfinx cell kernels (numba ``cfunc``) for
the energy, the residual (u and d node by node) and the Jacobian blocks, with the same arguments
(coefficients u, d, D; constants Q, kG, t, warp) as the UFL forms they complement. The
material is the orthotropic St. Venant-Kirchhoff law of
:class:`~clothfem.shell.material.FabricMaterial`, quadratic in the tying strains with a
geometry-only matrix (precomputed per point), plus, where the material has them, the terms
that act on the lamina strains (E11, E22, 2 E12) of the assumed membrane strains at each
3 x 3 point, each diagonal in those three components: the decrimping stiffening of
:class:`~clothfem.shell.material.DecrimpingFabric`, the Dahl yarn friction of
:mod:`clothfem.shell.hysteresis` and the Kelvin-Voigt viscosity of
:mod:`clothfem.shell.viscosity` (their histories at the same points, the Quadrature
functions of the model's rule of degree 4, read by the kernel).
"""

from __future__ import annotations

import math

import basix
import numba
import numpy as np
from dolfinx import cpp as _cpp
from dolfinx import fem
from numba.extending import intrinsic

__all__ = ["MitcForms", "tying_tables"]

_G2 = np.array([0.5 - 0.5 / math.sqrt(3.0), 0.5 + 0.5 / math.sqrt(3.0)])
_G3 = np.array([0.5 - 0.5 * math.sqrt(0.6), 0.5, 0.5 + 0.5 * math.sqrt(0.6)])
_W3 = np.array([5.0, 8.0, 5.0]) / 18.0


def _lagrange(nodes: np.ndarray, x: float) -> np.ndarray:
    """The 1-D Lagrange basis through ``nodes`` at ``x``."""
    out = np.ones(len(nodes))
    for a, xa in enumerate(nodes):
        for b, xb in enumerate(nodes):
            if a != b:
                out[a] *= (x - xb) / (xa - xb)
    return out


def _grid(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.array([[ri, sj] for sj in s for ri in r])


def tying_tables(tying: str = "mitc9") -> dict[str, np.ndarray]:
    """The constant tables of the kernels on the reference cell [0, 1]^2.

    ``tying = "mitc9"``: the tying points and interpolation above; ``"full"``: every strain
    at the 3 x 3 points (identity interpolation), the fully integrated energy.
    Returns the integration points ``q`` (9, 2) and weights ``w`` (9); per tying set
    k = 0 (e_rr, g_r), 1 (e_ss, g_s), 2 (e_rs) its points and the interpolation matrix
    ``P{k}`` (9 x n_k); and the Q2 shape functions at all of them (basix, dolfinx's order).
    """
    if tying not in ("mitc9", "full"):
        raise ValueError(f"tying must be 'mitc9' or 'full', got {tying!r}")
    q = _grid(_G3, _G3)
    w = np.array([wr * ws for ws in _W3 for wr in _W3])
    if tying == "full":
        sets = [(_G3, _G3)] * 3
    else:
        sets = [(_G2, _G3), (_G3, _G2), (_G2, _G2)]
    element = basix.create_element(
        basix.ElementFamily.P, basix.CellType.quadrilateral, 2, basix.LagrangeVariant.gll_warped
    )
    out = {"q": q, "w": w}
    tab = element.tabulate(1, q)  # (3, 9 points, 9 shape functions, 1)
    out["Nq"], out["dNq"] = tab[0, :, :, 0], np.stack([tab[1, :, :, 0], tab[2, :, :, 0]], -1)
    for k, (r, s) in enumerate(sets):
        pts = _grid(r, s)
        P = np.array([np.outer(_lagrange(s, qs), _lagrange(r, qr)).ravel() for qr, qs in q])
        tab = element.tabulate(1, pts)
        out[f"points{k}"], out[f"P{k}"] = pts, P
        out[f"N{k}"] = tab[0, :, :, 0]
        out[f"dN{k}"] = np.stack([tab[1, :, :, 0], tab[2, :, :, 0]], -1)
    return out


# kernel outputs
ENERGY_MEMBRANE, ENERGY_SHEAR, R_UD, K_UU, K_UD, K_DU, K_DD = range(7)


@numba.njit(cache=True)
def _offsets(P0, P1, P2):
    """Where each strain component's tying values start in the vector e: (e_rr, e_ss,
    e_rs, g_r, g_s); and its length."""
    n0, n1, n2 = P0.shape[1], P1.shape[1], P2.shape[1]
    return np.array([0, n0, n0 + n1, n0 + n1 + n2, 2 * n0 + n1 + n2]), 2 * n0 + 2 * n1 + n2


@numba.njit(cache=True)
def _tying_strains(coords, coef, tabs):
    """The tying strains e, and per tying point (all sets in order, (points, 3)) the current
    tangents x_r, x_s and the director d: what the first and second derivatives of e are
    made of (:func:`_strain_derivatives`, :func:`_add_residual`).

    The strains are formed from the displacement derivatives (e_rr = X_r . u_r + u_r . u_r
    / 2, g_r = X_r . (d - D) + u_r . d), not as differences of the current and reference
    metrics, whose round-off grows with the coordinates' size."""
    off, ne = _offsets(tabs[2][0], tabs[2][1], tabs[2][2])
    e = np.zeros(ne)
    n_points = tabs[3][0].shape[0] + tabs[3][1].shape[0] + tabs[3][2].shape[0]
    xr, xs, dd = np.zeros((n_points, 3)), np.zeros((n_points, 3)), np.zeros((n_points, 3))
    ur, us, Xr, Xs, dp, Dp = (
        np.empty(3),
        np.empty(3),
        np.empty(3),
        np.empty(3),
        np.empty(3),
        np.empty(3),
    )
    start = 0
    for k in range(3):
        N, dN = tabs[3][k], tabs[4][k]
        for p in range(N.shape[0]):
            for c in range(3):
                a_ur = a_us = a_Xr = a_Xs = a_d = a_D = 0.0
                for a in range(9):
                    X, u = coords[3 * a + c], coef[3 * a + c]
                    r, s_ = dN[p, a, 0], dN[p, a, 1]
                    a_ur += r * u
                    a_us += s_ * u
                    a_Xr += r * X
                    a_Xs += s_ * X
                    if k < 2:
                        a_d += N[p, a] * coef[27 + 3 * a + c]
                        a_D += N[p, a] * coef[54 + 3 * a + c]
                ur[c], us[c], Xr[c], Xs[c], dp[c], Dp[c] = a_ur, a_us, a_Xr, a_Xs, a_d, a_D
            i = start + p
            for c in range(3):
                xr[i, c], xs[i, c], dd[i, c] = Xr[c] + ur[c], Xs[c] + us[c], dp[c]
            if k == 2:
                acc = 0.0
                for c in range(3):
                    acc += Xr[c] * us[c] + ur[c] * Xs[c] + ur[c] * us[c]
                e[off[2] + p] = 0.5 * acc
                continue
            uk, Xk = (ur, Xr) if k == 0 else (us, Xs)
            ee = eg = 0.0
            for c in range(3):
                ee += Xk[c] * uk[c] + 0.5 * uk[c] * uk[c]
                eg += Xk[c] * (dp[c] - Dp[c]) + uk[c] * dp[c]
            e[off[k] + p], e[off[3 + k] + p] = ee, eg
        start += N.shape[0]
    return e, xr, xs, dd


@numba.njit(cache=True)
def _add_residual(out, s, xr, xs, dd, tabs):
    """out (54, node by node (u_a, d_a)) += B^T s, B = de/d(u, d), without forming B."""
    off, _ = _offsets(tabs[2][0], tabs[2][1], tabs[2][2])
    start = 0
    for k in range(3):
        N, dN = tabs[3][k], tabs[4][k]
        for p in range(N.shape[0]):
            i = start + p
            if k == 2:
                se = 0.5 * s[off[2] + p]
                for a in range(9):
                    r, q = se * dN[p, a, 0], se * dN[p, a, 1]
                    for c in range(3):
                        out[6 * a + c] += r * xs[i, c] + q * xr[i, c]
                continue
            se, sg = s[off[k] + p], s[off[3 + k] + p]
            x = xr if k == 0 else xs
            for a in range(9):
                r, n_ = dN[p, a, k], N[p, a] * sg
                for c in range(3):
                    out[6 * a + c] += r * (se * x[i, c] + sg * dd[i, c])
                    out[6 * a + 3 + c] += n_ * x[i, c]
        start += N.shape[0]


@numba.njit(cache=True)
def _strain_derivatives(xr, xs, dd, tabs):
    """B = de/d(u, d), (len(e), 54): u_a at columns 3 a + c, d_a at 27 + 3 a + c."""
    off, ne = _offsets(tabs[2][0], tabs[2][1], tabs[2][2])
    B = np.zeros((ne, 54))
    start = 0
    for k in range(3):
        N, dN = tabs[3][k], tabs[4][k]
        for p in range(N.shape[0]):
            i = start + p
            if k == 2:
                for a in range(9):
                    r, q = 0.5 * dN[p, a, 0], 0.5 * dN[p, a, 1]
                    for c in range(3):
                        B[off[2] + p, 3 * a + c] = r * xs[i, c] + q * xr[i, c]
                continue
            x = xr if k == 0 else xs
            row_e, row_g = off[k] + p, off[3 + k] + p
            for a in range(9):
                r, n_ = dN[p, a, k], N[p, a]
                for c in range(3):
                    B[row_e, 3 * a + c] = r * x[i, c]
                    B[row_g, 3 * a + c] = r * dd[i, c]
                    B[row_g, 27 + 3 * a + c] = n_ * x[i, c]
        start += N.shape[0]
    return B


@numba.njit(cache=True)
def _frame(coords, const, dNq, A, T):
    """At one integration point (shape derivatives ``dNq`` (9, 2)): fills A (3, 3), the map
    from the covariant membrane strains (e_rr, e_ss, e_rs) to the lamina ones (E11, E22,
    2 E12), and T (2, 2), T_ia = G^i . e_a, the map of the shear strains; returns the area
    Jacobian."""
    j0, j1 = np.zeros(3), np.zeros(3)
    for a in range(9):
        for c in range(3):
            j0[c] += dNq[a, 0] * coords[3 * a + c]
            j1[c] += dNq[a, 1] * coords[3 * a + c]
    n0 = j0[1] * j1[2] - j0[2] * j1[1]
    n1 = j0[2] * j1[0] - j0[0] * j1[2]
    n2 = j0[0] * j1[1] - j0[1] * j1[0]
    det = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0, n1, n2 = n0 / det, n1 / det, n2 / det
    wn = const[12] * n0 + const[13] * n1 + const[14] * n2
    w0, w1, w2 = const[12] - wn * n0, const[13] - wn * n1, const[14] - wn * n2
    wl = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    a0, a1, a2 = w0 / wl, w1 / wl, w2 / wl  # e1
    b0, b1, b2 = n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0  # e2 = n x e1
    g00 = j0[0] * j0[0] + j0[1] * j0[1] + j0[2] * j0[2]
    g01 = j0[0] * j1[0] + j0[1] * j1[1] + j0[2] * j1[2]
    g11 = j1[0] * j1[0] + j1[1] * j1[1] + j1[2] * j1[2]
    dg = g00 * g11 - g01 * g01
    # T_ia = G^i . e_a with G^0 = (g11 j0 - g01 j1) / dg, G^1 = (g00 j1 - g01 j0) / dg
    j0e1 = j0[0] * a0 + j0[1] * a1 + j0[2] * a2
    j1e1 = j1[0] * a0 + j1[1] * a1 + j1[2] * a2
    j0e2 = j0[0] * b0 + j0[1] * b1 + j0[2] * b2
    j1e2 = j1[0] * b0 + j1[1] * b1 + j1[2] * b2
    t00, t01 = (g11 * j0e1 - g01 * j1e1) / dg, (g11 * j0e2 - g01 * j1e2) / dg
    t10, t11 = (g00 * j1e1 - g01 * j0e1) / dg, (g00 * j1e2 - g01 * j0e2) / dg
    T[0, 0], T[0, 1], T[1, 0], T[1, 1] = t00, t01, t10, t11
    A[0, 0], A[0, 1], A[0, 2] = t00 * t00, t10 * t10, 2.0 * t00 * t10
    A[1, 0], A[1, 1], A[1, 2] = t01 * t01, t11 * t11, 2.0 * t01 * t11
    A[2, 0], A[2, 1], A[2, 2] = 2.0 * t00 * t01, 2.0 * t10 * t11, 2.0 * (t00 * t11 + t10 * t01)
    return det


@numba.njit(cache=True)
def _stiffness(D, A, T, const, scale):
    """Fills D (5, 5), the stiffness on (e_rr, e_ss, e_rs, g_r, g_s) times ``scale``:
    A^T Q A (membrane) and T diag(kG) T^T (shear), Q = const[0:9], kG = const[9:11]."""
    D[:, :] = 0.0
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                for m in range(3):
                    acc += A[k, i] * const[3 * k + m] * A[m, j]
            D[i, j] = scale * acc
    for i in range(2):
        for j in range(2):
            D[3 + i, 3 + j] = scale * (const[9] * T[i, 0] * T[j, 0] + const[10] * T[i, 1] * T[j, 1])


@numba.njit(cache=True)
def _cell_stiffness(coords, const, tabs):
    """The stiffness of every integration point of every cell, (cells, 81): per point the
    upper triangles of its membrane block (D00, D01, D02, D11, D12, D22) and shear block
    (D33, D34, D44) of :func:`_stiffness`, times weight, area Jacobian and thickness. It
    depends on the reference geometry and the material only, so it is computed once."""
    w, dNq = tabs[0], tabs[1]
    out = np.zeros((coords.shape[0], 81))
    A, T, D = np.empty((3, 3)), np.empty((2, 2)), np.empty((5, 5))
    for cell in range(coords.shape[0]):
        for qp in range(len(w)):
            det = _frame(coords[cell], const, dNq[qp], A, T)
            _stiffness(D, A, T, const, w[qp] * det * const[11])
            o = 9 * qp
            out[cell, o : o + 3] = D[0, 0:3]
            out[cell, o + 3 : o + 5] = D[1, 1:3]
            out[cell, o + 5] = D[2, 2]
            out[cell, o + 6 : o + 8] = D[3, 3:5]
            out[cell, o + 8] = D[4, 4]
    return out


@numba.njit(cache=True)
def _cell_frames(coords, const, tabs):
    """Per integration point of every cell, (cells, points, 10): the map A of :func:`_frame`
    (row by row) and the weight times the area Jacobian. Geometry only, computed once."""
    w, dNq = tabs[0], tabs[1]
    out = np.zeros((coords.shape[0], dNq.shape[0], 10))
    A, T = np.empty((3, 3)), np.empty((2, 2))
    for cell in range(coords.shape[0]):
        for qp in range(dNq.shape[0]):
            det = _frame(coords[cell], const, dNq[qp], A, T)
            for i in range(3):
                for j in range(3):
                    out[cell, qp, 3 * i + j] = A[i, j]
            out[cell, qp, 9] = w[qp] * det
    return out


@numba.njit(cache=True)
def _lamina_strains(coords, coefs, frames, tabs):
    """Lamina Green strains (E11, E22, E12) of the assumed membrane strains at the
    integration points of every cell: (cells, points, 3). ``coords`` (cells, 27), ``coefs``
    (cells, >= 81), ``frames`` of :func:`_cell_frames`."""
    Ps = tabs[2]
    off, _ = _offsets(Ps[0], Ps[1], Ps[2])
    out = np.zeros((coords.shape[0], frames.shape[1], 3))
    E = np.zeros(3)
    for cell in range(coords.shape[0]):
        e = _tying_strains(coords[cell], coefs[cell], tabs)[0]
        for qp in range(frames.shape[1]):
            A = frames[cell, qp]
            for c in range(3):
                acc = 0.0
                for i in range(Ps[c].shape[1]):
                    acc += Ps[c][qp, i] * e[off[c] + i]
                E[c] = acc
            for k in range(3):
                out[cell, qp, k] = A[3 * k] * E[0] + A[3 * k + 1] * E[1] + A[3 * k + 2] * E[2]
            out[cell, qp, 2] *= 0.5
    return out


@numba.njit(cache=True)
def _ramp(s):
    """P, p = P', h = P'' of the decrimping ramp (:func:`clothfem.shell.material.yarn_ramp`)."""
    if s <= -1.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 0.5 * s * s + 0.1, s, 1.0
    P = 0.25 * (0.2 + s * (0.75 + s * (1.0 + s * (0.5 - 0.05 * s * s))))
    p = 0.25 * (0.75 + s * (2.0 + s * (1.5 - 0.25 * s * s)))
    return P, p, 0.25 * (2.0 + 3.0 * s - s * s * s)


@numba.njit(cache=True)
def _law(L, const, coef, qp, sig, tan):
    """The material terms on the lamina strains L = (E11, E22, 2 E12) at point ``qp`` (in the
    kernels' order): returns their energy density [J/m^3] and fills their stresses ``sig``
    (d/dL) and diagonal tangents ``tan`` (d2/dL2). Decrimping (const[17:23]: dE, et, w per
    yarn), Dahl friction (const[23:27]: k, S per yarn; history (E_n, s_n) at
    coef[const[32]]) and viscosity (const[27:30] on E11, E22, E12, const[30] = 1 / h;
    history E_n at coef[const[33]]). The histories are in the rule's point order: point
    (r_i, s_j) of the kernels is its point 3 i + j."""
    sig[:], tan[:] = 0.0, 0.0
    phi = 0.0
    f = 3 * (qp % 3) + qp // 3  # this point in the history's (Quadrature function's) order
    for i in range(2):
        dE, et, w = const[17 + 3 * i], const[18 + 3 * i], const[19 + 3 * i]
        if dE > 0.0:
            P, p, h = _ramp((L[i] - et) / w)
            phi += dE * w * w * P
            sig[i] += dE * w * p
            tan[i] += dE * h
    o = int(const[32])
    if o >= 0:
        for i in range(2):
            k, S = const[23 + 2 * i], const[24 + 2 * i]
            d, sn = L[i] - coef[o + 4 * f + i], coef[o + 4 * f + 2 + i]
            g = 1.0 if d >= 0.0 else -1.0
            q = math.exp(-k * g * d / S)
            phi += S * g * d + (g * sn - S) * (S / k) * (1.0 - q) + sn * sn / (2.0 * k)
            sig[i] += g * S + (sn - g * S) * q
            tan[i] += k * q * (1.0 - g * sn / S)
    o = int(const[33])
    if o >= 0 and const[30] > 0.0:
        for j in range(3):
            c = const[30] * const[27 + j]
            d = (L[j] if j < 2 else 0.5 * L[2]) - coef[o + 3 * f + j]
            phi += 0.5 * c * d * d
            sig[j] += c * d if j < 2 else 0.5 * c * d
            tan[j] += c if j < 2 else 0.25 * c
    return phi


@numba.njit(cache=True)
def _geometric(K, s, tabs):
    """K (54 x 54, the columns of :func:`_strain_derivatives`) += sum_k s_k d2 e_k / d(u,
    d)^2: node matrices (9 x 9) of the u-u and u-d terms (e is linear in d), times the
    identity in the three components."""
    off, _ = _offsets(tabs[2][0], tabs[2][1], tabs[2][2])
    Guu, Gud = np.zeros((9, 9)), np.zeros((9, 9))
    for k in range(3):
        N, dN = tabs[3][k], tabs[4][k]
        for p in range(N.shape[0]):
            se = s[off[k] + p] * (0.5 if k == 2 else 1.0)
            sg = s[off[3 + k] + p] if k < 2 else 0.0
            for a in range(9):
                for b in range(9):
                    if k == 2:
                        Guu[a, b] += se * (dN[p, a, 0] * dN[p, b, 1] + dN[p, a, 1] * dN[p, b, 0])
                    else:
                        Guu[a, b] += se * dN[p, a, k] * dN[p, b, k]
                        Gud[a, b] += sg * dN[p, a, k] * N[p, b]
    for a in range(9):
        for b in range(9):
            for c in range(3):
                K[3 * a + c, 3 * b + c] += Guu[a, b]
                K[3 * a + c, 27 + 3 * b + c] += Gud[a, b]
                K[27 + 3 * b + c, 3 * a + c] += Gud[a, b]


@numba.njit(cache=True)
def _cell(out, coef, const, coords, mode, tabs, strains):
    """One output of a cell (``mode``): its membrane or shear energy or the residual (u_a,
    d_a node by node), added to ``out``, or for any Jacobian mode the whole 54 x 54 matrix,
    written to ``out`` (:func:`_jacobian`). ``tabs``: (w, dNq, (P0, P1, P2), (N0, N1, N2),
    (dN0, dN1, dN2)) of :func:`tying_tables`. With material terms and ``strains`` of 27
    values, the lamina strains (E11, E22, E12) of every point are written there too (as
    :func:`_lamina_strains` computes them)."""
    w, Ps = tabs[0], tabs[2]
    sets = (0, 1, 2, 0, 1)  # the tying set of each component (e_rr, e_ss, e_rs, g_r, g_s)
    off, ne = _offsets(Ps[0], Ps[1], Ps[2])
    e, xr, xs, dd = _tying_strains(coords, coef, tabs)
    s = np.zeros(ne)
    DD = np.zeros((ne, ne)) if mode >= K_UU else np.zeros((1, 1))
    D = np.zeros((5, 5))  # the membrane-shear coupling stays 0
    E, S = np.empty(5), np.empty(5)
    law = const[31] != 0.0
    A, L, sig, tan = np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(3)
    energy = 0.0
    for qp in range(len(w)):
        o = 81 + 9 * qp  # this point's stiffness (_cell_stiffness)
        D[0, 0], D[0, 1], D[0, 2] = coef[o], coef[o + 1], coef[o + 2]
        D[1, 1], D[1, 2], D[2, 2] = coef[o + 3], coef[o + 4], coef[o + 5]
        D[3, 3], D[3, 4], D[4, 4] = coef[o + 6], coef[o + 7], coef[o + 8]
        D[1, 0], D[2, 0], D[2, 1], D[4, 3] = D[0, 1], D[0, 2], D[1, 2], D[3, 4]
        for c in range(5):
            Pc = Ps[sets[c]]
            acc = 0.0
            for i in range(Pc.shape[1]):
                acc += Pc[qp, i] * e[off[c] + i]
            E[c] = acc
        for i in range(5):
            acc = 0.0
            for j in range(5):
                acc += D[i, j] * E[j]
            S[i] = acc
        if mode == ENERGY_MEMBRANE:  # D is block diagonal: membrane | shear
            energy += 0.5 * (E[0] * S[0] + E[1] * S[1] + E[2] * S[2])
        elif mode == ENERGY_SHEAR:
            energy += 0.5 * (E[3] * S[3] + E[4] * S[4])
        if law:  # the material terms on the lamina strains L = A E
            o = 162 + 10 * qp  # this point's A and weight x area Jacobian (_cell_frames)
            for i in range(3):
                for j in range(3):
                    A[i, j] = coef[o + 3 * i + j]
            scale = coef[o + 9] * const[11]
            for i in range(3):
                L[i] = A[i, 0] * E[0] + A[i, 1] * E[1] + A[i, 2] * E[2]
            if strains.size == 27:
                strains[3 * qp], strains[3 * qp + 1] = L[0], L[1]
                strains[3 * qp + 2] = L[2] * 0.5
            phi = _law(L, const, coef, qp, sig, tan)
            if mode == ENERGY_MEMBRANE:
                energy += scale * phi
            for i in range(3):
                for k in range(3):
                    S[i] += scale * A[k, i] * sig[k]
            if mode >= K_UU:  # the tangent only for the Jacobian blocks
                for i in range(3):
                    for j in range(3):
                        for k in range(3):
                            D[i, j] += scale * A[k, i] * tan[k] * A[k, j]
        for c in range(5):
            Pc = Ps[sets[c]]
            for i in range(Pc.shape[1]):
                s[off[c] + i] += Pc[qp, i] * S[c]
        if mode >= K_UU:
            for c1 in range(5):
                for c2 in range(5):
                    if D[c1, c2] == 0.0:
                        continue
                    r1, r2 = Ps[sets[c1]][qp], Ps[sets[c2]][qp]
                    for i in range(r1.shape[0]):
                        for j in range(r2.shape[0]):
                            DD[off[c1] + i, off[c2] + j] += D[c1, c2] * r1[i] * r2[j]
    if mode <= ENERGY_SHEAR:
        out[0] += energy
    elif mode == R_UD:
        _add_residual(out, s, xr, xs, dd, tabs)
    else:
        _jacobian(out.reshape(54, 54), s, DD, xr, xs, dd, tabs)


@numba.njit(cache=True)
def _jacobian(K, s, DD, xr, xs, dd, tabs):
    """Writes the cell's Jacobian to K (54 x 54, the columns of :func:`_strain_derivatives`
    in rows and columns): B^T DD B plus the geometric terms. DD is block diagonal (membrane
    rows, then shear rows) and the membrane rows of B have no d columns."""
    B = _strain_derivatives(xr, xs, dd, tabs)
    m = _offsets(tabs[2][0], tabs[2][1], tabs[2][2])[0][3]
    Bm, Bs = np.ascontiguousarray(B[:m, :27]), np.ascontiguousarray(B[m:])
    K[:, :] = Bs.T @ (np.ascontiguousarray(DD[m:, m:]) @ Bs)
    K[:27, :27] += Bm.T @ (np.ascontiguousarray(DD[:m, :m]) @ Bm)
    _geometric(K, s, tabs)


_SIGNATURE = numba.types.void(
    numba.types.CPointer(numba.types.double),
    numba.types.CPointer(numba.types.double),
    numba.types.CPointer(numba.types.double),
    numba.types.CPointer(numba.types.double),
    numba.types.CPointer(numba.types.int32),
    numba.types.CPointer(numba.types.uint8),
)


def _tables_tuple(tying: str) -> tuple:
    """:func:`tying_tables` as the kernels take them: (w, dNq, (P0, P1, P2), (N0, N1, N2),
    (dN0, dN1, dN2))."""
    tab = tying_tables(tying)
    return (tab["w"], tab["dNq"]) + tuple(
        tuple(np.ascontiguousarray(tab[f"{name}{k}"]) for k in range(3))
        for name in ("P", "N", "dN")
    )


# the two tying schemes, compiled into the one kernel below as constants
_TABS = {"mitc9": _tables_tuple("mitc9"), "full": _tables_tuple("full")}
_TABS_MITC9, _TABS_FULL = _TABS["mitc9"], _TABS["full"]
#: Position of the kernel's output mode and tying scheme (0: mitc9, 1: full) in its
#: constants, after the model's 15 (Q, kG, t, warp); then the material terms of
#: :func:`_law` (decrimping 6, friction 4, viscosity 3 and 1 / h) and the layout: LAW (1 if
#: any term), the offsets of the friction and viscosity histories among the coefficients
#: (-1: none), CELL the offset of the local cell number (the last coefficient), CACHE the
#: address of the Jacobian cache (:attr:`MitcForms.K`; an address is below 2^53, exact) and
#: STRAINS the address where the residual writes the lamina strains of every cell's points
#: for the histories' commit (0: nowhere; :meth:`MitcForms.history_strains`).
MODE, TYING, LAW, CELL, CACHE, STRAINS = 15, 16, 31, 34, 35, 36
N_CONST = 37
#: The coefficients: u, d, D (27 each), the point stiffness (81); with material terms the
#: point frames (10 a point, :func:`_cell_frames`), the friction history (4 a point) and the
#: viscosity history (3 a point) where present; the local cell number.
N_COEF = 162 + 90 + 36 + 27 + 1


@intrinsic
def _pointer(typingctx, address):
    """The float64 pointer of an integer address."""
    sig = numba.types.CPointer(numba.types.float64)(numba.types.int64)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@numba.njit(cache=True)
def _cache_entry(coef, const, coords):
    """The cell's Jacobian in the cache (54 x 54 flat, :func:`_jacobian`) and whether it is
    that of the kernel's inputs. A cell's entry is its key, the inputs (coefficients,
    constants but the mode, coordinates), then the Jacobian; a key that differs in any bit
    is replaced by the inputs', for the Jacobian to be recomputed."""
    n = int(const[CELL]) + 1
    key = np.concatenate((coef[:n], const, coords))
    key[n + MODE] = 0.0
    address = int(const[CACHE]) + 8 * (key.size + 54 * 54) * int(coef[n - 1])
    old = numba.carray(_pointer(address), (key.size,))
    K = numba.carray(_pointer(address + 8 * key.size), (54 * 54,))
    if np.array_equal(old.view(np.int64), key.view(np.int64)):
        return K, True
    old[:] = key
    return K, False


@numba.njit(cache=True)
def _compute(out, coef, const, coords, mode, strains):
    """:func:`_cell` with the tables of the form's tying scheme."""
    if const[TYING] == 0.0:
        _cell(out, coef, const, coords, mode, _TABS_MITC9, strains)
    else:
        _cell(out, coef, const, coords, mode, _TABS_FULL, strains)


@numba.cfunc(_SIGNATURE, nopython=True, cache=True)
def _kernel(A_, w_, c_, coords_, local_index, permutation):
    """The dolfinx cell kernel of every output of :func:`_cell`: the output (``mode``) and
    the tying scheme come in the form's constants, so one compiled function (cached on
    disk) serves all forms. ``A_`` is viewed at the largest element tensor's size; each
    output writes only its own entries. A Jacobian block is copied from the cell's whole
    Jacobian in the cache, computed when the kernel's inputs changed."""
    const = numba.carray(c_, (N_CONST,))
    out = numba.carray(A_, (27 * 27,))
    coef = numba.carray(w_, (N_COEF,))
    coords = numba.carray(coords_, (27,))
    mode = int(const[MODE])
    none = np.empty(0)
    if mode == R_UD and const[STRAINS] != 0.0:
        cell = int(coef[int(const[CELL])])
        strains = numba.carray(_pointer(int(const[STRAINS]) + 8 * 27 * cell), (27,))
        _compute(out, coef, const, coords, mode, strains)
        return
    if mode < K_UU:
        _compute(out, coef, const, coords, mode, none)
        return
    K, cached = _cache_entry(coef, const, coords)
    if not cached:
        _compute(K, coef, const, coords, mode, none)
    first = 54 * 27 * ((mode - K_UU) // 2) + 27 * ((mode - K_UU) % 2)  # the block's K[0, 0]
    for i in range(27):
        out[27 * i : 27 * i + 27] += K[first + 54 * i : first + 54 * i + 27]


class MitcForms:
    """The compiled MITC9 membrane + shear forms of a 9-node shell (dolfinx cpp Forms with
    numba kernels): ``energy`` (membrane, shear), the residual ``R`` on ``V6`` (the Q2
    space with six components per node: (R_u, R_d) of each node, in V's node order) and
    Jacobian blocks ``K`` = [[K_uu, K_ud], [K_du, K_dd]], in the layout of the UFL forms of
    :class:`~clothfem.shell.model.ShellModel` (u and d in the same vector space V).

    V: the (u, d) space (9-node quadrilaterals, degree 2); u, d, D: displacement, current
    and reference directors; Q, kG, t, warp: the model's constants (plane-stress stiffness
    3x3 [Pa], (k G13, k G23) [Pa], thickness [m], warp direction). The stiffness of every
    integration point (``stiffness``, a DG0 field of 81 values per cell) is computed here
    from the reference geometry and these constants' values: later changes of the
    constants do not reach the kernels. The material terms, where the material has them:
    ``yarn`` the decrimping constants (2 x 3, :meth:`DecrimpingFabric.yarn_parameters`),
    ``friction`` a :class:`~clothfem.shell.hysteresis.YarnFriction` and ``viscosity`` a
    :class:`~clothfem.shell.viscosity.MembraneViscosity`, both with their history on the
    rule of degree 4 (the 3 x 3 points); their constants (e.g. the viscosity's 1 / h) are
    read at every assembly. The Jacobian forms use a cache of this object (:attr:`K`): it
    must outlive their use.
    """

    def __init__(
        self,
        V: fem.FunctionSpace,
        *,
        u,
        d,
        D,
        Q,
        kG,
        t,
        warp,
        tying: str = "mitc9",
        yarn: fem.Constant | None = None,
        friction=None,
        viscosity=None,
    ):
        mesh = V.mesh
        if mesh.topology.cell_type.name != "quadrilateral" or V.ufl_element().degree() != 2:
            raise ValueError("the MITC9 element needs 9-node quadrilaterals (degree 2)")
        if mesh.geometry.cmap.degree != 2:
            raise ValueError("the MITC9 element needs a second-order (9-node) mesh geometry")
        if tying not in _TABS:
            raise ValueError(f"tying must be 'mitc9' or 'full', got {tying!r}")
        self._tabs, self._mesh = _TABS[tying], mesh
        const = np.concatenate([np.ravel(c.value) for c in (Q, kG, t, warp)])
        n_cells = len(mesh.geometry.dofmap.offsets) - 1  # owned and ghost cells
        W = fem.VectorFunctionSpace(mesh, ("DG", 0), dim=81)
        self.stiffness = fem.Function(W, name="mitc_stiffness")
        coords = self._coords(n_cells)
        dofs = W.dofmap.list.array.reshape(-1)[:n_cells]
        self.stiffness.x.array.reshape(-1, 81)[dofs] = _cell_stiffness(coords, const, self._tabs)
        self._frames = _cell_frames(coords, const, self._tabs)  # local cells, owned first
        n_owned = mesh.topology.index_map(2).size_local
        self._owned_coords = np.ascontiguousarray(coords[:n_owned])  # for lamina_strains
        coefficients = [u, d, D, self.stiffness]
        law, layout = self._law_constants(mesh, yarn, friction, viscosity)
        if layout.value[0]:  # the point frames, for the material terms
            F = fem.VectorFunctionSpace(mesh, ("DG", 0), dim=90)
            self.frames = fem.Function(F, name="mitc_frames")
            self.frames.x.array.reshape(-1, 90)[dofs] = self._frames.reshape(n_cells, 90)
            coefficients.append(self.frames)
        for history, dim in ((friction, 4), (viscosity, 3)):
            if history is not None:
                if history.history.x.array.size != dim * 9 * n_cells:
                    raise ValueError("the MITC9 material history needs the 3 x 3 points a cell")
                coefficients.append(history.history)
        cell = fem.Function(fem.FunctionSpace(mesh, ("DG", 0)), name="mitc_cell")
        cell_dofs = cell.function_space.dofmap.list.array[:n_cells]
        cell.x.array[cell_dofs] = np.arange(n_cells)  # the kernels' index into the cache
        coefficients.append(cell)
        coeffs = [f._cpp_object for f in coefficients]
        consts = [c._cpp_object for c in (Q, kG, t, warp)]
        scheme = fem.Constant(mesh, float(list(_TABS).index(tying)))
        self._constants = [scheme, *law, layout]  # kept alive with the forms
        self._layout, self._n_cells, self._cache = layout, n_cells, None
        self._strains = None  # the residual's lamina strains, (cells, 27), for the histories
        if friction is not None or viscosity is not None:
            self._strains = np.full((n_cells, 27), np.nan)
            values = layout.value.copy()
            values[STRAINS - LAW] = self._strains.ctypes.data
            layout.value = values

        def form(mode: int, spaces: list):
            self._constants.append(fem.Constant(mesh, float(mode)))
            tail = [self._constants[-1]._cpp_object, scheme._cpp_object]
            tail += [c._cpp_object for c in (*law, layout)]
            integrals = {_cpp.fem.IntegralType.cell: ([(-1, _kernel.address)], None)}
            cpp_spaces = [s._cpp_object for s in spaces]
            return _cpp.fem.Form_float64(
                cpp_spaces, integrals, coeffs, consts + tail, False, mesh._mesh
            )

        self.energy = {"membrane": form(ENERGY_MEMBRANE, []), "shear": form(ENERGY_SHEAR, [])}
        # the residual node by node, (u_a, d_a): one kernel call per cell
        self.V6 = fem.VectorFunctionSpace(mesh, (V.ufl_element().family(), 2), dim=6)
        self.R = form(R_UD, [self.V6])
        self._K = [
            [form(K_UU, [V, V]), form(K_UD, [V, V])],
            [form(K_DU, [V, V]), form(K_DD, [V, V])],
        ]

    @property
    def K(self) -> list[list]:
        """The Jacobian blocks [[K_uu, K_ud], [K_du, K_dd]]. Their kernel computes a cell's
        whole Jacobian (54 x 54) and keeps it, with its inputs, in a cache allocated here at
        the first use (cells x (inputs + 54 x 54) values): a block assembled after another
        at the same state (e.g. by ``assemble_matrix_block``) is a copy."""
        if self._cache is None:
            n_key = int(self._layout.value[CELL - LAW]) + 1 + N_CONST + 27
            self._cache = np.full((self._n_cells, n_key + 54 * 54), np.nan)
            layout = self._layout.value.copy()
            layout[CACHE - LAW] = self._cache.ctypes.data
            self._layout.value = layout
        return self._K

    @staticmethod
    def _law_constants(mesh, yarn, friction, viscosity) -> tuple[list, fem.Constant]:
        """The constants of :func:`_law` (zeros for an absent term) and the layout
        (LAW, friction offset, viscosity offset, cell number offset, cache address 0,
        strains address 0)."""
        law = [
            yarn if yarn is not None else fem.Constant(mesh, np.zeros((2, 3))),
            friction.k if friction is not None else fem.Constant(mesh, np.zeros((2, 2))),
            viscosity.eta if viscosity is not None else fem.Constant(mesh, np.zeros(3)),
            viscosity.inv_h if viscosity is not None else fem.Constant(mesh, 0.0),
        ]
        any_law = any(x is not None for x in (yarn, friction, viscosity))
        offset, layout = 162 + 90 * any_law, [float(any_law)]
        for history, dim in ((friction, 4), (viscosity, 3)):
            layout.append(float(offset) if history is not None else -1.0)
            offset += 9 * dim if history is not None else 0
        return law, fem.Constant(mesh, np.array([*layout, float(offset), 0.0, 0.0]))

    def _coords(self, n_cells: int) -> np.ndarray:
        """The node coordinates of the first ``n_cells`` local cells, (n_cells, 27)."""
        geo = self._mesh.geometry
        nodes = geo.dofmap.array.reshape(-1, 9)[:n_cells]
        return np.ascontiguousarray(geo.x[nodes].reshape(n_cells, 27))

    def lamina_strains(self) -> np.ndarray:
        """(E11, E22, E12) of the assumed membrane strains at the 3 x 3 points of every
        owned cell, (cells, 9, 3), at the current state (no collective call); points in the
        kernels' order (r fastest)."""
        form = self.energy["membrane"]
        coefs = _cpp.fem.pack_coefficients(form)[(_cpp.fem.IntegralType.cell, -1)]
        n_cells = len(self._owned_coords)
        coefs = np.ascontiguousarray(coefs[:n_cells])
        return _lamina_strains(self._owned_coords, coefs, self._frames[:n_cells], self._tabs)

    def yarn_strains(self) -> np.ndarray:
        """(E11, E22) of :meth:`lamina_strains`, (cells, 9, 2)."""
        return self.lamina_strains()[:, :, :2]

    def history_strains(self, components: int, *, at_residual: bool = False) -> np.ndarray:
        """The first ``components`` of :meth:`lamina_strains` in the point order of the
        histories (the Quadrature functions of the rule of degree 4: point (r_i, s_j) is
        3 i + j), (owned cells, 9, components). ``at_residual``: the state is the one of
        the last residual assembly, whose kernels wrote these strains (the same operations:
        the same values), so they are read instead of evaluated again (a model with
        material histories only)."""
        n = len(self._owned_coords)
        if at_residual and self._strains is not None:
            e = self._strains[:n].reshape(n, 9, 3)[:, :, :components]
        else:
            e = self.lamina_strains()[:, :, :components]
        return np.ascontiguousarray(e.reshape(-1, 3, 3, components).transpose(0, 2, 1, 3)).reshape(
            -1, 9, components
        )
