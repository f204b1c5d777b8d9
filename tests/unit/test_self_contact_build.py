"""The candidate list of clothfem.contact.self_contact.build_candidates against the cKDTree
build it replaced (kept here as the reference): the same node-triangle and edge pairs with
the same distances, on a straight tube, a flattened and bent tube (the elbow of
benchmarks/self_contact_cost.py) and a randomly crumpled sheet."""

import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial import cKDTree

from clothfem import mesh as meshes
from clothfem.contact import self_contact as sc

D = 1e-3


def reference(x, surface, *, distance, skin, edges=True):
    """The previous build: cKDTree queries, exact distances, then the neighbour exclusion."""
    tri, edge = surface.triangles, surface.edges
    reach = distance + skin
    e_reach = reach if edges else skin + 0.01 * distance
    xt = x[tri]
    cen = xt.mean(axis=1)
    rad = float(np.max(np.linalg.norm(xt - cen[:, None], axis=2), initial=0.0))
    hits = cKDTree(x).sparse_distance_matrix(cKDTree(cen), reach + rad, output_type="ndarray")
    node, t = hits["i"].astype(np.intp), hits["j"].astype(np.intp)
    dist = sc._pt_distances(x, np.column_stack([node, tri[t]]))
    keep = np.flatnonzero(dist < reach)
    keep = keep[sc._far(surface, node[keep, None], tri[t[keep]])]
    xe = x[edge]
    mid = xe.mean(axis=1)
    length = float(np.max(np.linalg.norm(xe[:, 0] - xe[:, 1], axis=1), initial=0.0))
    ee = cKDTree(mid).query_pairs(e_reach + length, output_type="ndarray").astype(np.intp)
    e0, e1 = edge[ee[:, 0]], edge[ee[:, 1]]
    ed = sc._ee_distances(x, np.column_stack([e0, e1]))
    close = np.flatnonzero(ed < e_reach)
    close = close[sc._far(surface, e0[close], e1[close])]
    return node[keep], t[keep], dist[keep], ee[close], ed[close]


def elbow(X, *, radius=0.06, xj=0.3, half=0.08, angle_deg=120.0):
    """The benchmark's elbow: the tube flattened about x = xj (walls 1.02 d apart), bent."""
    s = X[:, 0] - xj
    f = np.exp(-0.5 * (s / (0.5 * half)) ** 2)
    z = X[:, 2] * (1 - (1 - 0.51 * D / radius) * f)
    rho = 2 * half / np.deg2rad(angle_deg)
    psi = np.clip(s, -half, half) / rho
    rest = s - np.clip(s, -half, half)
    y = X[:, 1]
    xb = xj + (rho - y) * np.sin(psi) + rest * np.cos(psi)
    yb = rho - (rho - y) * np.cos(psi) + rest * np.sin(psi)
    return np.column_stack([xb, yb, z])


def crumpled(X):
    """A sheet folded onto itself and crumpled by random smooth waves of ~d amplitude."""
    rng = np.random.default_rng(11)
    u, v = X[:, 0] / 0.1, X[:, 1] / 0.05
    ang = np.pi * u
    x = np.column_stack([0.02 * np.sin(ang), X[:, 1], 0.004 * np.cos(ang) + 0.002])
    for _ in range(6):
        k, phase = rng.normal(scale=8.0, size=2), rng.uniform(0, 2 * np.pi)
        x += rng.normal(scale=1.5 * D, size=3) * np.sin(k[0] * u + k[1] * v + phase)[:, None]
    return x


@pytest.fixture(scope="module")
def tube():
    sm = meshes.cylinder(MPI.COMM_SELF, radius=0.06, length=0.5, n_around=16, n_along=20)
    return sc.mesh_nodes(sm.mesh)


@pytest.fixture(scope="module")
def sheet():
    sm = meshes.strip(MPI.COMM_SELF, length=0.1, width=0.05, nx=12, ny=6)
    return sc.mesh_nodes(sm.mesh)


def _as_sets(node, t, dist, ee, ed):
    pt = dict(zip(zip(node.tolist(), t.tolist(), strict=True), dist.tolist(), strict=True))
    e = dict(zip(map(tuple, np.asarray(ee).tolist()), ed.tolist(), strict=True))
    return pt, e


