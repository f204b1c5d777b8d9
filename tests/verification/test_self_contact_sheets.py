"""Fabric self-contact on point masses: pressed sheets, Coulomb sliding, a tunnelling node and
a fold closing past parallel, each checked by the independent intersection checker.

The meshes are built on ``MPI.COMM_SELF`` and every rank runs the same point-mass steps, so
the file runs unchanged under ``mpirun -n 2``.
"""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.intersections import check_surface
from clothfem.contact.self_contact import (
    SelfContactParameters,
    fabric_surface,
    mesh_nodes,
    self_contact_step,
)

D = 1e-3  # contact distance = fabric thickness [m]
MASS = 2e-5  # nodal mass [kg]


def sheets(*, nx=6, size=0.06, gap=3e-3, shift=(0.0, 0.0)):
    """Two copies of a square strip mesh, the second ``gap`` [m] above and shifted in plane."""
    sm = meshes.strip(MPI.COMM_SELF, length=size, width=size, nx=nx, ny=nx)
    X, cells = mesh_nodes(sm.mesh)
    n = len(X)
    top = X + [shift[0], shift[1], gap]
    surf = fabric_surface(np.vstack([cells, cells + n]), n_nodes=2 * n)
    return np.vstack([X, top]), surf, n


def momentum(m, a):
    return (m[:, None] * a).sum(axis=0)


def test_pressed_sheets_stay_apart_and_conserve_momentum():
    """Two sheets driven together at 0.5 m/s each (point masses, no elasticity) for 30 steps:
    every frame intersection-free with the layers >= 0.95 d apart (independent checker); the
    corrections are internal impulses (momentum of positions and velocities conserved to
    round-off); no pair in contact still approaches faster than 2 % of the initial speed
    (the nodes past the other sheet's edge fly on: point masses)."""
    x, surf, n = sheets(shift=(0.003, 0.002))
    m = np.full(2 * n, MASS)
    v = np.zeros_like(x)
    v[:n, 2], v[n:, 2] = 0.5, -0.5
    dt, p = 2e-4, SelfContactParameters(distance=D)
    cands, touched = None, 0
    for _ in range(30):
        xs = x + dt * v
        r = self_contact_step(x, xs, v, m, dt, surf, params=p, candidates=cands)
        cands = r.candidates
        scale = np.abs(momentum(m, xs)).max() + 1e-30
        assert np.abs(momentum(m, r.x - xs)).max() <= 1e-12 * max(scale, MASS * 2 * n * 0.1)
        assert np.abs(momentum(m, r.v - v)).max() <= 1e-12 * MASS * 2 * n * 0.5
        chk = check_surface(r.x, surf.triangles, radius=4 * D)
        assert chk.intersections == 0
        assert chk.min_distance >= 0.95 * D
        assert r.crossings_left == 0 and r.covered
        touched += len(r.jn) > 0
        x, v = r.x, r.v
    assert touched > 10
    # no pair in contact still approaches (relative speed 1 m/s before contact)
    c = r.contacts
    vn = np.einsum("ij,ij->i", np.einsum("ij,ijk->ik", c.coef, v[c.idx]), c.normal)
    assert vn.min() >= -0.02


def sliding_step(vt, vn, mu):
    """The top sheet touching the (prescribed) bottom one, moving at (vt, 0, -vn)."""
    x, surf, n = sheets(nx=4, gap=D)
    m = np.full(2 * n, MASS)
    fixed = np.r_[np.ones(n, bool), np.zeros(n, bool)]
    v = np.zeros_like(x)
    v[n:] = [vt, 0.0, -vn]
    dt = 1e-4
    p = SelfContactParameters(distance=D, mu=mu)
    r = self_contact_step(x, x + dt * v, v, m, dt, surf, params=p, fixed=fixed)
    return r, m[n:], v[n:], n


