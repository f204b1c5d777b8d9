r"""Fabric self-contact for the implicit (Newmark) integrator: a smooth, thickness-aware barrier
in the Newton system of each step, and a continuous-collision step filter so that no Newton
iterate crosses the fabric through itself.

**Why a barrier and not Lagrange multipliers on the pair gaps.** The body contact of the
Newmark path (:mod:`clothfem.contact.lagrange`) is an active set of (node, ellipsoid)
constraints whose normals are fixed by the rigid master. Between fabric layers the pairs are
node-triangle *and* edge-edge pairs whose closest features change from one Newton iterate
to the next (a node slides from one triangle to its neighbour, an edge pair degenerates to
a vertex pair), several pairs share nodes with nearly parallel normals (the bordered matrix
is then nearly singular, the failure the body contact already avoids by one constraint per
node), and the pair set is not known before the step: constraints would enter and leave the
active set at every pass. A barrier needs none of that: the pairs within the activation
distance simply add energy, gradient and Hessian to the step's residual and Jacobian, the
set may change between iterates, and the step filter below guarantees that no iterate passes
through the surface (which the active set cannot: an iterate between two passes may cross
a layer and then be pulled back to the wrong side). Measured on the pressed sheets of the
verification (81 + 49 nodes) at rest: of the 384 node-triangle pairs within d, the
constraint gradients have rank 284 (smallest singular value 8e-34), so multipliers on all
of them would make the bordered matrix singular and (b) would need a pair selection the
barrier does without; the barrier run (node-triangle pairs only) took 17, 16, 6, 6, 5, 4,
4, 4, 4 Newton iterations in its 9 steps (2 cut-backs while the layers met) and balances
the load to 0.03 %.

**The barrier** (Li et al., *Incremental Potential Contact*, 2020; the C2 clamped log
barrier on the unsigned distance ``s`` of a pair):

    b(s) = -(s - d)^2 ln(s / d)   for 0 < s < d,   0 for s >= d,

``d`` the activation distance (``distance``: the fabric thickness, or a stated multiple),
so the energy, its gradient and Hessian vanish continuously at ``s = d``. The step's
energy gains ``E = kappa sum_k w_k b(s_k)`` over all node-triangle pairs of the
triangulated surface (:func:`clothfem.contact.self_contact.fabric_surface`) closer than
``d``, as in IPC's sum over pairs: the distance of a point to a (non-degenerate) triangle
is C1 in the four nodes' positions, so the energy is C1 with a Hessian that jumps only
where a pair's closest feature changes (removing the duplicates a node above an edge has in
the edge's two triangles would make the energy itself jump there).
Constant weights ``w = A_p / 2`` (``A_p`` the lumped area of the pair's node on the
reference surface, a third of its triangles'); ``kappa = pressure / (d (1/2 + ln 2))``
[Pa/m], so that a node of two parallel layers at ``s = d / 2`` carries about ``pressure``
times its area from its face pair and the opposite node's (the neighbouring triangles' pairs
and the edge pairs add to it: the layers sit a little farther apart than that).

**Edge-edge pairs** (``edges = True``, IPC's mollified edge-edge barrier): the pairs of
surface edges ``(p0 p1, q0 q1)`` closer than ``d`` add ``kappa w m(c) b(s)`` with ``s``
the segments' distance (coefficients ``(1 - s, s, -(1 - t), -t)`` of the closest points),
``w = (A_e0 + A_e1) / 4`` (lumped reference edge areas, a third of each adjacent triangle)
and the mollifier ``m(c) = (2 - c / eps_x) c / eps_x`` for ``c = |e0 x e1|^2 < eps_x``, 1
above, ``eps_x = 1e-3 |E0|^2 |E1|^2`` (reference edges): the distance of two segments has
a kink where they are parallel (the minimiser is not unique), and ``m`` takes the pair's
energy to zero there as ``c``, so the sum stays C1. Edges closer to parallel than
``|e0 x e1|^2 < 1e-10 |e0|^2 |e1|^2`` take their closest points at an end (where the
mollifier has already taken their energy below 2e-7 of a crossing pair's). Edges also enter
the step filter.

Derivatives of the distance: ``s = min_w |r(x, w)|`` with ``r = sum_j c_j(w) x_j`` (the
node-triangle coefficients ``(1, -w0, -w1, -w2)`` of
:func:`clothfem.contact.self_contact.pair_contacts`, affine in the barycentric weights).
With ``phi = s^2 / 2`` and ``f = |r|^2 / 2`` at the minimiser (free parameters only: those
inside the pair's closest feature),
``grad phi = c (x) r`` and ``hess phi = f_xx - f_xw f_ww^-1 f_wx`` (the envelope theorem;
``f_xx = c c^T (x) I``, ``f_xw`` column ``k``: ``A_jk r + c_j X A_k`` on node ``j``,
``f_ww = (X A)^T X A``), then ``grad s = grad phi / s`` and ``hess s = hess phi / s -
grad phi grad phi^T / s^3``. Exact inside each closest-feature region; ``s`` is C1 across
regions.

**Step filter.** Before the line search of each Newton iterate the largest ``alpha`` in
``1, 1/2, 1/4, ...`` is taken such that along the straight path from the iterate no listed
pair crosses (the continuous crossing test of :func:`point_triangle_crossings` /
:func:`edge_edge_crossings`) and every pair within ``d`` keeps at least ``floor`` times
its distance; a Newton step moves no node by more than ``max_move d`` (so the candidate
list covering the path stays local). A path the list does not cover gets a list built at
the iterate with a skin of 2.5 times the path's largest node motion (valid along it: no
node moves farther); such a widened list is dropped at the next time step's start, so the
pair searches of later steps do not go through it.

**Parallel layout.** Like the explicit self-contact, every rank gathers all node positions
(``Allgatherv``), evaluates every pair redundantly (the same bits on every rank) and adds
the gradient to its owned rows; the Hessian's owned rows go into one AIJ matrix holding the
fabric tangent's pattern joined with the 3x3 blocks of the node pairs of the candidate list's
pairs built within ``d + skin`` (a list a filter rebuilds with a wider skin keeps the
pattern small), kept while the list is valid and while it holds every pair in use (else
rebuilt with them, decided on all ranks together).

**Friction between layers** (``mu`` > 0; IPC's lagged, smoothed Coulomb friction). At the
start of each step (:meth:`SelfBarrier.begin_step`, positions ``x^n``) the pairs within
``d`` are frozen with their coefficients ``c``, their normal force ``lambda_k = kappa w_k
|b'(s_k)|`` [N] and an orthonormal tangent basis ``T_k`` (3 x 2) of the plane normal to
``r_k(x^n)``. The step's energy gains the dissipation potential

    D(x) = sum_k mu lambda_k F(|u_k|),   u_k = T_k^T sum_j c_j (x_j - x_j^n),

``u_k`` the pair's tangential relative displacement over the step and ``F(y) = y - eps / 3``
for ``y >= eps``, ``F(y) = y^2 / eps - y^3 / (3 eps^2)`` below, ``eps = slip_velocity dt``:
the friction force ``mu lambda_k f1(y) u / y`` has Coulomb's magnitude ``mu lambda_k`` once
the pair slips by more than ``eps`` in the step (relative speed above ``slip_velocity``)
and falls smoothly to zero with the slip below it (static friction as a very stiff
tangential spring, ``f1(y) = 2 y / eps - y^2 / eps^2``). Its Hessian
``mu lambda c c^T (x) T A T^T`` is positive semi-definite: ``A = (I - u u^T / y^2) / y``
above ``eps``, ``(2 / eps - y / eps^2) I - u u^T / (eps^2 y)`` below (eigenvalues ``f1 / y``
and ``f1'``, both >= 0). The work of the friction forces over the accepted step, ``sum_k
mu lambda_k f1(y_k) y_k`` at the converged positions, is what the layer friction
dissipates (:meth:`SelfBarrier.end_step`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from mpi4py import MPI
from numpy.typing import NDArray
from petsc4py import PETSc

from ..spec import ContactSpec
from . import barrier_kernels as bk
from .self_contact import (
    CandidateList,
    FabricSurface,
    FilterBounds,
    _ee_distances,
    _pt_distances,
    bound_tolerance,
    build_candidates,
    closest_point_triangle,
    crossing_groups,
    fabric_surface,
    global_cells,
    motion_radius,
    segment_closest,
)

__all__ = [
    "BarrierPairs",
    "SelfBarrier",
    "SelfBarrierParameters",
    "SelfBarrierRecord",
    "barrier",
    "barrier_pairs",
    "distance_derivatives",
    "vertex_areas",
    "pair_energy",
    "EdgePairs",
    "FrictionPairs",
    "cross_derivatives",
    "edge_areas",
    "edge_energy",
    "edge_pairs",
    "friction_energy",
    "friction_pairs",
    "friction_slip",
    "friction_work",
    "tangent_basis",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

_FREE_EPS = 1e-9  # closest-point weight above which a node belongs to the closest feature
_HALF = 0.5 + math.log(2.0)  # |b'(d / 2)| / d


@dataclass(frozen=True, kw_only=True)
class SelfBarrierParameters:
    """distance: activation distance d [m] of the barrier (> 0; the fabric thickness or a
    stated multiple); pressure: the pressure [Pa] two parallel layers at d / 2 exert on each
    other (> 0; sets kappa); rings: neighbour exclusion as in
    :func:`clothfem.contact.self_contact.fabric_surface`; skin: candidate-list skin [m]
    (default d); floor: a Newton step keeps every pair within d at least this fraction of
    its distance (0 < floor < 1); max_move: largest node motion of one Newton step, in units
    of d (> 0); eps: crossing proximity of the step filter, fraction of d (0 < eps < 0.005);
    mu: Coulomb coefficient between layers (>= 0; 0: frictionless); slip_velocity: relative
    tangential speed [m/s] above which a pair slides with the full Coulomb force (> 0; the
    static friction's smoothing, module docstring); edges: edge-edge pairs in the energy
    (the mollified barrier) besides node-triangle pairs."""

    distance: float
    pressure: float = 1e3
    rings: int = 0
    skin: float | None = None
    floor: float = 0.1
    max_move: float = 10.0
    eps: float = 1e-3
    mu: float = 0.0
    slip_velocity: float = 1e-3
    edges: bool = True

    def __post_init__(self) -> None:
        def bad(name, rule):
            raise ValueError(
                f"SelfBarrierParameters.{name} must be {rule}, got {getattr(self, name)!r}"
            )

        if not (math.isfinite(self.distance) and self.distance > 0):
            bad("distance", "> 0 m")
        if not (math.isfinite(self.pressure) and self.pressure > 0):
            bad("pressure", "> 0 Pa")
        if int(self.rings) != self.rings or self.rings < 0:
            bad("rings", "an integer >= 0")
        if self.skin is not None and not (math.isfinite(self.skin) and self.skin > 0):
            bad("skin", "> 0 m")
        if not 0 < self.floor < 1:
            bad("floor", "in (0, 1)")
        if not (math.isfinite(self.max_move) and self.max_move > 0):
            bad("max_move", "> 0")
        if not 0 < self.eps < 0.005:
            bad("eps", "in (0, 0.005)")
        if not (math.isfinite(self.mu) and self.mu >= 0):
            bad("mu", ">= 0")
        if not (math.isfinite(self.slip_velocity) and self.slip_velocity > 0):
            bad("slip_velocity", "> 0 m/s")

    @property
    def kappa(self) -> float:
        """Barrier stiffness [Pa/m]."""
        return self.pressure / (_HALF * self.distance)

    @property
    def skin_length(self) -> float:
        return self.distance if self.skin is None else self.skin


def barrier(s: FloatArray, *, distance: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The clamped log barrier b(s) [m^2] and its first two derivatives at distances ``s``
    (> 0) [m], zero for ``s >= distance``."""
    s = np.asarray(s, dtype=float)
    d = distance
    on = s < d
    sc = np.where(on, s, d)
    lg = np.log(sc / d)
    e = sc - d
    b = np.where(on, -e * e * lg, 0.0)
    db = np.where(on, -2.0 * e * lg - e * e / sc, 0.0)
    d2b = np.where(on, -2.0 * lg - 4.0 * e / sc + e * e / (sc * sc), 0.0)
    return b, db, d2b


class BarrierPairs(NamedTuple):
    """Node-triangle pairs within the activation distance: nodes ``idx`` (M, 4) = (p, a, b,
    c), coefficients ``coef`` (M, 4) = ``(1, -w0, -w1, -w2)``, free directions ``free``
    (M, 4, 2) of the coefficients inside the closest
    feature (zero columns for none), distances ``dist`` (M,) [m], area weights ``weight``
    (M,) [m^2]."""

    idx: IntArray
    coef: FloatArray
    free: FloatArray
    dist: FloatArray
    weight: FloatArray


def _triangle_areas(x: FloatArray, tri: IntArray) -> FloatArray:
    return 0.5 * np.linalg.norm(
        np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1
    )


def vertex_areas(x: FloatArray, surface: FabricSurface) -> FloatArray:
    """Lumped vertex areas (N,) [m^2] of the surface at ``x``: a third of the adjacent
    triangles' areas."""
    tri = surface.triangles
    a = _triangle_areas(x, tri)
    return np.bincount(tri.ravel(), weights=np.repeat(a / 3.0, 3), minlength=surface.n_nodes)


def _free_directions(coef: FloatArray, groups: tuple) -> FloatArray:
    """Directions (M, 4, 2) of the coefficients that keep the closest point inside its
    feature: per group of nodes (sign, columns) the differences of its active nodes."""
    m = len(coef)
    free = np.zeros((m, 4, 2))
    slot = np.zeros(m, dtype=np.intp)
    rows = np.arange(m)
    for sign, cols in groups:
        act = np.abs(coef[:, cols]) > _FREE_EPS
        first = np.argmax(act, axis=1)
        for k in range(len(cols)):
            use = act[:, k] & (first != k)
            r = rows[use]
            free[r, cols[k], slot[use]] += sign
            free[r, np.asarray(cols)[first[use]], slot[use]] -= sign
            slot[use] += 1
    return free


def _near_rows(x: FloatArray, c: CandidateList, *, distance: float, edges: bool) -> IntArray:
    """Rows of the list's node-triangle pairs (edge pairs if ``edges``) that can be closer
    than ``distance`` [m] at ``x`` (N, 3): those that the lower bound (the build distance
    less twice the :func:`~clothfem.contact.self_contact.motion_radius` of the motion since
    the build) does not clear, then their compiled distances, each with a margin for
    round-off (as :class:`~clothfem.contact.self_contact.FilterBounds`)."""
    reach = distance + bound_tolerance(x, distance=distance)
    moved = 2.0 * motion_radius(x - c.x_build)
    built, nodes = (c.ee_dist, c.ee_nodes) if edges else (c.pt_dist, c.pt_nodes)
    if c.min_distance - moved >= reach:
        return np.zeros(0, dtype=np.intp)
    rows = c.rows_within(reach + moved, edges=edges)  # the others are cleared
    rows = rows[~(built[rows] - moved >= reach)]
    compiled = _ee_distances if edges else _pt_distances
    return rows[~(compiled(x, nodes[rows]) >= reach)]


def near_list(c: CandidateList, x: FloatArray, *, distance: float) -> CandidateList:
    """The pairs of the list ``c`` that can be within ``2 distance`` [m] of each other at
    ``x`` (N, 3) [m] (those :func:`_near_rows` leaves), in the list's order, as a list built
    at ``x`` with their distances there (:func:`near_list_holds`)."""
    pt = _near_rows(x, c, distance=2.0 * distance, edges=False)
    ee = _near_rows(x, c, distance=2.0 * distance, edges=True)
    return replace(
        c.subset(pt, ee), x_build=x.copy(),
        pt_dist=_pt_distances(x, c.pt_nodes[pt]), ee_dist=_ee_distances(x, c.ee_nodes[ee]),
    )  # fmt: skip


def near_list_holds(near: CandidateList, x: FloatArray, *, distance: float) -> bool:
    """Whether no pair of the full list left out of ``near`` (:func:`near_list`) can be
    within ``distance`` [m] at ``x``: twice the motion radius since ``near`` was built is
    less than ``distance`` (with the margin for round-off of :func:`_near_rows`), while the
    full list is valid at ``x``."""
    tol = bound_tolerance(x, distance=distance)
    return 2.0 * motion_radius(x - near.x_build) < distance - tol


def barrier_pairs(
    x: FloatArray,
    surface: FabricSurface,
    candidates: CandidateList,
    *,
    distance: float,
    vertex_area: FloatArray,
) -> BarrierPairs:
    """The node-triangle pairs of the candidate list closer than ``distance`` [m] at ``x``
    (N, 3), each with its constant area weight (module docstring). The pairs that can be
    that close are found first by lower bounds (the build distance less twice the
    :func:`~clothfem.contact.self_contact.motion_radius` of the motion since the build,
    then the compiled distance), with a margin for round-off; the closest points of those
    are then computed as for the whole list (row by row: the same bits)."""
    c = candidates
    rows = _near_rows(x, c, distance=distance, edges=False)
    if rows.size == 0:
        return BarrierPairs(
            c.pt_nodes[:0], np.zeros((0, 4)), np.zeros((0, 4, 2)), *[np.zeros(0)] * 2
        )
    g = c.pt_nodes[rows]
    p, a, b, cc = (x[g[:, k]] for k in range(4))
    q, w = closest_point_triangle(p, a, b, cc)
    dist = np.linalg.norm(p - q, axis=1)
    near = dist < distance
    coef = np.column_stack([np.ones(int(near.sum())), -w[near]])
    free = _free_directions(coef, ((1.0, (0,)), (-1.0, (1, 2, 3))))
    weight = 0.5 * vertex_area[c.pt_node[rows[near]]]
    return BarrierPairs(g[near], coef, free, dist[near], weight)


def _pt_distance(x: FloatArray, c: CandidateList, rows: IntArray | None = None) -> FloatArray:
    """Distances (M,) [m] of the list's point-triangle pairs (``rows`` of them) at ``x``."""
    g = c.pt_nodes if rows is None else c.pt_nodes[rows]
    p, a, b, cc = (x[g[:, k]] for k in range(4))
    return np.linalg.norm(p - closest_point_triangle(p, a, b, cc)[0], axis=1)


def _ee_distance(x: FloatArray, c: CandidateList, rows: IntArray | None = None) -> FloatArray:
    """Distances (M,) [m] of the list's edge pairs (``rows`` of them) at ``x``."""
    g = c.ee_nodes if rows is None else c.ee_nodes[rows]
    return segment_closest(*(x[g[:, k]] for k in range(4)))[2]


def distance_derivatives(
    y: FloatArray, coef: FloatArray, free: FloatArray, *, hessian: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """Distances (M,) [m], gradients (M, 12) and Hessians (M, 12, 12) [1/m] (None unless
    ``hessian``) of the pair distances ``s = |sum_j c_j y_j|`` with respect to the four
    nodes' positions ``y`` (M, 4, 3), the closest-point parameters moving along ``free``
    (M, 4, 2) (module docstring)."""
    r = np.einsum("mj,mjk->mk", coef, y)
    s = np.linalg.norm(r, axis=1)
    g = (coef[:, :, None] * r[:, None, :]).reshape(len(coef), 12) / s[:, None]
    if not hessian:
        return s, g, None
    one, zero = np.ones(len(s)), np.zeros(len(s))
    return s, g, _distance_hessians(y, coef, free, one, zero)


def _distance_hessians(
    y: FloatArray, coef: FloatArray, free: FloatArray, a: FloatArray, b: FloatArray
) -> FloatArray:
    """``a hess s + b grad s grad s^T`` (M, 12, 12) of the pairs (compiled loop)."""
    out = np.empty((len(coef), 12, 12))
    bk.distance_hessians(
        np.ascontiguousarray(y), np.ascontiguousarray(coef), np.ascontiguousarray(free),
        np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float), out,
    )  # fmt: skip
    return out


def pair_energy(
    x: FloatArray, pairs: BarrierPairs, *, params: SelfBarrierParameters, hessian: bool = True
) -> tuple[float, FloatArray, FloatArray | None, FloatArray]:
    """Barrier energy [J], its gradient (M, 12) [N] and Hessian (M, 12, 12) [N/m] per pair
    (None unless ``hessian``), and each pair's force ``-dE/ds`` (M,) [N], at ``x`` (N, 3)
    [m] for the pairs' closest features."""
    y = x[pairs.idx]
    s, gs, _ = distance_derivatives(y, pairs.coef, pairs.free, hessian=False)
    b, db, d2b = barrier(s, distance=params.distance)
    k = params.kappa * pairs.weight
    grad = (k * db)[:, None] * gs
    if not hessian:
        return float(np.sum(k * b)), grad, None, -k * db
    hess = _distance_hessians(y, pairs.coef, pairs.free, k * db, k * d2b)
    return float(np.sum(k * b)), grad, hess, -k * db


def edge_areas(x: FloatArray, surface: FabricSurface) -> FloatArray:
    """Lumped edge areas (E,) [m^2] of the surface's ``edges`` at ``x``: a third of each
    adjacent triangle's area."""
    tri = surface.triangles
    a = _triangle_areas(x, tri)
    n = np.int64(surface.n_nodes)
    keys = surface.edges[:, 0].astype(np.int64) * n + surface.edges[:, 1]
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    rows = np.searchsorted(keys, e[:, 0].astype(np.int64) * n + e[:, 1])
    return np.bincount(rows, weights=np.tile(a / 3.0, 3), minlength=len(keys))


class EdgePairs(NamedTuple):
    """Edge-edge pairs within the activation distance: nodes ``idx`` (M, 4) = (p0, p1, q0,
    q1), coefficients ``coef`` (M, 4) = ``(1 - s, s, -(1 - t), -t)``, free directions
    ``free`` (M, 4, 2), distances ``dist`` (M,) [m], area weights ``weight`` (M,) [m^2] and
    the mollifier thresholds ``eps_x`` (M,) [m^4] (module docstring)."""

    idx: IntArray
    coef: FloatArray
    free: FloatArray
    dist: FloatArray
    weight: FloatArray
    eps_x: FloatArray


_PARALLEL = 1e-10  # |e0 x e1|^2 / (|e0|^2 |e1|^2) below which two edges count as parallel


def _parallel(e0: FloatArray, e1: FloatArray) -> NDArray[np.bool_]:
    a, e, b = (np.einsum("ij,ij->i", u, w) for u, w in ((e0, e0), (e1, e1), (e0, e1)))
    return a * e - b * b <= _PARALLEL * a * e


def _end_closest(p0, p1, q0, q1) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closest points of segments through their ends (each end against the other segment,
    the nearest of the four): parameters ``s``, ``t`` and distances, for parallel edges."""
    e0, e1 = p1 - p0, q1 - q0

    def on(pt, a, e):  # parameter of the point of segment a + u e closest to pt
        return np.clip(np.einsum("ij,ij->i", pt - a, e) / np.einsum("ij,ij->i", e, e), 0, 1)

    zero, one = np.zeros(len(p0)), np.ones(len(p0))
    cand = [(zero, on(p0, q0, e1)), (one, on(p1, q0, e1)), (on(q0, p0, e0), zero)]
    cand.append((on(q1, p0, e0), one))
    st = np.array(cand)  # (4, 2, M)
    r = p0 + st[:, 0, :, None] * e0 - q0 - st[:, 1, :, None] * e1
    d = np.linalg.norm(r, axis=2)
    best = np.argmin(d, axis=0)
    cols = np.arange(len(p0))
    return st[best, 0, cols], st[best, 1, cols], d[best, cols]


def edge_pairs(
    x: FloatArray,
    X: FloatArray,
    candidates: CandidateList,
    *,
    distance: float,
    edge_area: FloatArray,
) -> EdgePairs:
    """The edge-edge pairs of the candidate list closer than ``distance`` [m] at ``x`` (N,
    3), with weights ``(A_e0 + A_e1) / 4`` from the lumped ``edge_area`` and the mollifier
    threshold ``1e-3 |E0|^2 |E1|^2`` of the reference edges (``X``)."""
    c = candidates
    # the bounds select the pairs (with a margin), the exact distances decide
    cand = _near_rows(x, c, distance=distance, edges=True)
    y = [x[c.ee_nodes[cand, k]] for k in range(4)]
    s, t, dist = segment_closest(*y)
    par = _parallel(y[1] - y[0], y[3] - y[2])
    if par.any():  # closest points at an end: no near-singular interior minimiser
        s[par], t[par], dist[par] = _end_closest(*(a[par] for a in y))
    near = dist < distance
    cand = cand[near]
    s, t, g, dist = s[near], t[near], c.ee_nodes[cand], dist[near]
    coef = np.column_stack([1.0 - s, s, t - 1.0, -t])
    free = _free_directions(coef, ((1.0, (0, 1)), (-1.0, (2, 3))))
    weight = 0.25 * edge_area[c.ee[cand]].sum(axis=1)
    E0, E1 = X[g[:, 1]] - X[g[:, 0]], X[g[:, 3]] - X[g[:, 2]]
    eps_x = 1e-3 * np.sum(E0 * E0, axis=1) * np.sum(E1 * E1, axis=1)
    return EdgePairs(g, coef, free, dist, weight, eps_x)


def cross_derivatives(
    y: FloatArray, *, hessian: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """``c = |e0 x e1|^2 = |e0|^2 |e1|^2 - (e0 . e1)^2`` of the edges ``e0 = y1 - y0``, ``e1 =
    y3 - y2`` of (M, 4, 3) node positions, its gradient (M, 12) and Hessian (M, 12, 12)
    (None unless ``hessian``)."""
    m = len(y)
    e0, e1 = y[:, 1] - y[:, 0], y[:, 3] - y[:, 2]
    a, b, d = (np.sum(u * w, axis=1) for u, w in ((e0, e0), (e0, e1), (e1, e1)))
    c = a * d - b * b
    g0 = 2.0 * (d[:, None] * e0 - b[:, None] * e1)  # dc/de0
    g1 = 2.0 * (a[:, None] * e1 - b[:, None] * e0)  # dc/de1
    eye = np.eye(3)
    h00 = 2.0 * (d[:, None, None] * eye - np.einsum("mi,mj->mij", e1, e1))
    h11 = 2.0 * (a[:, None, None] * eye - np.einsum("mi,mj->mij", e0, e0))
    h01 = (
        4.0 * np.einsum("mi,mj->mij", e0, e1)
        - 2.0 * np.einsum("mi,mj->mij", e1, e0)
        - 2.0 * b[:, None, None] * eye
    )
    S = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])  # node -> edge
    grad = (S[None, :, 0, None] * g0[:, None] + S[None, :, 1, None] * g1[:, None]).reshape(m, 12)
    if not hessian:
        return c, grad, None
    He = np.empty((m, 2, 2, 3, 3))
    He[:, 0, 0], He[:, 1, 1], He[:, 0, 1] = h00, h11, h01
    He[:, 1, 0] = np.transpose(h01, (0, 2, 1))
    hess = np.empty((m, 4, 3, 4, 3))
    for i in range(4):  # node i on edge p = i // 2 with sign S[i, p]
        for j in range(4):
            hess[:, i, :, j, :] = S[i, i // 2] * S[j, j // 2] * He[:, i // 2, j // 2]
    return c, grad, hess.reshape(m, 12, 12)


def edge_energy(
    x: FloatArray, pairs: EdgePairs, *, params: SelfBarrierParameters, hessian: bool = True
) -> tuple[float, FloatArray, FloatArray | None, FloatArray]:
    """The mollified edge-edge barrier ``kappa w m(c) b(s)`` [J] (module docstring), its
    gradient (M, 12) [N] and Hessian (M, 12, 12) [N/m] per pair (None unless ``hessian``),
    and each pair's force ``-dE/ds`` (M,) [N], at ``x`` (N, 3) [m] for the pairs' closest
    features."""
    y = x[pairs.idx]
    s, gs, _ = distance_derivatives(y, pairs.coef, pairs.free, hessian=False)
    b, db, d2b = barrier(s, distance=params.distance)
    c, gc, _ = cross_derivatives(y, hessian=False)
    ex = pairs.eps_x
    on = c < ex
    mol = np.where(on, (2.0 - c / ex) * c / ex, 1.0)
    dm = np.where(on, 2.0 / ex - 2.0 * c / (ex * ex), 0.0)
    d2m = np.where(on, -2.0 / (ex * ex), 0.0)
    k = params.kappa * pairs.weight
    grad = (k * dm * b)[:, None] * gc + (k * mol * db)[:, None] * gs
    if not hessian:
        return float(np.sum(k * mol * b)), grad, None, -k * mol * db
    hess = _distance_hessians(y, pairs.coef, pairs.free, k * mol * db, k * mol * d2b)
    if on.any():  # the mollifier's terms, on the pairs near parallel
        o = np.flatnonzero(on)
        ko, gco, gso = k[o], gc[o], gs[o]
        outer = lambda u, w: np.einsum("mi,mj->mij", u, w)  # noqa: E731
        hess[o] += (ko * d2m[o] * b[o])[:, None, None] * outer(gco, gco)
        hess[o] += (ko * dm[o] * b[o])[:, None, None] * cross_derivatives(y[o])[2]
        hess[o] += (ko * dm[o] * db[o])[:, None, None] * (outer(gco, gso) + outer(gso, gco))
    return float(np.sum(k * mol * b)), grad, hess, -k * mol * db


class FrictionPairs(NamedTuple):
    """The pairs of a step's layer friction, frozen at the step's start (module docstring):
    nodes ``idx`` (M, 4), coefficients ``coef`` (M, 4), ``r0`` (M, 3) [m] = ``sum_j c_j
    x_j^n``, tangent bases ``basis`` (M, 3, 2) and normal forces ``force`` (M,) [N]."""

    idx: IntArray
    coef: FloatArray
    r0: FloatArray
    basis: FloatArray
    force: FloatArray


def tangent_basis(n: FloatArray) -> FloatArray:
    """Orthonormal bases (M, 3, 2) of the planes normal to the unit vectors ``n`` (M, 3)."""
    e = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = e - np.sum(e * n, axis=1)[:, None] * n
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1)], axis=2)


def friction_pairs(
    x: FloatArray, idx: IntArray, coef: FloatArray, force: FloatArray
) -> FrictionPairs:
    """Barrier pairs (nodes ``idx`` (M, 4), coefficients ``coef`` (M, 4), normal forces
    ``force`` (M,) [N]) at the step's start positions ``x`` (N, 3) [m], frozen for the layer
    friction with their tangent planes."""
    r = np.einsum("mj,mjk->mk", coef, x[idx])
    n = r / np.linalg.norm(r, axis=1)[:, None]
    return FrictionPairs(idx, coef, r, tangent_basis(n), force)


def friction_slip(x: FloatArray, fp: FrictionPairs) -> FloatArray:
    """Tangential relative displacements (M, 2) [m] of the frozen pairs since the step's
    start, at positions ``x`` (N, 3) [m]."""
    r = np.einsum("mj,mjk->mk", fp.coef, x[fp.idx])
    return np.einsum("mkl,mk->ml", fp.basis, r - fp.r0)


def friction_work(x: FloatArray, fp: FrictionPairs, *, mu: float, eps: float) -> float:
    """Work [J] of the layer friction forces over the step to ``x``: ``sum mu lambda f1(y)
    y`` (module docstring), ``eps`` [m] the slip of full sliding."""
    y = np.linalg.norm(friction_slip(x, fp), axis=1)
    f1 = np.where(y >= eps, 1.0, 2.0 * y / eps - y * y / eps**2)
    return float(np.sum(mu * fp.force * f1 * y))


def friction_energy(
    x: FloatArray, fp: FrictionPairs, *, mu: float, eps: float, hessian: bool = True
) -> tuple[float, FloatArray, FloatArray | None]:
    """The layer friction's dissipation potential D [J] (module docstring), its gradient
    (M, 12) [N] and Hessian (M, 12, 12) [N/m] per pair (None unless ``hessian``) at
    positions ``x`` (N, 3) [m]; ``eps`` [m]: the slip in the step above which a pair slides
    with mu x its normal force."""
    m = len(fp.force)
    u = friction_slip(x, fp)
    y = np.linalg.norm(u, axis=1)
    slide = y >= eps
    ys = np.where(y > 0.0, y, 1.0)
    F = np.where(slide, y - eps / 3.0, y * y / eps - y**3 / (3.0 * eps * eps))
    f1y = np.where(slide, 1.0 / ys, 2.0 / eps - y / eps**2)  # f1(y) / y
    cuu = np.where(slide, -1.0 / ys**3, -1.0 / (eps * eps * ys))  # the u u^T coefficient
    k = mu * fp.force
    tu = np.einsum("mkl,ml->mk", fp.basis, u)
    grad = ((k * f1y)[:, None, None] * fp.coef[:, :, None] * tu[:, None, :]).reshape(m, 12)
    if not hessian:
        return float(np.sum(k * F)), grad, None
    hess = np.empty((m, 12, 12))
    bk.friction_hessians(
        np.ascontiguousarray(fp.coef), np.ascontiguousarray(fp.basis),
        np.ascontiguousarray(u), f1y, cuu, np.ascontiguousarray(k, dtype=float), hess,
    )  # fmt: skip
    return float(np.sum(k * F)), grad, hess


@dataclass(frozen=True)
class SelfBarrierRecord:
    """Barrier diagnostics of the last converged step (identical on every rank)."""

    pairs: int  # pairs within the activation distance
    min_distance: float  # smallest pair distance [m] (inf: none listed within the skin)
    energy: float  # barrier energy [J]
    force: float  # sum of the pairs' forces -dE/ds [N]
    filtered: int  # Newton steps the crossing filter shortened since the last record
    rebuilds: int  # candidate-list rebuilds since the last record
    wall: float  # seconds in the barrier since the last record
    friction_work: float  # work of the layer friction over the steps since the last record [J]


class SelfBarrier:
    """The barrier of a :class:`clothfem.dynamics.ShellSystem`'s fabric for the Newton
    solves of :class:`clothfem.contact.dynamic.DynamicContact`: :meth:`add_residual`,
    :meth:`jacobian` and the step filter :meth:`max_step` (all collective)."""

    def __init__(self, system, *, params: SelfBarrierParameters) -> None:
        self.system, self.model, self.params = system, system.model, params
        self.comm = self.model.comm
        n = self.n = self.model.n_owned
        cells, n_glob, self.lo = global_cells(self.model.V)
        self.surface = fabric_surface(cells, n_nodes=n_glob, rings=params.rings)
        self._counts = np.array(self.comm.allgather(3 * n))
        self.X = self._gather(self.model.x_nodes[:n])
        self.vertex_area = vertex_areas(self.X, self.surface)
        self.edge_area = edge_areas(self.X, self.surface)
        vec = system.create_vector()
        start = vec.getOwnershipRange()[0]
        vec.destroy()
        self.row0 = np.concatenate(self.comm.allgather(start + 3 * np.arange(n, dtype=np.int64)))
        self.candidates: CandidateList | None = None
        self._pattern: tuple | None = None  # (candidate list, K pattern, combined layout)
        # (candidate list, node groups (M, 4)): the blocks the list's patterns hold beyond
        # its near pairs (the pairs in use outside them, :meth:`jacobian`)
        self._extra: tuple[CandidateList, IntArray] | None = None
        self._C: PETSc.Mat | None = None
        self.filtered = self.rebuilds = 0
        self.wall = 0.0
        self._last = (0, math.inf, 0.0, 0.0)
        self._fric: FrictionPairs | None = None  # this step's frozen friction pairs
        self._eps = 0.0  # this step's slip of full sliding [m]
        self.friction_work = self._work = 0.0  # layer friction's work: total, since record

    # ----------------------------------------------------------------- geometry
    # the last positions gathered (this rank's u rows, all positions) and the last ones the
    # candidate list was found valid at (the list, the positions)
    _gathered: tuple | None = None
    _valid_at: tuple | None = None
    _chosen: tuple | None = None  # (list, positions, pairs within d there): _selected
    _near: tuple | None = None  # (candidate list, its pairs near some positions): _near_list

    def _gather(self, a: FloatArray) -> FloatArray:
        out = np.empty(int(self._counts.sum()))
        self.comm.Allgatherv(np.ascontiguousarray(a, dtype=float).ravel(), [out, self._counts])
        return out.reshape(-1, 3)

    def positions(self, x: PETSc.Vec | FloatArray | None = None) -> FloatArray:
        """Positions (N, 3) [m] of all nodes in global numbering at ``x`` (a vector or this
        rank's array of (u, theta); default: the model's state), on every rank (collective).
        The same u rows on every rank as at the previous call are not gathered again."""
        if x is None:
            u = self.model.u.x.array[: 3 * self.n]
        elif isinstance(x, np.ndarray):
            u = x[: 3 * self.n]
        else:
            u = x.getArray(readonly=True)[: 3 * self.n]
        last = self._gathered
        same = last is not None and np.array_equal(last[0], u)
        if self.comm.size > 1:  # collective: every rank gathers or none
            same = self.comm.allreduce(int(not same)) == 0
        if same:
            return last[1].copy()
        xa = self.X + self._gather(u)
        self._gathered = (u.copy(), xa)
        return xa.copy()

    def _list(self, *xs: FloatArray, span: float = 0.0) -> CandidateList:
        p = self.params
        c = self.candidates
        if c is None or not all(self._valid(c, x) for x in xs):
            # built at xs[0], every node of xs[1:] within span of it: valid there by the
            # motion bound of CandidateList.valid, with room for the next iterates
            skin = max(p.skin_length, 2.5 * span)
            self.candidates = build_candidates(xs[0], self.surface, distance=p.distance, skin=skin)
            self.rebuilds += 1
        return self.candidates

    def _valid(self, c: CandidateList, x: FloatArray) -> bool:
        """``c.valid(x)``, known without the check for the last positions found valid."""
        last = self._valid_at
        if last is not None and last[0] is c and np.array_equal(last[1], x):
            return True
        ok = c.valid(x)
        if ok:
            self._valid_at = (c, x.copy())
        return ok

    def _near_list(self, xa: FloatArray) -> CandidateList:
        """The pairs of the candidate list within ``2 d`` of each other at some positions
        ``x_r`` (its ``x_build``, with the pairs' distances there), kept while no pair of
        the list outside it can be within ``d`` at ``xa`` (twice the motion radius since
        ``x_r`` less than ``d``, with a margin for round-off): the pair searches of the
        Newton iterates read it instead of the whole list, whose skin a step filter's
        rebuild may make wide."""
        c, d = self._list(xa), self.params.distance
        sub = self._near
        if sub is not None and sub[0] is c and near_list_holds(sub[1], xa, distance=d):
            return sub[1]
        near = near_list(c, xa, distance=d)
        self._near = (c, near)
        return near

    def pairs(self, xa: FloatArray) -> BarrierPairs:
        """The pairs within the activation distance at positions ``xa`` (N, 3) [m]."""
        return barrier_pairs(
            xa, self.surface, self._near_list(xa), distance=self.params.distance,
            vertex_area=self.vertex_area,
        )  # fmt: skip

    def energy(self, x: PETSc.Vec | None = None) -> float:
        """Barrier energy plus this step's friction potential [J] at ``x`` (default: the
        model's state; collective)."""
        return self._terms(self.positions(x), hessian=False)[0]

    # ----------------------------------------------------------------- friction
    def begin_step(self, x: PETSc.Vec, dt: float) -> None:
        """Freeze the layer friction's pairs at the step's start ``x`` for a step of ``dt``
        [s] (collective). A candidate list a step filter built wider than the skin is
        dropped here: it served one Newton step's path, and its size would slow every pair
        search of the steps after."""
        c = self.candidates
        if c is not None and c.skin > self.params.skin_length:
            self.candidates = None
        if self.params.mu == 0.0:
            return
        t0 = time.perf_counter()
        xa = self.positions(x)
        rows = [(pr.idx, pr.coef, en[3]) for pr, en in self._barrier_parts(xa, hessian=False)]
        idx, coef, force = (np.concatenate(a) for a in zip(*rows, strict=True))
        self._fric = friction_pairs(xa, idx, coef, force)
        self._eps = self.params.slip_velocity * dt
        self.wall += time.perf_counter() - t0

    def end_step(self, x: PETSc.Vec) -> None:
        """Add the friction's work over the accepted step ending at ``x`` (collective)."""
        if self._fric is None:
            return
        w = friction_work(self.positions(x), self._fric, mu=self.params.mu, eps=self._eps)
        self.friction_work += w
        self._work += w

    # ----------------------------------------------------------------- residual, Jacobian
    def _edge_pairs(self, xa: FloatArray) -> EdgePairs | None:
        """The edge-edge pairs within d at ``xa`` (after :meth:`pairs` made the list valid)."""
        if not self.params.edges:
            return None
        p = self.params
        return edge_pairs(
            xa, self.X, self._near_list(xa), distance=p.distance, edge_area=self.edge_area
        )

    def _selected(self, xa: FloatArray) -> tuple[BarrierPairs, EdgePairs | None]:
        """The node-triangle and edge-edge pairs within d at ``xa``; those of the last
        positions asked are kept (the Jacobian and the step's start ask again for the
        positions of the last residual)."""
        c = self._list(xa)
        last = self._chosen
        if last is not None and last[0] is c and np.array_equal(last[1], xa):
            return last[2]
        chosen = (self.pairs(xa), self._edge_pairs(xa))
        self._chosen = (c, xa.copy(), chosen)
        return chosen

    def _barrier_parts(self, xa: FloatArray, *, hessian: bool) -> list[tuple]:
        """Per kind of pair within d at ``xa`` (node-triangle, then edge-edge): the pairs
        and :func:`pair_energy` / :func:`edge_energy` of them (energy, gradients, Hessians,
        forces)."""
        bp, ep = self._selected(xa)
        parts = [(bp, pair_energy(xa, bp, params=self.params, hessian=hessian))]
        if ep is not None:
            parts.append((ep, edge_energy(xa, ep, params=self.params, hessian=hessian)))
        return parts

    def _terms(self, xa: FloatArray, *, hessian: bool) -> tuple:
        """At positions ``xa``: the energy [J], per kind of pair (the barrier's node-triangle
        and edge-edge pairs, the friction's) the node groups (M, 4), gradients (M, 12) and
        Hessians (M, 12, 12; None unless ``hessian``), and the barrier's diagnostics (pairs,
        smallest distance, energy, force)."""
        p, h = self.params, hessian
        e, parts, dist, force = 0.0, [], [], []
        for pr, (pe, pg, ph, pf) in self._barrier_parts(xa, hessian=h):
            e += pe
            parts.append((pr.idx, pg, ph))
            dist.append(pr.dist)
            force.append(pf)
        d = np.concatenate(dist)
        last = (len(d), float(np.min(d, initial=math.inf)), e, float(np.concatenate(force).sum()))
        fp = self._fric
        if fp is not None:
            fe, fg, fh = friction_energy(xa, fp, mu=p.mu, eps=self._eps, hessian=h)
            e += fe
            parts.append((fp.idx, fg, fh))
        return e, parts, last

    def gradient(self, xa: FloatArray) -> FloatArray:
        """dE/dx (N, 3) [N] of the barrier and this step's friction at the positions ``xa``
        (N, 3) [m] of all nodes (the forces on the nodes are its negative)."""
        _, parts, self._last = self._terms(xa, hessian=False)
        idx, grad = (np.concatenate(a) for a in list(zip(*parts, strict=True))[:2])
        n, node, g = self.surface.n_nodes, idx.ravel(), grad.reshape(-1, 3)
        # summed in the pairs' order, as np.add.at would (bincount is its fast form)
        return np.column_stack([np.bincount(node, weights=g[:, k], minlength=n) for k in range(3)])

    def add_residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None:
        """f += dE/dx on this rank's u rows (collective)."""
        t0 = time.perf_counter()
        G = self.gradient(self.positions(x))
        fa = f.getArray()
        fa[: 3 * self.n] += G[self.lo : self.lo + self.n].ravel()
        self.wall += time.perf_counter() - t0

    def _layout(self, K: PETSc.Mat, kp: IntArray, ki: IntArray, need: IntArray | None = None):
        """The combined pattern of ``K`` and the node-pair blocks of the candidate list's
        pairs built within ``d + skin`` (not the wider skin a filter rebuild may take), plus
        those of the node groups ``need`` (M, 4) when given, else of the groups the list's
        last pattern took: a pattern missing a block of the pairs in use is rebuilt with
        them (:meth:`jacobian`), and a list keeps them while it lives. ``kp``, ``ki``: the
        CSR row pointers and columns of ``K``."""
        c = self.candidates
        if (
            need is None
            and self._pattern is not None
            and self._pattern[0] is c
            and np.array_equal(self._pattern[1], kp)
            and np.array_equal(self._pattern[2], ki)
        ):
            return self._pattern[3]
        reach = self.params.distance + self.params.skin_length
        extra = need if need is not None else self._extra_groups()
        groups = np.concatenate(
            [c.pt_nodes[c.pt_dist < reach], c.ee_nodes[c.ee_dist < reach], extra]
        )
        nloc, ncol = K.getLocalSize()[0], np.int64(K.getSize()[1])
        a = np.repeat(groups, 4, axis=1).ravel()
        b = np.tile(groups, (1, 4)).ravel()
        own = (a >= self.lo) & (a < self.lo + self.n)
        ab = np.unique(np.column_stack([a[own], b[own]]), axis=0)
        rows = (3 * (ab[:, :1] - self.lo) + np.arange(3))[:, :, None]  # (P, 3, 1)
        cols = (self.row0[ab[:, 1]][:, None] + np.arange(3))[:, None, :]  # (P, 1, 3)
        h_keys = (rows.astype(np.int64) * ncol + cols).ravel()
        k_rows = np.repeat(np.arange(nloc), np.diff(kp)).astype(np.int64)
        k_keys = k_rows * ncol + ki
        keys = np.union1d(k_keys, h_keys)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(keys // ncol, minlength=nloc))])
        indices = (keys % ncol).astype(PETSc.IntType)
        if self._C is not None:
            self._C.destroy()
        indptr = indptr.astype(PETSc.IntType)
        self._C_data = None
        if self.comm.size == 1:  # SeqAIJ on our arrays: jacobian() writes the values in place
            self._C_data = np.zeros(len(keys))
            C = PETSc.Mat().createAIJWithArrays(
                K.getSizes(), (indptr, indices, self._C_data), comm=K.getComm()
            )
        else:  # MPIAIJ copies into its diagonal / off-diagonal parts: jacobian() sets rows
            C = PETSc.Mat().createAIJ(size=K.getSizes(), comm=K.getComm())
            C.setPreallocationCSR((indptr, indices))
        C.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATION_ERR, True)
        self._C = C
        lay = (keys, indptr, indices, np.searchsorted(keys, k_keys), ncol)
        self._pattern = (c, kp.copy(), ki.copy(), lay)
        self._extra = (c, extra)
        return lay

    def _extra_groups(self) -> IntArray:
        """The node groups (M, 4) the current list's patterns hold beyond its near pairs."""
        e = self._extra
        if e is None or e[0] is not self.candidates:
            return np.zeros((0, 4), dtype=np.intp)
        return e[1]

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat) -> PETSc.Mat:
        """K + d^2E/dx^2 as a matrix of its own (the pattern of ``K`` joined with the node-pair
        blocks of the candidate list's near pairs; kept while both are and while it holds
        the pairs in use), collective."""
        t0 = time.perf_counter()
        xa = self.positions(x)
        _, parts, _ = self._terms(xa, hessian=True)  # (re)builds the list first
        kp, ki, kv = K.getValuesCSR()
        lay = self._layout(K, kp, ki)
        data = self._sum(lay, kv, parts)
        if not self.comm.allreduce(data is not None, op=MPI.LAND):  # a pair outside the list's
            lay = self._layout(K, kp, ki, need=np.concatenate([q[0] for q in parts]))
            data = self._sum(lay, kv, parts)
        C = self._C
        if self._C_data is None:
            C.setValuesCSR(lay[1], lay[2], data)
        C.assemble()  # also marks the new values
        self.wall += time.perf_counter() - t0
        return C

    def _sum(self, lay: tuple, kv: FloatArray, parts: list[tuple]) -> FloatArray | None:
        """The values of the layout ``lay``: K's values ``kv``, then the rows of this rank's
        nodes of the pairs' Hessians in their order (:func:`.barrier_kernels.add_blocks`),
        or None if the layout misses a block of them."""
        keys, indptr, indices, pos_k, _ = lay
        data = np.zeros(len(keys)) if self._C_data is None else self._C_data
        data[:] = 0.0
        data[pos_k] = kv
        for node, _, hess in parts:
            node = np.ascontiguousarray(node, dtype=np.int64)
            if not bk.add_blocks(hess, node, self.lo, self.n, self.row0, indptr, indices, data):
                return None
        return data

    # ----------------------------------------------------------------- checkpoint
    def state_arrays(self) -> dict[str, np.ndarray]:
        """What fixes the pairs and the Jacobian's pattern of the next steps: the candidate
        list's build positions ``x_build`` (N, 3) [m] (no rows: no list yet) and ``skin``
        [m], and the node groups ``need`` (M, 4) its pattern holds beyond the near pairs.
        The same on every rank; restore with :meth:`restore_arrays`. (The friction's pairs
        are frozen again at every step's start, :meth:`begin_step`.)"""
        c = self.candidates
        return {
            "x_build": c.x_build.copy() if c is not None else np.zeros((0, 3)),
            "skin": np.array(c.skin if c is not None else 0.0),
            "need": self._extra_groups().astype(np.int64),
        }

    def restore_arrays(self, data: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`state_arrays`: the list built again at its build positions
        (:func:`~clothfem.contact.self_contact.build_candidates` is deterministic), whose
        first pattern then takes the saved groups."""
        x = np.asarray(data["x_build"], dtype=float)
        if len(x) == 0:
            self.candidates = self._extra = None
            return
        if x.shape != self.X.shape:
            raise ValueError("checkpoint barrier state does not match this mesh")
        p = self.params
        c = build_candidates(x, self.surface, distance=p.distance, skin=float(data["skin"]))
        self.candidates = c
        self._extra = (c, np.asarray(data["need"], dtype=np.intp).reshape(-1, 4))

    # ----------------------------------------------------------------- step filter
    def max_step(self, x0: FloatArray, dx: FloatArray) -> float:
        """The largest fraction ``alpha`` in 1, 1/2, 1/4, ... of the Newton step ``dx`` from
        ``x0`` (this rank's (u, theta) arrays) with no crossing along the path and every
        pair within d at least ``floor`` times its distance at the end (0 if none down to
        2^-30; collective, the same value on every rank).

        Only the pairs whose distance bounds
        (:class:`~clothfem.contact.self_contact.FilterBounds`) leave a crossing or the
        floor possible reach the exact tests: the others pass them anyway."""
        t0 = time.perf_counter()
        p, n = self.params, self.n
        xa0 = self.positions(x0)
        D = self._gather(dx[: 3 * n])
        move = float(np.max(np.linalg.norm(D, axis=1), initial=0.0))
        alpha = min(1.0, p.max_move * p.distance / move) if move > 0 else 1.0
        alpha = 2.0 ** math.floor(math.log2(alpha)) if alpha < 1.0 else 1.0
        eps = p.eps * p.distance
        bounds: FilterBounds | None = None
        for _ in range(31):
            xa1 = xa0 + alpha * D
            c0 = self.candidates
            c = self._list(xa0, xa1, span=alpha * move)
            ok = c is c0 or c.valid(xa0, xa1)  # a list kept is valid at both
            if ok:
                if bounds is None or bounds.cands is not c:
                    bounds = FilterBounds(c, xa0, D, distance=p.distance, floor=p.floor, eps=eps)
                if not bounds.all_clear(alpha):
                    (c_pt, c_ee), (f_pt, f_ee) = bounds.rows(alpha)
                    # the explicit fail-safe's check on the pairs that can cross
                    ok = not (len(c_pt) or len(c_ee)) or not any(
                        len(g)
                        for g in crossing_groups(c.subset(c_pt, c_ee), self.surface, xa0, xa1, eps)
                    )
                    # every listed pair keeps at least floor x min(its distance, d)
                    ok = ok and all(
                        len(r) == 0
                        or bool(
                            np.all(f(xa1, c, r) >= p.floor * np.minimum(f(xa0, c, r), p.distance))
                        )
                        for f, r in ((_pt_distance, f_pt), (_ee_distance, f_ee))
                    )
            if ok:
                break
            alpha *= 0.5
        else:
            alpha = 0.0
        if alpha < 1.0:
            self.filtered += 1
        self.wall += time.perf_counter() - t0
        return alpha

    def record(self) -> SelfBarrierRecord:
        """Diagnostics at the last residual evaluation, counters since the last call."""
        pairs, dmin, e, force = self._last
        rec = SelfBarrierRecord(
            pairs=pairs, min_distance=dmin, energy=e, force=force, filtered=self.filtered,
            rebuilds=self.rebuilds, wall=self.wall, friction_work=self._work,
        )  # fmt: skip
        self.filtered = self.rebuilds = 0
        self.wall = self._work = 0.0
        return rec

    def intersections(self) -> int:
        """Intersecting triangle pairs of the current surface by the independent checker
        (collective: rank 0 counts, the count is broadcast)."""
        from .intersections import intersecting_pairs

        x = self.positions()
        count = len(intersecting_pairs(x, self.surface.triangles)) if self.comm.rank == 0 else 0
        return int(self.comm.bcast(count, root=0))

    @classmethod
    def from_scene(cls, system, contact: ContactSpec) -> SelfBarrier | None:
        """From a scene's ``contact`` section: None unless ``self_contact`` is true; the
        activation distance ``self_distance`` [m] (default: the fabric thickness), the
        layer friction ``self_mu`` (default: ``mu``) and the pressure ``self_pressure``
        [Pa] of two layers at half that distance."""
        if not contact.self_contact:
            return None
        d = contact.self_distance or system.model.thickness
        mu = contact.mu if contact.self_mu is None else contact.self_mu
        params = SelfBarrierParameters(distance=d, mu=mu, pressure=contact.self_pressure)
        return cls(system, params=params)
