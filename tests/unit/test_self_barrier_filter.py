"""The distance bounds by which the implicit barrier's step filter and pair search skip work
(:class:`clothfem.contact.self_contact.FilterBounds`, the pre-selection of
:func:`clothfem.contact.self_barrier.barrier_pairs`): on a folded sheet moved in many ways,
they decide as the exact tests on every listed pair do, and the pairs they return are the
same bits (NumPy and the compiled loops only: runs unchanged on every rank)."""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.self_barrier import (
    _ee_distance,
    _free_directions,
    _pt_distance,
    barrier_pairs,
    edge_areas,
    edge_pairs,
    near_list,
    near_list_holds,
    vertex_areas,
)
from clothfem.contact.self_contact import (
    FilterBounds,
    build_candidates,
    closest_point_triangle,
    crossing_groups,
    fabric_surface,
    mesh_nodes,
    motion_radius,
)

D = 1e-3  # activation distance [m]
FLOOR, EPS = 0.1, 1e-3 * D  # the filter's defaults (SelfBarrierParameters)


def folded_sheet():
    """A 4 x 2 nine-node sheet whose half x > 0.02 is folded back 0.6 d above the other; the
    folded half's nodes (a mask)."""
    sm = meshes.strip(MPI.COMM_SELF, length=0.04, width=0.02, nx=4, ny=2)
    X, cells = mesh_nodes(sm.mesh)
    x = X.copy()
    far = X[:, 0] > 0.02 + 1e-12
    x[far, 0] = 0.04 - X[far, 0] + 0.0013
    x[far, 2] = 0.6 * D
    x[np.abs(X[:, 0] - 0.02) < 1e-12, 2] = 0.3 * D
    x[far, :2] += np.random.default_rng(1).uniform(-1e-4, 1e-4, size=(far.sum(), 2))
    return x, fabric_surface(cells, n_nodes=len(X)), far


def reference_pairs(x, surface, c, va):
    """barrier_pairs by the closest points of every listed pair."""
    p, a, b, cc = (x[c.pt_nodes[:, k]] for k in range(4))
    q, w = closest_point_triangle(p, a, b, cc)
    dist = np.linalg.norm(p - q, axis=1)
    near = dist < D
    coef = np.column_stack([np.ones(int(near.sum())), -w[near]])
    free = _free_directions(coef, ((1.0, (0,)), (-1.0, (1, 2, 3))))
    return c.pt_nodes[near], coef, free, dist[near], 0.5 * va[c.pt_node[near]]


def reference_ok(c, surface, x0, x1):
    """The step filter's test by the exact checks of every listed pair."""
    if any(len(g) for g in crossing_groups(c, surface, x0, x1, EPS)):
        return False
    return all(
        bool(np.all(f(x1, c) >= FLOOR * np.minimum(f(x0, c), D)))
        for f in (_pt_distance, _ee_distance)
    )


def bounded_ok(bounds, c, surface, x0, x1, alpha):
    """The same test as SelfBarrier.max_step runs it: the exact checks on the pairs the
    bounds leave."""
    if bounds.all_clear(alpha):
        return True
    (c_pt, c_ee), (f_pt, f_ee) = bounds.rows(alpha)
    if any(len(g) for g in crossing_groups(c.subset(c_pt, c_ee), surface, x0, x1, EPS)):
        return False
    return all(
        bool(np.all(f(x1, c, r) >= FLOOR * np.minimum(f(x0, c, r), D)))
        for f, r in ((_pt_distance, f_pt), (_ee_distance, f_ee))
    )


def steps(x, far):
    """Newton-like steps from ``x``: random, pressing the folded half down (some through the
    other layer), lifting it, and rigid translations on top."""
    rng = np.random.default_rng(5)
    down = np.zeros_like(x)
    down[far, 2] = -0.6 * D
    out = []
    for scale in (1e-3, 0.1, 0.5, 2.0):
        out.append(scale * D * rng.normal(size=x.shape))
    for k in (0.3, 0.8, 0.95, 1.0, 1.5, 3.0):
        out.append(k * down + 0.01 * D * rng.normal(size=x.shape))
    out.append(-down)
    out += [s + rng.normal(size=3) * D for s in out[:3] + out[5:7]]
    return out


