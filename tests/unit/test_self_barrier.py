"""The fabric-fabric barrier of the implicit path: the barrier function, the distance
derivatives of every closest-feature case, Taylor tests of the energy's gradient and Hessian
on a folded sheet, and the same for the layer friction's dissipation potential (NumPy only:
runs unchanged on every rank)."""

from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.self_barrier import (
    SelfBarrierParameters,
    barrier,
    barrier_pairs,
    cross_derivatives,
    distance_derivatives,
    edge_areas,
    edge_energy,
    edge_pairs,
    friction_energy,
    friction_pairs,
    friction_slip,
    friction_work,
    pair_energy,
    vertex_areas,
)
from clothfem.contact.self_contact import build_candidates, fabric_surface, mesh_nodes

D = 1e-3  # activation distance [m]


def remainder_orders(at, f0, slope, curvature, steps):
    """Observed orders of the Taylor remainders |f(h) - f0 - h slope| and |f(h) - f0 - h slope
    - h^2 curvature / 2| over the halving ``steps`` h, f(h) = ``at(h)``."""
    h = np.asarray(steps, dtype=float)
    r1 = np.array([at(hk) for hk in h]) - f0 - h * slope
    e1, e2 = np.abs(r1), np.abs(r1 - 0.5 * h * h * curvature)
    return np.log2(e1[:-1] / e1[1:]), np.log2(e2[:-1] / e2[1:])


def test_barrier_is_c2_at_the_activation_distance():
    """b, b', b'' vanish at s = d; b' and b'' agree with central differences inside."""
    s = np.array([0.1, 0.3, 0.7, 0.95]) * D
    b, db, d2b = barrier(s, distance=D)
    h = 1e-9
    bp, dbp, _ = barrier(s + h, distance=D)
    bm, dbm, _ = barrier(s - h, distance=D)
    assert np.allclose(db, (bp - bm) / (2 * h), rtol=1e-6)
    assert np.allclose(d2b, (dbp - dbm) / (2 * h), rtol=1e-6)
    at = barrier(np.array([D, 2 * D]), distance=D)
    assert all(np.all(a == 0.0) for a in at)
    near = barrier(np.array([D * (1 - 1e-6)]), distance=D)
    assert abs(near[2][0]) < 1e-5  # b'' -> 0 continuously


