"""Forward-increment Lagrange multiplier (FILM) contact step for lumped-mass explicit dynamics.

Eqs. 22-25 of Man & Swan (2007), after Carpenter, Taylor & Katona (1991), on point masses
against rigid, moving ellipsoids (pure NumPy).

The central-difference predictor (Eq. 23) ignores contact; the corrector
``d^{n+1} = d* + d^c``, ``d^c = -dt^2 M^{-1} G^T lambda`` (Eq. 24) must satisfy the constraint of
Eq. 22b evaluated with ``G(d*)``, giving Eq. 25,
``lambda = [dt^2 G M^{-1} G^T]^{-1} G (d* + X)``.  Here the lumped mass matrix ``M`` is diagonal
and every penetrating node has exactly one constraint against a rigid body whose motion is
prescribed (its degrees of freedom are not unknowns), so ``G M^{-1} G^T`` is block diagonal and
Eq. 25 **decouples per node**: node ``i`` is moved to the point required by the constraint and
its multiplier follows from Eq. 24 alone,

    lambda_i = m_i (x_i^{n+1} - x_i*) / dt^2        (vector, N).

With Eq. 21 ``G`` has three rows per pair (the slave node is put *at* its projection), and the
constraint target is the exact closest point ``p_i`` of ``x_i*`` (plus an optional offset
``h n_i``), so ``x^{n+1} - x* = (h - gap*) n`` and

    lam_n = m (h - gap*) / dt^2 >= 0

because only nodes with ``gap* < h`` are corrected (``gap`` < 0 is penetration).  ``lam_n n`` is
the contact force on the fabric; the body receives ``-lam_n n`` (use that in Eq. 28).  This is the
Belytschko & Neal (1991) result that the explicit multipliers have the right sign without
iteration.

Post-impact velocity (paper, end of Sec. 3.2): the impact is non-resilient, the node moves with
the body surface point, ``v = v_b(p) = v_c + omega x (p - c)``.  Optionally (finite ``mu``) the
tangential part follows Coulomb's law on impulses (as in Bridson, Fedkiw & Anderson 2002): the
relative normal velocity is set to zero, which changes it by ``dv_n``, and the tangential relative
velocity is reduced by at most ``mu |dv_n|``.  The tangential velocity change is also applied to
the position (``x += dt dv_t``, i.e. the friction force ``m dv_t / dt`` enters ``d^c`` of Eq. 24),
so a sticking node does not creep; the shifted node is then put back on the surface of its
contact ellipsoid (it moves with, and stays on, the body surface).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from clothfem.contact.compiled import film_kernel
from clothfem.contact.friction import coulomb_return_map
from clothfem.contact.geometry import (
    EllipsoidData,
    _check_bodies,
    _CheckedBodies,
    check_points,
    closest_point_union,
    closest_points,
    gap_lower_bound,
)

__all__ = ["FilmResult", "film_step"]

_GAP_TOL = 1e-12  # m per m of coordinate magnitude: round-off allowance on final gaps
# the exact projections' root solve (closest_points' defaults, passed to the C loop too)
_PROJ_TOL, _PROJ_MAX_ITER = 1e-13, 100

FloatArray = NDArray[np.float64]


class FilmResult(NamedTuple):
    """Result of :func:`film_step` for N nodes.

    Attributes
    ----------
    x : (N, 3) float array
        Corrected positions ``x^{n+1}`` in m (``x*`` for inactive nodes).
    v : (N, 3) float array
        Post-impact velocities in m/s (``v*`` for inactive nodes).
    active : (N,) bool array
        Nodes whose predictor violated the constraint (``gap* < offset``) and were corrected.
    lam_n : (N,) float array
        Normal multiplier ``m (x_proj - x*) . n / dt^2 >= 0`` in N (0 where inactive).
    force : (N, 3) float array
        Total contact force on the fabric ``m (x^{n+1} - x*) / dt^2`` in N: ``lam_n n`` plus
        ``friction`` plus an O(dt^2) normal term from keeping a sliding node on the curved
        surface.
    friction : (N, 3) float array
        Tangential (friction) part of ``force`` in N.
    normal : (N, 3) float array
        Outward unit normal of the contact body at the contact point (zeros where inactive).
    body : (N,) int array
        Index of the contact ellipsoid (-1 where inactive).
    gap : (N,) float array
        Signed gap to the union at ``x`` (m, ``< 0`` penetration); ``gap*`` where inactive,
        there a lower bound (>= offset) for nodes the broad phase cleared
        (:func:`~clothfem.contact.geometry.gap_lower_bound`).
    stick : (N,) bool array
        Active nodes whose tangential relative velocity was brought to zero.
    dissipation : (N,) float array
        Frictional dissipation increment in J (Coulomb return map, ``>= 0``).
    unresolved : (N,) bool array
        Active nodes still closer than ``offset`` to (or inside) an ellipsoid of the union after
        ``max_passes`` re-projections (overlap regions; see
        :func:`~clothfem.contact.geometry.closest_point_union`).
    """

    x: FloatArray
    v: FloatArray
    active: NDArray[np.bool_]
    lam_n: FloatArray
    force: FloatArray
    friction: FloatArray
    normal: FloatArray
    body: NDArray[np.intp]
    gap: FloatArray
    stick: NDArray[np.bool_]
    dissipation: FloatArray
    unresolved: NDArray[np.bool_]


def _check_velocities(
    body_velocities: Sequence[tuple[ArrayLike, ArrayLike]] | None, k: int
) -> tuple[FloatArray, FloatArray]:
    if body_velocities is None:
        return np.zeros((k, 3)), np.zeros((k, 3))
    items = list(body_velocities)
    if len(items) != k:
        raise ValueError(
            f"body_velocities must have one (v_c, omega) pair per body ({k}), got {len(items)}"
        )
    vc = np.zeros((k, 3))
    om = np.zeros((k, 3))
    for i, pair in enumerate(items):
        try:
            a, b = pair
        except (TypeError, ValueError):
            raise ValueError(f"body_velocities[{i}] must be a (v_c, omega) pair") from None
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        if a.shape != (3,) or b.shape != (3,) or not np.all(np.isfinite(a) & np.isfinite(b)):
            raise ValueError(
                f"body_velocities[{i}] must be finite (3,) v_c in m/s and omega in rad/s"
            )
        vc[i], om[i] = a, b
    return vc, om


def _near_others(
    x: FloatArray, own: NDArray[np.intp], ells: Sequence[EllipsoidData], cut: float
) -> NDArray[np.intp]:
    """Indices of the points whose gap lower bound to an ellipsoid other than ``own`` is
    below ``cut``."""
    if len(ells) == 1:
        return np.zeros(0, dtype=np.intp)
    lb = gap_lower_bound(x, ells, per_body=True)
    lb[np.arange(len(own)), own] = np.inf
    return np.flatnonzero(lb.min(axis=1) < cut)


def film_step(
    x_star: ArrayLike,
    v_star: ArrayLike,
    m: ArrayLike,
    dt: float,
    bodies: Sequence[EllipsoidData],
    *,
    body_velocities: Sequence[tuple[ArrayLike, ArrayLike]] | None = None,
    mu: float | None = None,
    offset: float = 0.0,
    max_passes: int = 3,
    fixed: ArrayLike | None = None,
    kernel: str = "compiled",
) -> FilmResult:
    """One FILM contact correction (Eqs. 22-25) for point masses against moving ellipsoids.

    Parameters
    ----------
    x_star : (N, 3) array
        Predictor positions ``x*`` at ``t^{n+1}`` in m (Eq. 23, central difference without
        contact).
    v_star : (N, 3) array
        Predictor velocities in m/s consistent with ``x*`` (e.g. ``(x* - x^n) / dt``).
    m : (N,) array or scalar
        Lumped nodal masses in kg, > 0.
    dt : float
        Time step in s, > 0.
    bodies : sequence of (c, Q, r)
        The ellipsoids at ``t^{n+1}`` (centre m, axes as columns, radii m).
    body_velocities : sequence of (v_c, omega), optional
        Centre velocity (m/s) and angular velocity (rad/s) of each ellipsoid at ``t^{n+1}``;
        all at rest if None.
    mu : float or None, optional
        None (default): the paper's non-resilient assumption, the node takes the full body
        velocity ``v_b(p)`` (perfect stick).  A number ``>= 0``: Coulomb friction on the impulse,
        ``|dv_t| <= mu |dv_n|``; ``0`` is frictionless (tangential velocity unchanged).
    offset : float, optional
        Contact thickness ``h >= 0`` in m: nodes are kept at ``gap >= h`` (e.g. half the fabric
        thickness); default 0.
    max_passes : int, optional
        Projection passes (>= 1; 1 is the plain single projection of the paper).  Nodes whose
        corrected position is still within ``offset`` of (or inside) another ellipsoid of the
        union -- possible where ellipsoids overlap, e.g. at the elbow -- are re-projected from
        there onto the union; those left are flagged ``unresolved``.
    fixed : (N,) bool array, optional
        Nodes that are never corrected (prescribed displacements): their ``x``/``v`` are
        ``x*``/``v*``, they are inactive, and their ``gap`` is ``inf`` (not evaluated). The
        result is that of the other nodes alone.
    kernel : {"compiled", "numpy"}, optional
        ``"compiled"`` (default): the C loop of ``film_kernel.c``
        (:mod:`clothfem.contact.compiled`); ``"numpy"``: the vectorised NumPy reference
        below. Both run the same algorithm in the same order of operations and agree to
        round-off (tested); the C loop avoids NumPy's per-call overhead, which dominates at
        the few hundred contact nodes of a sleeve.

    Returns
    -------
    FilmResult
        Corrected positions and velocities, multipliers (``lam_n >= 0``, force on fabric
        ``+lam_n n``), friction forces, contact data and flags.
    """
    xs = check_points(x_star, name="x_star")
    n = xs.shape[0]
    vs = check_points(v_star, name="v_star")
    if vs.shape != xs.shape:
        raise ValueError(f"v_star must have shape {xs.shape} like x_star, got {vs.shape}")
    mass = np.asarray(m, dtype=float)
    if mass.ndim == 0:
        mass = np.full(n, float(mass))
    if mass.shape != (n,) or not np.all(np.isfinite(mass)) or np.any(mass <= 0.0):
        raise ValueError(f"m must be finite lumped masses > 0 kg, scalar or shape ({n},)")
    if not (np.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be a finite time step > 0 s, got {dt}")
    ells = _check_bodies(bodies)
    vc, om = _check_velocities(body_velocities, len(ells))
    if mu is not None and not (np.isfinite(mu) and mu >= 0.0):
        raise ValueError(f"mu must be None (full stick) or a finite coefficient >= 0, got {mu}")
    if not (np.isfinite(offset) and offset >= 0.0):
        raise ValueError(f"offset must be a finite contact thickness >= 0 m, got {offset}")
    if int(max_passes) != max_passes or max_passes < 1:
        raise ValueError(f"max_passes must be an integer >= 1, got {max_passes}")
    if fixed is not None:
        fixed = np.asarray(fixed)
        if fixed.shape != (n,) or fixed.dtype != bool:
            raise ValueError(f"fixed must be a bool array of shape ({n},), got {fixed.shape}")
    args = (xs, vs, mass, dt, ells, vc, om, mu, offset, int(max_passes), fixed)
    if kernel == "compiled":
        return _film_compiled(*args)
    if kernel != "numpy":
        raise ValueError(f"kernel must be 'compiled' or 'numpy', got {kernel!r}")
    if fixed is None or not fixed.any():
        return _film_numpy(*args[:-1])
    # the free nodes alone, then the fixed ones as they came (inactive, gap not evaluated)
    free = ~fixed
    sub = _film_numpy(xs[free], vs[free], mass[free], *args[3:-1])
    z, z3, no = np.zeros(n), np.zeros((n, 3)), np.zeros(n, dtype=bool)
    full = FilmResult(
        xs.copy(), vs.copy(), no.copy(), z.copy(), z3.copy(), z3.copy(), z3.copy(),
        np.full(n, -1, dtype=np.intp), np.full(n, np.inf), no.copy(), z.copy(), no.copy(),
    )  # fmt: skip
    for whole, part in zip(full, sub, strict=True):
        whole[free] = part
    return full


class _Buffers:
    """Output arrays of the C loop for ``n`` nodes and their addresses, allocated once;
    ``result`` is the :class:`FilmResult` of views into them."""

    def __init__(self, n: int) -> None:
        self.n = n
        x, v, force, friction, normal = (np.empty((n, 3)) for _ in range(5))
        lam_n, gap, dissipation = np.empty(n), np.empty(n), np.empty(n)
        active, stick, unresolved = (np.zeros(n, dtype=np.uint8) for _ in range(3))
        body = np.empty(n, dtype=np.int64)
        order = (x, v, active, lam_n, force, friction, normal, body, gap, stick, dissipation)
        self.ptrs = tuple(a.ctypes.data for a in (*order, unresolved))
        self.result = FilmResult(
            x, v, active.view(bool), lam_n, force, friction, normal, body.view(np.intp), gap,
            stick.view(bool), dissipation, unresolved.view(bool),
        )  # fmt: skip


def _film_compiled(
    xs: FloatArray,
    vs: FloatArray,
    mass: FloatArray,
    dt: float,
    ells: _CheckedBodies,
    vc: FloatArray,
    om: FloatArray,
    mu: float | None,
    offset: float,
    max_passes: int,
    fixed: NDArray[np.bool_] | None,
    buffers: _Buffers | None = None,
) -> FilmResult:
    """:func:`film_step` by the C loop of ``film_kernel.c`` (validated input); into
    ``buffers`` (then the result's arrays are overwritten by the next call) or new arrays."""
    n, k = xs.shape[0], len(ells)
    out = buffers if buffers is not None and buffers.n == n else _Buffers(n)
    # C-contiguous float64 copies only where needed; kept referenced for the call
    xs, vs, mass, c, Q, r, vc, om = (
        np.ascontiguousarray(a, dtype=float) for a in (xs, vs, mass, ells.c, ells.Q, ells.r, vc, om)
    )
    mask = None if fixed is None else np.ascontiguousarray(fixed).view(np.uint8)
    film_kernel()(
        n, xs.ctypes.data, vs.ctypes.data, mass.ctypes.data, dt,
        k, c.ctypes.data, Q.ctypes.data, r.ctypes.data, vc.ctypes.data, om.ctypes.data,
        int(mu is not None), 0.0 if mu is None else float(mu), offset, max_passes,
        _PROJ_TOL, _PROJ_MAX_ITER, _GAP_TOL, None if mask is None else mask.ctypes.data,
        *out.ptrs,
    )  # fmt: skip
    return out.result


def _film_numpy(
    xs: FloatArray,
    vs: FloatArray,
    mass: FloatArray,
    dt: float,
    ells: Sequence[tuple[FloatArray, FloatArray, FloatArray]],
    vc: FloatArray,
    om: FloatArray,
    mu: float | None,
    offset: float,
    max_passes: int,
) -> FilmResult:
    """:func:`film_step` in vectorised NumPy (validated input): the reference of the C loop."""
    n = xs.shape[0]
    # broad phase: exact projections only where the gap's lower bound does not clear offset
    gap = gap_lower_bound(xs, ells)
    scale = max(1.0, float(np.max(np.abs(xs), initial=0.0)))
    near = np.flatnonzero(gap < offset + _GAP_TOL * scale)
    pr = closest_point_union(xs[near], ells)
    gap[near] = pr.gap
    active = gap < offset
    x = xs.copy()
    v = vs.copy()
    lam_n = np.zeros(n)
    normal = np.zeros((n, 3))
    body = np.full(n, -1, dtype=np.intp)
    stick = np.zeros(n, dtype=bool)
    dissipation = np.zeros(n)
    friction = np.zeros((n, 3))
    unresolved = np.zeros(n, dtype=bool)

    a = np.flatnonzero(active)
    if a.size:
        on = active[near]  # the active nodes among the projected ones (same order as a)
        p = pr.point[on].copy()
        nr = pr.normal[on].copy()
        bk = pr.body[on].copy()
        xa = p + offset * nr
        tol_gap = _GAP_TOL * max(1.0, float(np.max(np.abs(xa))))
        if len(ells) > 1:
            # overlap regions: re-project nodes whose target is still within `offset` of
            # another ellipsoid of the union (for a single convex body one pass is exact)
            todo = np.arange(a.size)
            for _ in range(int(max_passes) - 1):
                # a node on its body's surface is farther than offset from the others
                # unless their lower bound says it may not be
                todo = todo[_near_others(xa[todo], bk[todo], ells, offset)]
                if todo.size == 0:
                    break
                chk = closest_point_union(xa[todo], ells)
                bad = chk.gap < offset - tol_gap
                todo = todo[bad]
                if todo.size == 0:
                    break
                p[todo], nr[todo], bk[todo] = chk.point[bad], chk.normal[bad], chk.body[bad]
                xa[todo] = p[todo] + offset * nr[todo]
        ma = mass[a]
        lam_n[a] = ma * np.einsum("ij,ij->i", xa - xs[a], nr) / dt**2

        # post-impact velocity: non-resilient normal, friction on the tangential part
        centres = np.stack([e[0] for e in ells])
        vb = vc[bk] + np.cross(om[bk], p - centres[bk])
        vrel = vs[a] - vb
        vrel_n = np.einsum("ij,ij->i", vrel, nr)
        vrel_t = vrel - vrel_n[:, None] * nr
        dv_n = -vrel_n  # brings the relative normal velocity to zero
        if mu is None:
            dv_t = -vrel_t
            stick[a] = True
        else:
            fr = coulomb_return_map(
                ma * np.abs(dv_n) / dt, -ma[:, None] * vrel_t / dt, mu, penalty=ma / dt**2
            )
            dv_t = fr.force * dt / ma[:, None]
            stick[a] = fr.stick
            dissipation[a] = fr.dissipation
        v[a] = vs[a] + dv_n[:, None] * nr + dv_t
        # tangential friction displacement (friction force m dv_t / dt in d^c of Eq. 24), then
        # back onto the contact surface: the node stays in contact with the body it moves with
        # (removes the O(dt^2 |dv_t|^2 / curvature radius) lift-off of a straight tangent step)
        moved = np.flatnonzero(np.any(dv_t != 0.0, axis=1))
        if moved.size:
            xm = xa[moved] + dt * dv_t[moved]
            bm = bk[moved]
            sels = [bm == k for k in range(len(ells))]
            for sel, pk in zip(sels, closest_points([xm[s] for s in sels], ells), strict=True):
                xm[sel] = pk.point + offset * pk.normal
            xa[moved] = xm
        x[a] = xa
        friction[a] = ma[:, None] * dv_t / dt
        normal[a] = nr
        body[a] = bk
        # final gaps: offset from the own body (by construction), less only where another
        # ellipsoid may come closer
        fin_gap = np.full(a.size, offset)
        check = _near_others(xa, bk, ells, offset)
        if check.size:
            fin_gap[check] = closest_point_union(xa[check], ells).gap
        gap[a] = fin_gap
        unresolved[a] = fin_gap < offset - tol_gap
    force = mass[:, None] * (x - xs) / dt**2
    return FilmResult(
        x, v, active, lam_n, force, friction, normal, body, gap, stick, dissipation, unresolved
    )
