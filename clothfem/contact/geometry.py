"""Gaps, closest points and normals of fabric nodes against rigid ellipsoids (pure NumPy).

Stage 1-2 of the contact pipeline (detect candidates -> gaps and normals -> multipliers and
forces -> friction -> diagnostics).  Nothing here imports the FEM layer.

Ellipsoid data
--------------
An ellipsoid is the plain triple ``(c, Q, r)``:

* ``c`` (3,) centre in m,
* ``Q`` (3, 3) orthonormal matrix whose **columns** are the unit axes ``e1, e2, e3``, so the local
  coordinates of a point ``x`` are ``y = Q.T @ (x - c)`` (row-wise: ``y = (x - c) @ Q``),
* ``r`` (3,) radii in m along ``e1, e2, e3``, all finite and > 0.

A body (union of ellipsoids) is a sequence of such triples.  (``clothfem.body.Ellipsoid`` stores the
axes as rows; its triple is ``(e.centre, e.axes.T, e.radii)``.)

Sign convention (used everywhere in ``clothfem.contact``)
---------------------------------------------------------
``gap = (x - p) . n`` where ``p`` is the exact closest point of the surface and ``n`` the
**outward** unit normal at ``p``.  Since ``x - p`` is parallel to ``n``, ``gap`` is the signed
distance in m:

* ``gap > 0``  the node is outside (admissible, separated),
* ``gap = 0``  on the surface,
* ``gap < 0``  penetration, by ``-gap`` m.

The paper's Eq. 15 writes ``g = -(x_s - x_m) . n <= 0`` for admissible states, i.e. its ``g`` is
``-gap`` (its Eqs. 17-18 then treat ``g > 0`` as penetration).  We use ``gap`` so that the
Kuhn-Tucker conditions read ``gap >= 0, lambda_N >= 0, lambda_N * gap = 0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "EllipsoidData",
    "Projection",
    "UnionProjection",
    "candidates",
    "check_ellipsoid",
    "check_points",
    "closest_point_ellipsoid",
    "closest_point_union",
    "closest_points",
    "gap_lower_bound",
    "gradient_projection",
    "implicit_value",
    "radial_projection",
]

FloatArray = NDArray[np.float64]
EllipsoidData = tuple[ArrayLike, ArrayLike, ArrayLike]
"""``(c, Q, r)``: centre (3,) m, axes as columns (3, 3), radii (3,) m."""

_ORTHO_TOL = 1e-8
# local coordinates below this fraction of the largest radius are treated as exactly zero
# (avoids underflow of (r_i y_i)^2 in the root function)
_TINY = 1e-150


class Projection(NamedTuple):
    """Closest-point projection onto one surface.

    Attributes
    ----------
    point : (N, 3) float array
        Surface point ``p`` in m.
    normal : (N, 3) float array
        Outward unit normal at ``p``.
    gap : (N,) float array
        Signed gap ``(x - p) . n`` in m; ``< 0`` is penetration (see module docstring).
    """

    point: FloatArray
    normal: FloatArray
    gap: FloatArray


class UnionProjection(NamedTuple):
    """Projection onto a union of ellipsoids (see :func:`closest_point_union`).

    Attributes
    ----------
    point, normal, gap :
        As in :class:`Projection`, for the selected ellipsoid.
    body : (N,) int array
        Index of the selected ellipsoid in ``bodies``.
    inside_other : (N,) bool array
        True where ``point`` lies strictly inside another ellipsoid of the union, so it is not
        on the union's boundary (only possible for nodes inside at least one ellipsoid).
    """

    point: FloatArray
    normal: FloatArray
    gap: FloatArray
    body: NDArray[np.intp]
    inside_other: NDArray[np.bool_]


# --------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------
def check_vectors(x: ArrayLike, name: str, n: int | None = None) -> FloatArray:
    """Return ``x`` as a finite (N, 3) float array (N = ``n`` if given) or raise a one-line
    ``ValueError`` naming ``name``."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        want = "(N, 3)" if n is None else f"({n}, 3)"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return a


