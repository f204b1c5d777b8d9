"""Implicit Newmark dynamics with Lagrange-multiplier contact: a sphere strikes a free patch."""

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.contact.dynamic import DynamicContact
from clothfem.contact.lagrange import LagrangeContactParameters
from clothfem.shell import FabricMaterial, ShellModel

COMM = MPI.COMM_WORLD
R, VZ, T = 0.03, 0.5, 1e-3  # sphere radius [m], speed [m/s], fabric thickness [m]
C0 = np.array([0.05, 0.0, -0.032])


def bodies_at(t):
    return [(C0 + np.array([0.0, 0.0, VZ * t]), np.eye(3), np.full(3, R))], [
        (np.array([0.0, 0.0, VZ]), np.zeros(3))
    ]


@pytest.fixture(scope="module")
def run():
    sm = meshes.strip(COMM, length=0.1, width=0.1, nx=4, ny=4)
    model = ShellModel(sm, material=FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0), thickness=T)
    system = dy.ShellSystem(model)
    # plain Newmark velocities: the momentum balance below is exact only without the
    # non-resilient velocity correction (which adds the impulse of a perfectly plastic impact)
    dc = DynamicContact(
        system, bodies_at, params=LagrangeContactParameters(mu=0.0), non_resilient=False
    )
    n = model.n_owned
    rows = []

    def on_step(r):
        Mv = dc.v.duplicate()
        system.mass_mult(dc.v, Mv)
        pz = COMM.allreduce(float(Mv.getArray()[2 : 3 * n : 3].sum()), op=MPI.SUM)
        fz = COMM.allreduce(float(dc.contact.state().force_on_fabric[:, 2].sum()), op=MPI.SUM)
        rows.append((r, pz, fz))

    dc.run(t_end=0.02, dt=1e-3, on_step=on_step)
    return rows


def test_momentum_equals_contact_impulse(run):
    """Newmark (gamma = 1/2) momentum balance of the free patch: P_z(t_n) equals the
    trapezoidal sum of the z contact forces; internal forces sum to zero (translation
    invariance of the strain energy)."""
    impulse, f_prev = 0.0, 0.0
    for r, pz, fz in run:
        impulse += r.dt * 0.5 * (f_prev + fz)
        f_prev = fz
        assert abs(pz - impulse) <= 1e-9 * max(abs(impulse), 1e-12)
    assert impulse > 0  # the sphere did push the patch up


def test_no_penetration_and_kkt_each_step(run):
    assert max(r.contact.n_active for r, _, _ in run) > 0
    for r, _, _ in run:
        assert r.contact.max_penetration <= 1e-3 * T
        assert r.contact.min_multiplier >= 0


def test_non_resilient_nodes_move_with_the_body():
    """Paper, Sec. 3.2: after every step a node in contact has the body's normal velocity
    (the sphere's VZ projected on its normal), and the correction is a plastic impact: it
    only removes approach velocity, it never adds separation."""
    from clothfem.contact.geometry import closest_point_union

    sm = meshes.strip(COMM, length=0.1, width=0.1, nx=4, ny=4)
    model = ShellModel(sm, material=FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0), thickness=T)
    dc = DynamicContact(dy.ShellSystem(model), bodies_at, params=LagrangeContactParameters())
    n = model.n_owned
    seen = []

    def on_step(r):
        act = np.flatnonzero(dc.contact.active)
        x = dc.contact.X[act] + model.u.x.array[: 3 * n].reshape(n, 3)[act]
        nrm = closest_point_union(x, dc.contact.bodies).normal if len(act) else np.zeros((0, 3))
        v = dc.v.getArray()[: 3 * n].reshape(n, 3)[act]
        rel = np.einsum("ij,ij->i", v, nrm) - VZ * nrm[:, 2]
        seen.append(COMM.allreduce(len(act), op=MPI.SUM))
        assert np.all(np.abs(rel) <= 1e-12)

    dc.run(t_end=0.01, dt=1e-3, on_step=on_step)
    assert max(seen) > 0


def test_bad_parameters():
    sm = meshes.strip(COMM, length=0.1, width=0.1, nx=1, ny=1)
    model = ShellModel(sm, material=FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0), thickness=T)
    system = dy.ShellSystem(model)
    with pytest.raises(ValueError, match=r"beta must be in \(0, 0.5\]"):
        DynamicContact(system, bodies_at, beta=0.0)
    with pytest.raises(ValueError, match=r"gamma must be in \[0.5, 1\]"):
        DynamicContact(system, bodies_at, gamma=0.4)
