"""Forward-increment Lagrange multiplier step (Eqs. 22-25) on point masses."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfem.contact import (
    body_point_velocity,
    closest_point_ellipsoid,
    closest_point_union,
    diagnostics,
    film_step,
)

G = np.array([0.0, 0.0, -9.81])


@pytest.fixture(params=["compiled", "numpy"])
def film(request):
    """film_step with each implementation: every physical check below holds for both."""
    return functools.partial(film_step, kernel=request.param)


def test_falling_masses_never_end_inside_moving_rotating_ellipsoid(film) -> None:
    """Point masses dropped onto an ellipsoid that rises and spins: after every step each node
    is on or outside the surface, and every multiplier is >= 0."""
    r = np.array([0.20, 0.06, 0.10])
    Q0 = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
    c0 = np.zeros(3)
    v_c = np.array([0.05, 0.0, 0.4])
    omega = np.array([0.0, 1.5, 0.8])
    rng = np.random.default_rng(0)
    n = 40
    x = np.column_stack([rng.uniform(-0.15, 0.15, n), rng.uniform(-0.05, 0.05, n), np.full(n, 0.2)])
    v = np.zeros((n, 3))
    m = rng.uniform(1e-4, 1e-3, n)
    dt = 2e-3
    n_contacts = 0
    for step in range(1, 151):
        t = step * dt
        Q = Rotation.from_rotvec(omega * t).as_matrix() @ Q0
        c = c0 + v_c * t
        v_star = v + dt * G
        x_star = x + dt * v_star
        for mu in (None,) if step % 2 else (0.4,):
            res = film(x_star, v_star, m, dt, [(c, Q, r)], body_velocities=[(v_c, omega)], mu=mu)
        x, v = res.x, res.v
        gap = closest_point_ellipsoid(x, c, Q, r).gap
        assert gap.min() >= -1e-12, (step, gap.min())
        assert np.all(res.lam_n >= 0.0)
        assert np.all(res.lam_n[~res.active] == 0.0)
        assert not res.unresolved.any()
        d = diagnostics(res.gap, res.lam_n)
        assert d.max_penetration <= 1e-12 and d.min_multiplier >= 0.0
        assert d.complementarity <= 1e-12 * max(1.0, res.lam_n.max())
        n_contacts += int(res.active.sum())
    assert n_contacts > 100  # contact did happen


def test_multipliers_equal_global_eq25_solve(film) -> None:
    """Lumped M and one constraint per node against a rigid body: the global solve of Eq. 25
    with G of Eq. 21 (slave block -I, master known) equals the per-node formula."""
    c, Q, r = np.zeros(3), np.eye(3), np.array([0.2, 0.06, 0.1])
    rng = np.random.default_rng(1)
    x_star = rng.normal(scale=0.08, size=(12, 3))
    m = rng.uniform(0.5, 2.0, 12)
    dt = 1e-3
    res = film(x_star, np.zeros((12, 3)), m, dt, [(c, Q, r)], mu=0.0)
    act = np.flatnonzero(res.active)
    assert act.size >= 3
    p = closest_point_ellipsoid(x_star[act], c, Q, r).point
    N = x_star.shape[0]
    Gm = np.zeros((3 * act.size, 3 * N))
    for row, i in enumerate(act):
        Gm[3 * row : 3 * row + 3, 3 * i : 3 * i + 3] = -np.eye(3)
    Minv = np.diag(np.repeat(1.0 / m, 3))
    # Eq. 22b: G (d + X) + x_m = -(x_s - x_m) = 0 with the rigid master point x_m = p known
    rhs = Gm @ x_star.ravel() + p.ravel()
    lam = np.linalg.solve(dt**2 * Gm @ Minv @ Gm.T, rhs)  # Eq. 25
    d_c = -(dt**2) * Minv @ Gm.T @ lam  # Eq. 24
    np.testing.assert_allclose((x_star.ravel() + d_c).reshape(-1, 3), res.x, atol=1e-15)
    np.testing.assert_allclose(lam.reshape(-1, 3), res.force[act], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(res.lam_n[act], np.linalg.norm(res.force[act], axis=1), rtol=1e-12)
    assert np.all(res.lam_n[act] > 0)


def _incline(film, mu: float | None, alpha: float, T: float = 0.2, dt: float = 1e-3):
    """Point mass released at rest on a huge sphere whose tangent plane at the start is inclined
    by alpha: locally a block on an incline."""
    R = 1.0e3
    nrm = np.array([np.sin(alpha), 0.0, np.cos(alpha)])
    body = [(-R * nrm, np.eye(3), np.full(3, R))]
    x = np.zeros((1, 3))
    v = np.zeros((1, 3))
    for _ in range(round(T / dt)):
        v_star = v + dt * G
        res = film(x + dt * v_star, v_star, 1.0, dt, body, mu=mu)
        x, v = res.x, res.v
        assert res.active[0] and res.lam_n[0] > 0
    downslope = np.array([np.cos(alpha), 0.0, -np.sin(alpha)])
    return float(x[0] @ downslope), res


@pytest.mark.parametrize("mu", [0.0, 0.2, 0.45])
def test_block_on_incline_slides_with_closed_form_acceleration(film, mu: float) -> None:
    """Block on an incline with Coulomb friction (e.g. Meriam & Kraige, Engineering Mechanics:
    Dynamics, Sec. 3/4): for mu < tan(alpha) it slides with a = g (sin(alpha) - mu cos(alpha)),
    so s(T) = a T^2 / 2; normal force m g cos(alpha)."""
    alpha, T, dt = np.radians(30.0), 0.2, 1e-3
    s, res = _incline(film, mu, alpha, T, dt)
    a = 9.81 * (np.sin(alpha) - mu * np.cos(alpha))
    # symplectic Euler: s_n = a dt^2 n (n + 1) / 2
    n = round(T / dt)
    assert s == pytest.approx(a * dt**2 * n * (n + 1) / 2, rel=2e-3)
    assert s == pytest.approx(0.5 * a * T**2, rel=1e-2)
    assert res.lam_n[0] == pytest.approx(9.81 * np.cos(alpha), rel=1e-3)
    if mu > 0:
        assert not res.stick[0]
        assert np.linalg.norm(res.friction[0]) == pytest.approx(mu * 9.81 * np.cos(alpha), 1e-3)
        assert res.dissipation[0] > 0
    else:
        assert np.all(res.friction == 0.0) and res.dissipation[0] == 0.0


@pytest.mark.parametrize("mu", [0.6, None])
def test_block_on_incline_sticks_when_mu_exceeds_tan_alpha(film, mu: float | None) -> None:
    s, res = _incline(film, mu, np.radians(30.0))
    assert abs(s) <= 1e-9
    assert res.stick[0]
    # friction balances the downslope weight component m g sin(alpha)
    assert np.linalg.norm(res.friction[0]) == pytest.approx(9.81 * 0.5, rel=1e-3)


def test_non_resilient_velocity_is_body_point_velocity(film) -> None:
    c, Q, r = np.array([0.0, 0.0, 0.1]), np.eye(3), np.array([0.2, 0.06, 0.06])
    v_c, omega = np.array([0.3, -0.1, 0.2]), np.array([1.0, 2.0, -0.5])
    x_star = np.array([[0.05, 0.0, 0.15], [0.0, 0.0, 0.5]])
    v_star = np.array([[1.0, 2.0, -3.0], [0.0, 0.0, -1.0]])
    res = film(x_star, v_star, 1e-3, 1e-3, [(c, Q, r)], body_velocities=[(v_c, omega)])
    assert res.active.tolist() == [True, False]
    p = closest_point_ellipsoid(x_star[:1], c, Q, r).point
    np.testing.assert_allclose(res.v[0], body_point_velocity(p, c, v_c, omega)[0], atol=1e-14)
    np.testing.assert_array_equal(res.v[1], v_star[1])
    np.testing.assert_array_equal(res.x[1], x_star[1])
    assert res.body.tolist() == [0, -1]


def test_union_overlap_reprojection_and_offset(film) -> None:
    """Nodes deep in the elbow overlap: with re-projection passes they end outside the union or
    are reported as unresolved; the offset keeps nodes at gap >= h."""
    J = np.zeros(3)
    th = np.radians(57.0)
    upper = (
        np.array([0, 0, 0.13]),
        np.column_stack([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]]),
        np.array([0.15, 0.06, 0.06]),
    )
    fa = np.array([np.sin(th), 0.0, -np.cos(th)])
    fore = (
        0.18 * fa,
        np.column_stack([fa, np.cross([0, 1.0, 0], fa), [0, 1.0, 0]]),
        np.array([0.20, 0.06, 0.06]),
    )
    bodies = [upper, fore]
    rng = np.random.default_rng(2)
    x_star = J + rng.normal(scale=0.05, size=(400, 3))
    z = np.zeros_like(x_star)
    one = film(x_star, z, 1e-3, 1e-3, bodies, max_passes=1)
    more = film(x_star, z, 1e-3, 1e-3, bodies, max_passes=4)
    assert one.unresolved.sum() > 0
    assert more.unresolved.sum() < one.unresolved.sum()
    ok = ~more.unresolved
    assert more.gap[ok].min() >= -1e-12
    np.testing.assert_array_equal(more.unresolved, more.active & (more.gap < -1e-12))
    u = closest_point_union(more.x, bodies)
    on = more.active
    np.testing.assert_allclose(u.gap[on], more.gap[on], atol=1e-15)
    # the others: the exact gap where projected, else the broad phase's lower bound
    assert np.all((more.gap[~on] >= 0.0) & (more.gap[~on] <= u.gap[~on] + 1e-15))
    h = 5e-4
    off = film(x_star, z, 1e-3, 1e-3, bodies, offset=h, max_passes=4)
    assert off.gap[off.active & ~off.unresolved].min() >= h - 1e-12
    assert off.unresolved.sum() < 0.1 * off.active.sum()


def test_bad_input_raises() -> None:
    b = [(np.zeros(3), np.eye(3), np.ones(3))]
    x = np.zeros((2, 3))
    with pytest.raises(ValueError, match="mu must be None"):
        film_step(x, x, 1.0, 1e-3, b, mu=-0.5)
    with pytest.raises(ValueError, match="dt must be a finite time step > 0"):
        film_step(x, x, 1.0, 0.0, b)
    with pytest.raises(ValueError, match="m must be finite lumped masses > 0"):
        film_step(x, x, np.array([1.0, 0.0]), 1e-3, b)
    with pytest.raises(ValueError, match=r"v_star must have shape \(2, 3\)"):
        film_step(x, np.zeros((3, 3)), 1.0, 1e-3, b)
    with pytest.raises(ValueError, match="body_velocities must have one"):
        film_step(x, x, 1.0, 1e-3, b, body_velocities=[])
    with pytest.raises(ValueError, match="offset must be"):
        film_step(x, x, 1.0, 1e-3, b, offset=-1.0)
    with pytest.raises(ValueError, match=r"bodies\[0\]: r must be"):
        film_step(x, x, 1.0, 1e-3, [(np.zeros(3), np.eye(3), np.array([1.0, 1.0, 0.0]))])


def _sleeve_like_cloud(n: int, seed: int):
    """Points around a bent two-ellipsoid arm (the elbow overlap included), with velocities
    and masses, and the moving bodies."""
    rng = np.random.default_rng(seed)
    th = np.radians(40.0)
    Q1 = Rotation.from_rotvec([0.0, -th, 0.0]).as_matrix()
    J = np.array([0.30, 0.0, 0.0])
    bodies = [
        (np.array([0.22, 0.0, 0.0]), np.eye(3), np.array([0.15, 0.06, 0.06])),
        (J + Q1 @ np.array([0.12, 0.0, 0.0]), Q1, np.array([0.20, 0.06, 0.06])),
    ]
    w = np.array([0.0, -1.0, 0.0])
    vel = [(np.zeros(3), np.zeros(3)), (np.cross(w, bodies[1][0] - J), w)]
    a = rng.uniform(0.0, 2.0 * np.pi, n)
    s = rng.uniform(0.0, 0.55, n)
    rad = rng.uniform(0.045, 0.07, n)
    x = np.column_stack([s, rad * np.cos(a), rad * np.sin(a)])
    far = s > 0.3  # the forearm half follows the forearm
    x[far] = J + (x[far] - J) @ Q1.T
    return x, rng.normal(scale=0.2, size=(n, 3)), rng.uniform(1e-4, 1e-3, n), bodies, vel


@pytest.mark.parametrize("mu", [None, 0.0, 0.1, 0.5])
@pytest.mark.parametrize("offset", [0.0, 5e-4])
@pytest.mark.parametrize("max_passes", [1, 3])
def test_compiled_kernel_equals_numpy_reference(mu, offset, max_passes) -> None:
    """The C loop and the vectorised NumPy step run one algorithm: on a sleeve-like cloud
    around overlapping, moving ellipsoids (hundreds of active, sliding, sticking and
    re-projected nodes) every flag and index is equal and every number agrees to round-off."""
    x, v, m, bodies, vel = _sleeve_like_cloud(1500, seed=3)
    kw = dict(body_velocities=vel, mu=mu, offset=offset, max_passes=max_passes)
    a = film_step(x, v, m, 3e-4, bodies, kernel="numpy", **kw)
    b = film_step(x, v, m, 3e-4, bodies, kernel="compiled", **kw)
    assert a.active.sum() > 200
    if mu is not None and mu > 0:
        assert 0 < a.stick.sum() < a.active.sum()  # both stick and slip occur
    for name in a._fields:
        fa, fb = getattr(a, name), getattr(b, name)
        assert fa.shape == fb.shape and fa.dtype == fb.dtype, name
        if fa.dtype == bool or fa.dtype.kind == "i":
            np.testing.assert_array_equal(fa, fb, err_msg=name)
        else:
            scale = max(float(np.max(np.abs(fa), initial=0.0)), 1e-300)
            np.testing.assert_allclose(fb, fa, rtol=0, atol=1e-14 * scale, err_msg=name)


def test_fixed_nodes_are_left_as_they_came(film) -> None:
    """Prescribed nodes (``fixed``) are not corrected, and the other nodes get exactly the
    answer of a step without the fixed ones."""
    x, v, m, bodies, vel = _sleeve_like_cloud(600, seed=5)
    fixed = np.zeros(600, dtype=bool)
    fixed[::7] = True
    kw = dict(body_velocities=vel, mu=0.3, offset=2e-4)
    res = film(x, v, m, 3e-4, bodies, fixed=fixed, **kw)
    alone = film(x[~fixed], v[~fixed], m[~fixed], 3e-4, bodies, **kw)
    assert alone.active.sum() > 50 and (closest_point_union(x[fixed], bodies).gap < 0).any()
    for name in res._fields:
        np.testing.assert_array_equal(getattr(res, name)[~fixed], getattr(alone, name), name)
    np.testing.assert_array_equal(res.x[fixed], x[fixed])
    np.testing.assert_array_equal(res.v[fixed], v[fixed])
    assert not res.active[fixed].any() and np.all(res.force[fixed] == 0.0)
    assert np.all(res.gap[fixed] == np.inf) and np.all(res.body[fixed] == -1)
    with pytest.raises(ValueError, match=r"fixed must be a bool array of shape \(600,\)"):
        film(x, v, m, 3e-4, bodies, fixed=np.zeros(600))


def test_unknown_kernel_and_compiler_failure_raise(tmp_path, monkeypatch) -> None:
    from clothfem.contact.compiled import KernelBuildError, _build

    b = [(np.zeros(3), np.eye(3), np.ones(3))]
    x = np.zeros((2, 3))
    with pytest.raises(ValueError, match="kernel must be 'compiled' or 'numpy', got 'fortran'"):
        film_step(x, x, 1.0, 1e-3, b, kernel="fortran")
    monkeypatch.setenv("CLOTHFEM_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    with pytest.raises(KernelBuildError, match="cannot run the C compiler 'no-such-compiler-xyz'"):
        _build(Path(__file__))
    src = tmp_path / "broken.c"
    src.write_text("this is not C\n")
    monkeypatch.setenv("CC", "cc")
    with pytest.raises(KernelBuildError, match="building broken.c failed"):
        _build(src)
    assert not list(tmp_path.glob("*.so"))  # nothing half-built is left in the cache