def check_points(x: ArrayLike, *, name: str = "x") -> FloatArray:
    """Return ``x`` as a finite (N, 3) float array or raise a one-line ``ValueError``."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (positions in m), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (positions in m), got NaN or inf")
    return a


def check_ellipsoid(
    c: ArrayLike, Q: ArrayLike, r: ArrayLike, *, name: str = "ellipsoid"
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validate ``(c, Q, r)`` and return float arrays, or raise a one-line ``ValueError``.

    ``c`` must be finite (3,), ``Q`` (3, 3) with orthonormal columns (``|Q^T Q - I| <= 1e-8``),
    ``r`` finite (3,) with every radius > 0 m.
    """
    c = np.asarray(c, dtype=float)
    Q = np.asarray(Q, dtype=float)
    r = np.asarray(r, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"{name}: c must be a finite (3,) centre in m, got shape {c.shape}")
    if Q.shape != (3, 3) or not np.all(np.isfinite(Q)):
        raise ValueError(f"{name}: Q must be a finite (3, 3) matrix of axes, got {Q.shape}")
    dev = float(np.max(np.abs(Q.T @ Q - np.eye(3))))
    if dev > _ORTHO_TOL:
        raise ValueError(
            f"{name}: Q must have orthonormal columns (max|Q^T Q - I| <= {_ORTHO_TOL:g}), "
            f"got deviation {dev:.3g}"
        )
    if r.shape != (3,) or not np.all(np.isfinite(r)) or np.any(r <= 0.0):
        raise ValueError(f"{name}: r must be three finite radii > 0 m, got {r.tolist()}")
    return c, Q, r


class _CheckedBodies(tuple):
    """Ellipsoids that passed :func:`_check_bodies` (not checked again when passed on), with
    their data stacked: ``c`` (K, 3), ``Q`` (K, 3, 3), ``r`` (K, 3)."""

    c: FloatArray
    Q: FloatArray
    r: FloatArray


def _check_bodies(bodies: Sequence[EllipsoidData]) -> _CheckedBodies:
    if isinstance(bodies, _CheckedBodies):
        return bodies
    try:
        items = list(bodies)
    except TypeError:
        raise ValueError("bodies must be a sequence of (c, Q, r) triples") from None
    if not items:
        raise ValueError("bodies must contain at least one (c, Q, r) triple, got none")
    # fast path: every body checked at once on the stacked arrays (the contact step calls
    # this every time step); any failure is reported by the per-body checks below
    try:
        c = np.array([b[0] for b in items], dtype=float)
        Q = np.array([b[1] for b in items], dtype=float)
        r = np.array([b[2] for b in items], dtype=float)
        k = len(items)
        ok = c.shape == (k, 3) and Q.shape == (k, 3, 3) and r.shape == (k, 3)
        ok = ok and all(len(b) == 3 for b in items)
        ok = ok and bool(np.isfinite(c).all() & np.isfinite(Q).all() & np.isfinite(r).all())
        ok = ok and bool((r > 0.0).all())
        ok = ok and float(np.abs(np.einsum("kji,kjl->kil", Q, Q) - np.eye(3)).max()) <= _ORTHO_TOL
    except (TypeError, ValueError, IndexError):
        ok = False
    if ok:
        out = _CheckedBodies(zip(c, Q, r, strict=True))
    else:
        checked = []
        for k, b in enumerate(items):
            try:
                cb, Qb, rb = b
            except (TypeError, ValueError):
                raise ValueError(f"bodies[{k}] must be a (c, Q, r) triple") from None
            checked.append(check_ellipsoid(cb, Qb, rb, name=f"bodies[{k}]"))
        out = _CheckedBodies(checked)
        c, Q, r = (np.array([e[i] for e in checked]) for i in range(3))
    out.c, out.Q, out.r = c, Q, r
    return out


def _check_tol(tol: float, max_iter: int) -> None:
    if not (np.isfinite(tol) and 0.0 < tol < 1.0):
        raise ValueError(f"tol must be in (0, 1) (relative), got {tol}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter must be an integer >= 1, got {max_iter}")


