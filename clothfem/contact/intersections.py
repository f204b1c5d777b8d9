"""Independent checks of a triangulated fabric surface: intersecting triangle pairs and the
smallest distance between layers (pure NumPy and SciPy).

Written to check :mod:`clothfem.contact.self_contact` from outside: it shares only the
triangulation (:func:`clothfem.contact.self_contact.triangulate_q9`), not the geometry,
the neighbour exclusion or the candidate search.

* Intersection: two triangles that share no vertex intersect when an edge of one crosses
  the other (segment-triangle test of Moller & Trumbore 1997, applied to the six edges).
  Coplanar overlapping triangles are not detected (no edge crosses the other's plane
  transversally); measure zero for a deforming fabric.
* Layer distance: the smallest vertex-triangle and edge-edge distance over the pairs whose
  nodes are more than ``rings`` edges apart in the triangulation's graph (closer pairs
  belong to the same smooth layer).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

__all__ = [
    "SurfaceCheck",
    "check_surface",
    "intersecting_pairs",
    "layer_distance",
    "point_triangle_distance",
    "segment_hits_triangle",
    "segments_distance",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def _check(x: ArrayLike, triangles: ArrayLike) -> tuple[FloatArray, IntArray]:
    x = np.asarray(x, dtype=float)
    tri = np.asarray(triangles, dtype=np.intp)
    if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
        raise ValueError(f"x must be finite positions of shape (N, 3) in m, got {x.shape}")
    if (
        tri.ndim != 2
        or tri.shape[1] != 3
        or (tri.size and not 0 <= tri.min() <= tri.max() < len(x))
    ):
        raise ValueError(f"triangles must be (T, 3) indices into x (N = {len(x)})")
    return x, tri


def segment_hits_triangle(
    p: FloatArray, q: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> NDArray[np.bool_]:
    """Whether segments ``p q`` cross triangles ``(a, b, c)`` (all (M, 3)), Moller-Trumbore."""
    e, e1, e2 = q - p, b - a, c - a
    h = np.cross(e, e2)
    det = np.einsum("ij,ij->i", e1, h)
    scale = np.linalg.norm(e, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > 1e-14 * scale
    f = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = p - a
    u = f * np.einsum("ij,ij->i", s, h)
    qv = np.cross(s, e1)
    v = f * np.einsum("ij,ij->i", e, qv)
    t = f * np.einsum("ij,ij->i", e2, qv)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)


def _candidate_triangles(x: FloatArray, tri: IntArray, radius: float) -> IntArray:
    """Triangle pairs (K, 2) whose bounding spheres about the centroids come within
    ``radius`` [m] and that share no vertex."""
    xt = x[tri]
    cen = xt.mean(axis=1)
    rad = float(np.max(np.linalg.norm(xt - cen[:, None], axis=2), initial=0.0))
    pairs = cKDTree(cen).query_pairs(2 * rad + radius, output_type="ndarray").astype(np.intp)
    A, B = tri[pairs[:, 0]], tri[pairs[:, 1]]
    shared = np.zeros(len(pairs), dtype=bool)
    for i in range(3):
        shared |= np.any(A[:, [i]] == B, axis=1)
    return pairs[~shared]


def intersecting_pairs(x: ArrayLike, triangles: ArrayLike) -> IntArray:
    """Pairs (K, 2) of triangles that share no vertex and intersect."""
    x, tri = _check(x, triangles)
    pairs = _candidate_triangles(x, tri, 0.0)
    A, B = tri[pairs[:, 0]], tri[pairs[:, 1]]
    hit = np.zeros(len(pairs), dtype=bool)
    for S, T in ((A, B), (B, A)):
        for i, j in ((0, 1), (1, 2), (2, 0)):
            hit |= segment_hits_triangle(x[S[:, i]], x[S[:, j]], x[T[:, 0]], x[T[:, 1]], x[T[:, 2]])
    return pairs[hit]


def point_triangle_distance(
    p: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> FloatArray:
    """Distances (M,) of points ``p`` to triangles ``(a, b, c)``: to the plane where the
    point's projection falls inside (barycentric signs), else to the nearest edge."""
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    h = np.einsum("ij,ij->i", p - a, n) / np.where(nn > 0, nn, 1.0)
    f = p - h[:, None] * n  # projection on the plane
    inside = nn > 0
    for u, w in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(w - u, f - u), n) >= 0
    plane = np.abs(h) * np.sqrt(nn)
    edge = np.minimum(
        np.minimum(_point_segment(p, a, b), _point_segment(p, b, c)), _point_segment(p, c, a)
    )
    return np.where(inside, plane, edge)