def _configs(tube, sheet):
    X, cells = tube
    Xs, cs = sheet
    yield "straight", X, cells
    yield "elbow", elbow(X), cells
    yield "crumpled", crumpled(Xs), cs


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("rings", [0, 1])
@pytest.mark.parametrize("edges", [True, False])
def test_build_matches_the_reference(tube, sheet, monkeypatch, compiled, rings, edges):
    if compiled and not sc._numba_kernels():
        pytest.skip("numba not importable")
    if not compiled:
        monkeypatch.setattr(sc, "_numba_kernels", lambda: ())
    for name, x, cells in _configs(tube, sheet):
        surf = sc.fabric_surface(cells, n_nodes=len(x), rings=rings)
        for skin in (2 * D, 10 * D):
            c = sc.build_candidates(x, surf, distance=D, skin=skin, edges=edges)
            ref = reference(x, surf, distance=D, skin=skin, edges=edges)
            got = _as_sets(c.pt_node, c.pt_tri, c.pt_dist, c.ee, c.ee_dist)
            assert got == _as_sets(*ref), (name, skin)
            assert len(c.pt_node) == len(ref[0]) and len(c.ee) == len(ref[3])
            np.testing.assert_array_equal(c.pt_nodes[:, 1:], surf.triangles[c.pt_tri])
            np.testing.assert_array_equal(c.ee_nodes, surf.edges[c.ee].reshape(-1, 4))
            if name != "straight" and skin > 2 * D:
                assert len(c.pt_node) > 100 and len(c.ee) > 100, name


def test_pairs_are_sorted(tube):
    X, cells = tube
    surf = sc.fabric_surface(cells, n_nodes=len(X))
    c = sc.build_candidates(elbow(X), surf, distance=D, skin=2 * D)
    assert np.all(np.diff(c.pt_node * len(surf.triangles) + c.pt_tri) > 0)
    assert np.all(c.ee[:, 0] < c.ee[:, 1])
    assert np.all(np.diff(c.ee[:, 0] * len(surf.edges) + c.ee[:, 1]) > 0)


def test_compiled_spread_matches_numpy(tube, monkeypatch):
    if not sc._numba_kernels():
        pytest.skip("numba not importable")
    X, cells = tube
    surf = sc.fabric_surface(cells, n_nodes=len(X))
    c = sc.build_candidates(elbow(X), surf, distance=D, skin=2 * D)
    rng = np.random.default_rng(5)
    for scale in (1e-4, 3e-4, 0.1):
        dx = rng.normal(scale=scale, size=X.shape)
        compiled = c.tiles.spread(dx)
        monkeypatch.setattr(sc, "_numba_kernels", lambda: ())
        assert compiled == pytest.approx(c.tiles.spread(dx), rel=1e-12)
        monkeypatch.undo()
    assert c.tiles.spread(np.full_like(X, 1.0)) == 0.0  # a rigid translation is free
    torn = np.zeros_like(X)
    torn[: len(X) // 2] = 1.0
    assert c.tiles.spread(torn) == np.inf  # nodes farther apart than far moved apart


@pytest.mark.parametrize("skin", [2 * D, 12 * D])
def test_a_valid_list_holds_every_close_pair(sheet, skin):
    """While the list is valid, every node-triangle and edge pair closer than d at the moved
    positions is listed (random smooth deformations of the crumpled sheet, a skin below
    and above the longest edge)."""
    Xs, cells = sheet
    x = crumpled(Xs)
    surf = sc.fabric_surface(cells, n_nodes=len(x))
    c = sc.build_candidates(x, surf, distance=D, skin=skin)
    pt = set(zip(c.pt_node.tolist(), c.pt_tri.tolist(), strict=True))
    ee = set(map(tuple, c.ee.tolist()))
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(30):
        k = rng.normal(scale=30.0, size=3)
        wave = np.sin(x @ k + rng.uniform(0, 2 * np.pi))[:, None]
        moved = x + rng.normal(scale=0.1 * skin, size=3) * wave + rng.normal(scale=3 * skin, size=3)
        if not c.valid(moved):
            continue
        checked += 1
        fresh = sc.build_candidates(moved, surf, distance=D, skin=1e-9 * D)
        close = fresh.pt_dist < D
        found = zip(fresh.pt_node[close].tolist(), fresh.pt_tri[close].tolist(), strict=True)
        assert set(found) <= pt
        assert set(map(tuple, fresh.ee[fresh.ee_dist < D].tolist())) <= ee
    assert checked >= 5