# --------------------------------------------------------------------------------------------
# Eq. 26 and the cheap approximations
# --------------------------------------------------------------------------------------------
def implicit_value(x: ArrayLike, c: ArrayLike, Q: ArrayLike, r: ArrayLike) -> FloatArray:
    """Implicit function of Eq. 26, ``f(x) = sum_i ((x - c) . e_i)^2 / r_i^2 - 1`` (N,).

    Dimensionless; ``f < 0`` inside (penetration), ``f = 0`` on the surface, ``f > 0`` outside.
    """
    x = check_points(x)
    c, Q, r = check_ellipsoid(c, Q, r)
    return _f_local((x - c) @ Q, r)


def _f_local(y: FloatArray, r: FloatArray) -> FloatArray:
    return np.sum((y / r) ** 2, axis=1) - 1.0


def _finish_local(
    x: FloatArray, y: FloatArray, pl: FloatArray, c: FloatArray, Q: FloatArray, r: FloatArray
) -> Projection:
    """Local surface points ``pl`` -> global point, outward normal (gradient) and gap."""
    nl = pl / r**2
    nl /= np.linalg.norm(nl, axis=1, keepdims=True)
    gap = np.einsum("ij,ij->i", y - pl, nl)
    return Projection(c + pl @ Q.T, nl @ Q.T, gap)


def _radial_local(y: FloatArray, r: FloatArray) -> FloatArray:
    rho = np.sqrt(np.sum((y / r) ** 2, axis=1))
    pl = np.empty_like(y)
    ok = rho > 0.0
    pl[ok] = y[ok] / rho[ok, None]
    # the centre: the closest surface points are the ends of the shortest axis
    k = int(np.argmin(r))
    pl[~ok] = 0.0
    pl[~ok, k] = r[k]
    return pl


def radial_projection(x: ArrayLike, c: ArrayLike, Q: ArrayLike, r: ArrayLike) -> Projection:
    """Approximate projection along the ray from the centre: ``p = c + (x - c)/sqrt(f(x) + 1)``.

    Cheap (no iteration) but not the closest point unless the ellipsoid is a sphere or ``x``
    lies on an axis; ``gap = (x - p) . n`` with ``n`` the true outward normal at ``p``
    (so ``sign(gap) = sign(f(x))`` but ``|gap|`` is not the distance).  The centre maps to the
    end of the shortest axis.
    """
    x = check_points(x)
    c, Q, r = check_ellipsoid(c, Q, r)
    y = (x - c) @ Q
    return _finish_local(x, y, _radial_local(y, r), c, Q, r)


def gradient_projection(x: ArrayLike, c: ArrayLike, Q: ArrayLike, r: ArrayLike) -> Projection:
    """Approximate projection along the gradient line of Eq. 26 (last paragraph of Sec. 3.2).

    ``p = x + a grad f(x)`` with the root ``a`` of the quadratic ``f(x + a grad f) = 0`` of
    smallest ``|a|`` (for points inside, the positive root).  Where the gradient line misses the
    surface (possible for some outside points) or vanishes (the centre), the radial projection
    is used.  ``gap = (x - p) . n`` with ``n`` the outward normal at ``p``; not the distance.
    """
    x = check_points(x)
    c, Q, r = check_ellipsoid(c, Q, r)
    y = (x - c) @ Q
    w = 2.0 * y / r**2
    A = np.sum((w / r) ** 2, axis=1)
    B = 2.0 * np.sum(y * w / r**2, axis=1)
    C = _f_local(y, r)
    disc = B * B - 4.0 * A * C
    ok = (A > 0.0) & (disc >= 0.0)
    pl = _radial_local(y, r)
    if np.any(ok):
        sq = np.sqrt(disc[ok])
        Bk, Ak, Ck = B[ok], A[ok], C[ok]
        # numerically stable roots of A a^2 + B a + C = 0
        qq = -0.5 * (Bk + np.where(Bk >= 0.0, sq, -sq))
        with np.errstate(divide="ignore", invalid="ignore"):
            a1 = np.where(qq != 0.0, Ck / qq, 0.0)
            a2 = np.where(qq != 0.0, qq / Ak, 0.0)
        a = np.where(np.abs(a1) <= np.abs(a2), a1, a2)
        a = np.where(Ck < 0.0, np.maximum(a1, a2), a)  # inside: move outward
        pl[ok] = y[ok] + a[:, None] * w[ok]
    # polish onto the surface (removes round-off of the quadratic)
    pl /= np.sqrt(np.sum((pl / r) ** 2, axis=1))[:, None]
    return _finish_local(x, y, pl, c, Q, r)


