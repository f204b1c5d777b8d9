"""Fabric self-contact for the explicit integrator: proximity corrections consistent with FILM
plus a continuous-collision fail-safe (NumPy and SciPy; the MPI wrapper at the end).

Pipeline (each stage a small function on whole arrays):

surface (8 triangles per 9-node cell) -> candidate list (cKDTree broad phase, kept while the
relative motion of nearby nodes stays below the skin) -> node-triangle (and edge-edge) gaps
and side-aware normals -> position projection (mass-weighted, Eq. 25 per pair) -> inelastic
normal impulses -> Coulomb friction impulses -> continuous crossing check over the step
(node-triangle and edge-edge) -> impact zones -> diagnostics.

The response stages run as projected Gauss-Seidel sweeps and the distance loops of the
narrow phase as plain loops, compiled by numba (Debian's python3-numba) on first use when it
imports; without numba the NumPy references run (an accelerated projected Jacobi for the
response, vectorised geometry), tested to agree.

Conventions:

* ``distance`` ``d`` [m]: the contact distance between mid-surfaces (the fabric thickness, or
  a stated multiple); a pair is admissible when ``gap >= d``.
* A pair is a node ``p`` against a triangle ``(a, b, c)`` with barycentric weights ``w`` of
  the closest point ``q = w0 a + w1 b + w2 c``: coefficients ``(1, -w0, -w1, -w2)`` on the
  nodes ``(p, a, b, c)``, normal ``n`` pointing from the triangle to the node, ``gap = (p -
  q) . n``. A normal impulse ``J >= 0`` [N s] changes node ``k``'s velocity by ``coef_k J n /
  m_k``; the coefficients sum to zero, so every correction is an internal impulse (linear
  momentum is conserved to round-off).
* Nodes with prescribed displacements have zero inverse mass (they are never corrected).

FILM consistency (:mod:`clothfem.contact.explicit`): positions are projected onto the
admissible set (``gap = d``) with the lumped masses (``lambda = m_eff (d - gap*) / dt^2``,
Eq. 25 for one pair), the relative normal velocity of a pair in contact is brought to zero
(non-resilient impact), and the tangential relative velocity is reduced by at most ``mu``
times the normal impulse; the friction velocity change also moves the positions (``dx = dt
dv_t``), so sticking layers do not creep.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..spec import ContactSpec

__all__ = [
    "CandidateList",
    "FabricSurface",
    "FilterBounds",
    "PairContacts",
    "SelfContact",
    "SelfContactParameters",
    "SelfContactRecord",
    "SelfContactResult",
    "build_candidates",
    "check_resolution",
    "closest_point_triangle",
    "edge_contacts",
    "edge_edge_crossings",
    "fabric_surface",
    "global_cells",
    "mesh_nodes",
    "motion_radius",
    "friction_impulses",
    "near_pairs",
    "normal_impulses",
    "pair_contacts",
    "crossing_groups",
    "point_triangle_crossings",
    "project_positions",
    "segment_closest",
    "segment_distance",
    "self_contact_step",
    "triangulate_q9",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# boundary nodes of a dolfinx 9-node quadrilateral (basix Q2 order: vertices (0,0), (1,0),
# (0,1), (1,1), mid-edges (.5,0), (0,.5), (1,.5), (.5,1), centre) counter-clockwise
Q9_RING = np.array([0, 4, 1, 6, 3, 7, 2, 5])
Q9_CENTRE = 8
_FACE_EPS = 1e-9  # barycentric weight above which the closest point is inside the face
_TILE_SPLIT = 2  # tiles per reach of the list's validity bound (Tiles)


# --------------------------------------------------------------------------- surface
def triangulate_q9(cells: ArrayLike) -> tuple[IntArray, IntArray]:
    """The 8 triangles of each 9-node cell (a fan about the centre node through the corner and
    mid-side nodes, oriented like the cell): (8 C, 3) node indices and the cell of each."""
    c = np.asarray(cells)
    if c.ndim != 2 or c.shape[1] != 9:
        raise ValueError(f"cells must have shape (C, 9) (9-node quadrilaterals), got {c.shape}")
    ring = c[:, Q9_RING]
    tri = np.stack([ring, np.roll(ring, -1, axis=1), np.repeat(c[:, [Q9_CENTRE]], 8, 1)], -1)
    return tri.reshape(-1, 3).astype(np.intp), np.repeat(np.arange(len(c)), 8)


@dataclass(frozen=True)
class FabricSurface:
    """Triangulated fabric surface: ``triangles`` (T, 3) and ``edges`` (E, 2) node indices,
    ``cell_of`` (T,) the 9-node cell of each triangle, ``near_keys`` the sorted keys ``a n +
    b`` of the node pairs within ``rings`` cell rings (never in contact with each other)."""

    triangles: IntArray
    cell_of: IntArray
    edges: IntArray
    n_nodes: int
    near_keys: NDArray[np.int64]
    rings: int


def fabric_surface(cells: ArrayLike, *, n_nodes: int, rings: int = 0) -> FabricSurface:
    """Surface of 9-node ``cells`` (C, 9) on ``n_nodes`` nodes. Nodes ``a``, ``b`` are *near*
    (excluded from contact) when ``a == b`` (``rings = 0``: a node never contacts its own
    triangles, an edge never an edge sharing a node) or when a chain of at most ``rings``
    cells, consecutive ones sharing a node, joins them (``rings = 1``: they share a cell)."""
    if int(rings) != rings or rings < 0:
        raise ValueError(f"rings must be an integer >= 0, got {rings!r}")
    c = np.asarray(cells, dtype=np.intp)
    tri, cell_of = triangulate_q9(c)
    if c.size and (c.min() < 0 or c.max() >= n_nodes):
        raise ValueError(f"cells must index nodes 0..{n_nodes - 1}, got {c.min()}..{c.max()}")
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges = np.unique(e, axis=0)
    if rings == 0:
        keys = np.arange(n_nodes, dtype=np.int64) * (n_nodes + 1)
        return FabricSurface(tri, cell_of, edges, int(n_nodes), keys, 0)
    inc = sp.csr_matrix(
        (np.ones(c.size), (np.repeat(np.arange(len(c)), 9), c.ravel())), shape=(len(c), n_nodes)
    )
    share = (inc.T @ inc).astype(bool).astype(np.int8).tocsr()
    reach = share
    for _ in range(int(rings) - 1):
        reach = (reach @ share).astype(bool).astype(np.int8).tocsr()
    coo = reach.tocoo()
    keys = np.sort(coo.row.astype(np.int64) * n_nodes + coo.col)
    return FabricSurface(tri, cell_of, edges, int(n_nodes), keys, int(rings))


def near_pairs(surface: FabricSurface, a: ArrayLike, b: ArrayLike) -> NDArray[np.bool_]:
    """Whether nodes ``a[i]`` and ``b[i]`` are near (within the surface's cell rings)."""
    keys = np.asarray(a, dtype=np.int64) * surface.n_nodes + np.asarray(b, dtype=np.int64)
    k = surface.near_keys
    i = np.minimum(np.searchsorted(k, keys), len(k) - 1)
    return k[i] == keys


# --------------------------------------------------------------------------- geometry
def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.einsum("ij,ij->i", a, b)


def closest_point_triangle(
    p: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Closest points of ``p`` on triangles ``(a, b, c)`` (all (M, 3)) by the Voronoi regions
    of Ericson (2005), Sec. 5.1.5: the points (M, 3) and their barycentric weights (M, 3)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4, d5, d6 = _dot(ab, bp), _dot(ac, bp), _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = vb / den, vc / den
        bary = np.stack([1.0 - v - w, v, w], axis=1)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        t_ac = d2 / (d2 - d6)
        t_ab = d1 / (d1 - d3)
    one = np.ones_like(d1)
    zero = np.zeros_like(d1)
    # regions in reverse order of precedence (vertex A first in Ericson's tests)
    regions = [
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), (zero, 1 - t_bc, t_bc)),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), (1 - t_ac, zero, t_ac)),
        ((d6 >= 0) & (d5 <= d6), (zero, zero, one)),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), (1 - t_ab, t_ab, zero)),
        ((d3 >= 0) & (d4 <= d3), (zero, one, zero)),
        ((d1 <= 0) & (d2 <= 0), (one, zero, zero)),
    ]
    for sel, (w0, w1, w2) in regions:
        bary[sel] = np.stack([w0, w1, w2], axis=1)[sel]
    q = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return q, bary


