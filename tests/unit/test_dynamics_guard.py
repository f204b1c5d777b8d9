"""Dynamic failures near |theta| = pi say so (the total-rotation parametrisation's singularity)."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.shell import FabricMaterial, ShellModel


def test_rotation_note_names_the_singularity():
    sm = meshes.strip(MPI.COMM_WORLD, length=1.0, width=0.1, nx=2, ny=1)
    mat = FabricMaterial.isotropic(E=1e6, nu=0.0, rho=1.0)
    system = dy.ShellSystem(ShellModel(sm, material=mat, thickness=0.01))
    assert dy.rotation_note(system) == ""  # at rest
    if system.n:
        system.model.theta.x.array[0] = 0.97 * math.pi
    assert "near the singularity at pi" in dy.rotation_note(system)


def test_singular_rotary_mass_on_one_rank_stops_every_rank():
    """A singular lumped rotary block is found rank-locally; the explicit run must stop with
    the diagnosis on every rank (raising on one rank alone left the others waiting in the
    next collective call). Here the block 'fails' on rank 0 only, at the third solve."""
    sm = meshes.strip(MPI.COMM_WORLD, length=1.0, width=0.1, nx=2, ny=1)
    mat = FabricMaterial.isotropic(E=1e6, nu=0.0, rho=1.0)
    system = dy.ShellSystem(ShellModel(sm, material=mat, thickness=0.01))
    st = dy.stable_time_step(system)
    calls = [0]
    solve = system.lumped_solve

    def failing(f):
        calls[0] += 1
        if MPI.COMM_WORLD.rank == 0 and calls[0] == 3:
            raise np.linalg.LinAlgError("Singular matrix")
        return solve(f)

    system.lumped_solve = failing
    with pytest.raises(dy.DynamicsDivergence, match="lumped rotary mass became singular"):
        dy.integrate_explicit(system, t_end=20 * st.dt_crit, dt=0.5 * st.dt_crit, stable=st)