# --------------------------------------------------------------------------------------------
# exact closest point (Eberly)
# --------------------------------------------------------------------------------------------
def _closest_positive_octant(z: FloatArray, r: FloatArray, tol: float, max_iter: int) -> FloatArray:
    """Closest surface point of points ``z >= 0`` (N, 3) to ``sum (p_i/r_i)^2 = 1``, each
    point with its own radii ``r`` (N, 3) (scaled so that every row's largest radius is 1).

    Lagrange condition: ``p_i = r_i^2 z_i / (t + r_i^2)``, with ``t`` the largest root of
    ``F(t) = sum_i (r_i z_i / (t + r_i^2))^2 - 1`` -- the one with ``t > -r_min^2``, which is the
    global minimiser for points inside and outside alike (``I + t diag(1/r^2)`` must be PSD).
    We solve in ``s = t + r_min^2 > 0`` with ``delta_i = r_i^2 - r_min^2 >= 0`` so that nothing
    cancels near ``t = -r_min^2``.  ``H(s) = (F + 1)^(-1/2) - 1`` is concave and increasing
    (a power mean of ``s + delta_i`` with exponent -2), so Newton on ``H`` started from the
    lower bracket end converges monotonically; a bisection safeguard is kept anyway.

    If every ``z_i`` on a shortest axis is 0 and ``F(s = 0) <= 0`` there is no root with
    ``s > 0``: then ``s = 0`` and the free shortest-axis coordinate follows from ``f(p) = 0``
    (Eberly's degenerate case; covers the centre, points on long axes, spheres, prolate and
    oblate shapes).

    Every operation is elementwise per point (row), so a point gets the same bits whether it
    is solved alone or batched with points of other ellipsoids.
    """
    rmin = r.min(axis=1)
    delta = (r - rmin[:, None]) * (r + rmin[:, None])
    on_min = delta == 0.0
    a = (r * z) ** 2  # (N, 3)
    p = np.empty_like(z)

    # degenerate case test
    zmin_sum = np.where(on_min, z, 0.0).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        F0 = np.where(on_min, 0.0, a / np.where(on_min, 1.0, delta) ** 2).sum(axis=1) - 1.0
    degen = (zmin_sum == 0.0) & (F0 <= 0.0)
    if np.any(degen):
        off = ~on_min[degen]
        rd = r[degen]
        with np.errstate(divide="ignore", invalid="ignore"):
            pd = np.where(off, rd**2 * z[degen] / np.where(off, delta[degen], 1.0), 0.0)
        kmin = np.argmax(on_min[degen], axis=1)  # the first shortest axis
        pd[np.arange(len(pd)), kmin] = rmin[degen] * np.sqrt(np.maximum(-F0[degen], 0.0))
        p[degen] = pd

    idx = np.flatnonzero(~degen)
    if idx.size:
        az = a[idx]
        dl = delta[idx]
        rz = np.sqrt(az)  # r_i z_i
        norm_rz = np.sqrt(az.sum(axis=1))
        lo = np.maximum.reduce(
            [np.zeros(idx.size), (rz - dl).max(axis=1), norm_rz - dl.max(axis=1)]
        )
        hi = norm_rz.copy()
        s = np.where(lo > 0.0, lo, hi)
        active = np.arange(idx.size)
        for _ in range(int(max_iter)):
            sa = s[active]
            d = sa[:, None] + dl[active]
            q = az[active] / (d * d)
            u = q.sum(axis=1)
            up = (q / d).sum(axis=1)
            la, ha = lo[active], hi[active]
            la = np.where(u > 1.0, sa, la)
            ha = np.where(u < 1.0, sa, ha)
            lo[active], hi[active] = la, ha
            # Newton step on H(s) = u^(-1/2) - 1:  H / H' = u (1 - sqrt(u)) / up
            s_nt = sa - u * (1.0 - np.sqrt(u)) / up
            ok = (s_nt >= la) & (s_nt <= ha)
            s_new = np.where(ok, s_nt, 0.5 * (la + ha))
            done = (ok & (np.abs(s_new - sa) <= tol * s_new)) | (ha - la <= tol * ha)
            s[active] = s_new
            active = active[~done]
            if active.size == 0:
                break
        p[idx] = r[idx] ** 2 * z[idx] / (s[:, None] + dl)
    # polish: put p exactly on the surface (moves p by O(residual) along the ray)
    p /= np.sqrt(np.sum((p / r) ** 2, axis=1))[:, None]
    return p