@pytest.mark.parametrize("built_away", [False, True])
def test_filter_bounds_decide_as_the_exact_checks(built_away):
    """For every step and alpha = 1 ... 1/64 with the list valid: the filter's decision
    with the bounds equals the exact checks on every listed pair; pairs the bounds clear
    neither cross nor end below their floor; both decisions and both levels occur."""
    x, surf, far = folded_sheet()
    rng = np.random.default_rng(2)
    xb = x + (0.02 * D * rng.normal(size=x.shape) if built_away else 0.0)
    c = build_candidates(xb, surf, distance=D, skin=4 * D)
    seen = set()
    for dx in steps(x, far):
        bounds = FilterBounds(c, x, dx, distance=D, floor=FLOOR, eps=EPS)
        for alpha in 0.5 ** np.arange(7):
            x1 = x + alpha * dx
            if not c.valid(x, x1):
                continue
            ok = reference_ok(c, surf, x, x1)
            assert bounded_ok(bounds, c, surf, x, x1, alpha) == ok
            clear = bounds.all_clear(alpha)
            seen |= {("ok", ok), ("all clear", clear)}
            (c_pt, c_ee), (f_pt, f_ee) = bounds.rows(alpha)
            rest_pt = np.setdiff1d(np.arange(len(c.pt_dist)), c_pt)
            rest_ee = np.setdiff1d(np.arange(len(c.ee_dist)), c_ee)
            assert not any(
                len(g) for g in crossing_groups(c.subset(rest_pt, rest_ee), surf, x, x1, EPS)
            )
            for f, rows in ((_pt_distance, f_pt), (_ee_distance, f_ee)):
                rest = np.setdiff1d(np.arange(len(f(x, c))), rows)
                assert np.all(f(x1, c, rest) >= FLOOR * np.minimum(f(x, c, rest), D))
            if clear:
                assert not any(len(r) for r in (c_pt, c_ee, f_pt, f_ee))
    assert seen == {("ok", True), ("ok", False), ("all clear", True), ("all clear", False)}


def test_barrier_pairs_are_the_reference_bits():
    """barrier_pairs with its pre-selection returns the arrays of the closest points of
    every listed pair, bit for bit, at positions moved since the list's build (pairs near,
    none near, some leaving)."""
    x, surf, far = folded_sheet()
    va = vertex_areas(x, surf)
    c = build_candidates(x, surf, distance=D, skin=4 * D)
    counts = set()
    for dx in steps(x, far):
        for alpha in (1.0, 0.25):
            y = x + alpha * dx
            if not c.valid(y):
                continue
            got = barrier_pairs(y, surf, c, distance=D, vertex_area=va)
            ref = reference_pairs(y, surf, c, va)
            for a, b in zip(got, ref, strict=True):
                assert a.dtype == b.dtype and a.shape == b.shape
                assert np.array_equal(a, b)
            counts.add(min(len(got.dist), 1))
    far_away = x.copy()
    far_away[far, 2] += 3 * D  # the layers 3.6 d apart: cleared by the build distances
    got = barrier_pairs(far_away, surf, c, distance=D, vertex_area=va)
    assert len(got.dist) == 0 and got.idx.shape == (0, 4) and got.free.shape == (0, 4, 2)
    assert counts == {0, 1}


def test_near_list_gives_the_full_lists_pairs():
    """Along paths of small steps from the folded sheet (the folded half pressed down,
    lifted, moved at random), the pairs within d found in the near list (kept while
    near_list_holds, built again from the full list otherwise) are the full list's, node-
    triangle and edge-edge, bit for bit; the near list is kept and rebuilt on the way and
    holds fewer pairs than the full list; positions with and without pairs within d occur;
    rows_within selects at least the rows within its limit."""
    x, surf, far = folded_sheet()
    va, ea = vertex_areas(x, surf), edge_areas(x, surf)
    c = build_candidates(x, surf, distance=D, skin=6 * D)
    for edges, dist in ((False, c.pt_dist), (True, c.ee_dist)):
        for limit in (0.0, 0.5 * D, 2 * D, 1.0):
            rows = c.rows_within(limit, edges=edges)
            assert np.all(np.diff(rows) > 0) and set(np.flatnonzero(dist <= limit)) <= set(rows)
    rng = np.random.default_rng(7)
    kept = rebuilt = 0
    found = set()  # whether pairs within d were found, per position
    for dx in steps(x, far)[4:]:
        near, y = near_list(c, x, distance=D), x.copy()
        for _ in range(12):
            y = y + dx / 12 + 0.02 * D * rng.normal(size=x.shape)
            if not c.valid(y):
                break
            if near_list_holds(near, y, distance=D):
                kept += 1
            else:
                near, rebuilt = near_list(c, y, distance=D), rebuilt + 1
            assert len(near.pt_dist) + len(near.ee_dist) < len(c.pt_dist) + len(c.ee_dist)
            for got, ref in (
                (barrier_pairs(y, surf, near, distance=D, vertex_area=va),
                 barrier_pairs(y, surf, c, distance=D, vertex_area=va)),
                (edge_pairs(y, x, near, distance=D, edge_area=ea),
                 edge_pairs(y, x, c, distance=D, edge_area=ea)),
            ):  # fmt: skip
                for a, b in zip(got, ref, strict=True):
                    assert a.shape == b.shape and np.array_equal(a, b)
                found.add(len(ref.dist) > 0)
    assert kept > 0 and rebuilt > 0 and found == {True, False}


def test_motion_radius_bounds_the_relative_motion():
    """Any two displacements differ by at most twice the motion radius; a rigid
    translation adds nothing."""
    rng = np.random.default_rng(4)
    Dm = rng.normal(size=(50, 3))
    r = motion_radius(Dm)
    diff = np.linalg.norm(Dm[:, None] - Dm[None], axis=2)
    assert diff.max() <= 2 * r * (1 + 1e-12)
    assert motion_radius(Dm + [3.0, -1.0, 2.0]) == pytest.approx(r, rel=1e-12)
    assert motion_radius(np.zeros((0, 3))) == 0.0