def test_sliding_sheet_coulomb_impulse():
    """Sliding (vt >> mu vn): every pair's tangential impulse is mu x its normal impulse, so
    the top sheet's tangential momentum change is -mu x its normal momentum change (closed
    form Coulomb), its normal approach is stopped, and the kinetic energy the friction takes
    out is the Coulomb force's work |dPt| vt (frictionless: none)."""
    mu = 0.3
    r, m, v, n = sliding_step(1.0, 0.01, mu)
    assert len(r.jn) > n  # node-triangle and edge pairs
    assert not r.stick.any()
    jt = np.linalg.norm(r.jt, axis=1)
    np.testing.assert_allclose(jt, mu * r.jn, rtol=1e-12, atol=1e-18)
    dP = momentum(m, r.v[n:] - v)
    np.testing.assert_allclose(dP[2], m.sum() * 0.01, rtol=1e-3)  # approach stopped
    np.testing.assert_allclose(-dP[0], mu * dP[2], rtol=1e-12)  # Coulomb: |dPt| = mu dPn
    assert abs(dP[1]) <= 1e-12 * abs(dP[0])
    # dissipated: Coulomb's force x slip, |dPt| vt, to O(mu vn / vt) = 0.3 %
    assert r.friction_loss == pytest.approx(mu * dP[2] * 1.0, rel=5e-3)
    assert sliding_step(1.0, 0.01, 0.0)[0].friction_loss == 0.0


def test_sticking_sheet_below_the_limit():
    """Sticking (vt < mu vn): the tangential relative velocity is removed; no pair's
    tangential impulse exceeds mu x its normal impulse and the total stays below the sheet's
    limit (pairs with a small share of the normal impulse may slide)."""
    mu = 0.5
    r, m, v, n = sliding_step(1e-3, 0.01, mu)
    jt = np.linalg.norm(r.jt, axis=1)
    assert np.all(jt <= mu * r.jn * (1 + 1e-12))
    assert jt.sum() < 0.5 * mu * r.jn.sum()
    np.testing.assert_allclose(r.v[n:, 0], 0.0, atol=2e-3 * 1e-3)
    dP = momentum(m, r.v[n:] - v)
    assert abs(dP[0] + m.sum() * 1e-3) <= 2e-3 * m.sum() * 1e-3


def test_tunnelling_node_is_caught_by_the_failsafe():
    """A node driven 10 mm straight through the sheet 5 mm below in one step: the predictor
    intersects, the continuous check finds the crossings, the impact zones remove them, and
    momentum is conserved."""
    x, surf, n = sheets(nx=4, gap=5e-3)
    m = np.full(2 * n, MASS)
    k = n + int(np.argmin(np.linalg.norm(x[n:] - [0.03, 0.0, 5e-3], axis=1)))
    v = np.zeros_like(x)
    v[k, 2] = -10.0
    dt = 1e-3
    xs = x + dt * v
    assert check_surface(xs, surf.triangles, radius=4 * D).intersections > 0
    r = self_contact_step(x, xs, v, m, dt, surf, params=SelfContactParameters(distance=D))
    assert r.crossings > 0 and r.crossings_left == 0 and r.zone_nodes >= 4
    assert check_surface(r.x, surf.triangles, radius=4 * D).intersections == 0
    assert r.x[k, 2] > 0.0  # still above the lower sheet
    np.testing.assert_allclose(momentum(m, r.v), momentum(m, v), atol=1e-15)


def fold(X, alpha, *, a, s_c):
    """The strip bent at s_c: an arc of length 2a turned through alpha [rad], legs straight."""
    s, y = X[:, 0] - s_c, X[:, 1]
    rho = 2 * a / alpha
    psi = np.clip(s, -a, a) / rho
    rest = s - np.clip(s, -a, a)
    return np.column_stack(
        [
            s_c + rho * np.sin(psi) + rest * np.cos(psi),
            y,
            rho * (1 - np.cos(psi)) + rest * np.sin(psi),
        ]
    )


@pytest.mark.parametrize("mu", [0.0, 0.4])
def test_fold_closing_past_parallel_stays_apart(mu):
    """A strip folded by prescribed motion until its legs would cross (the fold closes from
    0.8 pi to pi + 0.5 rad): every corrected frame is intersection-free with the legs at
    least 0.9 d apart, while the prescribed-only configuration crosses itself."""
    a, leg = 0.01, 0.04
    sm = meshes.strip(MPI.COMM_SELF, length=2 * (a + leg), width=0.02, nx=20, ny=4)
    X, cells = mesh_nodes(sm.mesh)
    surf = fabric_surface(cells, n_nodes=len(X))
    m = np.full(len(X), MASS)
    s_c, dt = a + leg, 1e-3
    alphas = np.linspace(0.8 * np.pi, np.pi + 0.5, 61)
    assert check_surface(fold(X, alphas[-1], a=a, s_c=s_c), surf.triangles, radius=4 * D)[0] > 0
    x = fold(X, alphas[0], a=a, s_c=s_c)
    p = SelfContactParameters(distance=D, mu=mu)
    cands, worst, touched = None, np.inf, 0
    for a0, a1 in zip(alphas[:-1], alphas[1:], strict=True):
        v = (fold(X, a1, a=a, s_c=s_c) - fold(X, a0, a=a, s_c=s_c)) / dt
        r = self_contact_step(x, x + dt * v, v, m, dt, surf, params=p, candidates=cands)
        cands, x = r.candidates, r.x
        chk = check_surface(x, surf.triangles, radius=4 * D)
        assert chk.intersections == 0
        worst = min(worst, chk.min_distance)
        touched += len(r.jn) > 0
    assert touched > 5
    assert worst >= 0.9 * D