def closest_point_ellipsoid(
    x: ArrayLike,
    c: ArrayLike,
    Q: ArrayLike,
    r: ArrayLike,
    *,
    tol: float = 1e-13,
    max_iter: int = 100,
) -> Projection:
    """Exact closest point on the ellipsoid surface for points inside and outside.

    Eberly's method ("Distance from a point to an ellipse, an ellipsoid, or a hyperellipsoid"):
    reflect into the positive octant of the local frame, solve the scalar Lagrange equation
    ``sum_i (r_i y_i / (t + r_i^2))^2 = 1`` for its root ``t > -r_min^2`` (``t > 0`` outside,
    ``-r_min^2 < t < 0`` inside; this root is the global minimiser in both cases), set
    ``p_i = r_i^2 y_i / (t + r_i^2)`` and reflect back.  The degenerate case (point on the plane of
    a shortest axis, incl. the centre, axes, spheres, prolate/oblate shapes) is handled in closed
    form.  Vectorised over N; no NaN for finite input.  Where the closest point is not unique
    (centre, medial surface inside) one of the minimisers is returned, preferring ``+e_i``.
    For several ellipsoids at once, :func:`closest_points` gives the same numbers.

    Parameters
    ----------
    x : (N, 3) array
        Slave-node positions in m.
    c, Q, r :
        Ellipsoid centre (3,) m, axes as columns (3, 3), radii (3,) m.
    tol : float, optional
        Relative tolerance of the root ``s = t + r_min^2`` (Newton/bisection stop).
    max_iter : int, optional
        Iteration cap of the safeguarded Newton solver (typically 4-11 are used).

    Returns
    -------
    Projection
        ``point`` p (N, 3) m on the surface (``|f(p)| ~ 1e-16``), outward unit ``normal``
        (N, 3) at p, signed ``gap = (x - p) . n`` (N,) in m: ``< 0`` penetration.
    """
    x = check_points(x)
    c, Q, r = check_ellipsoid(c, Q, r)
    return closest_points([x], [(c, Q, r)], tol=tol, max_iter=max_iter)[0]


