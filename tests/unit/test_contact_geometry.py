"""Closest-point projection onto ellipsoids and unions (clothfem.contact.geometry)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from clothfem.contact import (
    candidates,
    closest_point_ellipsoid,
    closest_point_union,
    closest_points,
    gap_lower_bound,
    gradient_projection,
    implicit_value,
    radial_projection,
)

SHAPES = {
    "general": (0.30, 0.20, 0.10),
    "elongated_1to20": (0.20, 0.01, 0.05),
    "needle_1to20": (0.01, 0.20, 0.01),
    "disc_1to20": (0.20, 0.20, 0.01),
    "near_sphere": (0.100, 0.1001, 0.0999),
    "sphere": (0.06, 0.06, 0.06),
    "forearm": (0.20, 0.06, 0.06),
}


def _frame(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(scale=0.5, size=3), Rotation.random(random_state=seed).as_matrix()


def _brute_force_distance(x: np.ndarray, c: np.ndarray, Q: np.ndarray, r: np.ndarray) -> float:
    """Independent reference: dense (theta, phi) sampling, then SLSQP on p with f(p) = 0."""
    y = Q.T @ (x - c)
    th, ph = np.meshgrid(np.linspace(0, np.pi, 181), np.linspace(0, 2 * np.pi, 360))
    s = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    pts = s * r
    p0 = pts[np.argmin(np.sum((pts - y) ** 2, axis=1))]
    res = minimize(
        lambda p: np.sum((p - y) ** 2),
        p0,
        jac=lambda p: 2 * (p - y),
        constraints={
            "type": "eq",
            "fun": lambda p: np.sum((p / r) ** 2) - 1,
            "jac": lambda p: 2 * p / r**2,
        },
        method="SLSQP",
        options={"ftol": 1e-16, "maxiter": 200},
    )
    p = res.x / np.sqrt(np.sum((res.x / r) ** 2))  # back onto the surface
    return float(min(np.linalg.norm(p - y), np.linalg.norm(p0 - y)))


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_projection_matches_brute_force(shape: str) -> None:
    r = np.array(SHAPES[shape])
    c, Q = _frame(sorted(SHAPES).index(shape))
    rng = np.random.default_rng(7)
    # half inside (radial fraction < 1), half outside (up to 3 radii away)
    u = rng.normal(size=(16, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    frac = np.concatenate([rng.uniform(0.05, 0.95, 8), rng.uniform(1.05, 3.0, 8)])
    x = c + (u * r * frac[:, None]) @ Q.T
    pr = closest_point_ellipsoid(x, c, Q, r)
    f_x = implicit_value(x, c, Q, r)
    for i in range(x.shape[0]):
        d_ref = _brute_force_distance(x[i], c, Q, r)
        d = abs(pr.gap[i])
        # ours is never farther than the reference (it is the global minimum) ...
        assert d <= d_ref + 1e-12, (shape, i, d, d_ref)
        # ... and the reference finds the same distance
        assert d == pytest.approx(d_ref, abs=1e-9), (shape, i)
        assert np.sign(pr.gap[i]) == np.sign(f_x[i])


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_projection_point_on_surface_and_normal_collinear(shape: str) -> None:
    r = np.array(SHAPES[shape])
    c, Q = _frame(3)
    rng = np.random.default_rng(11)
    x = c + rng.normal(size=(3000, 3)) * r.max() * rng.uniform(0, 2, (3000, 1))
    pr = closest_point_ellipsoid(x, c, Q, r)
    assert np.all(np.isfinite(pr.point)) and np.all(np.isfinite(pr.gap))
    assert np.max(np.abs(implicit_value(pr.point, c, Q, r))) <= 1e-10
    np.testing.assert_allclose(np.linalg.norm(pr.normal, axis=1), 1.0, atol=1e-14)
    d = x - pr.point
    # x - p parallel to n, gap = (x - p) . n = signed distance
    assert np.max(np.linalg.norm(np.cross(d, pr.normal), axis=1)) <= 1e-12
    np.testing.assert_allclose(np.abs(pr.gap), np.linalg.norm(d, axis=1), atol=1e-13)
    f_x = implicit_value(x, c, Q, r)
    assert np.all(pr.gap[f_x < -1e-12] < 0) and np.all(pr.gap[f_x > 1e-12] > 0)
    # normal is the outward gradient direction of Eq. 26 at p
    grad = ((pr.point - c) @ Q / r**2) @ Q.T
    grad /= np.linalg.norm(grad, axis=1, keepdims=True)
    np.testing.assert_allclose(pr.normal, grad, atol=1e-12)


def test_sphere_closed_form() -> None:
    c, Q = _frame(5)
    R = 0.07
    rng = np.random.default_rng(2)
    x = c + rng.normal(scale=0.1, size=(500, 3))
    pr = closest_point_ellipsoid(x, c, Q, np.full(3, R))
    dist = np.linalg.norm(x - c, axis=1)
    np.testing.assert_allclose(pr.gap, dist - R, atol=1e-15)
    np.testing.assert_allclose(pr.point, c + R * (x - c) / dist[:, None], atol=1e-15)


def test_degenerate_points_centre_axes_and_surface() -> None:
    r = np.array([0.3, 0.2, 0.1])
    c, Q = np.zeros(3), np.eye(3)
    # centre: closest points are the ends of the shortest axis
    pr = closest_point_ellipsoid(np.zeros((1, 3)), c, Q, r)
    assert pr.gap[0] == pytest.approx(-0.1, abs=1e-15)
    assert abs(pr.point[0, 2]) == pytest.approx(0.1, abs=1e-15)
    # on the long axis, inside: Eberly's closed form p1 = r1^2 a / (r1^2 - r3^2)
    a = 0.05
    pr = closest_point_ellipsoid(np.array([[a, 0.0, 0.0]]), c, Q, r)
    p1 = r[0] ** 2 * a / (r[0] ** 2 - r[2] ** 2)
    np.testing.assert_allclose(
        pr.point[0], [p1, 0.0, r[2] * np.sqrt(1 - (p1 / r[0]) ** 2)], atol=1e-15
    )
    assert pr.gap[0] == pytest.approx(-np.hypot(p1 - a, pr.point[0, 2]), abs=1e-15)
    # on the long axis, inside but close to the tip: the tip itself is the closest point
    pr = closest_point_ellipsoid(np.array([[0.29, 0.0, 0.0], [-0.5, 0.0, 0.0]]), c, Q, r)
    np.testing.assert_allclose(pr.point, [[0.3, 0, 0], [-0.3, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(pr.gap, [-0.01, 0.2], atol=1e-15)
    # points on the surface map to themselves with gap 0
    u = np.random.default_rng(0).normal(size=(100, 3))
    s = u / np.linalg.norm(u / r, axis=1, keepdims=True)
    pr = closest_point_ellipsoid(s, c, Q, r)
    np.testing.assert_allclose(pr.point, s, atol=1e-15)
    assert np.max(np.abs(pr.gap)) <= 1e-15
    # prolate / oblate centres and tiny offsets near the degenerate plane: no NaN, continuity
    for rr in ([0.06, 0.06, 0.2], [0.2, 0.2, 0.01], [1.0, 1.0 + 1e-12, 1.0 - 1e-12]):
        rr = np.array(rr)
        xs = np.array([[0, 0, 0], [1e-300, 0, 0], [0, 0, 1e-200], [1e-9, 1e-9, 1e-9]], float)
        pr = closest_point_ellipsoid(xs, c, Q, rr)
        assert np.all(np.isfinite(pr.point))
        np.testing.assert_allclose(pr.gap, -rr.min(), atol=1e-8)


def test_extreme_coordinates_no_nan() -> None:
    r = np.array([0.2, 0.01, 0.05])
    c, Q = _frame(1)
    x = np.array([[1e6, -1e6, 3e5], [1e-12, 0, 0], [0, 0, 0]]) + c
    pr = closest_point_ellipsoid(x, c, Q, r)
    assert np.all(np.isfinite(pr.point)) and np.all(np.isfinite(pr.gap))
    assert pr.gap[0] == pytest.approx(np.linalg.norm(x[0] - c), rel=1e-6)


def test_implicit_value_and_approximations() -> None:
    r = np.array([0.3, 0.2, 0.1])
    c, Q = _frame(4)
    rng = np.random.default_rng(5)
    y = rng.normal(scale=0.3, size=(400, 3))
    x = c + y @ Q.T
    np.testing.assert_allclose(
        implicit_value(x, c, Q, r), np.sum((y / r) ** 2, 1) - 1, rtol=1e-12, atol=1e-12
    )
    exact = closest_point_ellipsoid(x, c, Q, r)
    for approx in (radial_projection(x, c, Q, r), gradient_projection(x, c, Q, r)):
        assert np.max(np.abs(implicit_value(approx.point, c, Q, r))) <= 1e-12
        # the exact closest point is never farther than an approximate surface point
        d_apx = np.linalg.norm(x - approx.point, axis=1)
        assert np.all(np.abs(exact.gap) <= d_apx + 1e-14)
        assert np.all(np.sign(approx.gap) == np.sign(exact.gap))
    # the approximations are exact for a sphere
    s = np.full(3, 0.1)
    ex = closest_point_ellipsoid(x, c, Q, s)
    for approx in (radial_projection(x, c, Q, s), gradient_projection(x, c, Q, s)):
        np.testing.assert_allclose(approx.point, ex.point, atol=1e-14)
        np.testing.assert_allclose(approx.gap, ex.gap, atol=1e-14)


def _arm(angle_deg: float = 57.0):
    """Upper arm along -z from the shoulder, forearm rotated about the elbow J (Sec. 4.1)."""
    J = np.zeros(3)
    up_axis = np.array([0.0, 0.0, 1.0])
    Qu = np.column_stack([up_axis, [1.0, 0, 0], [0, 1.0, 0]])
    upper = (J + 0.15 * up_axis - 0.02 * up_axis, Qu, np.array([0.15, 0.06, 0.06]))
    th = np.radians(angle_deg)
    fa_axis = np.array([np.sin(th), 0.0, -np.cos(th)])
    Qf = np.column_stack([fa_axis, np.cross([0, 1.0, 0], fa_axis), [0, 1.0, 0]])
    fore = (J + 0.20 * fa_axis - 0.02 * fa_axis, Qf, np.array([0.20, 0.06, 0.06]))
    return J, [upper, fore]


def test_union_rule_on_overlapping_arm() -> None:
    J, bodies = _arm()
    rng = np.random.default_rng(3)
    x = J + rng.normal(scale=0.08, size=(3000, 3))
    un = closest_point_union(x, bodies)
    single = [closest_point_ellipsoid(x, *b) for b in bodies]
    gaps = np.stack([s.gap for s in single], axis=1)
    # one rule: smallest signed gap (deepest penetration if inside any, else the closest)
    np.testing.assert_array_equal(un.body, np.argmin(gaps, axis=1))
    # the pruned search (other ellipsoids only where their gap bound does not clear the
    # first one's gap) gives bit for bit the projections on every ellipsoid
    rows = np.arange(len(x))
    np.testing.assert_array_equal(un.gap, gaps.min(axis=1))
    for field in ("point", "normal"):
        every = np.stack([getattr(s, field) for s in single], axis=1)
        np.testing.assert_array_equal(getattr(un, field), every[rows, un.body])
    inside_both = np.all(gaps < 0, axis=1)
    outside_all = np.all(gaps > 0, axis=1)
    assert inside_both.sum() > 20 and outside_all.sum() > 20
    # deepest wins in the overlap
    assert np.all(un.gap[inside_both] <= gaps[inside_both].max(axis=1))
    # flag is exactly "projection lies strictly inside the other ellipsoid"
    for k, b in enumerate(bodies):
        f_other = implicit_value(un.point, *b)
        np.testing.assert_array_equal(
            un.inside_other[un.body != k], (f_other < -1e-10)[un.body != k]
        )
    # the limitation does occur at the elbow, and only for points inside an ellipsoid
    assert un.inside_other[inside_both].any()
    assert not np.any(un.inside_other & (un.gap >= 0))
    # outside all: gap is the distance to the union (never flagged)
    assert not np.any(un.inside_other[outside_all])
    # a hand-placed point in the overlap near the elbow: deeper in the upper arm
    xp = np.array([[0.0, 0.0, 0.03]])
    u1 = closest_point_union(xp, bodies)
    assert u1.body[0] == 0 and u1.gap[0] < 0


def test_candidates_are_conservative() -> None:
    J, bodies = _arm()
    rng = np.random.default_rng(8)
    x = J + rng.normal(scale=0.2, size=(4000, 3))
    margin = 0.01
    cand = candidates(x, bodies, margin)
    assert len(cand) == 2
    for k, b in enumerate(bodies):
        near = np.flatnonzero(closest_point_ellipsoid(x, *b).gap <= margin)
        assert np.all(np.isin(near, cand[k]))
        assert cand[k].size < x.shape[0]  # it does prune
        assert np.all(np.diff(cand[k]) > 0)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros(3), np.eye(3), np.array([0.1, 0.0, 0.1])), "r must be"),
        ((np.zeros(3), np.eye(3), np.array([0.1, -0.2, 0.1])), "r must be"),
        ((np.zeros(3), np.eye(3), np.array([0.1, 0.1])), "r must be"),
        ((np.zeros(3), np.diag([1.0, 1.0, 1.1]), np.ones(3)), "Q must have orthonormal"),
        ((np.zeros(3), np.eye(2), np.ones(3)), "Q must be"),
        ((np.zeros(2), np.eye(3), np.ones(3)), "c must be"),
    ],
)
def test_bad_ellipsoid_raises(args, match) -> None:
    with pytest.raises(ValueError, match=match):
        closest_point_ellipsoid(np.zeros((2, 3)), *args)


def test_bad_points_and_options_raise() -> None:
    e = (np.zeros(3), np.eye(3), np.ones(3))
    with pytest.raises(ValueError, match=r"x must have shape \(N, 3\)"):
        closest_point_ellipsoid(np.zeros((2, 2)), *e)
    with pytest.raises(ValueError, match="x must be finite"):
        closest_point_ellipsoid(np.array([[np.nan, 0, 0]]), *e)
    with pytest.raises(ValueError, match="tol must be"):
        closest_point_ellipsoid(np.zeros((1, 3)), *e, tol=0.0)
    with pytest.raises(ValueError, match="max_iter must be"):
        closest_point_ellipsoid(np.zeros((1, 3)), *e, max_iter=0)
    with pytest.raises(ValueError, match="margin must be"):
        candidates(np.zeros((1, 3)), [e], -1.0)
    with pytest.raises(ValueError, match="bodies must contain"):
        closest_point_union(np.zeros((1, 3)), [])
    with pytest.raises(ValueError, match=r"bodies\[0\] must be a \(c, Q, r\) triple"):
        closest_point_union(np.zeros((1, 3)), [(np.zeros(3), np.eye(3))])


def test_closest_points_batches_bodies_bit_for_bit() -> None:
    """One root solve for several ellipsoids of different shapes (spheres, needles, discs)
    gives each point the bits of a call on its own ellipsoid alone, degenerate points
    (centre, axes, shortest-axis planes) and empty point sets included; the distances agree
    with the brute-force reference."""
    rng = np.random.default_rng(11)
    bodies, xs = [], []
    for seed, r in enumerate(SHAPES.values()):
        c, Q = _frame(seed)
        r = np.asarray(r)
        y = rng.normal(size=(40, 3)) * r * rng.uniform(0.2, 2.0, (40, 1))
        y[0] = 0.0  # centre
        y[1, 1:] = 0.0  # on the first axis
        y[2, np.argmin(r)] = 0.0  # on a shortest-axis plane
        bodies.append((c, Q, r))
        xs.append(c + y @ Q.T)
    xs[2] = np.zeros((0, 3))  # no points on one body
    batched = closest_points(xs, bodies)
    for x, b, pr in zip(xs, bodies, batched, strict=True):
        alone = closest_point_ellipsoid(x, *b)
        for got, want in zip(pr, alone, strict=True):
            np.testing.assert_array_equal(got, want)
    for k in (0, 3, 5):
        for i in (3, 7):
            d_ref = _brute_force_distance(xs[k][i], *bodies[k])
            assert abs(abs(batched[k].gap[i]) - d_ref) <= 1e-9
    with pytest.raises(ValueError, match="one point array per body"):
        closest_points(xs[:2], bodies)


def test_gap_lower_bound_is_a_lower_bound() -> None:
    """Broad phase of the explicit contact: outside the union never above the exact gap,
    negative exactly for the points inside, exact for a sphere."""
    J, bodies = _arm()
    rng = np.random.default_rng(9)
    x = J + rng.normal(scale=0.15, size=(3000, 3))
    lb = gap_lower_bound(x, bodies)
    exact = closest_point_union(x, bodies).gap
    inside = np.any([implicit_value(x, *b) < 0 for b in bodies], axis=0)
    assert inside.any() and not inside.all()
    np.testing.assert_array_equal(lb < 0, inside)
    assert np.all(lb[~inside] <= exact[~inside] + 1e-12)
    assert np.mean(lb > 0.01) > 0.3  # it does clear far points
    sphere = [(np.array([0.1, 0.0, 0.0]), np.eye(3), np.full(3, 0.05))]
    np.testing.assert_allclose(
        gap_lower_bound(x, sphere), closest_point_union(x, sphere).gap, atol=1e-13
    )
