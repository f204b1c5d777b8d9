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


def test_explicit_run_past_the_stable_step_stops_with_a_diagnosis():
    """Central difference at 1.1 dt_crit (check off) on a hanging strip: the highest mode
    grows until a director rotation passes pi (from <= 0.5 rad) in one step; the run stops there
    with DynamicsDivergence naming dt and dt_crit, not later with NaN or a singular rotary
    mass. At 0.9 dt_crit the same run is stable over the same span."""
    from clothfem.shell import Clamp, Gravity

    sm = meshes.strip(MPI.COMM_WORLD, length=1.0, width=0.2, nx=4, ny=1)
    mat = FabricMaterial.isotropic(E=1e6, nu=0.0, rho=400.0)
    model = ShellModel(
        sm, material=mat, thickness=0.002, supports=[Clamp("root")], loads=[Gravity((0, 0, -9.81))]
    )
    system = dy.ShellSystem(model)
    st = dy.stable_time_step(system, lam=1.0)
    t_end = 300 * st.dt_crit
    with pytest.raises(dy.DynamicsDivergence, match=r"reached \|theta\| = .* does not resolve"):
        dy.integrate_explicit(system, t_end=t_end, dt=1.1 * st.dt_crit, stable=st, check="off")
    stable_model = ShellModel(
        sm, material=mat, thickness=0.002, supports=[Clamp("root")], loads=[Gravity((0, 0, -9.81))]
    )
    stable_system = dy.ShellSystem(stable_model)
    recs, _ = dy.integrate_explicit(stable_system, t_end=t_end, dt=0.9 * st.dt_crit, stable=st)
    assert len(recs) == math.ceil(t_end / (0.9 * st.dt_crit) - 1e-9)
    assert stable_system.max_rotation() <= 0.5