def closest_points(
    xs: Sequence[ArrayLike],
    bodies: Sequence[EllipsoidData],
    *,
    tol: float = 1e-13,
    max_iter: int = 100,
) -> list[Projection]:
    """:func:`closest_point_ellipsoid` of the points ``xs[k]`` (N_k, 3) on ellipsoid
    ``bodies[k]`` for every k, with one root solve for all points (the per-call cost of the
    iteration is paid once, not once per ellipsoid). The results are bit for bit those of
    one :func:`closest_point_ellipsoid` call per ellipsoid.

    Parameters
    ----------
    xs : sequence of (N_k, 3) arrays
        Positions in m, one array per ellipsoid (N_k may be 0).
    bodies : sequence of (c, Q, r)
        The ellipsoids, as many as ``xs``.
    tol, max_iter :
        As in :func:`closest_point_ellipsoid`.

    Returns
    -------
    list of Projection
        One per ellipsoid, in the order of ``bodies``.
    """
    ells = _check_bodies(bodies)
    if len(xs) != len(ells):
        raise ValueError(f"xs must hold one point array per body ({len(ells)}), got {len(xs)}")
    _check_tol(tol, max_iter)
    xs = [check_points(x, name=f"xs[{k}]") for k, x in enumerate(xs)]
    ys, zs, rss, signs, scales = [], [], [], [], []
    for x, (c, Q, r) in zip(xs, ells, strict=True):
        y = (x - c) @ Q
        scale = float(r.max())
        ys_ = y / scale
        z = np.abs(ys_)
        z[z < _TINY] = 0.0
        ys.append(y)
        zs.append(z)
        rss.append(np.broadcast_to(r / scale, z.shape))
        signs.append(np.where(ys_ < 0.0, -1.0, 1.0))
        scales.append(scale)
    pz = _closest_positive_octant(np.concatenate(zs), np.concatenate(rss), tol, max_iter)
    out = []
    start = 0
    for x, y, sign, scale, (c, Q, r) in zip(xs, ys, signs, scales, ells, strict=True):
        stop = start + len(y)
        out.append(_finish_local(x, y, sign * pz[start:stop] * scale, c, Q, r))
        start = stop
    return out


# --------------------------------------------------------------------------------------------
# unions and broad phase
# --------------------------------------------------------------------------------------------
def closest_point_union(
    x: ArrayLike,
    bodies: Sequence[EllipsoidData],
    *,
    inside_tol: float = 1e-10,
    tol: float = 1e-13,
    max_iter: int = 100,
) -> UnionProjection:
    """Project points onto a union of (possibly overlapping) ellipsoids.

    Rule: for every point take the ellipsoid with the **smallest signed gap**.  This is one rule
    for both cases: if the point is inside one or more ellipsoids it picks the deepest
    penetration (most negative gap); if it is outside all it picks the closest one, which is
    then the exact distance to the union (its closest point can never lie inside another
    ellipsoid, otherwise the segment to it would cross that one closer).  Ties go to the lower
    index.

    Known limitation: for a point inside an ellipsoid that overlaps another one (e.g. at the
    elbow, where the upper-arm and forearm ellipsoids overlap) the projection onto the chosen
    ellipsoid's surface may lie inside another ellipsoid, so it is not on the union's boundary
    and the node would still penetrate after being moved there.  Such points are flagged in
    ``inside_other`` (``f_j(p) < -inside_tol`` for some ``j`` other than the chosen one) so
    callers can report them or re-project (see :func:`clothfem.contact.explicit.film_step`).

    Parameters
    ----------
    x : (N, 3) array
        Positions in m.
    bodies : sequence of (c, Q, r)
        The ellipsoids (see module docstring).
    inside_tol : float, optional
        Threshold on the dimensionless Eq. 26 value for ``inside_other``.
    tol, max_iter :
        Passed to :func:`closest_points`.

    Returns
    -------
    UnionProjection
        point, normal, gap (m, ``< 0`` penetration), chosen ``body`` index, ``inside_other``.
    """
    x = check_points(x)
    ells = _check_bodies(bodies)
    if not (np.isfinite(inside_tol) and inside_tol >= 0.0):
        raise ValueError(f"inside_tol must be finite and >= 0, got {inside_tol}")
    n, k_all = x.shape[0], len(ells)
    rows = np.arange(n)
    gaps = np.full((n, k_all), np.inf)
    points = np.zeros((n, k_all, 3))
    normals = np.zeros((n, k_all, 3))

    def project(sel: list[NDArray[np.intp]]) -> None:
        projs = closest_points([x[s] for s in sel], ells, tol=tol, max_iter=max_iter)
        for k, (s, pr) in enumerate(zip(sel, projs, strict=True)):
            gaps[s, k], points[s, k], normals[s, k] = pr.gap, pr.point, pr.normal

    if k_all == 1:
        project([rows])
    else:
        # each point first on the ellipsoid of smallest gap lower bound, then on the others
        # only where their bound does not clear that gap (points inside an ellipsoid: always;
        # the bound holds for points outside): the same answer as projecting on every one
        lb = gap_lower_bound(x, ells, per_body=True)
        first = np.argmin(lb, axis=1)
        project([np.flatnonzero(first == k) for k in range(k_all)])
        need = (lb < 0.0) | (lb <= gaps[rows, first][:, None])
        need[rows, first] = False
        if need.any():
            project([np.flatnonzero(need[:, k]) for k in range(k_all)])
    body = np.argmin(gaps, axis=1)  # ties: the lower index
    point, normal, gap = points[rows, body], normals[rows, body], gaps[rows, body]
    inside_other = np.zeros(x.shape[0], dtype=bool)
    if len(ells) > 1:
        for k, (c, Q, r) in enumerate(ells):
            fk = _f_local((point - c) @ Q, r)
            inside_other |= (fk < -inside_tol) & (body != k)
    return UnionProjection(point, normal, gap, body, inside_other)


