"""The fabric-fabric barrier of the implicit path: the barrier function, the distance
derivatives of every closest-feature case, Taylor tests of the energy's gradient and Hessian
on a folded sheet, and the same for the layer friction's dissipation potential (NumPy only:
runs unchanged on every rank)."""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.self_barrier import (
    SelfBarrierParameters,
    barrier,
    barrier_pairs,
    distance_derivatives,
    friction_energy,
    friction_pairs,
    friction_slip,
    friction_work,
    pair_energy,
    vertex_areas,
)
from clothfem.contact.self_contact import build_candidates, fabric_surface, mesh_nodes

D = 1e-3  # activation distance [m]


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
    e1, e2 = [], []
    for h in 1e-3 * 0.5 ** np.arange(4):
        y = y0 + h * v.reshape(1, 4, 3)
        sh = distance_derivatives(y, *coef_at(y))[0][0]
        e1.append(abs(sh - s0[0] - h * g[0] @ v))
        e2.append(abs(sh - s0[0] - h * g[0] @ v - 0.5 * h * h * v @ H[0] @ v))
    o1, o2 = np.log2(np.array(e1[:-1]) / e1[1:]), np.log2(np.array(e2[:-1]) / e2[1:])
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
    e1, e2 = [], []
    for h in 0.5 ** np.arange(1, 6):
        eh = energy(x0 + h * v)[0][0]
        e1.append(abs(eh - e0 - h * np.sum(G * v)))
        e2.append(abs(eh - e0 - h * np.sum(G * v) - 0.5 * h * h * Hv))
    o1, o2 = np.log2(np.array(e1[:-1]) / e1[1:]), np.log2(np.array(e2[:-1]) / e2[1:])
    assert np.all(o1 > 1.8), o1
    assert np.all(o2 > 2.7), o2


def frozen_friction():
    """The folded sheet's barrier pairs frozen for the friction at their positions x0."""
    x0, surf = folded_sheet()
    p = SelfBarrierParameters(distance=D, pressure=500.0, mu=0.3)
    va = vertex_areas(x0, surf)
    c = build_candidates(x0, surf, distance=D, skin=D)
    bp = barrier_pairs(x0, surf, c, distance=D, vertex_area=va)
    return x0, friction_pairs(x0, bp, params=p), p, bp


def test_friction_pairs_frame_and_forces():
    """The frozen tangent bases are orthonormal and normal to each pair's distance vector;
    the frozen normal forces are the barrier's pair forces -dE/ds."""
    x0, fp, p, bp = frozen_friction()
    T = fp.basis
    np.testing.assert_allclose(
        np.einsum("mki,mkj->mij", T, T), np.broadcast_to(np.eye(2), (len(T), 2, 2)), atol=1e-14
    )
    np.testing.assert_allclose(np.einsum("mk,mkl->ml", fp.r0, T), 0.0, atol=1e-15)
    np.testing.assert_allclose(fp.force, pair_energy(x0, bp, params=p)[3], rtol=1e-14)
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
    e1, e2 = [], []
    for h in 0.5 ** np.arange(1, 6):
        eh = friction_energy(x1 + h * v, fp, mu=p.mu, eps=eps)[0]
        e1.append(abs(eh - e0 - h * np.sum(G * v)))
        e2.append(abs(eh - e0 - h * np.sum(G * v) - 0.5 * h * h * Hv))
    o1, o2 = np.log2(np.array(e1[:-1]) / e1[1:]), np.log2(np.array(e2[:-1]) / e2[1:])
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