def _point_segment(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    e = b - a
    ee = np.einsum("ij,ij->i", e, e)
    s = np.clip(np.einsum("ij,ij->i", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - a - s[:, None] * e, axis=1)


def segments_distance(p1: FloatArray, p2: FloatArray, q1: FloatArray, q2: FloatArray) -> FloatArray:
    """Distances (M,) between segments: the lines' common perpendicular where its feet lie
    on both segments, else the smallest endpoint-to-segment distance."""
    ends = np.minimum.reduce(
        [
            _point_segment(p1, q1, q2),
            _point_segment(p2, q1, q2),
            _point_segment(q1, p1, p2),
            _point_segment(q2, p1, p2),
        ]
    )
    u, v, w = p2 - p1, q2 - q1, p1 - q1
    a, b, c = (np.einsum("ij,ij->i", *z) for z in ((u, u), (u, v), (v, v)))
    d, e = np.einsum("ij,ij->i", u, w), np.einsum("ij,ij->i", v, w)
    den = a * c - b * b
    ok = den > 1e-12 * a * c
    s = np.divide(b * e - c * d, den, out=np.zeros_like(den), where=ok)
    t = np.divide(a * e - b * d, den, out=np.zeros_like(den), where=ok)
    feet = ok & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    perp = np.linalg.norm(w + s[:, None] * u - t[:, None] * v, axis=1)
    return np.where(feet, np.minimum(perp, ends), ends)


def _hops(tri: IntArray, n: int, rings: int) -> sp.csr_matrix:
    """Nodes at most ``rings`` edges apart in the triangulation's graph (boolean CSR)."""
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    g = ((g + g.T + sp.identity(n, format="csr")) > 0).astype(np.int8)
    r = g
    for _ in range(rings - 1):
        r = ((r @ g) > 0).astype(np.int8)
    return r.tocsr()


def layer_distance(x: ArrayLike, triangles: ArrayLike, *, rings: int = 2, radius: float) -> float:
    """Smallest vertex-triangle or edge-edge distance [m] over pairs whose nodes are all more
    than ``rings`` (>= 1) edges apart, among pairs within ``radius`` [m] (> 0); inf if none."""
    x, tri = _check(x, triangles)
    if int(rings) != rings or rings < 1:
        raise ValueError(f"rings must be an integer >= 1, got {rings!r}")
    if not radius > 0:
        raise ValueError(f"radius must be > 0 m, got {radius!r}")
    hop = _hops(tri, len(x), int(rings))
    pairs = _candidate_triangles(x, tri, radius)
    A, B = tri[pairs[:, 0]], tri[pairs[:, 1]]
    far = np.ones(len(pairs), dtype=bool)
    for i in range(3):
        for j in range(3):
            far &= ~np.asarray(hop[A[:, i], B[:, j]]).ravel().astype(bool)
    A, B = A[far], B[far]
    best = np.inf
    for S, T in ((A, B), (B, A)):
        for i in range(3):
            d = point_triangle_distance(x[S[:, i]], x[T[:, 0]], x[T[:, 1]], x[T[:, 2]])
            best = min(best, float(np.min(d, initial=np.inf)))
    for i, j in ((0, 1), (1, 2), (2, 0)):
        for k, m in ((0, 1), (1, 2), (2, 0)):
            d = segments_distance(x[A[:, i]], x[A[:, j]], x[B[:, k]], x[B[:, m]])
            best = min(best, float(np.min(d, initial=np.inf)))
    return best if best <= radius else np.inf


class SurfaceCheck(NamedTuple):
    """Intersecting triangle pairs and the smallest layer distance [m] of a surface."""

    intersections: int
    min_distance: float


def check_surface(
    x: ArrayLike, triangles: ArrayLike, *, rings: int = 2, radius: float
) -> SurfaceCheck:
    """:func:`intersecting_pairs` count and :func:`layer_distance` of one configuration."""
    return SurfaceCheck(
        len(intersecting_pairs(x, triangles)),
        layer_distance(x, triangles, rings=rings, radius=radius),
    )