def gap_lower_bound(
    x: ArrayLike, bodies: Sequence[EllipsoidData], *, per_body: bool = False
) -> FloatArray:
    """Broad phase: ``min_k (s_k - 1) r_min,k`` [m], (N,), a lower bound of the gap to the
    union for points outside it, negative exactly for the points inside an ellipsoid
    (``per_body``: the (N, K) values of each ellipsoid instead of their minimum).

    With ``s^2 = f + 1`` (Eq. 26) the point lies on the surface of the ellipsoid scaled by s;
    for s > 1 that surface keeps a distance ``>= (s - 1) r_min`` from the ellipsoid (the
    ellipsoid grown by a ball of radius ``(s - 1) r_min`` lies inside the scaled one, as its
    support function is ``>= r_min``), so the gap is ``>= (s - 1) r_min``; exact for spheres.
    No iteration: use it to skip the exact projection of points whose bound clears the
    contact distance (every point inside is kept, its value is not its depth).
    """
    x = check_points(x)
    ells = _check_bodies(bodies)
    lb = np.empty((x.shape[0], len(ells)))
    for k, (c, Q, r) in enumerate(ells):
        lb[:, k] = (np.sqrt(_f_local((x - c) @ Q, r) + 1.0) - 1.0) * r.min()
    return lb if per_body else lb.min(axis=1, initial=np.inf)


def candidates(
    x: ArrayLike, bodies: Sequence[EllipsoidData], margin: float
) -> list[NDArray[np.intp]]:
    """Broad phase: indices of the points near each ellipsoid's oriented bounding box.

    Point ``i`` is a candidate of ellipsoid ``k`` if ``|y_j| <= r_j + margin`` for all local
    coordinates ``y = Q^T (x - c)``, i.e. it lies in the box of half-widths ``r + margin``.
    Conservative: every point whose gap to ellipsoid ``k`` is ``<= margin`` is included
    (penetrating points too); some farther points (box corners) may be included as well.

    Parameters
    ----------
    x : (N, 3) array
        Positions in m.
    bodies : sequence of (c, Q, r)
        The ellipsoids.
    margin : float
        Search distance in m, ``>= 0``.

    Returns
    -------
    list of int arrays
        ``out[k]`` holds the sorted indices of the candidates of ellipsoid ``k``.
    """
    x = check_points(x)
    ells = _check_bodies(bodies)
    if not (np.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"margin must be finite and >= 0 m, got {margin}")
    out = []
    for c, Q, r in ells:
        # cheap sphere pre-filter, then the oriented box
        d2 = np.sum((x - c) ** 2, axis=1)
        pre = np.flatnonzero(d2 <= (np.linalg.norm(r) + margin) ** 2)
        y = (x[pre] - c) @ Q
        out.append(pre[np.all(np.abs(y) <= r + margin, axis=1)])
    return out