def segment_closest(
    p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Closest points of segments ``p1 p2`` and ``q1 q2`` (Ericson 2005, Sec. 5.1.9): the
    parameters ``s``, ``t`` in [0, 1] along each and the distances (M,) [m]."""
    d1, d2, r = p2 - p1, q2 - q1, p1 - q1
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    c, b = _dot(d1, r), _dot(d1, d2)
    den = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-300, np.clip((b * f - c * e) / den, 0, 1), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    return s, t, np.linalg.norm(p1 + s[:, None] * d1 - q1 - t[:, None] * d2, axis=1)


def segment_distance(p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray) -> FloatArray:
    """Distances (M,) [m] between segments ``p1 p2`` and ``q1 q2``."""
    return segment_closest(p1, p2, q1, q2)[2]


def _pt_distances(x: FloatArray, idx: IntArray) -> FloatArray:
    """Distances (M,) [m] of node ``idx[:, 0]`` to triangle ``idx[:, 1:]`` (numba loop when
    numba imports, else :func:`closest_point_triangle`)."""
    if len(idx) == 0:
        return np.zeros(0)
    if _numba_kernels():
        out = np.empty(len(idx))
        _numba_kernels()[4](x, np.ascontiguousarray(idx, dtype=np.int64), out)
        return out
    q, _ = closest_point_triangle(*(x[idx[:, k]] for k in range(4)))
    return np.linalg.norm(x[idx[:, 0]] - q, axis=1)


def _ee_distances(x: FloatArray, idx: IntArray) -> FloatArray:
    """Distances (M,) [m] of segments ``idx[:, :2]`` and ``idx[:, 2:]`` (numba loop when
    numba imports, else :func:`segment_distance`)."""
    if len(idx) == 0:
        return np.zeros(0)
    if _numba_kernels():
        out = np.empty(len(idx))
        _numba_kernels()[5](x, np.ascontiguousarray(idx, dtype=np.int64), out)
        return out
    return segment_distance(*(x[idx[:, k]] for k in range(4)))


def _unit_normals(x: FloatArray, tri: IntArray) -> FloatArray:
    n = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


# --------------------------------------------------------------------------- broad phase
@dataclass(frozen=True)
class CandidateList:
    """Pairs that can come within the contact distance (point-triangle) or cross (edge-edge)
    while the relative motion since ``x_build`` stays small (a Verlet list, :meth:`valid`):
    the node ``pt_node`` against triangle ``pt_tri`` at distance ``pt_dist`` [m] at build,
    edges ``ee[:, 0]``, ``ee[:, 1]`` (rows of the surface's edges) at ``ee_dist`` [m]; the
    nodes of each pair in ``pt_nodes`` and ``ee_nodes``; the tiles of :func:`_tiles`."""

    x_build: FloatArray
    skin: float
    pt_node: IntArray
    pt_tri: IntArray
    pt_dist: FloatArray
    ee: IntArray
    ee_dist: FloatArray
    pt_nodes: IntArray  # (M, 4) the node and the triangle's nodes of each pair
    ee_nodes: IntArray  # (K, 4) the nodes of both edges of each pair
    tiles: Tiles

    def valid(self, *xs: FloatArray) -> bool:
        """Whether no unlisted pair can be within ``distance`` (or cross) at any of ``xs``.

        A pair's distance changes by at most the largest relative displacement (since the
        build) of a node of one side and a node of the other. Nodes in the same or touching
        tiles (edge ``R = 2 L + distance + 3 skin``, ``L`` the longest edge) stay within
        ``skin`` of each other's displacement when each node's displacement from its tile's
        mean plus the difference of the tile means do; so do the nodes of one triangle or
        edge (at most ``L`` apart). An unlisted pair (at least ``distance + skin`` apart)
        whose nodes are all in touching tiles then stays at least ``distance`` apart. If
        some of its nodes are in touching tiles and some not, it was at least ``R - 2 L``
        apart and moves by at most ``3 skin`` relative to itself (through a node pair in
        touching tiles: ``skin`` along each side, ``skin`` across). If none are, it was at
        least ``R - L`` apart and stays at least ``distance`` apart while no node moved more
        than ``(R - L - distance) / 2`` from a common point (the centre of the displacements'
        bounding box: a rigid translation of everything costs nothing). Rigid motion of a
        region costs nothing but the rotation across a few tiles. Cheaper and enough when
        it holds: twice the :func:`motion_radius` of the displacements since the build
        (with a margin for round-off) is below ``skin``, so no pair's distance fell by as
        much as ``skin``."""
        return all(
            self._moved_less(x) or self.tiles.spread(x - self.x_build) <= self.skin for x in xs
        )

    def _moved_less(self, x: FloatArray) -> bool:
        """Whether twice the motion radius since the build, with the round-off margin of
        :func:`bound_tolerance`, is below the skin at ``x`` (N, 3) [m]."""
        moved = 2.0 * motion_radius(x - self.x_build)
        return moved + bound_tolerance(x, distance=self.skin) < self.skin

    def subset(self, pt: IntArray, ee: IntArray) -> CandidateList:
        """The list of the point-triangle pairs ``pt`` and the edge pairs ``ee`` (rows, in
        order) of this one, with its build positions and tiles."""
        return replace(
            self, pt_node=self.pt_node[pt], pt_tri=self.pt_tri[pt], pt_dist=self.pt_dist[pt],
            ee=self.ee[ee], ee_dist=self.ee_dist[ee], pt_nodes=self.pt_nodes[pt],
            ee_nodes=self.ee_nodes[ee],
        )  # fmt: skip

    @cached_property
    def _by_distance(self) -> tuple[tuple[IntArray, FloatArray], tuple[IntArray, FloatArray]]:
        """Per kind (point-triangle, edge-edge): the rows in order of build distance and
        those distances."""
        out = []
        for dist in (self.pt_dist, self.ee_dist):
            order = np.argsort(dist, kind="stable")
            out.append((order, dist[order]))
        return out[0], out[1]

    def rows_within(self, limit: float, *, edges: bool) -> IntArray:
        """The rows, in list order, of the point-triangle (edge-edge if ``edges``) pairs
        whose build distance is at most ``limit`` [m] (and a few ulps beyond: callers test
        their own bound on these rows), found in the rows sorted by build distance."""
        order, dist = self._by_distance[int(edges)]
        k = np.searchsorted(dist, limit + 4.0 * np.spacing(abs(limit)), side="right")
        if 16 * k < len(order):
            return np.sort(order[:k])
        mask = np.zeros(len(order), dtype=bool)
        mask[order[:k]] = True
        return np.flatnonzero(mask)

    @cached_property
    def min_distance(self) -> float:
        """The smallest build distance [m] of a listed pair (inf for none)."""
        return min(
            float(np.min(self.pt_dist, initial=np.inf)),
            float(np.min(self.ee_dist, initial=np.inf)),
        )


class Tiles(NamedTuple):
    """Cubes of edge ``size`` [m] holding the nodes at build: ``tile`` (N,) of each node,
    ``order``/``starts`` the nodes sorted by tile, ``pairs`` (P, 2) the tiles touching each
    other (and themselves, ``pairs[:, 0] <= pairs[:, 1]``), ``far`` [m] the largest
    displacement allowed to any node."""

    size: float
    tile: IntArray
    order: IntArray
    starts: IntArray
    pairs: IntArray
    far: float

    def spread(self, D: FloatArray) -> float:
        """The relative-displacement bound of nodes in touching tiles for displacements
        ``D`` (N, 3) [m] (each node against its tile's mean, plus the difference of the two
        tiles' means), inf when a node's displacement is more than ``far`` from the centre
        of their bounding box (compiled loop when numba imports)."""
        if len(D) == 0:
            return 0.0
        centre = 0.5 * (D.max(axis=0) + D.min(axis=0))
        if _numba_kernels():
            D = np.ascontiguousarray(D, dtype=float)
            far2 = self.far**2
            return _numba_kernels()[9](D, centre, self.tile, self.pairs, len(self.starts), far2)
        Dc = D - centre
        if float(np.max(np.einsum("ij,ij->i", Dc, Dc))) > self.far**2:
            return np.inf
        Ds = D[self.order]
        counts = np.diff(np.r_[self.starts, len(D)])
        mean = np.add.reduceat(Ds, self.starts, axis=0) / counts[:, None]
        r = Ds - np.repeat(mean, counts, axis=0)
        rmax = np.maximum.reduceat(np.sqrt(np.einsum("ij,ij->i", r, r)), self.starts)
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        dm = mean[a] - mean[b]
        return float(np.max(rmax[a] + np.sqrt(np.einsum("ij,ij->i", dm, dm)) + rmax[b]))


def _tiles(x: FloatArray, *, longest: float, distance: float, skin: float) -> Tiles:
    """Tiles of edge ``R / 2`` (``R = 2 longest + distance + 3 skin``) over the nodes ``x``
    and their pairs within two tiles of each other ("touching": nodes closer than ``R`` are
    in such a pair, nodes in no such pair are more than ``R`` apart); any node may then move
    ``(longest + 3 skin) / 2`` before the list expires (:meth:`CandidateList.valid`)."""
    reach = 2.0 * longest + distance + 3.0 * skin
    size = reach / _TILE_SPLIT
    key = np.floor(x / size).astype(np.int64)
    key -= key.min(axis=0) - _TILE_SPLIT
    base = int(key.max()) + _TILE_SPLIT + 1
    code = (key[:, 0] * base + key[:, 1]) * base + key[:, 2]
    uniq, tile = np.unique(code, return_inverse=True)
    k3 = np.stack([uniq // (base * base), (uniq // base) % base, uniq % base], 1)
    pairs = []
    steps = np.arange(-_TILE_SPLIT, _TILE_SPLIT + 1)
    for off in np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), -1).reshape(-1, 3):
        kk = k3 + off
        c = (kk[:, 0] * base + kk[:, 1]) * base + kk[:, 2]
        j = np.minimum(np.searchsorted(uniq, c), len(uniq) - 1)
        hit = np.flatnonzero(uniq[j] == c)
        pairs.append(np.column_stack([hit, j[hit]]))
    p = np.concatenate(pairs)
    order = np.argsort(tile, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(tile[order]) != 0])
    far = 0.5 * (reach - longest - distance)
    return Tiles(size, tile.astype(np.int64), order, starts, p[p[:, 0] <= p[:, 1]], far)


def motion_radius(D: FloatArray) -> float:
    """``max_i |D_i - c|`` [m] over the displacements ``D`` (N, 3), ``c`` the centre of their
    bounding box: two nodes' displacements differ by at most twice this, so no pair's
    distance changes by more (a rigid translation costs nothing)."""
    if len(D) == 0:
        return 0.0
    Dc = D - 0.5 * (D.max(axis=0) + D.min(axis=0))
    return float(np.sqrt(np.max(np.einsum("ij,ij->i", Dc, Dc))))


def _moved(x: FloatArray, x_ref: FloatArray) -> FloatArray:
    return np.sqrt(np.einsum("ij,ij->i", x - x_ref, x - x_ref))


def _relative_motion(D: FloatArray, g: IntArray, split: int) -> FloatArray:
    """Largest ``|D_i - D_k|`` (M,) [m] over the nodes ``i`` of one side (the first ``split``
    columns of ``g``) and ``k`` of the other: a bound on the change of the pair's distance."""
    if len(g) and _numba_kernels():
        out = np.empty(len(g))
        _numba_kernels()[3](
            np.ascontiguousarray(D), np.ascontiguousarray(g, dtype=np.int64), split, out
        )
        return out
    Dg = D[g]
    diff = Dg[:, :split, None, :] - Dg[:, None, split:, :]
    return np.sqrt(np.max(np.einsum("mabk,mabk->mab", diff, diff), axis=(1, 2), initial=0.0))


def _far(surface: FabricSurface, a: IntArray, b: IntArray) -> NDArray[np.bool_]:
    """Rows where no node of ``a`` (M, i) is near a node of ``b`` (M, j)."""
    far = np.ones(len(a), dtype=bool)
    for i in range(a.shape[1]):
        for j in range(b.shape[1]):
            far &= ~near_pairs(surface, a[:, i], b[:, j])
    return far


def build_candidates(
    x: FloatArray, surface: FabricSurface, *, distance: float, skin: float, edges: bool = True
) -> CandidateList:
    """Candidate pairs at positions ``x`` (N, 3): point-triangle pairs closer than
    ``distance + skin`` [m], edge pairs closer than that (``edges``: edge-edge proximity) or
    than ``skin`` (for the crossing check only), none near; sorted by node and triangle, by
    first and second edge (``ee[:, 0] < ee[:, 1]``). Broad phase: a uniform grid of the
    bounding boxes with the neighbour exclusion and the exact distances in one compiled loop
    (numba), else cKDTree queries (nodes against triangle centroids, edge midpoints against
    each other), the neighbour exclusion, then exact distances."""
    tri, edge = surface.triangles, surface.edges
    reach = distance + skin
    e_reach = reach if edges else skin + 0.01 * distance  # > skin + 2 eps (eps < 0.005 d)
    xe = x[edge]
    length = float(np.max(np.linalg.norm(xe[:, 0] - xe[:, 1], axis=1), initial=0.0))
    find = _grid_candidates if _numba_kernels() else _tree_candidates
    node, t, dist, ee, ed = find(x, surface, reach, e_reach)
    return CandidateList(
        x.copy(), float(skin), node, t, dist, ee, ed,
        np.column_stack([node, tri[t]]), edge[ee].reshape(-1, 4),
        _tiles(x, longest=length, distance=distance, skin=skin),
    )  # fmt: skip


def _sorted_pairs(a: IntArray, b: IntArray, dist: FloatArray) -> tuple:
    order = np.lexsort((b, a))
    return a[order], b[order], dist[order]


def _tree_candidates(x: FloatArray, surface: FabricSurface, reach: float, e_reach: float):
    """:func:`build_candidates` by cKDTree queries (without numba): node, triangle and
    distance of the point-triangle pairs, edge pairs (K, 2) and their distances."""
    tri, edge = surface.triangles, surface.edges
    xt = x[tri]
    cen = xt.mean(axis=1)
    rad = float(np.max(np.linalg.norm(xt - cen[:, None], axis=2), initial=0.0))
    hits = cKDTree(x).sparse_distance_matrix(cKDTree(cen), reach + rad, output_type="ndarray")
    node, t = hits["i"].astype(np.intp), hits["j"].astype(np.intp)
    far = np.flatnonzero(_far(surface, node[:, None], tri[t]))
    node, t = node[far], t[far]
    dist = _pt_distances(x, np.column_stack([node, tri[t]]))
    close = dist < reach
    node, t, dist = _sorted_pairs(node[close], t[close], dist[close])
    xe = x[edge]
    mid = xe.mean(axis=1)
    length = float(np.max(np.linalg.norm(xe[:, 0] - xe[:, 1], axis=1), initial=0.0))
    ee = cKDTree(mid).query_pairs(e_reach + length, output_type="ndarray").astype(np.intp)
    ee = ee[_far(surface, edge[ee[:, 0]], edge[ee[:, 1]])]
    ed = _ee_distances(x, np.column_stack([edge[ee[:, 0]], edge[ee[:, 1]]]))
    close = ed < e_reach
    e0, e1, ed = _sorted_pairs(ee[close, 0], ee[close, 1], ed[close])
    return node, t, dist, np.column_stack([e0, e1]), ed


def _near_csr(surface: FabricSurface) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The near relation as compressed rows: the near nodes of ``a`` are
    ``cols[ptr[a]:ptr[a + 1]]`` (sorted)."""
    n, k = surface.n_nodes, surface.near_keys
    ptr = np.searchsorted(k // n, np.arange(n + 1)).astype(np.int64)
    return ptr, (k % n).astype(np.int64)


def _grid_ranges(lo_a: FloatArray, lo_b: FloatArray, size: float, half: bool = False):
    """Items ``a`` and ``b`` in cubes of edge ``size`` [m] by the low corners of their boxes
    (``lo_a``, ``lo_b``): ``a`` sorted by cube with the cubes' starts, ``b`` sorted by cube,
    and per cube of ``a`` the ranges (in ``b``'s order) of the 27 cubes around it (any two
    boxes of edge at most ``size - reach`` within ``reach`` of each other are there);
    ``half`` (``a`` is ``b``): the cube itself first, then the 13 cubes after it."""
    origin = np.minimum(lo_a.min(axis=0), lo_b.min(axis=0))
    ca = np.floor((lo_a - origin) / size).astype(np.int64) + 1
    cb = np.floor((lo_b - origin) / size).astype(np.int64) + 1
    base = int(max(ca.max(), cb.max())) + 2
    ka, kb = ((c[:, 0] * base + c[:, 1]) * base + c[:, 2] for c in (ca, cb))
    a_item, b_item = np.argsort(ka, kind="stable"), np.argsort(kb, kind="stable")
    ua, a_start = np.unique(ka[a_item], return_index=True)
    ub, b_start = np.unique(kb[b_item], return_index=True)
    b_end = np.r_[b_start[1:], len(kb)]
    off = np.stack(np.meshgrid(*[[-1, 0, 1]] * 3, indexing="ij"), -1).reshape(-1, 3)
    step = (off[:, 0] * base + off[:, 1]) * base + off[:, 2]
    if half:
        step = np.sort(step[step >= 0])
    want = ua[:, None] + step[None, :]
    j = np.minimum(np.searchsorted(ub, want), len(ub) - 1)
    hit = ub[j] == want
    lo, hi = np.where(hit, b_start[j], 0), np.where(hit, b_end[j], 0)
    starts = np.r_[a_start, len(ka)]
    return a_item, starts, b_item, lo.astype(np.int64), hi.astype(np.int64)


def _grid_candidates(x: FloatArray, surface: FabricSurface, reach: float, e_reach: float):
    """:func:`build_candidates` on a uniform grid by the compiled loops (the same pairs and
    distances as :func:`_tree_candidates`): boxes within ``reach`` (slightly widened against
    round-off), not near, exact distance below ``reach``."""
    tri, edge = surface.triangles.astype(np.int64), surface.edges.astype(np.int64)
    scale = max(1.0, float(np.max(np.abs(x), initial=0.0)))
    ptr, cols = _near_csr(surface)
    kern = _numba_kernels()
    node, t, dist = (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0))
    if len(tri):
        xt = x[tri]
        lo, hi = xt.min(axis=1), xt.max(axis=1)
        node, t, dist = _grid_run(kern[7], x, tri, lo, hi, x, reach, scale, ptr, cols)
    ee, ed = np.zeros((0, 2), np.intp), np.zeros(0)
    if len(edge):
        xe = x[edge]
        lo, hi = xe.min(axis=1), xe.max(axis=1)
        e0, e1, ed = _grid_run(kern[8], x, edge, lo, hi, lo, e_reach, scale, ptr, cols, True)
        ee = np.column_stack([e0, e1])
    return node, t, dist, ee, ed


def _grid_run(kernel, x, items, lo, hi, lo_a, reach, scale, ptr, cols, half=False):
    """One grid kernel (:func:`_pt_grid_kernel` or :func:`_ee_grid_kernel`) over items
    ``a`` with boxes from ``lo_a`` and ``items`` with boxes ``lo``, ``hi``: the sorted pairs
    and their distances."""
    widened = reach * (1.0 + 1e-9) + 1e-12 * scale
    size = (float(np.max(hi - lo, initial=0.0)) + widened) * (1.0 + 1e-6)
    grid = _grid_ranges(lo_a, lo, size, half)
    cap = 4 * len(lo_a) + 1024
    while True:
        a, b, d = np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap)
        args = (x, items, lo, hi, *grid, widened, reach, ptr, cols)
        m = kernel(*args, a, b, d)
        if m <= cap:
            return _sorted_pairs(a[:m].astype(np.intp), b[:m].astype(np.intp), d[:m])
        cap = m


# --------------------------------------------------------------------------- narrow phase
class PairContacts(NamedTuple):
    """Point-triangle pairs: nodes ``idx`` (M, 4) = (p, a, b, c), coefficients ``coef`` (M, 4)
    = (1, -w0, -w1, -w2), unit ``normal`` (M, 3) from the triangle to the node, ``gap`` (M,)
    [m] along it, ``tri`` (M,) the triangle; edge pairs (:func:`edge_contacts`): the nodes
    of both edges, coefficients ``(1 - s, s, t - 1, -t)``, ``tri = -1``."""

    idx: IntArray
    coef: FloatArray
    normal: FloatArray
    gap: FloatArray
    tri: IntArray


def pair_contacts(
    x0: FloatArray,
    x: FloatArray,
    surface: FabricSurface,
    node: IntArray,
    tri: IntArray,
    *,
    kernel: str = "numpy",
) -> PairContacts:
    """Gaps and normals of node-triangle pairs at ``x``. Closest point inside the face: the
    triangle normal, signed by the side the node was on at the step's start ``x0`` when the
    pair's motion over the step can have taken it through the plane (then a node that
    passed through the face gets ``gap < 0``), else by its side now; on an edge or vertex:
    the direction from the closest point to the node. ``kernel``: "numpy", or "numba"/"auto" for the
    compiled loop (the same operations pair by pair)."""
    t = surface.triangles[tri]
    idx = np.column_stack([node, t])
    scale = max(1.0, float(np.max(np.abs(x[node]), initial=0.0)))
    if len(node) and _use_numba(kernel):
        coef, n, gap = np.empty((len(node), 4)), np.empty((len(node), 3)), np.empty(len(node))
        _numba_kernels()[2](
            x0, x, np.ascontiguousarray(idx, dtype=np.int64), scale, _FACE_EPS, coef, n, gap
        )
        return PairContacts(idx, coef, n, gap, tri)
    q, w = closest_point_triangle(x[node], x[t[:, 0]], x[t[:, 1]], x[t[:, 2]])
    r = x[node] - q
    dist = np.linalg.norm(r, axis=1)
    nf = _unit_normals(x, t)
    r0 = x0[node] - np.einsum("ij,ijk->ik", w, x0[t])
    n0 = _unit_normals(x0, t)
    s0, s1 = _dot(r0, n0), _dot(r, nf)
    now = np.where(s1 < 0, -1.0, 1.0)
    # the start's side counts only if the step's relative motion can have carried the node
    # through the face (a node-triangle distance changes by at most that motion, and
    # |r0| bounds the distance at the start); otherwise the crossing check decides
    reach = _relative_motion(x - x0, idx, 1) + 1e-15 * scale
    can = np.linalg.norm(r0, axis=1) + dist <= reach
    side = np.where((s0 != 0) & can, np.sign(s0), now)
    face = np.all(w > _FACE_EPS, axis=1) | (dist <= 1e-12 * scale)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(face[:, None], side[:, None] * nf, r / dist[:, None])
    gap = np.where(face, _dot(r, n), dist)
    coef = np.column_stack([np.ones(len(node)), -w])
    return PairContacts(idx, coef, n, gap, tri)


def edge_contacts(
    x0: FloatArray, x: FloatArray, surface: FabricSurface, ee: IntArray, *, kernel: str = "numpy"
) -> PairContacts:
    """Gaps and normals of edge pairs ``ee`` (M, 2) at ``x``: the normal points from the
    second edge's closest point to the first's, reversed (``gap < 0``) when the same points
    were on the other side at the step's start ``x0`` and the pair's motion over the step
    can have carried one edge through the other. ``kernel`` as for
    :func:`pair_contacts`."""
    e0, e1 = surface.edges[ee[:, 0]], surface.edges[ee[:, 1]]
    idx = np.column_stack([e0, e1])
    scale = max(1.0, float(np.max(np.abs(x0[idx.ravel()]), initial=0.0)))
    tri = np.full(len(ee), -1, dtype=np.intp)
    if len(ee) and _use_numba(kernel):
        coef, n, gap = np.empty((len(ee), 4)), np.empty((len(ee), 3)), np.empty(len(ee))
        _numba_kernels()[6](x0, x, np.ascontiguousarray(idx, dtype=np.int64), scale, coef, n, gap)
        return PairContacts(idx, coef, n, gap, tri)
    s, t, dist = segment_closest(*(x[idx[:, k]] for k in range(4)))
    coef = np.column_stack([1 - s, s, t - 1, -t])
    r, r0 = _relative(x, idx, coef), _relative(x0, idx, coef)
    tiny = dist <= 1e-12 * scale
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(tiny[:, None], r0 / np.linalg.norm(r0, axis=1)[:, None], r / dist[:, None])
    # reversed only if the step's relative motion can have carried one edge through the other
    can = np.linalg.norm(r0, axis=1) + dist <= _relative_motion(x - x0, idx, 2) + 1e-15 * scale
    side = np.where((_dot(r0, n) < 0) & (can | tiny), -1.0, 1.0)
    n = np.nan_to_num(side[:, None] * n, nan=0.0, posinf=0.0, neginf=0.0)
    return PairContacts(idx, coef, n, _dot(r, n), tri)


def _closest_per_key(c: PairContacts, key: IntArray) -> PairContacts:
    """Per ``key`` (the node of a node-triangle pair, the first edge of an edge pair) the
    closest pair on each side (normals agreeing with or opposing its closest pair's): a node
    pressed between two layers keeps both."""
    if len(c.gap) == 0:
        return c
    order = np.lexsort((c.gap, key))
    node = key[order]
    first = np.r_[True, node[1:] != node[:-1]]
    head = order[np.maximum.accumulate(np.where(first, np.arange(len(node)), 0))]
    group = node * 2 + (_dot(c.normal[order], c.normal[head]) < 0)
    by = np.lexsort((c.gap[order], group))
    g = group[by]
    keep = order[by[np.r_[True, g[1:] != g[:-1]]]]
    return PairContacts(*(a[keep] for a in c))


# --------------------------------------------------------------------------- response
def _scaling(idx: IntArray, coef: FloatArray, inv_m: FloatArray) -> FloatArray:
    """Jacobi diagonal (M,) [1/kg] of ``G M^-1 G^T``, inflated to the Gershgorin row sums
    (``sum_k |coef_ck| s_k / m_k``, ``s_k = sum_c |coef_ck|``) so that the simultaneous
    update converges; exact (``1/m_p + sum w^2/m_k``) for an isolated pair."""
    a = np.abs(coef)
    s = np.bincount(idx.ravel(), weights=a.ravel(), minlength=len(inv_m))
    return np.sum(a * s[idx] * inv_m[idx], axis=1)


def _apply(y: FloatArray, idx: IntArray, coef: FloatArray, imp: FloatArray, inv_m: FloatArray):
    """``y_k += inv_m_k sum_c coef_ck imp_c`` in place (imp (M, 3): impulse vectors)."""
    w = (coef[:, :, None] * imp[:, None, :]).reshape(-1, 3)
    flat = idx.ravel()
    for k in range(3):
        y[:, k] += inv_m * np.bincount(flat, weights=w[:, k], minlength=len(y))


def _relative(y: FloatArray, idx: IntArray, coef: FloatArray) -> FloatArray:
    return np.einsum("ij,ijk->ik", coef, y[idx])


def _accelerated(
    y0: FloatArray, c: PairContacts, inv_m: FloatArray, residual, project, passes: int, tol: float
) -> tuple[FloatArray, FloatArray]:
    """Projected gradient with Nesterov momentum and adaptive restart (O'Donoghue & Candes
    2015) on the pair impulses P (M, 3), preconditioned by :func:`_scaling`: minimises the
    quadratic whose gradient is ``residual(y)`` at ``y = y0 + M^-1 G^T P`` subject to
    ``P = project(P)``. Stops when no impulse changes by more than ``tol`` x its scaling
    (``tol`` in the units of ``y``). Returns ``y`` and ``P``."""
    D = _scaling(c.idx, c.coef, inv_m)
    ok = (D > 0)[:, None]
    Dz = np.where(ok[:, 0], D, 1.0)[:, None]
    P = np.zeros((len(D), 3))
    Y, t = P, 1.0
    for _ in range(passes):
        y = y0.copy()
        _apply(y, c.idx, c.coef, Y, inv_m)
        g = residual(y)
        Pn = np.where(ok, project(Y - g / Dz), 0.0)
        step = Pn - P
        done = float(np.max(np.abs(step) * Dz, initial=0.0)) <= tol
        if np.sum(g * step) > 0:  # momentum points uphill: restart
            t, t1 = 1.0, 1.0
        else:
            t1 = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        Y = Pn + ((t - 1.0) / t1) * step
        P, t = Pn, t1
        if done:
            break
    y = y0.copy()
    _apply(y, c.idx, c.coef, P, inv_m)
    return y, P


def _gs_normal(idx, coef, normal, inv_m, y, target, passes, tol, J):  # pragma: no cover
    """Projected Gauss-Seidel over the pairs in order (numba): ``J >= 0`` with relative
    normal value ``>= target`` (``y`` and ``J`` in place); returns the sweeps used."""
    m = idx.shape[0]
    w = np.zeros(m)
    for c in range(m):
        for k in range(4):
            w[c] += coef[c, k] * coef[c, k] * inv_m[idx[c, k]]
    for it in range(passes):
        change = 0.0
        for c in range(m):
            if w[c] <= 0.0:
                continue
            rn = 0.0
            for k in range(4):
                for j in range(3):
                    rn += coef[c, k] * y[idx[c, k], j] * normal[c, j]
            new = max(0.0, J[c] - (rn - target) / w[c])
            dj = new - J[c]
            J[c] = new
            for k in range(4):
                s = inv_m[idx[c, k]] * coef[c, k] * dj
                for j in range(3):
                    y[idx[c, k], j] += s * normal[c, j]
            change = max(change, abs(dj) * w[c])
        if change <= tol:
            return it + 1
    return passes


def _gs_friction(idx, coef, normal, inv_m, y, lim, passes, tol, Jt):  # pragma: no cover
    """Projected Gauss-Seidel (numba) on tangential impulses ``|Jt| <= lim`` that stop the
    tangential relative velocity (``y`` and ``Jt`` in place); returns the sweeps used."""
    m = idx.shape[0]
    w = np.zeros(m)
    for c in range(m):
        for k in range(4):
            w[c] += coef[c, k] * coef[c, k] * inv_m[idx[c, k]]
    r, t = np.zeros(3), np.zeros(3)
    for it in range(passes):
        change = 0.0
        for c in range(m):
            if w[c] <= 0.0 or lim[c] <= 0.0:
                continue
            for j in range(3):
                r[j] = 0.0
                for k in range(4):
                    r[j] += coef[c, k] * y[idx[c, k], j]
            rn, tn = 0.0, 0.0
            for j in range(3):
                rn += r[j] * normal[c, j]
                tn += Jt[c, j] * normal[c, j]
            mag = 0.0
            for j in range(3):
                t[j] = Jt[c, j] - tn * normal[c, j] - (r[j] - rn * normal[c, j]) / w[c]
                mag += t[j] * t[j]
            mag = np.sqrt(mag)
            scale = lim[c] / mag if mag > lim[c] else 1.0
            dmax = 0.0
            for j in range(3):
                dj = t[j] * scale - Jt[c, j]
                Jt[c, j] += dj
                dmax = max(dmax, abs(dj))
                for k in range(4):
                    y[idx[c, k], j] += inv_m[idx[c, k]] * coef[c, k] * dj
            change = max(change, dmax * w[c])
        if change <= tol:
            return it + 1
    return passes


def _dot3(x, i, j, y, k, l):  # pragma: no cover
    """``(x[i] - x[j]) . (y[k] - y[l])`` on rows of (N, 3) arrays (numba, no allocation)."""
    return (
        (x[i, 0] - x[j, 0]) * (y[k, 0] - y[l, 0])
        + (x[i, 1] - x[j, 1]) * (y[k, 1] - y[l, 1])
        + (x[i, 2] - x[j, 2]) * (y[k, 2] - y[l, 2])
    )


def _bary(x, p, a, b, cc):  # pragma: no cover
    """Barycentric weights of the closest point of node ``p`` on triangle ``(a, b, cc)``
    (Ericson's Voronoi regions, the order of :func:`closest_point_triangle`; numba)."""
    d1, d2 = _dot3(x, b, a, x, p, a), _dot3(x, cc, a, x, p, a)
    d3, d4 = _dot3(x, b, a, x, p, b), _dot3(x, cc, a, x, p, b)
    d5, d6 = _dot3(x, b, a, x, p, cc), _dot3(x, cc, a, x, p, cc)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    if d1 <= 0 and d2 <= 0:
        return 1.0, 0.0, 0.0
    if d3 >= 0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        v = d1 / (d1 - d3)
        return 1 - v, v, 0.0
    if d6 >= 0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        w = d2 / (d2 - d6)
        return 1 - w, 0.0, w
    if va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1 - w, w
    den = va + vb + vc
    w1, w2 = vb / den, vc / den
    return 1.0 - w1 - w2, w1, w2


def _seg_st(x, i1, i2, j1, j2):  # pragma: no cover
    """Parameters of the closest points of segments ``i1 i2`` and ``j1 j2`` (the order of
    :func:`segment_closest`; numba)."""
    a, e, f = _dot3(x, i2, i1, x, i2, i1), _dot3(x, j2, j1, x, j2, j1), _dot3(x, j2, j1, x, i1, j1)
    c, b = _dot3(x, i2, i1, x, i1, j1), _dot3(x, i2, i1, x, j2, j1)
    den = a * e - b * b
    s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > 1e-300 else 0.0
    t = (b * s + f) / e
    if t < 0:
        s = min(max(-c / a, 0.0), 1.0)
    elif t > 1:
        s = min(max((b - c) / a, 0.0), 1.0)
    return s, min(max(t, 0.0), 1.0)


def _pt_dist(x, p, a, b, cc):  # pragma: no cover
    """Distance of node ``p`` to triangle ``(a, b, cc)`` (numba)."""
    w0, w1, w2 = _bary(x, p, a, b, cc)
    s = 0.0
    for j in range(3):
        d = x[p, j] - (w0 * x[a, j] + w1 * x[b, j] + w2 * x[cc, j])
        s += d * d
    return np.sqrt(s)


def _ee_dist(x, i1, i2, j1, j2):  # pragma: no cover
    """Distance of segments ``i1 i2`` and ``j1 j2`` (numba)."""
    s, t = _seg_st(x, i1, i2, j1, j2)
    q = 0.0
    for j in range(3):
        d = (1 - s) * x[i1, j] + s * x[i2, j]
        d -= (1 - t) * x[j1, j] + t * x[j2, j]
        q += d * d
    return np.sqrt(q)


def _pt_dist_kernel(x, idx, out):  # pragma: no cover
    """Distances of node ``idx[:, 0]`` to triangle ``idx[:, 1:]`` (numba)."""
    for c in range(idx.shape[0]):
        out[c] = _pt_dist(x, idx[c, 0], idx[c, 1], idx[c, 2], idx[c, 3])


def _ee_dist_kernel(x, idx, out):  # pragma: no cover
    """Distances of segments ``idx[:, :2]`` and ``idx[:, 2:]`` (numba)."""
    for c in range(idx.shape[0]):
        out[c] = _ee_dist(x, idx[c, 0], idx[c, 1], idx[c, 2], idx[c, 3])


def _near(ptr, cols, a, b):  # pragma: no cover
    """Whether nodes ``a`` and ``b`` are near (row ``a`` of the compressed relation; numba)."""
    for k in range(ptr[a], ptr[a + 1]):
        if cols[k] == b:
            return True
    return False


def _apart(lo_a, hi_a, i, lo, hi, j, r):  # pragma: no cover
    """Whether box ``i`` of ``lo_a``, ``hi_a`` is farther than ``r`` from box ``j`` of ``lo``,
    ``hi`` along an axis (numba)."""
    for k in range(3):
        if lo_a[i, k] > hi[j, k] + r or hi_a[i, k] < lo[j, k] - r:
            return True
    return False


def _pt_grid_kernel(x, tri, lo, hi, a_item, a_start, b_item, nb_lo, nb_hi, r, reach, ptr, cols,
                    out_a, out_b, out_d):  # fmt: skip  # pragma: no cover
    """Node-triangle pairs of the grid (numba): nodes ``a_item`` by cube (``a_start``),
    triangles ``b_item`` with the ranges ``nb_lo``/``nb_hi`` of the cubes around; boxes
    within ``r``, not near, distance below ``reach``. Writes up to the outputs' length,
    returns the number of pairs."""
    m, cap = 0, out_a.shape[0]
    for c in range(a_start.shape[0] - 1):
        for ia in range(a_start[c], a_start[c + 1]):
            p = a_item[ia]
            for k in range(nb_lo.shape[1]):
                for ib in range(nb_lo[c, k], nb_hi[c, k]):
                    t = b_item[ib]
                    if _apart(x, x, p, lo, hi, t, r):
                        continue
                    a, b, cc = tri[t, 0], tri[t, 1], tri[t, 2]
                    if _near(ptr, cols, p, a) or _near(ptr, cols, p, b) or _near(ptr, cols, p, cc):
                        continue
                    d = _pt_dist(x, p, a, b, cc)
                    if d < reach:
                        if m < cap:
                            out_a[m], out_b[m], out_d[m] = p, t, d
                        m += 1
    return m


def _ee_grid_kernel(x, edge, lo, hi, a_item, a_start, b_item, nb_lo, nb_hi, r, reach, ptr, cols,
                    out_a, out_b, out_d):  # fmt: skip  # pragma: no cover
    """Edge pairs ``i < j`` of the grid (numba), as :func:`_pt_grid_kernel` with edges on
    both sides and the half neighbourhood of :func:`_grid_ranges` (each pair of cubes once;
    in a cube itself the later items): boxes within ``r``, no node of one near a node of the
    other, distance below ``reach`` (the lower edge first)."""
    m, cap = 0, out_a.shape[0]
    for c in range(a_start.shape[0] - 1):
        for ia in range(a_start[c], a_start[c + 1]):
            for k in range(nb_lo.shape[1]):
                for ib in range(ia + 1 if k == 0 else nb_lo[c, k], nb_hi[c, k]):
                    i, j = min(a_item[ia], b_item[ib]), max(a_item[ia], b_item[ib])
                    if _apart(lo, hi, i, lo, hi, j, r):
                        continue
                    i1, i2, j1, j2 = edge[i, 0], edge[i, 1], edge[j, 0], edge[j, 1]
                    if (
                        _near(ptr, cols, i1, j1) or _near(ptr, cols, i1, j2)
                        or _near(ptr, cols, i2, j1) or _near(ptr, cols, i2, j2)
                    ):  # fmt: skip
                        continue
                    d = _ee_dist(x, i1, i2, j1, j2)
                    if d < reach:
                        if m < cap:
                            out_a[m], out_b[m], out_d[m] = i, j, d
                        m += 1
    return m


def _ee_kernel(x0, x, idx, scale, coef, normal, gap):  # pragma: no cover
    """:func:`edge_contacts` pair by pair (numba): coefficients, normals and gaps."""
    r, r0 = np.zeros(3), np.zeros(3)
    for c in range(idx.shape[0]):
        s, t = _seg_st(x, idx[c, 0], idx[c, 1], idx[c, 2], idx[c, 3])
        coef[c, 0], coef[c, 1], coef[c, 2], coef[c, 3] = 1 - s, s, t - 1, -t
        r[:] = 0.0
        r0[:] = 0.0
        for k in range(4):
            for j in range(3):
                r[j] += coef[c, k] * x[idx[c, k], j]
                r0[j] += coef[c, k] * x0[idx[c, k], j]
        dist = np.sqrt(r @ r)
        n = r0 / np.sqrt(r0 @ r0) if dist <= 1e-12 * scale else r / dist
        rel = 0.0
        for i in range(2):
            for k in range(2, 4):
                q = 0.0
                for j in range(3):
                    dd = (x[idx[c, i], j] - x0[idx[c, i], j]) - (x[idx[c, k], j] - x0[idx[c, k], j])
                    q += dd * dd
                rel = max(rel, q)
        tiny = dist <= 1e-12 * scale
        can = np.sqrt(r0 @ r0) + dist <= np.sqrt(rel) + 1e-15 * scale
        side = -1.0 if (r0 @ n < 0 and (can or tiny)) else 1.0
        for j in range(3):
            v = side * n[j]
            normal[c, j] = v if np.isfinite(v) else 0.0
        gap[c] = r @ normal[c]


def _pairs_kernel(x0, x, idx, scale, face_eps, coef, normal, gap):  # pragma: no cover
    """:func:`pair_contacts` pair by pair (numba): coefficients, normals and gaps."""
    for c in range(idx.shape[0]):
        p, a, b, cc = idx[c, 0], idx[c, 1], idx[c, 2], idx[c, 3]
        w0, w1, w2 = _bary(x, p, a, b, cc)
        ab, ac = np.empty(3), np.empty(3)
        for j in range(3):
            ab[j] = x[b, j] - x[a, j]
            ac[j] = x[cc, j] - x[a, j]
        r, r0 = np.empty(3), np.empty(3)
        for j in range(3):
            r[j] = x[p, j] - (w0 * x[a, j] + w1 * x[b, j] + w2 * x[cc, j])
            r0[j] = x0[p, j] - (w0 * x0[a, j] + w1 * x0[b, j] + w2 * x0[cc, j])
        dist = np.sqrt(r @ r)
        nf = np.cross(ab, ac)
        ln = np.sqrt(nf @ nf)
        nf = nf / ln if ln > 0 else nf * 0.0
        e1 = np.empty(3)
        e2 = np.empty(3)
        for j in range(3):
            e1[j] = x0[b, j] - x0[a, j]
            e2[j] = x0[cc, j] - x0[a, j]
        n0 = np.cross(e1, e2)
        l0 = np.sqrt(n0 @ n0)
        n0 = n0 / l0 if l0 > 0 else n0 * 0.0
        s0, s1 = r0 @ n0, r @ nf
        now = -1.0 if s1 < 0 else 1.0
        rel = 0.0
        for k in (a, b, cc):
            q = 0.0
            for j in range(3):
                dd = (x[p, j] - x0[p, j]) - (x[k, j] - x0[k, j])
                q += dd * dd
            rel = max(rel, q)
        can = np.sqrt(r0 @ r0) + dist <= np.sqrt(rel) + 1e-15 * scale
        side = np.sign(s0) if (s0 != 0 and can) else now
        face = (w0 > face_eps and w1 > face_eps and w2 > face_eps) or dist <= 1e-12 * scale
        for j in range(3):
            normal[c, j] = side * nf[j] if face else r[j] / dist
        gap[c] = r @ normal[c] if face else dist
        coef[c, 0], coef[c, 1], coef[c, 2], coef[c, 3] = 1.0, -w0, -w1, -w2


def _spread_kernel(D, centre, tile, pairs, n_tiles, far2):  # pragma: no cover
    """:meth:`Tiles.spread` in three passes (numba): inf when a displacement is farther than
    ``sqrt(far2)`` from ``centre``, else the largest bound over the touching tile
    ``pairs``."""
    mean, count = np.zeros((n_tiles, 3)), np.zeros(n_tiles)
    for i in range(D.shape[0]):
        s = 0.0
        for j in range(3):
            s += (D[i, j] - centre[j]) ** 2
        if s > far2:
            return np.inf
        count[tile[i]] += 1.0
        for j in range(3):
            mean[tile[i], j] += D[i, j]
    for t in range(n_tiles):
        for j in range(3):
            mean[t, j] /= count[t]
    rmax = np.zeros(n_tiles)
    for i in range(D.shape[0]):
        t = tile[i]
        s = 0.0
        for j in range(3):
            s += (D[i, j] - mean[t, j]) ** 2
        rmax[t] = max(rmax[t], np.sqrt(s))
    best = 0.0
    for k in range(pairs.shape[0]):
        a, b = pairs[k, 0], pairs[k, 1]
        s = 0.0
        for j in range(3):
            s += (mean[a, j] - mean[b, j]) ** 2
        best = max(best, rmax[a] + np.sqrt(s) + rmax[b])
    return best


def _motion_kernel(D, g, split, out):  # pragma: no cover
    """:func:`_relative_motion` pair by pair (numba)."""
    for c in range(g.shape[0]):
        best = 0.0
        for i in range(split):
            for k in range(split, 4):
                s = 0.0
                for j in range(3):
                    dd = D[g[c, i], j] - D[g[c, k], j]
                    s += dd * dd
                best = max(best, s)
        out[c] = np.sqrt(best)


_KERNELS: tuple = ()
_TRIED = False


def _numba_kernels() -> tuple:
    """The Gauss-Seidel kernels compiled by numba (Debian's python3-numba) on first use, or
    () without numba (then the NumPy solver runs)."""
    global _KERNELS, _TRIED
    if not _TRIED:
        _TRIED = True
        try:
            from numba import njit
        except ImportError:  # pragma: no cover
            return _KERNELS
        jit = njit(cache=True, error_model="numpy")
        g = globals()
        g["_dot3"] = jit(_dot3)  # the loops below call these
        g["_bary"], g["_seg_st"] = jit(_bary), jit(_seg_st)
        for f in (_pt_dist, _ee_dist, _near, _apart):
            g[f.__name__] = jit(f)
        _KERNELS = tuple(
            jit(f)
            for f in (
                _gs_normal, _gs_friction, _pairs_kernel, _motion_kernel, _pt_dist_kernel,
                _ee_dist_kernel, _ee_kernel, _pt_grid_kernel, _ee_grid_kernel, _spread_kernel,
            )
        )  # fmt: skip
    return _KERNELS


def _use_numba(kernel: str) -> bool:
    if kernel not in ("auto", "numba", "numpy"):
        raise ValueError(f"kernel must be 'auto', 'numba' or 'numpy', got {kernel!r}")
    if kernel == "numpy":
        return False
    if kernel == "numba" and not _numba_kernels():
        raise ValueError("kernel 'numba' needs numba (python3-numba); use 'auto' or 'numpy'")
    return bool(_numba_kernels())


def _arrays(c: PairContacts):
    return (
        np.ascontiguousarray(c.idx, dtype=np.int64),
        np.ascontiguousarray(c.coef, dtype=float),
        np.ascontiguousarray(c.normal, dtype=float),
    )


def _normal_solve(y0, c: PairContacts, inv_m, target, passes, tol, kernel="auto"):
    if _use_numba(kernel):
        y, J = np.array(y0, dtype=float), np.zeros(len(c.gap))
        _numba_kernels()[0](*_arrays(c), np.ascontiguousarray(inv_m), y, target, passes, tol, J)
        return y, J
    n = c.normal

    def residual(y):
        return (_dot(_relative(y, c.idx, c.coef), n) - target)[:, None] * n

    def project(P):
        return np.maximum(_dot(P, n), 0.0)[:, None] * n

    y, P = _accelerated(y0, c, inv_m, residual, project, passes, tol)
    return y, _dot(P, n)


def project_positions(
    x: FloatArray,
    c: PairContacts,
    inv_m: FloatArray,
    *,
    distance: float,
    passes: int,
    tol: float,
    kernel: str = "auto",
) -> tuple[FloatArray, FloatArray]:
    """Mass-weighted projection of the pairs to ``gap >= distance`` (normals and weights held):
    corrected positions and the position multipliers ``m_eff dgap`` (M,) [kg m] (FILM's
    ``lambda dt^2``, Eq. 25 for one pair). ``tol`` [m]: convergence of the gaps."""
    return _normal_solve(x, c, inv_m, distance, passes, tol, kernel)


def normal_impulses(
    v: FloatArray,
    c: PairContacts,
    inv_m: FloatArray,
    *,
    passes: int,
    tol: float,
    kernel: str = "auto",
) -> tuple[FloatArray, FloatArray]:
    """Inelastic normal impulses ``J >= 0`` (M,) [N s] that stop every pair's approach (zero
    relative normal velocity where ``J > 0``, none approaching; ``tol`` [m/s]): the new
    velocities and ``J``."""
    return _normal_solve(v, c, inv_m, 0.0, passes, tol, kernel)


def friction_impulses(
    v: FloatArray,
    c: PairContacts,
    inv_m: FloatArray,
    Jn: FloatArray,
    *,
    mu: float,
    passes: int,
    tol: float,
    kernel: str = "auto",
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Coulomb friction on impulses: tangential impulses ``|Jt| <= mu Jn`` (M, 3) [N s] that
    bring the tangential relative velocity to zero where the limit allows (stick), else
    ``|Jt| = mu Jn`` against it (slip). Returns the new velocities, ``Jt``, the stick mask."""
    n, lim = c.normal, mu * np.asarray(Jn, dtype=float)
    if _use_numba(kernel):
        v, Jt = np.array(v, dtype=float), np.zeros((len(lim), 3))
        _numba_kernels()[1](*_arrays(c), np.ascontiguousarray(inv_m), v, lim, passes, tol, Jt)
        return v, Jt, np.linalg.norm(Jt, axis=1) < lim * (1.0 - 1e-9)

    def residual(y):
        r = _relative(y, c.idx, c.coef)
        return r - _dot(r, n)[:, None] * n

    def project(P):
        P = P - _dot(P, n)[:, None] * n
        mag = np.linalg.norm(P, axis=1)
        return P * np.where(mag > lim, lim / np.where(mag > 0, mag, 1.0), 1.0)[:, None]

    v, Jt = _accelerated(v, c, inv_m, residual, project, passes, tol)
    return v, Jt, np.linalg.norm(Jt, axis=1) < lim * (1.0 - 1e-9)


# --------------------------------------------------------------------------- fail-safe
def _cubic(
    u0: FloatArray, du: FloatArray, v0: FloatArray, dv: FloatArray, w0: FloatArray, dw: FloatArray
) -> FloatArray:
    """Coefficients (M, 4) of ``det[u0 + t du, v0 + t dv, w0 + t dw]`` in powers of t."""
    c0 = _dot(u0, np.cross(v0, w0))
    c1 = _dot(du, np.cross(v0, w0)) + _dot(u0, np.cross(dv, w0)) + _dot(u0, np.cross(v0, dw))
    c2 = _dot(du, np.cross(dv, w0)) + _dot(du, np.cross(v0, dw)) + _dot(u0, np.cross(dv, dw))
    c3 = _dot(du, np.cross(dv, dw))
    return np.stack([c0, c1, c2, c3], axis=1)


def _poly(c: FloatArray, t: FloatArray) -> FloatArray:
    return ((c[:, 3] * t + c[:, 2]) * t + c[:, 1]) * t + c[:, 0]


def _unit_roots(c: FloatArray, iterations: int = 45) -> FloatArray:
    """The (up to 3) roots in [0, 1] of cubics (M, 4), (M, 3) with nan where none: the cubic
    is split at the roots of its derivative into monotone pieces, each bisected."""
    if len(c) == 0:
        return np.full((0, 3), np.nan)
    a, b, cc = 3 * c[:, 3], 2 * c[:, 2], c[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = np.sqrt(b * b - 4 * a * cc)
        lin = np.abs(a) <= 1e-300
        r1 = np.where(lin, -cc / np.where(b == 0, np.inf, b), (-b - disc) / (2 * a))
        r2 = np.where(lin, np.nan, (-b + disc) / (2 * a))
    crit = np.sort(np.clip(np.nan_to_num(np.stack([r1, r2], 1), nan=1.0), 0, 1), axis=1)
    knots = np.column_stack([np.zeros(len(c)), crit, np.ones(len(c))])
    out = np.full((len(c), 3), np.nan)
    for k in range(3):
        lo, hi = knots[:, k], knots[:, k + 1]
        has = np.flatnonzero((_poly(c, lo) * _poly(c, hi) <= 0) & (hi >= lo))
        if has.size == 0:
            continue
        ck, lo, hi = c[has], lo[has].copy(), hi[has].copy()
        flo = _poly(ck, lo)
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            fm = _poly(ck, mid)
            left = (flo * fm) <= 0
            hi, lo, flo = np.where(left, mid, hi), np.where(left, lo, mid), np.where(left, flo, fm)
        out[has, k] = 0.5 * (lo + hi)
    return out


def _coplanar_positions(x0: FloatArray, x1: FloatArray, P: list[IntArray]):
    """For each of the up to three times in [0, 1] at which the four nodes ``P[k][i]``
    (moving on straight paths from ``x0`` to ``x1``) are coplanar: the rows ``s`` that have
    such a time and the four nodes' positions then (a list of four (len(s), 3) arrays)."""
    d = [x1[i] - x0[i] for i in P]
    co = _cubic(
        x0[P[1]] - x0[P[0]], d[1] - d[0], x0[P[2]] - x0[P[0]], d[2] - d[0],
        x0[P[3]] - x0[P[0]], d[3] - d[0],
    )  # fmt: skip
    for tt in _unit_roots(co).T:
        s = np.flatnonzero(np.isfinite(tt))
        if s.size:
            yield s, [x0[i[s]] + tt[s, None] * dk[s] for i, dk in zip(P, d, strict=True)]


def point_triangle_crossings(
    x0: FloatArray,
    x1: FloatArray,
    surface: FabricSurface,
    node: IntArray,
    tri: IntArray,
    eps: float,
) -> NDArray[np.bool_]:
    """Whether node ``node[i]`` comes within ``eps`` [m] of triangle ``tri[i]`` at a time its
    point is coplanar with the triangle, along the straight paths from ``x0`` to ``x1``."""
    t = surface.triangles[tri]
    hit = np.zeros(len(node), dtype=bool)
    for s, pos in _coplanar_positions(x0, x1, [node, t[:, 0], t[:, 1], t[:, 2]]):
        q, _ = closest_point_triangle(*pos)
        hit[s] |= np.linalg.norm(pos[0] - q, axis=1) <= eps
    return hit


def edge_edge_crossings(
    x0: FloatArray, x1: FloatArray, surface: FabricSurface, ee: IntArray, eps: float
) -> NDArray[np.bool_]:
    """Whether edge pairs ``ee`` (M, 2) come within ``eps`` [m] of each other at a time their
    four nodes are coplanar, along the straight paths from ``x0`` to ``x1``."""
    e0, e1 = surface.edges[ee[:, 0]], surface.edges[ee[:, 1]]
    hit = np.zeros(len(ee), dtype=bool)
    for s, pos in _coplanar_positions(x0, x1, [e0[:, 0], e0[:, 1], e1[:, 0], e1[:, 1]]):
        hit[s] |= segment_distance(*pos) <= eps
    return hit


def crossing_groups(cands: CandidateList, surface, x0, x1, eps) -> tuple[IntArray, IntArray]:
    """Node groups (rows of 4) of the point-triangle and edge-edge pairs that cross. Two
    filters before the cubic (:func:`_relative_motion` bounds the change of a pair's
    distance): the distance at ``x1`` is at least the build distance less the relative
    motion since the build, and changes along the step by at most twice the largest step of
    a node; then the exact distance at ``x1`` less the pair's relative motion over it."""
    D1, step = x1 - cands.x_build, x1 - x0
    reach = eps + 2.0 * float(np.max(_moved(x1, x0), initial=0.0))
    out = []
    for g, dist0, split in ((cands.pt_nodes, cands.pt_dist, 1), (cands.ee_nodes, cands.ee_dist, 2)):
        s = np.flatnonzero(dist0 - _relative_motion(D1, g, split) <= reach)
        if s.size:
            gs = g[s]
            dist = _pt_distances(x1, gs) if split == 1 else _ee_distances(x1, gs)
            s = s[dist <= _relative_motion(step, gs, split) + eps]
        out.append(s)
    s_pt, s_ee = out
    if s_pt.size + s_ee.size == 0:
        return np.zeros((0, 4), dtype=np.intp), np.zeros((0, 4), dtype=np.intp)
    h_pt = point_triangle_crossings(x0, x1, surface, cands.pt_node[s_pt], cands.pt_tri[s_pt], eps)
    h_ee = edge_edge_crossings(x0, x1, surface, cands.ee[s_ee], eps)
    return cands.pt_nodes[s_pt[h_pt]], cands.ee_nodes[s_ee[h_ee]]


def bound_tolerance(x: FloatArray, *, distance: float) -> float:
    """The margin [m] that keeps distance bounds bounds under round-off at positions ``x``
    (N, 3) [m]: 1e-6 ``distance`` plus 1e-12 of the largest coordinate (at least 1 m)."""
    scale = max(1.0, float(np.max(np.abs(x), initial=0.0)))
    return 1e-6 * distance + 1e-12 * scale


class FilterBounds:
    """Lower bounds on the listed pairs' distances along the steps ``alpha D`` from ``x0``
    (both (N, 3) [m]) for the step filter of the implicit barrier
    (:meth:`clothfem.contact.self_barrier.SelfBarrier.max_step`): which pairs of the list
    ``cands`` can come within ``eps`` [m] of each other on the path, and which can end
    closer than ``floor`` x min(their distance at ``x0``, ``distance``); only those need
    the exact tests.

    A pair's distance changes by at most its nodes' relative motion. Three levels, each on
    what the one before leaves: all pairs at once (the smallest build distance less twice
    the :func:`motion_radius` of the displacements since the build and ``alpha`` times
    twice that of ``D``), each pair's build distance less the same, then each pair's
    distance at ``x0`` (compiled loop) less ``alpha`` times its relative motion over ``D``
    (:func:`_relative_motion`). All bound the exact distance anywhere on the path; ``tol``
    (1e-6 ``distance`` plus 1e-12 of the largest coordinate) keeps them bounds under
    round-off, so a pair they clear passes the exact tests too."""

    def __init__(
        self, cands: CandidateList, x0: FloatArray, D: FloatArray, *,
        distance: float, floor: float, eps: float,
    ) -> None:  # fmt: skip
        self.cands, self.x0, self.D = cands, x0, D
        self.distance, self.floor, self.eps = distance, floor, eps
        self.tol = bound_tolerance(x0, distance=distance)
        self.r0 = 2.0 * motion_radius(x0 - cands.x_build)
        self.rD = 2.0 * motion_radius(D)
        self._pairs: list | None = None
        self._alpha = 0.0  # the largest alpha the pair bounds hold the rows of

    def _clear(self, lb: FloatArray | float, floor: FloatArray | float):
        return (lb > self.eps + self.tol) & (lb >= floor + self.tol)

    def all_clear(self, alpha: float) -> bool:
        """Whether no listed pair can come within ``eps`` on the path of ``alpha D`` or end
        below its floor (the bound of all pairs at once)."""
        lb = self.cands.min_distance - self.r0 - alpha * self.rD
        return bool(self._clear(lb, self.floor * self.distance))

    def rows(self, alpha: float) -> tuple[tuple[IntArray, IntArray], tuple[IntArray, IntArray]]:
        """The point-triangle and edge-edge rows of the list the pair bounds do not clear
        for ``alpha``: those that can come within ``eps`` on the path, those that can end
        below their floor."""
        c, x0, D = self.cands, self.x0, self.D
        if self._pairs is None or alpha > self._alpha:
            self._pairs, self._alpha = [], alpha
            reach = self.r0 + alpha * self.rD
            limit = reach + max(self.eps, self.floor * self.distance) + self.tol
            for dist, g, split in ((c.pt_dist, c.pt_nodes, 1), (c.ee_dist, c.ee_nodes, 2)):
                s = c.rows_within(limit, edges=split == 2)  # the others are cleared
                s = s[~self._clear(dist[s] - reach, self.floor * self.distance)]
                gs = g[s]
                d0 = _pt_distances(x0, gs) if split == 1 else _ee_distances(x0, gs)
                self._pairs.append((s, d0, _relative_motion(D, gs, split)))
        cross, low = [], []
        for s, d0, rm in self._pairs:
            lb = d0 - alpha * rm
            cross.append(s[~(lb > self.eps + self.tol)])
            low.append(s[~(lb >= self.floor * np.minimum(d0, self.distance) + self.tol)])
        return (cross[0], cross[1]), (low[0], low[1])


def _impact_zones(
    x0: FloatArray,
    x1: FloatArray,
    v: FloatArray,
    mass: FloatArray,
    fixed: NDArray[np.bool_],
    links: IntArray,
) -> IntArray:
    """Merge the node groups ``links`` (K, 4) into zones (connected components) and move each
    zone rigidly by its mass-weighted mean displacement with its mean velocity (a perfectly
    inelastic collision of the zone; momentum conserved; a zone holding prescribed nodes
    takes their mean motion). ``x1``, ``v`` in place; returns the zone nodes."""
    n = len(x0)
    a = np.repeat(links[:, :1], 3, axis=1).ravel()
    b = links[:, 1:].ravel()
    g = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    nodes = np.unique(links)
    zl = lab[nodes]
    _, zi = np.unique(zl, return_inverse=True)
    w = np.where(fixed[nodes], 1.0, 0.0)
    has_fixed = np.bincount(zi, weights=w) > 0
    w = np.where(has_fixed[zi], w, mass[nodes])
    tot = np.bincount(zi, weights=w)
    dx = x1[nodes] - x0[nodes]
    for k in range(3):
        mdx = np.bincount(zi, weights=w * dx[:, k]) / tot
        mv = np.bincount(zi, weights=w * v[nodes, k]) / tot
        x1[nodes, k] = x0[nodes, k] + mdx[zi]
        v[nodes, k] = mv[zi]
    return nodes


# --------------------------------------------------------------------------- the step
@dataclass(frozen=True, kw_only=True)
class SelfContactParameters:
    """distance: contact distance d [m] between mid-surfaces (> 0; the fabric thickness or a
    multiple of it); mu: Coulomb coefficient between layers (>= 0); rings: 0 (default) a
    node never contacts its own triangles nor an edge one sharing a node, k >= 1 nor the
    triangles of nodes within k cell rings; skin: Verlet-list skin [m] (> 0; default 2
    d); passes: sweeps / iterations of each response stage (>= 1); tolerance: allowed gap
    deficit, fraction of d (0 < tol < 1); failsafe_passes: crossing checks and impact-zone
    merges per step (>= 1); eps: crossing proximity, fraction of d (0 < eps < 0.005); kernel:
    the response solver, "numba" (projected Gauss-Seidel over the pairs, compiled), "numpy"
    (accelerated projected Jacobi, vectorised) or "auto" (numba when importable);
    edge_proximity: edge-edge pairs closer than d are corrected too (else node-triangle
    pairs only; edges then enter the crossing check alone)."""

    distance: float
    mu: float = 0.0
    rings: int = 0
    skin: float | None = None
    passes: int = 50
    tolerance: float = 0.01
    failsafe_passes: int = 8
    eps: float = 1e-3
    kernel: str = "auto"
    edge_proximity: bool = True

    def __post_init__(self) -> None:
        def bad(name, value, rule):
            raise ValueError(f"SelfContactParameters {name} must be {rule}, got {value!r}")

        if not (np.isfinite(self.distance) and self.distance > 0):
            bad("distance", self.distance, "> 0 m")
        if not (np.isfinite(self.mu) and self.mu >= 0):
            bad("mu", self.mu, ">= 0")
        if self.skin is not None and not (np.isfinite(self.skin) and self.skin > 0):
            bad("skin", self.skin, "None or > 0 m")
        if int(self.rings) != self.rings or self.rings < 0:
            bad("rings", self.rings, "an integer >= 0")
        for name in ("passes", "failsafe_passes"):
            val = getattr(self, name)
            if int(val) != val or val < 1:
                bad(name, val, "an integer >= 1")
        if not (0 < self.tolerance < 1):
            bad("tolerance", self.tolerance, "in (0, 1)")
        if not (0 < self.eps < 0.005):
            bad("eps", self.eps, "in (0, 0.005)")
        if self.kernel not in ("auto", "numba", "numpy"):
            bad("kernel", self.kernel, "'auto', 'numba' or 'numpy'")

    @property
    def skin_length(self) -> float:
        return 2.0 * self.distance if self.skin is None else float(self.skin)


class SelfContactResult(NamedTuple):
    """One self-contact correction of N nodes: corrected positions ``x`` [m] and velocities
    ``v`` [m/s]; ``contacts`` the pairs in contact, their position multipliers ``lam`` [kg m]
    (``lam / dt^2`` is FILM's multiplier in N), normal impulses ``jn`` [N s] and tangential
    impulses ``jt`` (M, 3) [N s], ``stick`` mask; ``max_deficit`` the largest ``d - gap`` of
    the predictor [m]; ``min_gap`` the smallest pair gap after [m] (inf: no pair);
    ``crossings`` crossing pairs found in the first fail-safe pass, ``crossings_left`` after
    the last; ``zone_nodes`` nodes moved as impact zones; ``rebuilt`` whether the candidate
    list was rebuilt; ``candidates`` the list (pass it to the next step); ``covered`` False
    when the capped skin could not cover a node's motion in the step (the crossing check
    then saw only the pairs near the end of the step); ``friction_loss`` the kinetic energy
    the friction impulses took out [J] (what the friction between layers dissipated in the
    step; >= 0 to the solver's tolerance, the impulses being the maximal-dissipation ones)."""

    x: FloatArray
    v: FloatArray
    contacts: PairContacts
    lam: FloatArray
    jn: FloatArray
    jt: FloatArray
    stick: NDArray[np.bool_]
    max_deficit: float
    min_gap: float
    crossings: int
    crossings_left: int
    zone_nodes: int
    rebuilt: bool
    candidates: CandidateList
    covered: bool
    friction_loss: float


def _list_for(cands, x_now, x_other, surface, p: SelfContactParameters, both=True) -> tuple:
    """The candidate list valid for ``x_now`` and ``x_other`` (rebuilt at ``x_now`` if not;
    ``both=False``: ``x_other`` is known to be valid for ``cands``), whether it was rebuilt,
    and whether it covers the step (False only when the skin cap of 10 d left ``x_other``
    outside a rebuilt list: a node moved more than about d in the step)."""
    span = float(np.max(_moved(x_now, x_other), initial=0.0))
    # valid at x_other too: every node within span of the build, so the tile bound is at
    # most 6 span < skin and no node is past the allowed displacement (> 1.5 skin); capped,
    # so that one violent step cannot build a list of the whole garment
    cap = max(p.skin_length, 10.0 * p.distance)
    skin = min(max(p.skin_length, 8.0 * span), cap)
    # a list widened for one violent step is not kept once the steps are small again
    oversized = cands is not None and cands.skin > 2.0 * skin
    if cands is not None and not oversized:
        if cands.valid(*((x_now, x_other) if both else (x_now,))):
            return cands, False, True
    # listed: every pair closer than the contact distance plus its tolerance band, so that the
    # pairs in contact (gap < d + tol) are the same whichever valid list holds them (a run
    # resumed with a fresh list repeats the uninterrupted one)
    reach = p.distance * (1.0 + p.tolerance)
    c = build_candidates(x_now, surface, distance=reach, skin=skin, edges=p.edge_proximity)
    return c, True, skin >= 6.5 * span or c.valid(x_other)


def self_contact_step(
    x0: ArrayLike,
    x_star: ArrayLike,
    v_star: ArrayLike,
    mass: ArrayLike,
    dt: float,
    surface: FabricSurface,
    *,
    params: SelfContactParameters,
    fixed: ArrayLike | None = None,
    candidates: CandidateList | None = None,
) -> SelfContactResult:
    """Self-contact correction of the predictor ``x_star`` (N, 3) [m] with half-step
    velocities ``v_star`` [m/s], from the crossing-free start ``x0`` of the step of ``dt``
    [s], lumped ``mass`` (N,) [kg]; ``fixed`` (N,) nodes are not corrected."""
    x0, xs, vs = (np.asarray(a, dtype=float) for a in (x0, x_star, v_star))
    n, p = surface.n_nodes, params
    if not (x0.shape == xs.shape == vs.shape == (n, 3)):
        raise ValueError(f"x0, x_star, v_star must have shape ({n}, 3), got {xs.shape}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    m = np.broadcast_to(np.asarray(mass, dtype=float), (n,))
    if not np.all(m > 0):
        raise ValueError("mass must be > 0 kg at every node")
    fx = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
    inv_m = np.where(fx, 0.0, 1.0 / m)
    d, tol = p.distance, p.tolerance * p.distance
    cands, rebuilt, covered = _list_for(candidates, xs, x0, surface, p)
    c = _contacts_now(x0, xs, surface, cands, d, tol, p.edge_proximity, p.kernel)
    x, v = xs.copy(), vs.copy()
    lam, jn = np.zeros(len(c.gap)), np.zeros(len(c.gap))
    jt, stick = np.zeros((len(jn), 3)), np.ones(len(jn), dtype=bool)
    loss = 0.0
    if len(c.gap):
        k = {"passes": p.passes, "kernel": p.kernel}
        x, lam = project_positions(xs, c, inv_m, distance=d, tol=1e-3 * tol, **k)
        v, jn = normal_impulses(vs, c, inv_m, tol=1e-9 * _speed(vs), **k)
        if p.mu > 0:
            v1, jt, stick = friction_impulses(v, c, inv_m, jn, mu=p.mu, tol=1e-9 * _speed(vs), **k)
            x += dt * (v1 - v)
            loss = 0.5 * float(np.sum(m * (_dot(v, v) - _dot(v1, v1))))
            v = v1
    x, v, found, left, zone, cands2, covered2 = _failsafe(x0, x, v, m, fx, surface, cands, p)
    return SelfContactResult(
        x, v, c, lam, jn, jt, stick,
        float(np.max(d - c.gap, initial=0.0)),
        float(np.min(_dot(_relative(x, c.idx, c.coef), c.normal), initial=np.inf)),
        found, left, zone, rebuilt or cands2 is not cands, cands2, covered and covered2, loss,
    )  # fmt: skip


_NO_PAIRS = PairContacts(
    np.zeros((0, 4), np.intp), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.intp)
)


def _contacts_now(x0, xs, surface, cands: CandidateList, d, tol, edges, kernel) -> PairContacts:
    """Node-triangle and edge pairs closer than ``d + tol`` at ``xs`` (per node / first
    edge the closest on each side), after the list's bound: build distance less the pair's
    relative motion since the build (the list holds every pair within ``d + tol``)."""
    D = xs - cands.x_build
    sel = np.flatnonzero(cands.pt_dist - _relative_motion(D, cands.pt_nodes, 1) < d + tol)
    if sel.size == 0 and (not edges or len(cands.ee) == 0):
        return _NO_PAIRS
    c = pair_contacts(x0, xs, surface, cands.pt_node[sel], cands.pt_tri[sel], kernel=kernel)
    c = PairContacts(*(a[c.gap < d + tol] for a in c))
    c = _closest_per_key(c, c.idx[:, 0])
    if not edges:
        return c
    sel = np.flatnonzero(cands.ee_dist - _relative_motion(D, cands.ee_nodes, 2) < d + tol)
    ce = edge_contacts(x0, xs, surface, cands.ee[sel], kernel=kernel)
    close = ce.gap < d + tol
    ce = _closest_per_key(PairContacts(*(a[close] for a in ce)), cands.ee[sel][close, 0])
    return PairContacts(*(np.concatenate([a, b]) for a, b in zip(c, ce, strict=True)))


def _speed(v: FloatArray) -> float:
    return max(float(np.max(np.abs(v), initial=0.0)), 1e-30)


def _failsafe(x0, x, v, m, fx, surface, cands, p: SelfContactParameters):
    """Crossing check over the step and impact zones until none is left (or the passes are
    used up): positions, velocities, crossings of the first and last pass, zone nodes, the
    candidate list (rebuilt if a correction made it invalid), whether the lists covered
    the step."""
    eps = p.eps * p.distance
    found, links, zone = -1, np.zeros((0, 4), dtype=np.intp), np.zeros(0, dtype=np.intp)
    covered = True
    for _ in range(p.failsafe_passes):
        cands, _, ok = _list_for(cands, x, x0, surface, p, both=False)
        covered &= ok
        pt, ee = crossing_groups(cands, surface, x0, x, eps)
        count = len(pt) + len(ee)
        found = count if found < 0 else found
        if count == 0:
            return x, v, found, 0, len(zone), cands, covered
        links = np.concatenate([links, pt, ee])
        x, v = x.copy(), v.copy()
        zone = _impact_zones(x0, x, v, m, fx, links)
    cands, _, ok = _list_for(cands, x, x0, surface, p, both=False)
    pt, ee = crossing_groups(cands, surface, x0, x, eps)
    return x, v, found, len(pt) + len(ee), len(zone), cands, covered & ok


# --------------------------------------------------------------------------- explicit runner
@dataclass(frozen=True)
class SelfContactRecord:
    """Self-contact diagnostics of the steps since the previous :meth:`SelfContact.collect`
    (identical on every rank: the correction is computed redundantly)."""

    time: float  # of the window's last step [s]
    steps: int  # explicit steps in the window
    contacts: int  # node-triangle and edge-edge pairs in contact in the last step
    max_deficit: float  # largest d - gap of a predictor in the window [m] (0: none closer)
    min_gap: float  # smallest pair gap after the corrections in the window [m]
    normal_impulse: float  # sum of the normal impulses, mean over the window's steps [N s]
    crossings: int  # crossing pairs the fail-safe found in the window
    crossings_left: int  # crossing pairs left after the fail-safe in the window
    zone_nodes: int  # nodes moved in impact zones in the window
    rebuilds: int  # candidate-list rebuilds in the window
    uncovered: int  # steps whose motion the capped candidate list did not cover
    wall: float  # seconds spent in the self-contact correction in the window
    friction_loss: float  # kinetic energy the layer friction took out in the window [J]


def global_cells(V) -> tuple[IntArray, int, int]:
    """The 9-node cells of a dolfinx Q2 vector space ``V`` on every rank in global node
    numbers (owned cells of each rank, in rank order), the number of nodes and the first
    global number of this rank's owned nodes (collective)."""
    comm, im = V.mesh.comm, V.dofmap.index_map
    n_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    local = V.dofmap.list.array.reshape(-1, V.dofmap.dof_layout.num_dofs)[:n_cells]
    if local.shape[1] != 9:
        raise ValueError(f"self-contact needs 9-node cells (Q2), got {local.shape[1]} nodes")
    glob = im.local_to_global(local.ravel().astype(np.int32)).reshape(-1, 9)
    cells = np.concatenate(comm.allgather(glob.astype(np.int64))).astype(np.intp)
    return cells, int(im.size_global), int(im.local_range[0])


def check_resolution(x: FloatArray, cells: IntArray, surface: FabricSurface, d: float) -> None:
    """Raise ValueError if, at ``x``, a node is closer than ``d`` [m] to a triangle of a cell
    sharing a node with it that the surface's exclusion does not cover: on a smooth surface
    the contact distance must stay below the mesh's in-surface node-triangle gaps."""
    if surface.rings > 0:
        return
    c = build_candidates(x, surface, distance=d, skin=1e-9 * d, edges=False)
    if len(c.pt_dist) == 0:
        return
    ring = fabric_surface(cells, n_nodes=surface.n_nodes, rings=1)
    smooth = ~_far(ring, c.pt_nodes[:, :1], c.pt_nodes[:, 1:])
    if np.any(smooth & (c.pt_dist < d)):
        gap = float(c.pt_dist[smooth].min())
        raise ValueError(
            f"self-contact distance must be below the mesh's in-surface node-triangle gap "
            f"{gap:.3g} m with rings = 0, got {d!r} (refine d or use rings = 1)"
        )


def mesh_nodes(mesh) -> tuple[FloatArray, IntArray]:
    """Node positions (N, 3) [m] and 9-node cells (C, 9) of an order-2 quadrilateral dolfinx
    ``mesh`` in the numbering of its Q2 space, the whole mesh on every rank (collective)."""
    from dolfinx import fem

    V = fem.VectorFunctionSpace(mesh, ("Q", 2))
    cells, _, _ = global_cells(V)
    n = V.dofmap.index_map.size_local
    X = np.concatenate(mesh.comm.allgather(V.tabulate_dof_coordinates()[:n]))
    return X, cells


class SelfContact:
    """Self-contact of a :class:`clothfem.dynamics.ShellSystem` in
    :func:`clothfem.dynamics.integrate_explicit`, after a :class:`FilmContact` ``film``.

    Every rank gathers all node positions and velocities (three ``Allgatherv`` of 3 N
    doubles per step), runs :func:`self_contact_step` on the whole surface -- the same input
    and operations give the same bits on every rank -- and writes back its owned nodes. The
    step's start positions are the model's state when the step's correction is called
    (``integrate_explicit`` evaluates the forces at the corrected positions afterwards).
    """

    def __init__(self, system, *, params: SelfContactParameters, film=None) -> None:
        self.system, self.model, self.params, self.film = system, system.model, params, film
        self.comm = self.model.comm
        n = self.n = self.model.n_owned
        cells, n_glob, self.lo = global_cells(self.model.V)
        self.surface = fabric_surface(cells, n_nodes=n_glob, rings=params.rings)
        self._counts = np.array(self.comm.allgather(3 * n))
        self.X = self._gather(self.model.x_nodes[:n])
        check_resolution(self.X, cells, self.surface, params.distance)
        self.mass = self._gather(np.repeat(system.lumped_u[0 : 3 * n : 3], 3).reshape(n, 3))[:, 0]
        self.fixed = np.zeros(n_glob, dtype=bool)
        self._rows: np.ndarray | None = None
        self.candidates: CandidateList | None = None
        self.last: SelfContactResult | None = None
        self._v_own: FloatArray | None = None
        self.history: list[SelfContactRecord] = []
        self.wall, self.time = 0.0, 0.0
        self.friction_loss = 0.0  # layer friction's dissipation since the start [J]
        self._window = self._empty_window()

    def positions(self) -> FloatArray:
        """Current positions (N, 3) [m] of all nodes in global numbering, on every rank
        (collective; e.g. for :func:`clothfem.contact.intersections.check_surface` with
        ``self.surface.triangles``)."""
        return self.X + self._gather(self.model.u.x.array[: 3 * self.n])

    def _gather(self, a: FloatArray) -> FloatArray:
        out = np.empty(int(self._counts.sum()))
        self.comm.Allgatherv(np.ascontiguousarray(a, dtype=float).ravel(), [out, self._counts])
        return out.reshape(-1, 3)

    def _set_fixed(self, rows) -> None:
        rows = np.asarray(rows)
        if self._rows is not None and np.array_equal(rows, self._rows):
            return
        self._rows = rows.copy()
        own = np.zeros((self.n, 3))
        own[rows[rows < 3 * self.n] // 3] = 1.0
        self.fixed = self._gather(own)[:, 0] > 0

    def correct_positions(self, x, v_pred, t: float, h: float, rows) -> None:
        """FILM (if given), then the self-contact correction of the predictor ``x`` (in place);
        the velocities are written by :meth:`correct_velocities`."""
        if self.film is not None:
            self.film.correct_positions(x, v_pred, t, h, rows)
            self.film.correct_velocities(v_pred)
        t0 = time.perf_counter()
        n, lo = self.n, self.lo
        self._set_fixed(rows)
        u = x.getArray()[: 3 * n].reshape(n, 3)
        v = v_pred.getArray(readonly=True)[: 3 * n].reshape(n, 3)
        x0 = self.X + self._gather(self.model.u.x.array[: 3 * n])
        xs, vs = self.X + self._gather(u), self._gather(v)
        res = self_contact_step(
            x0, xs, vs, self.mass, h, self.surface,
            params=self.params, fixed=self.fixed, candidates=self.candidates,
        )  # fmt: skip
        self.candidates, self.last = res.candidates, res
        own = slice(lo, lo + n)
        moved = np.flatnonzero(np.any(res.x[own] != xs[own], axis=1))
        u[moved] = res.x[own][moved] - self.X[own][moved]
        self._v_own = res.v[own]
        self._record(res, t, time.perf_counter() - t0)

    def correct_velocities(self, v) -> None:
        """The corrected half-step velocities of the owned nodes (in place)."""
        if self._v_own is None:
            return
        va = v.getArray()[: 3 * self.n].reshape(self.n, 3)
        changed = np.flatnonzero(np.any(self._v_own != va, axis=1))
        va[changed] = self._v_own[changed]

    @staticmethod
    def _empty_window() -> dict:
        return {
            "steps": 0, "contacts": 0, "deficit": 0.0, "gap": np.inf, "jn": 0.0, "found": 0,
            "left": 0, "zone": 0, "rebuilds": 0, "wall": 0.0, "uncovered": 0, "loss": 0.0,
        }  # fmt: skip

    def _record(self, res: SelfContactResult, t: float, wall: float) -> None:
        w = self._window
        w["steps"] += 1
        w["deficit"] = max(w["deficit"], res.max_deficit)
        w["gap"] = min(w["gap"], res.min_gap)
        w["jn"] += float(res.jn.sum())
        w["found"] += res.crossings
        w["left"] += res.crossings_left
        w["zone"] += res.zone_nodes
        w["rebuilds"] += int(res.rebuilt)
        w["uncovered"] += int(not res.covered)
        w["wall"] += wall
        w["loss"] += res.friction_loss
        w["contacts"] = len(res.jn)
        self.time = t
        self.wall += wall
        self.friction_loss += res.friction_loss

    def collect(self) -> SelfContactRecord:
        """The diagnostics of the steps since the previous call (appended to
        :attr:`history`; not collective: every rank holds the same values)."""
        w = self._window
        if w["steps"] == 0:
            raise RuntimeError("SelfContact.collect: no step since the last collect")
        rec = SelfContactRecord(
            time=self.time,
            steps=w["steps"],
            contacts=w["contacts"],
            max_deficit=w["deficit"],
            min_gap=w["gap"],
            normal_impulse=w["jn"] / w["steps"],
            crossings=w["found"],
            crossings_left=w["left"],
            zone_nodes=w["zone"],
            rebuilds=w["rebuilds"],
            uncovered=w["uncovered"],
            wall=w["wall"],
            friction_loss=w["loss"],
        )
        self.history.append(rec)
        self._window = self._empty_window()
        return rec

    def intersections(self) -> int:
        """Intersecting triangle pairs of the current surface by the independent checker
        (:func:`clothfem.contact.intersections.intersecting_pairs`; collective: computed on
        rank 0, the count broadcast)."""
        from .intersections import intersecting_pairs

        x = self.positions()
        count = len(intersecting_pairs(x, self.surface.triangles)) if self.comm.rank == 0 else 0
        return int(self.comm.bcast(count, root=0))

    @classmethod
    def from_scene(cls, system, contact: ContactSpec, *, film=None) -> SelfContact | None:
        """From a scene's ``contact`` section: None unless ``self_contact`` is true; the
        distance ``self_distance`` [m] (default: the fabric thickness) and ``self_mu``
        (default: ``mu``)."""
        if not contact.self_contact:
            return None
        d = contact.self_distance or system.model.thickness
        mu = contact.self_mu
        mu = contact.mu if mu is None else mu
        return cls(system, params=SelfContactParameters(distance=d, mu=mu), film=film)
