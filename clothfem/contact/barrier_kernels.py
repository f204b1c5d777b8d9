"""Compiled per-pair loops of the self-contact barrier (:mod:`.self_barrier`): the pairs'
12 x 12 Hessians and their sum into the barrier's matrix.

Each loop runs over the pairs (M of them) and writes into arrays the caller allocates; numba
(Debian's python3-numba, as :mod:`clothfem.shell.mitc`) compiles them on first use and
caches the machine code. The mathematics is that of :mod:`.self_barrier`'s docstring; the
tests check every Hessian against finite differences of its gradient.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["add_blocks", "distance_hessians", "friction_hessians"]


@numba.njit(cache=True)
def distance_hessians(y, coef, free, a, b, out):  # pragma: no cover - compiled
    """``out[m] = a[m] hess s + b[m] grad s grad s^T`` (M, 12, 12) of the pair distances
    ``s = |sum_j c_j y_j|`` of the node positions ``y`` (M, 4, 3) [m], coefficients ``coef``
    (M, 4), the closest point moving along ``free`` (M, 4, 2) (the envelope theorem:
    ``hess phi = c c^T (x) I - F W^-1 F^T`` for ``phi = s^2 / 2``, then ``hess s = hess phi
    / s - grad phi grad phi^T / s^3``)."""
    XA = np.empty((3, 2))
    F = np.empty((12, 2))
    G = np.empty((12, 2))
    gp = np.empty(12)
    for m in range(y.shape[0]):
        r = np.zeros(3)
        for j in range(4):
            for k in range(3):
                r[k] += coef[m, j] * y[m, j, k]
        s = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        for k in range(3):
            for la in range(2):
                acc = 0.0
                for j in range(4):
                    acc += y[m, j, k] * free[m, j, la]
                XA[k, la] = acc
        w00 = XA[0, 0] * XA[0, 0] + XA[1, 0] * XA[1, 0] + XA[2, 0] * XA[2, 0]
        w01 = XA[0, 0] * XA[0, 1] + XA[1, 0] * XA[1, 1] + XA[2, 0] * XA[2, 1]
        w11 = XA[0, 1] * XA[0, 1] + XA[1, 1] * XA[1, 1] + XA[2, 1] * XA[2, 1]
        for la in range(2):  # a direction no node uses: W = 1 there (its F column is 0)
            used = False
            for j in range(4):
                used = used or free[m, j, la] != 0.0
            if not used:
                if la == 0:
                    w00 += 1.0
                else:
                    w11 += 1.0
        det = w00 * w11 - w01 * w01
        i00, i01, i11 = w11 / det, -w01 / det, w00 / det
        for j in range(4):
            for k in range(3):
                q = 3 * j + k
                F[q, 0] = free[m, j, 0] * r[k] + coef[m, j] * XA[k, 0]
                F[q, 1] = free[m, j, 1] * r[k] + coef[m, j] * XA[k, 1]
                G[q, 0] = F[q, 0] * i00 + F[q, 1] * i01
                G[q, 1] = F[q, 0] * i01 + F[q, 1] * i11
                gp[q] = coef[m, j] * r[k]
        s3 = s * s * s
        for p in range(12):
            for q in range(12):
                h = -(G[p, 0] * F[q, 0] + G[p, 1] * F[q, 1])
                if p % 3 == q % 3:
                    h += coef[m, p // 3] * coef[m, q // 3]
                hs = h / s - gp[p] * gp[q] / s3
                out[m, p, q] = a[m] * hs + b[m] * (gp[p] / s) * (gp[q] / s)


@numba.njit(cache=True)
def friction_hessians(coef, basis, u, f1y, cuu, k, out):  # pragma: no cover - compiled
    """``out[m] = k c c^T (x) T A T^T`` (M, 12, 12) of the layer friction's pairs: ``A =
    f1y I + cuu u u^T`` (2 x 2) from the slips ``u`` (M, 2) [m], the tangent bases ``T =
    basis`` (M, 3, 2), coefficients ``coef`` (M, 4) and factors ``k`` (M,)."""
    B = np.empty((3, 3))
    for m in range(coef.shape[0]):
        a00 = f1y[m] + cuu[m] * u[m, 0] * u[m, 0]
        a01 = cuu[m] * u[m, 0] * u[m, 1]
        a11 = f1y[m] + cuu[m] * u[m, 1] * u[m, 1]
        for r in range(3):
            t0, t1 = basis[m, r, 0], basis[m, r, 1]
            for c in range(3):
                s0, s1 = basis[m, c, 0], basis[m, c, 1]
                B[r, c] = t0 * (a00 * s0 + a01 * s1) + t1 * (a01 * s0 + a11 * s1)
        for i in range(4):
            for j in range(4):
                w = k[m] * coef[m, i] * coef[m, j]
                for r in range(3):
                    for c in range(3):
                        out[m, 3 * i + r, 3 * j + c] = w * B[r, c]


@numba.njit(cache=True)
def _find(indices, lo, hi, col):  # pragma: no cover - compiled
    """Position of ``col`` in the sorted ``indices[lo:hi]``, or -1."""
    end = hi
    while lo < hi:
        mid = (lo + hi) // 2
        if indices[mid] < col:
            lo = mid + 1
        else:
            hi = mid
    if lo < end and indices[lo] == col:
        return lo
    return -1


@numba.njit(cache=True)
def add_blocks(hess, node, lo, n, row0, indptr, indices, data):  # pragma: no cover - compiled
    """Add the rows of the pairs' Hessians ``hess`` (M, 12, 12) that belong to this rank's
    nodes ``lo .. lo + n - 1`` (of the node groups ``node`` (M, 4)) into the values ``data``
    of a CSR pattern (``indptr``, ``indices``: local rows, global columns) whose node ``i``
    has the columns ``row0[i] + (0, 1, 2)``, in the pairs' order (row node, component, column
    node, component). Returns False, leaving ``data`` part-summed, if the pattern misses a
    block."""
    for m in range(hess.shape[0]):
        for a in range(4):
            na = node[m, a]
            if na < lo or na >= lo + n:
                continue
            for r in range(3):
                row = 3 * (na - lo) + r
                for b in range(4):
                    col = row0[node[m, b]]
                    at = _find(indices, indptr[row], indptr[row + 1], col)
                    if at < 0 or at + 2 >= indptr[row + 1] or indices[at + 2] != col + 2:
                        return False
                    for c in range(3):
                        data[at + c] += hess[m, 3 * a + r, 3 * b + c]
    return True
