"""Dynamic failures near |theta| = pi say so (the total-rotation parametrisation's singularity)."""

import math

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