def test_shell_strip_closing_like_a_book():
    """End to end: a free shell strip (clothfem.shell.ShellModel, explicit central
    difference) whose halves start turning up about the middle at 60 rad/s closes like a
    book; with SelfContact every step ends intersection-free (independent checker on the
    gathered positions) with the layers >= 0.5 d apart, and the halves did meet. Without
    self-contact the same run passes through itself."""
    from clothfem import dynamics as dy
    from clothfem.contact.intersections import intersecting_pairs
    from clothfem.contact.self_contact import SelfContact
    from clothfem.shell import FabricMaterial, ShellModel

    def run(with_contact: bool):
        sm = meshes.strip(MPI.COMM_WORLD, length=0.1, width=0.02, nx=10, ny=2)
        mat = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)
        model = ShellModel(sm, material=mat, thickness=1e-3)
        system = dy.ShellSystem(model, rotary_scale=100.0)
        contact = SelfContact(system, params=SelfContactParameters(distance=D, mu=0.3))
        n = model.n_owned
        v0 = system.create_vector()
        s = model.x_nodes[:n, 0] - 0.05
        v0.getArray()[: 3 * n].reshape(n, 3)[:, 2] = 60.0 * np.abs(s)
        frames = []

        def on_step(r):
            frames.append(contact.positions())

        dy.integrate_explicit(
            system, t_end=0.045, velocity=v0, on_step=on_step,
            contact=contact if with_contact else None,
        )  # fmt: skip
        return contact, frames

    contact, frames = run(True)
    tri = contact.surface.triangles
    for x in frames[::5] + frames[-3:]:
        chk = check_surface(x, tri, radius=4 * D)
        assert chk.intersections == 0
        assert chk.min_distance >= 0.5 * D
    rec = contact.collect()
    assert rec.steps == len(frames) and rec.crossings_left == 0
    assert max(len(contact.last.jn), 1) > 1  # the halves are in contact at the end
    _, free = run(False)
    assert len(intersecting_pairs(free[-1], tri)) > 0


def test_film_then_self_contact_in_one_step():
    """The runner's chain: a sphere rises into a free patch (FILM) with
    SelfContact wrapping the FilmContact; FILM still keeps every node out of the body (gap
    >= -1e-12 as without self-contact) and the fabric never intersects itself."""
    from clothfem import dynamics as dy
    from clothfem.contact import closest_point_union
    from clothfem.contact.film import FilmContact
    from clothfem.contact.self_contact import SelfContact
    from clothfem.shell import FabricMaterial, ShellModel

    c0, radius, vz = np.array([0.05, 0.0, -0.035]), 0.03, 0.5

    def bodies_at(t):
        centre = c0 + [0.0, 0.0, vz * t]
        return [(centre, np.eye(3), np.full(3, radius))], [(np.array([0, 0, vz]), np.zeros(3))]

    sm = meshes.strip(MPI.COMM_WORLD, length=0.1, width=0.1, nx=4, ny=4)
    mat = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)
    model = ShellModel(sm, material=mat, thickness=1e-3)
    system = dy.ShellSystem(model, rotary_scale=100.0)
    fc = FilmContact(system, bodies_at)
    sc = SelfContact(system, params=SelfContactParameters(distance=D, mu=0.3), film=fc)
    worst = []

    def on_step(r):
        fc.collect()
        x = sc.positions()
        worst.append(check_surface(x, sc.surface.triangles, radius=4 * D).intersections)

    recs, _ = dy.integrate_explicit(system, t_end=0.03, contact=sc, on_step=on_step)
    assert max(h.active for h in fc.history) > 0 and max(worst) == 0
    n = model.n_owned
    x = model.x_nodes[:n] + model.u.x.array[: 3 * n].reshape(n, 3)
    gap = closest_point_union(x, bodies_at(recs[-1].time)[0]).gap
    assert MPI.COMM_WORLD.allreduce(float(gap.min(initial=np.inf)), op=MPI.MIN) > -1e-12
    assert sc.collect().steps == len(recs)
