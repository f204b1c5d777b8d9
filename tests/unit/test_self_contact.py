"""Unit tests of clothfem.contact.self_contact and clothfem.contact.intersections (point
masses on meshes built on ``MPI.COMM_SELF``: every rank runs the same checks)."""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact import intersections as ix
from clothfem.contact import self_contact as sc

RNG = np.random.default_rng(7)


@pytest.fixture(scope="module")
def strip():
    sm = meshes.strip(MPI.COMM_SELF, length=0.04, width=0.02, nx=4, ny=2)
    return sc.mesh_nodes(sm.mesh)


def test_triangulation_covers_each_cell_with_consistent_orientation(strip):
    X, cells = strip
    tri, cell_of = sc.triangulate_q9(cells)
    assert tri.shape == (8 * len(cells), 3)
    np.testing.assert_array_equal(np.bincount(cell_of), np.full(len(cells), 8))
    n = np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])
    np.testing.assert_allclose(0.5 * np.linalg.norm(n, axis=1).sum(), 0.04 * 0.02, rtol=1e-12)
    assert np.all(n[:, 2] > 0) or np.all(n[:, 2] < 0)  # one orientation (the cells')
    surf = sc.fabric_surface(cells, n_nodes=len(X))
    # closed form: a 4 x 2 grid of 9-node cells has 9 x 5 nodes and 8 triangles per cell
    assert len(X) == 45 and len(surf.edges) == 45 + 64 - 1  # Euler: V - E + F = 1


def test_closest_point_matches_the_independent_distance():
    p, a, b, c = (RNG.normal(size=(2000, 3)) for _ in range(4))
    q, w = sc.closest_point_triangle(p, a, b, c)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert w.min() >= -1e-12
    np.testing.assert_allclose(q, w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c, atol=1e-12)
    dist = np.linalg.norm(p - q, axis=1)
    np.testing.assert_allclose(dist, ix.point_triangle_distance(p, a, b, c), atol=1e-12)


def test_segment_distance_matches_the_independent_one():
    p1, p2, q1, q2 = (RNG.normal(size=(2000, 3)) for _ in range(4))
    s, t, dist = sc.segment_closest(p1, p2, q1, q2)
    assert s.min() >= 0 and s.max() <= 1 and t.min() >= 0 and t.max() <= 1
    np.testing.assert_allclose(dist, ix.segments_distance(p1, p2, q1, q2), atol=1e-12)


def test_smooth_surfaces_never_contact_themselves():
    """A flat strip and a tube have no candidate pairs at the thickness: with only a node's
    own triangles excluded, every other node-triangle pair of a smooth surface is about a
    third of a cell apart."""
    for sm in (
        meshes.strip(MPI.COMM_SELF, length=0.1, width=0.05, nx=10, ny=5),
        meshes.cylinder(MPI.COMM_SELF, radius=0.06, length=0.1, n_around=16, n_along=4),
    ):
        X, cells = sc.mesh_nodes(sm.mesh)
        surf = sc.fabric_surface(cells, n_nodes=len(X))
        c = sc.build_candidates(X, surf, distance=1e-3, skin=1e-3)
        assert len(c.pt_node) == 0 and len(c.ee) == 0


def test_near_pairs_are_the_cell_ring(strip):
    X, cells = strip
    own = sc.fabric_surface(cells, n_nodes=len(X))  # rings = 0: a node is near itself only
    a = np.arange(len(X))
    assert sc.near_pairs(own, a, a).all() and not sc.near_pairs(own, a[:-1], a[1:]).any()
    surf = sc.fabric_surface(cells, n_nodes=len(X), rings=1)
    a, b = np.meshgrid(np.arange(len(X)), np.arange(len(X)), indexing="ij")
    near = sc.near_pairs(surf, a.ravel(), b.ravel()).reshape(a.shape)
    share = np.zeros_like(near)
    for c in cells:
        share[np.ix_(c, c)] = True
    np.testing.assert_array_equal(near, share)
    two = sc.fabric_surface(cells, n_nodes=len(X), rings=2)
    with pytest.raises(ValueError, match="in-surface node-triangle gap"):
        sc.check_resolution(X, cells, own, 0.004)  # cells 10 mm: gaps ~3.5 mm
    sc.check_resolution(X, cells, own, 0.001)
    assert two.near_keys.size > surf.near_keys.size


