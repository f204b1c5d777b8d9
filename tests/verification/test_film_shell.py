"""Explicit shell dynamics with forward-increment Lagrange multiplier contact (Eqs. 22-25)."""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.contact import closest_point_union
from clothfem.contact.film import FilmContact, FilmParameters
from clothfem.shell import FabricMaterial, ShellModel
from clothfem.shell.conditions import Gravity

R, VZ = 0.03, 0.5  # sphere radius [m], upward speed [m/s]
C0 = np.array([0.05, 0.0, -0.035])  # top of the sphere 5 mm below the patch at t = 0


def bodies_at(t):
    return [(C0 + np.array([0.0, 0.0, VZ * t]), np.eye(3), np.full(3, R))], [
        (np.array([0.0, 0.0, VZ]), np.zeros(3))
    ]


@pytest.fixture(scope="module")
def run():
    sm = meshes.strip(MPI.COMM_WORLD, length=0.1, width=0.1, nx=4, ny=4)
    mat = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)
    model = ShellModel(sm, material=mat, thickness=1e-3)
    system = dy.ShellSystem(model, rotary_scale=100.0)
    contact = FilmContact(system, bodies_at)
    recs, st = dy.integrate_explicit(
        system, t_end=0.03, contact=contact, on_step=lambda r: contact.collect()
    )
    return model, contact, recs, st


def test_no_node_ever_inside_the_body(run):
    model, contact, recs, st = run
    assert len(contact.history) == len(recs) > 10
    assert min(h.min_gap_after for h in contact.history) > -1e-12
    assert max(h.active for h in contact.history) > 0  # the sphere did hit the patch
    assert max(h.max_penetration for h in contact.history) > 0  # ... through the predictor
    n = model.n_owned
    u = model.u.x.array[: 3 * n].reshape(n, 3)
    geo, _ = bodies_at(recs[-1].time)
    gap = closest_point_union(model.x_nodes[:n] + u, geo).gap
    assert MPI.COMM_WORLD.allreduce(float(gap.min(initial=np.inf)), op=MPI.MIN) > -1e-12


def test_contact_nodes_move_with_the_body_surface(run):
    """Non-resilient impact (paper, Sec. 3.2): a node in contact takes the body velocity."""
    model, contact, recs, _ = run
    res = contact.last
    assert MPI.COMM_WORLD.allreduce(int(res.active.sum()), op=MPI.SUM) > 0
    assert np.allclose(res.v[res.active], [0.0, 0.0, VZ], atol=1e-12)
    # the patch centre rides on the sphere top: its height is the top's height
    top = C0[2] + R + VZ * recs[-1].time
    z = model.displacement_at((0.05, 0.0, 0.0))[2]
    assert abs(z - top) < 1e-9


def test_multiplier_is_the_impulse_of_eq_24(run):
    """lambda = m (x - x*) . n / dt^2 >= 0 on every corrected node."""
    _, contact, recs, _ = run
    assert np.all(contact.last.lam_n >= 0)
    torque = contact.torque((0.05, 0.0, 0.0))
    assert np.all(np.isfinite(torque))


def test_bad_parameters():
    with pytest.raises(ValueError, match="mu must be None or >= 0"):
        FilmParameters(mu=-0.1)
    with pytest.raises(ValueError, match="offset must be >= 0"):
        FilmParameters(offset=-1.0)
    with pytest.raises(ValueError, match="kernel must be 'compiled' or 'numpy', got 'c'"):
        FilmParameters(kernel="c")


@pytest.mark.parametrize("mu", [None, 0.0, 0.3])
def test_contact_with_a_body_at_rest_adds_no_energy(mu):
    """A patch falls under gravity onto a sphere at rest and drapes over it: contact with a
    fixed body can only dissipate, so K + U never exceeds the work of gravity W (up to the
    trapezoidal energy bookkeeping). Correcting the full-step velocity made the tangential
    update explicit Euler; then K + U - W grew to ~W within 0.1 s (mu = 0, 0.3) or the run
    blew up (mu = None)."""
    sphere = np.array([0.05, 0.0, -R])  # top touching the patch centre at t = 0

    def at_rest(t):
        return [(sphere, np.eye(3), np.full(3, R))], [(np.zeros(3), np.zeros(3))]

    sm = meshes.strip(MPI.COMM_WORLD, length=0.1, width=0.1, nx=4, ny=4)
    mat = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)
    model = ShellModel(sm, material=mat, thickness=1e-3, loads=[Gravity((0.0, 0.0, -9.81))])
    system = dy.ShellSystem(model, rotary_scale=100.0)
    contact = FilmContact(system, at_rest, params=FilmParameters(mu=mu))
    recs, _ = dy.integrate_explicit(
        system, t_end=0.1, contact=contact, on_step=lambda r: contact.collect()
    )
    assert max(h.active for h in contact.history) > 5  # draped over the sphere
    work = recs[-1].external_work
    assert work > 0
    assert max(r.kinetic + r.strain - r.external_work for r in recs) <= 1e-3 * work


def test_windowed_diagnostics_aggregate_the_steps(run):
    """collect() every 4 steps gives the extremes, mean and sum of the per-step records of the
    same (deterministic) run."""
    _, contact, recs, _ = run
    sm = meshes.strip(MPI.COMM_WORLD, length=0.1, width=0.1, nx=4, ny=4)
    mat = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)
    system = dy.ShellSystem(ShellModel(sm, material=mat, thickness=1e-3), rotary_scale=100.0)
    windowed = FilmContact(system, bodies_at)

    def every_fourth(r):
        if r.step % 4 == 0 or r.step == len(recs):
            windowed.collect()

    dy.integrate_explicit(system, t_end=0.03, contact=windowed, on_step=every_fourth)
    per_step = contact.history
    start = 0
    for w in windowed.history:
        steps = per_step[start : start + w.steps]
        start += w.steps
        assert w.time == steps[-1].time and w.active == steps[-1].active
        assert w.n_stick == steps[-1].n_stick
        assert w.max_penetration == max(h.max_penetration for h in steps)
        assert w.min_gap_after == min(h.min_gap_after for h in steps)
        assert np.isclose(w.sum_lambda, np.mean([h.sum_lambda for h in steps]), rtol=1e-12)
        assert np.isclose(w.dissipation, sum(h.dissipation for h in steps), rtol=1e-12, atol=0)
    assert start == len(per_step) and len(windowed.history) > 2
    assert windowed.dissipation_total == pytest.approx(contact.dissipation_total, rel=1e-12)