CASES = {
    # node p over triangle (a, b, c), closest point inside the face, on an edge, a vertex
    "face": ([0.2, 0.3, 0.6], [0, 0, 0], [1, 0, 0], [0, 1, 0]),
    "edge": ([0.5, -0.3, 0.4], [0, 0, 0], [1, 0, 0], [0, 1, 0]),
    "vertex": ([-0.3, -0.2, 0.5], [0, 0, 0], [1, 0, 0], [0, 1, 0]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_distance_derivatives_taylor(case):
    """Gradient and Hessian of the pair distance against the closest-point distance
    recomputed at perturbed positions: first-order remainder O(h^2), second-order O(h^3)."""
    from clothfem.contact.self_barrier import _free_directions
    from clothfem.contact.self_contact import closest_point_triangle

    y0 = np.array(CASES[case], dtype=float)[None]

    def coef_at(y):
        _, w = closest_point_triangle(y[:, 0], y[:, 1], y[:, 2], y[:, 3])
        c = np.column_stack([np.ones(1), -w])
        return c, _free_directions(c, ((1.0, (0,)), (-1.0, (1, 2, 3))))

    c, free = coef_at(y0)
    s0, g, H = distance_derivatives(y0, c, free)
    rng = np.random.default_rng(3)
    v = rng.normal(size=12)

    def at(h):
        y = y0 + h * v.reshape(1, 4, 3)
        return distance_derivatives(y, *coef_at(y))[0][0]

    o1, o2 = remainder_orders(at, s0[0], g[0] @ v, v @ H[0] @ v, 1e-3 * 0.5 ** np.arange(4))
    assert np.all(o1 > 1.8), o1
    assert np.all(o2 > 2.7), o2


def folded_sheet():
    """A 4 x 2 nine-node sheet whose half x > 0.02 is folded back 0.6 d above the other."""
    sm = meshes.strip(MPI.COMM_SELF, length=0.04, width=0.02, nx=4, ny=2)
    X, cells = mesh_nodes(sm.mesh)
    x = X.copy()
    far = X[:, 0] > 0.02 + 1e-12
    x[far, 0] = 0.04 - X[far, 0] + 0.0013  # mirrored, shifted so the nodes are off the others
    x[far, 2] = 0.6 * D
    bend = np.abs(X[:, 0] - 0.02) < 1e-12
    x[bend, 2] = 0.3 * D
    # off the triangles' region boundaries (the Hessian jumps there)
    x[far, :2] += np.random.default_rng(1).uniform(-1e-4, 1e-4, size=(far.sum(), 2))
    return x, fabric_surface(cells, n_nodes=len(X))


def test_energy_gradient_and_hessian_taylor():
    """Energy of a folded sheet with both layers within d: the gradient and the Hessian of
    E(x) (pairs and closest features recomputed at every x) give remainders of orders 2 and
    3 along a random direction."""
    x0, surf = folded_sheet()
    p = SelfBarrierParameters(distance=D, pressure=500.0)
    va = vertex_areas(x0, surf)
    c = build_candidates(x0, surf, distance=D, skin=D)

    def energy(x):
        bp = barrier_pairs(x, surf, c, distance=D, vertex_area=va)
        return pair_energy(x, bp, params=p), bp

    (e0, g, H, _), bp = energy(x0)
    assert len(bp.dist) > 20
    G = np.zeros_like(x0)
    np.add.at(G, bp.idx.ravel(), g.reshape(-1, 3))
    rng = np.random.default_rng(7)
    v = rng.normal(size=x0.shape) * 1e-2 * D
    vp = v[bp.idx].reshape(len(bp.dist), 12)
    Hv = np.einsum("mi,mij,mj->", vp, H, vp)
    o1, o2 = remainder_orders(
        lambda h: energy(x0 + h * v)[0][0], e0, np.sum(G * v), Hv, 0.5 ** np.arange(1, 6)
    )
    assert np.all(o1 > 1.8), o1
    assert np.all(o2 > 2.7), o2


def frozen_friction():
    """The folded sheet's barrier pairs frozen for the friction at their positions x0."""
    x0, surf = folded_sheet()
    p = SelfBarrierParameters(distance=D, pressure=500.0, mu=0.3)
    va = vertex_areas(x0, surf)
    c = build_candidates(x0, surf, distance=D, skin=D)
    bp = barrier_pairs(x0, surf, c, distance=D, vertex_area=va)
    force = pair_energy(x0, bp, params=p)[3]
    return x0, friction_pairs(x0, bp.idx, bp.coef, force), p, bp


def test_friction_pairs_frame_and_forces():
    """The frozen tangent bases are orthonormal and normal to each pair's distance vector;
    the barrier's pair forces -dE/ds they carry are positive."""
    x0, fp, p, bp = frozen_friction()
    T = fp.basis
    np.testing.assert_allclose(
        np.einsum("mki,mkj->mij", T, T), np.broadcast_to(np.eye(2), (len(T), 2, 2)), atol=1e-14
    )
    np.testing.assert_allclose(np.einsum("mk,mkl->ml", fp.r0, T), 0.0, atol=1e-15)
    assert np.all(fp.force > 0)


@pytest.mark.parametrize("regime", ["sliding", "sticking"])
def test_friction_energy_taylor(regime):
    """The dissipation potential's gradient and Hessian: remainders of orders 2 and 3 along a
    random direction from a state moved tangentially since the step's start, every pair
    slipping more than eps (sliding) or less (sticking)."""
    x0, fp, p, _ = frozen_friction()
    slide = np.array([0.4, 0.3, 0.0]) * D
    eps = 0.01 * D if regime == "sliding" else 10 * D
    x1 = x0 + slide * (x0[:, 2] > 0.45 * D)[:, None]
    y = np.linalg.norm(friction_slip(x1, fp), axis=1)
    moved = y > 0
    assert moved.sum() > 10
    assert np.all(y[moved] > eps) if regime == "sliding" else np.all(y < eps)
    e0, g, H = friction_energy(x1, fp, mu=p.mu, eps=eps)
    G = np.zeros_like(x1)
    np.add.at(G, fp.idx.ravel(), g.reshape(-1, 3))
    v = np.random.default_rng(11).normal(size=x1.shape) * 1e-3 * D
    vp = v[fp.idx].reshape(len(fp.force), 12)
    Hv = np.einsum("mi,mij,mj->", vp, H, vp)
    o1, o2 = remainder_orders(
        lambda h: friction_energy(x1 + h * v, fp, mu=p.mu, eps=eps)[0],
        e0, np.sum(G * v), Hv, 0.5 ** np.arange(1, 6),
    )  # fmt: skip
    assert np.all(o1 > 1.8), o1
    assert np.all(o2 > 2.7), o2
    w = np.linalg.eigvalsh(H)  # positive semi-definite per pair
    assert w.min() >= -1e-12 * w.max()


def test_friction_force_is_coulomb_when_sliding():
    """A pair slipping by more than eps carries mu x its frozen normal force, opposite to
    its slip; a pair at rest carries none; the work over the step is mu lambda y."""
    x0, fp, p, _ = frozen_friction()
    eps = 1e-6 * D
    x1 = x0 + np.array([0.5, 0.0, 0.0]) * D * (x0[:, 2] > 0.45 * D)[:, None]
    _, g, _ = friction_energy(x1, fp, mu=p.mu, eps=eps)
    g = g.reshape(-1, 4, 3)
    u = friction_slip(x1, fp)
    y = np.linalg.norm(u, axis=1)
    slid = y > eps
    # the force on the slipping node (coefficient 1) of every node-triangle pair
    t_dir = np.einsum("mkl,ml->mk", fp.basis, u)[slid] / y[slid, None]
    np.testing.assert_allclose(
        -g[slid, 0], -p.mu * fp.force[slid, None] * t_dir, rtol=1e-12, atol=1e-18
    )
    np.testing.assert_allclose(g[~slid], 0.0, atol=1e-18)
    work = friction_work(x1, fp, mu=p.mu, eps=eps)
    np.testing.assert_allclose(work, np.sum(p.mu * fp.force * y), rtol=1e-12)


def test_cross_product_derivatives_taylor():
    """c = |e0 x e1|^2 of two random edges: gradient and Hessian against c at perturbed
    positions (c is quartic: remainders of orders 2 and 3)."""
    rng = np.random.default_rng(4)
    y0 = rng.normal(size=(1, 4, 3))
    c0, g, H = cross_derivatives(y0)
    e0, e1 = y0[0, 1] - y0[0, 0], y0[0, 3] - y0[0, 2]
    assert c0[0] == pytest.approx(np.sum(np.cross(e0, e1) ** 2), rel=1e-12)
    v = rng.normal(size=12)
    o1, o2 = remainder_orders(
        lambda h: cross_derivatives(y0 + h * v.reshape(1, 4, 3))[0][0],
        c0[0], g[0] @ v, v @ H[0] @ v, 1e-2 * 0.5 ** np.arange(4),
    )  # fmt: skip
    assert np.all(o1 > 1.8), o1
    assert np.all(o2 > 2.7), o2


def test_edge_energy_gradient_and_hessian_taylor():
    """The mollified edge-edge barrier of every edge pair of the folded sheet within d
    (crossing and nearly parallel edges, some mollified), each pair's closest points and
    mollifier recomputed at every x: gradient and Hessian remainders of orders 2 and 3 along
    a random direction per pair."""
    from clothfem.contact.self_barrier import EdgePairs, _free_directions
    from clothfem.contact.self_contact import segment_closest

    x0, surf = folded_sheet()
    p = SelfBarrierParameters(distance=D, pressure=500.0)
    c = build_candidates(x0, surf, distance=D, skin=D)
    ep = edge_pairs(x0, x0.copy(), c, distance=D, edge_area=edge_areas(x0, surf))
    cc = cross_derivatives(x0[ep.idx])[0]
    assert len(ep.dist) > 100 and np.sum(cc < ep.eps_x) > 10

    def energy(y, k):
        s, t, dist = segment_closest(*(y[:, j] for j in range(4)))
        coef = np.column_stack([1 - s, s, t - 1, -t])
        free = _free_directions(coef, ((1.0, (0, 1)), (-1.0, (2, 3))))
        one = EdgePairs(np.array([[0, 1, 2, 3]]), coef, free, dist, ep.weight[k : k + 1],
                        ep.eps_x[k : k + 1])  # fmt: skip
        return edge_energy(y[0], one, params=p)

    rng = np.random.default_rng(2)
    for k in range(len(ep.dist)):
        y0 = x0[ep.idx[k]][None]
        e0, g, H, _ = energy(y0, k)
        v = rng.normal(size=12) * 1e-3 * D
        o1, o2 = remainder_orders(
            lambda h, y0=y0, k=k, v=v: energy(y0 + h * v.reshape(1, 4, 3), k)[0],
            e0, g[0] @ v, v @ H[0] @ v, 0.5 ** np.arange(4),
        )  # fmt: skip
        assert np.all(o1 > 1.8), (k, o1)
        assert np.all(o2 > 2.7), (k, o2)


def test_edge_energy_vanishes_for_parallel_edges():
    """Two parallel edges d / 2 apart carry no edge-edge energy or force (the mollifier
    takes it to zero with |e0 x e1|^2; 1e-7 rad apart, finite and 2e-11 of it); crossing at
    30 degrees, the full barrier."""
    p = SelfBarrierParameters(distance=D)

    def pair(angle):
        q = np.array([0.0, 0.0, 0.5 * D])
        r = np.array([np.cos(angle), np.sin(angle), 0.0]) * 0.01
        x = np.array([[-0.01, 0.0, 0.0], [0.01, 0.0, 0.0], q - r, q + r])
        # a candidate list of the one edge pair, built at x (what edge_pairs reads)
        cands = SimpleNamespace(
            ee=np.array([[0, 1]]), ee_nodes=np.array([[0, 1, 2, 3]]), x_build=x,
            ee_dist=np.array([0.5 * D]), min_distance=0.5 * D,
            rows_within=lambda limit, edges: np.array([0]),
        )  # fmt: skip
        ep = edge_pairs(x, x, cands, distance=D, edge_area=np.ones(2))
        assert len(ep.dist) == 1 and ep.dist[0] == pytest.approx(0.5 * D, rel=1e-12)
        return edge_energy(x, ep, params=p)

    e_par, g_par, _, f_par = pair(0.0)
    assert e_par == 0.0 and np.all(g_par == 0.0) and f_par[0] == 0.0
    e_near, g_near, h_near, _ = pair(1e-7)  # closest points at an end: finite, ~0
    m = 2.0 * np.sin(1e-7) ** 2 / 1e-3  # the mollifier, 2 c / eps_x
    assert np.all(np.isfinite(h_near)) and e_near == pytest.approx(m * pair(np.pi / 6)[0], rel=1e-6)
    e30, _, _, f30 = pair(np.pi / 6)
    b = barrier(np.array([0.5 * D]), distance=D)
    w = 0.25 * 2.0  # (A_e0 + A_e1) / 4
    assert e30 == pytest.approx(p.kappa * w * b[0][0], rel=1e-12)
    assert f30[0] == pytest.approx(-p.kappa * w * b[1][0], rel=1e-12)