def test_unit_roots_of_a_cubic():
    roots = np.array([0.1, 0.45, 0.8])
    co = np.polynomial.polynomial.polyfromroots(roots)[None, :] * 3.0
    got = sc._unit_roots(co)
    np.testing.assert_allclose(np.sort(got[0]), roots, atol=1e-12)
    none = sc._unit_roots(np.array([[1.0, 0.0, 1.0, 0.0]]))  # 1 + t^2 > 0
    assert np.isnan(none).all()


def test_crossing_detection():
    """A point through a triangle and an edge through an edge are found; a parallel pass
    at 1 mm is not."""
    x0 = np.array([[0.2, 0.2, 1.0], [0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    x1 = x0.copy()
    x1[0, 2] = -1.0
    surf = sc.FabricSurface(
        np.array([[1, 2, 3]]), np.zeros(1, int), np.array([[0, 1], [2, 3]]), 4,
        np.zeros(0, np.int64), 1,
    )  # fmt: skip
    args = (surf, np.array([0]), np.array([0]), 1e-9)
    assert sc.point_triangle_crossings(x0, x1, *args)[0]
    x1[0, 2] = 1e-3
    assert not sc.point_triangle_crossings(x0, x1, *args)[0]
    e0 = np.array([[0.5, -1, 1], [0.5, 1, 1], [0, 0, 0], [1, 0, 0]], dtype=float)
    e1 = e0.copy()
    e1[:2, 2] = -1
    ee = np.array([[0, 1]])
    assert sc.edge_edge_crossings(e0, e1, surf, ee, 1e-9)[0]
    e1[:2, 2] = 1e-3
    assert not sc.edge_edge_crossings(e0, e1, surf, ee, 1e-9)[0]


def test_single_pair_projection_is_eq_25():
    """One node over a triangle (masses m, 2m, 3m, 4m): the projection moves the pair to the
    distance d with the multiplier m_eff (d - gap) of Eq. 25 and conserves momentum."""
    x = np.array([[0.25, 0.25, 0.0004], [0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    surf = sc.FabricSurface(
        np.array([[1, 2, 3]]), np.zeros(1, int), np.array([[1, 2]]), 4, np.zeros(0, np.int64), 1
    )
    c = sc.pair_contacts(x, x, surf, np.array([0]), np.array([0]))
    np.testing.assert_allclose(c.gap, [0.0004])
    np.testing.assert_allclose(c.normal, [[0, 0, 1]])
    m = np.array([1.0, 2.0, 3.0, 4.0])
    xn, lam = sc.project_positions(x, c, 1 / m, distance=1e-3, passes=5, tol=1e-15)
    w = -c.coef[0, 1:]
    m_eff = 1 / (1 / m[0] + np.sum(w**2 / m[1:]))
    np.testing.assert_allclose(lam, [m_eff * 6e-4], rtol=1e-12)
    gap = np.einsum("j,jk->k", c.coef[0], xn[c.idx[0]]) @ c.normal[0]  # normal and w held
    np.testing.assert_allclose(gap, 1e-3, rtol=1e-12)
    np.testing.assert_allclose((m[:, None] * (xn - x)).sum(axis=0), 0.0, atol=1e-18)


def test_side_follows_the_start_of_the_step():
    """A node that passed through the face in the step gets a negative gap."""
    x0 = np.array([[0.25, 0.25, 0.001], [0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    x = x0.copy()
    x[0, 2] = -0.0005
    surf = sc.FabricSurface(
        np.array([[1, 2, 3]]), np.zeros(1, int), np.array([[1, 2]]), 4, np.zeros(0, np.int64), 1
    )
    c = sc.pair_contacts(x0, x, surf, np.array([0]), np.array([0]))
    np.testing.assert_allclose(c.gap, [-0.0005])
    np.testing.assert_allclose(c.normal, [[0, 0, 1]])


def test_intersections_of_crossing_and_separate_triangles():
    x = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -0.5], [0.2, 0.2, 0.5], [0.8, 0.8, 0.5]],
        dtype=float,
    )
    tri = np.array([[0, 1, 2], [3, 4, 5]])
    assert len(ix.intersecting_pairs(x, tri)) == 1
    x[3:, 2] += 1.0
    assert len(ix.intersecting_pairs(x, tri)) == 0
    np.testing.assert_allclose(ix.layer_distance(x, tri, rings=1, radius=2.0), 0.5)


@pytest.mark.parametrize(
    "kw, msg",
    [
        ({"distance": 0.0}, "distance must be > 0 m"),
        ({"distance": 1e-3, "mu": -1.0}, "mu must be >= 0"),
        ({"distance": 1e-3, "rings": -1}, "rings must be an integer >= 0"),
        ({"distance": 1e-3, "skin": -1.0}, "skin must be None or > 0 m"),
        ({"distance": 1e-3, "tolerance": 1.0}, "tolerance must be in \\(0, 1\\)"),
    ],
)
def test_bad_parameters(kw, msg):
    with pytest.raises(ValueError, match=msg):
        sc.SelfContactParameters(**kw)


def test_scene_keys_build_self_contact_only_when_asked():
    """contact.self_contact defaults to false (SelfContact.from_scene builds nothing); true
    is allowed with newmark too (with self_mu, the layer friction of both integrators;
    static refuses both: test_scene_integrator_keys); the distance defaults to the
    thickness, mu to contact.mu."""
    from pathlib import Path

    from clothfem import scene as scenes

    path = Path(__file__).parents[2] / "demos" / "scenes" / "arm_sleeve.toml"
    data = scenes.load(path)
    assert data.contact.self_contact is False
    assert sc.SelfContact.from_scene(None, data.contact) is None
    on = scenes.load(path, ["contact.self_contact=true"]).contact
    assert on.self_contact is True and on.self_distance is None and on.self_mu is None
    nm = ["solver.integrator='newmark'", "contact.self_contact=true"]
    assert scenes.load(path, nm + ["contact.self_distance=2e-3"]).contact.self_contact
    assert scenes.load(path, nm + ["contact.self_mu=0.2"]).contact.self_mu == 0.2


@pytest.mark.parametrize("kernel", ["numpy", "auto"])
def test_both_response_solvers_separate_and_conserve_momentum(strip, kernel):
    """The vectorised accelerated Jacobi and the Gauss-Seidel kernel both leave every pair
    at >= (1 - tolerance) d with zero net impulse, from two copies of a strip 0.3 d apart."""
    X, cells = strip
    n = len(X)
    x0 = np.vstack([X, X + [0.002, 0.001, 3e-3]])
    surf = sc.fabric_surface(np.vstack([cells, cells + n]), n_nodes=2 * n)
    v = np.zeros_like(x0)
    v[:n, 2], v[n:, 2] = 0.5, -0.5
    dt, m = 2.7e-3, np.linspace(1.0, 2.0, 2 * n) * 1e-5
    p = sc.SelfContactParameters(distance=1e-3, mu=0.2, kernel=kernel, passes=200)
    r = sc.self_contact_step(x0, x0 + dt * v, v, m, dt, surf, params=p)
    assert len(r.jn) > n // 2 and r.crossings_left == 0
    c = r.contacts
    gap = np.einsum("ij,ij->i", np.einsum("ij,ijk->ik", c.coef, r.x[c.idx]), c.normal)
    assert gap.min() >= (1 - p.tolerance) * 1e-3
    np.testing.assert_allclose((m[:, None] * (r.v - v)).sum(0), 0.0, atol=1e-16)
    np.testing.assert_allclose((m[:, None] * (r.x - x0 - dt * v)).sum(0), 0.0, atol=1e-18)


def test_candidate_list_survives_rigid_motion_and_stays_complete():
    """The list stays valid under a rigid translation larger than its skin, turns invalid
    when layers move relative to each other by more than the skin, and while valid it holds
    every node-triangle pair closer than d (compared with a fresh build)."""
    sm = meshes.strip(MPI.COMM_SELF, length=0.04, width=0.02, nx=4, ny=2)
    X, cells = sc.mesh_nodes(sm.mesh)
    n = len(X)
    x = np.vstack([X, X + [0.0, 0.0, 1.03e-3]])
    surf = sc.fabric_surface(np.vstack([cells, cells + n]), n_nodes=2 * n)
    c = sc.build_candidates(x, surf, distance=1e-3, skin=1e-3)
    assert c.valid(x + [3e-3, -2e-3, 1e-3])  # rigid, 3.7 mm > skin
    shear = x.copy()
    shear[n:, 0] += 1.2e-3  # the top layer slides by more than the skin
    assert not c.valid(shear)
    listed = set(zip(c.pt_node.tolist(), c.pt_tri.tolist(), strict=True))
    checked = 0
    for _ in range(20):
        moved = x + RNG.normal(scale=6e-5, size=x.shape) + RNG.normal(scale=2e-3, size=3)
        if not c.valid(moved):
            continue
        checked += 1
        fresh = sc.build_candidates(moved, surf, distance=1e-3, skin=1e-9)
        close = fresh.pt_dist < 1e-3
        found = zip(fresh.pt_node[close].tolist(), fresh.pt_tri[close].tolist(), strict=True)
        assert close.any() and set(found) <= listed
    assert checked >= 5


def test_compiled_narrow_phase_matches_numpy():
    """The numba loops (node-triangle and edge-edge contacts, distances, relative-motion
    bounds) give the numpy references' values to round-off on random pairs (face, edge and
    vertex regions, nodes on either side at the step's start)."""
    if not sc._numba_kernels():
        pytest.skip("numba not importable")
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=(400, 3))
    x = x0 + 0.05 * rng.normal(size=x0.shape)
    surf = sc.FabricSurface(
        100 + np.arange(300).reshape(100, 3), np.zeros(100, int), np.zeros((0, 2), int),
        400, np.zeros(0, np.int64), 1,
    )  # fmt: skip
    node, tri = np.arange(100).repeat(3), rng.integers(0, 100, size=300)
    a = sc.pair_contacts(x0, x, surf, node, tri, kernel="numpy")
    b = sc.pair_contacts(x0, x, surf, node, tri, kernel="numba")
    for u, w in zip(a[1:4], b[1:4], strict=True):
        np.testing.assert_allclose(u, w, atol=1e-12)
    g = np.column_stack([node, surf.triangles[tri]])
    ref, _ = sc.closest_point_triangle(*(x[g[:, k]] for k in range(4)))
    np.testing.assert_allclose(
        sc._pt_distances(x, g), np.linalg.norm(x[g[:, 0]] - ref, axis=1), atol=1e-13
    )
    edges = rng.integers(0, 400, size=(200, 2))
    edges = edges[edges[:, 0] != edges[:, 1]]
    surf = sc.FabricSurface(surf.triangles, surf.cell_of, edges, 400, surf.near_keys, 1)
    ee = rng.integers(0, len(edges), size=(300, 2))
    a = sc.edge_contacts(x0, x, surf, ee, kernel="numpy")
    b = sc.edge_contacts(x0, x, surf, ee, kernel="numba")
    for u, w in zip(a[1:4], b[1:4], strict=True):
        np.testing.assert_allclose(u, w, atol=1e-12)
    gi = np.column_stack([edges[ee[:, 0]], edges[ee[:, 1]]])
    np.testing.assert_allclose(
        sc._ee_distances(x, gi), sc.segment_distance(*(x[gi[:, k]] for k in range(4))), atol=1e-13
    )
    D = rng.normal(size=(400, 3))
    exact = np.max([np.linalg.norm(D[g[:, 0]] - D[g[:, k]], axis=1) for k in (1, 2, 3)], axis=0)
    np.testing.assert_allclose(sc._relative_motion(D, g, 1), exact, rtol=1e-14)


def test_candidate_list_motion_bound_is_sound():
    """Twice the motion radius of the displacements since the build bounds the fall of
    every pair's distance: two layers 2.1 d apart (no pair listed between them with a skin
    of d) stay covered while the top one sinks by 0.9 d, and the list is refused once it
    sinks by 1.15 d, where unlisted pairs are within d (an undoubled radius would pass)."""
    sm = meshes.strip(MPI.COMM_SELF, length=0.04, width=0.02, nx=4, ny=2)
    X, cells = sc.mesh_nodes(sm.mesh)
    n, d = len(X), 1e-3
    x = np.vstack([X, X + [0.0, 0.0, 2.1 * d]])
    surf = sc.fabric_surface(np.vstack([cells, cells + n]), n_nodes=2 * n)
    c = sc.build_candidates(x, surf, distance=d, skin=d)
    assert not np.any((c.pt_node >= n) != (surf.triangles[c.pt_tri, 0] >= n))
    for sink, ok in ((0.9 * d, True), (1.15 * d, False)):
        y = x.copy()
        y[n:, 2] -= sink
        assert c._moved_less(y) is ok
        assert c.valid(y) is ok
        fresh = sc.build_candidates(y, surf, distance=d, skin=1e-9)
        across = (fresh.pt_dist < d) & (
            (fresh.pt_node >= n) != (surf.triangles[fresh.pt_tri, 0] >= n)
        )
        assert across.any() is not ok
