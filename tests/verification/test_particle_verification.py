"""Particle fabric against analytic answers and against the shell (clothfem.particle).

A sheet dropped on a sphere (FILM contact through clothfem.contact.explicit.film_step), the
order of the explicit step on a nonlinear swing, its energy error, and the static sag of
the arm-sleeve tube against the shell on the same mesh. NumPy on every rank except the
shell solve, which is collective: the tests run unchanged on 2 MPI ranks.
"""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import particle as pm
from clothfem.body import Ellipsoid
from clothfem.contact import closest_point_union
from clothfem.particle.network import regular_patch
from clothfem.shell import FabricMaterial

R = 0.05  # sphere radius [m]
COTTON = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1.0e5, rho=436.0)


@pytest.fixture(scope="module")
def drape():
    """A 0.2 m square sheet (6 x 6 cells) dropped from 5 mm above a sphere, damped to rest
    over 1 s; the paper's non-resilient contact (nodes stick)."""
    net = regular_patch(length=0.2, width=0.2, nx=6, ny=6, origin=(-0.1, -0.1, R + 0.005))
    fab = pm.fabric_from_material(net, material=COTTON, thickness=1e-3)
    sphere = Ellipsoid(centre=np.zeros(3), axes=np.eye(3), radii=np.full(3, R))
    model = pm.ParticleModel(
        network=net, fabric=fab, bodies=pm.bodies([sphere]),
        damping=pm.Damping(alpha=10.0, beta=1e-4),
    )  # fmt: skip
    dt = 0.9 * pm.stable_time_step(model)
    state = pm.ParticleState.at_rest(model)
    gaps, forces, worst = [], [], np.inf
    geo, _ = model.bodies(0.0)
    for _ in range(int(1.0 / dt)):
        state, info = pm.step_explicit(model, state, dt)
        gaps.append(info.min_gap)
        forces.append(info.contact_force)
        worst = min(worst, float(closest_point_union(state.x, geo).gap.min()))
    return model, state, np.array(gaps), np.array(forces), worst


def test_no_node_inside_the_sphere_after_the_film_correction(drape):
    model, state, gaps, forces, worst = drape
    assert gaps.min() > -1e-12  # film_step's own gaps, every step
    assert worst > -1e-12  # an independent closest-point check of every step's positions
    assert np.count_nonzero(np.linalg.norm(forces, axis=1)) > 0.9 * len(forces)
    # every rank advanced the whole sheet: the same positions bit for bit on every rank
    digest = state.x.tobytes()
    assert all(d == digest for d in MPI.COMM_WORLD.allgather(digest))


def test_contact_force_balances_the_weight_at_rest(drape):
    model, state, gaps, forces, _ = drape
    weight = model.mass.sum() * 9.81
    mean = forces[-200:].mean(axis=0)  # force on the fabric over the last 200 steps
    assert mean[2] == pytest.approx(weight, rel=0.01)
    assert np.hypot(mean[0], mean[1]) < 0.01 * weight
    assert pm.energies(model, state).kinetic < 1e-3 * model.mass.sum() * 9.81 * R


def swing(n, t_end=0.1):
    """A soft single-cell sheet pinned at a corner swinging under gravity (nonlinear: it
    moves by half its size), undamped, ``n`` velocity-Verlet steps to ``t_end``."""
    soft = FabricMaterial(E1=2e3, E2=2e3, G12=4e2, rho=436.0)
    net = regular_patch(length=0.1, width=0.1, nx=1, ny=1)
    fab = pm.fabric_from_material(net, material=soft, thickness=1e-3)
    model = pm.ParticleModel(network=net, fabric=fab, fixed=np.array([0]))
    state = pm.ParticleState.at_rest(model)
    e0, err = pm.energies(model, state).total, 0.0
    for _ in range(n):
        state, _ = pm.step_explicit(model, state, t_end / n)
        err = max(err, abs(pm.energies(model, state).total - e0))
    return model, state.x, err


def test_explicit_step_converges_at_second_order():
    model, _, _ = swing(1)
    n0 = 2 * int(np.ceil(0.1 / pm.stable_time_step(model)))
    _, ref, _ = swing(64 * n0)
    _, x1, e1 = swing(n0)
    _, x2, e2 = swing(2 * n0)
    _, x4, e4 = swing(4 * n0)
    assert np.abs(ref - model.network.x0).max() > 0.04  # large motion
    err = [np.abs(x - ref).max() for x in (x1, x2, x4)]
    assert err[0] / err[1] == pytest.approx(4.0, rel=0.1)
    assert err[1] / err[2] == pytest.approx(4.0, rel=0.1)
    assert e1 / e2 == pytest.approx(4.0, rel=0.25)  # energy error O(dt^2) too
    assert e2 / e4 == pytest.approx(4.0, rel=0.25)


def test_sleeve_sag_agrees_with_the_shell():
    """The arm-sleeve tube (8 x 10 cells, decrimped cotton, held at the shoulder) under
    gravity: cuff sag of the particle model within 2 % of the shell's (docs/results/
    particle.md has the mesh ladder)."""
    from clothfem.particle.sleeve import particle_sag, shell_sag

    shell = shell_sag(n_around=8, n_along=10, material="decrimped-cotton")
    for bending in ("provot", "choi-ko"):
        part = particle_sag(n_around=8, n_along=10, material="decrimped-cotton", bending=bending)
        assert part.mean == pytest.approx(shell.mean, rel=0.02)
        assert part.nodes == shell.nodes
