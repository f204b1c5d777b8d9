"""Particle (mass-spring) fabric: Man & Swan (2007), Sec. 2.1, after Provot (1995) and
Choi & Ko (2002). NumPy/SciPy only (the mesh builder uses dolfinx to read a SurfaceMesh).

    net = network_from_mesh(surface)                         # springs on the shell's nodes
    fab = fabric_from_material(net, material=mat, thickness=1e-3)
    model = ParticleModel(network=net, fabric=fab, fixed=net.nodes("shoulder"))
    state, records = integrate(model, ParticleState.at_rest(model), t_end=1.0, dt=1e-4)

User page: docs/particle.md.
"""

from .integrate import (
    StepInfo,
    bodies,
    integrate,
    limit_strain,
    solve_static,
    step_explicit,
    step_implicit,
)
from .model import (
    Damping,
    Energies,
    ParticleModel,
    ParticleState,
    StrainLimit,
    accelerations,
    energies,
    internal_forces,
    stable_time_step,
    support_reaction,
    tangent,
)
from .network import (
    FLEXION,
    SHEAR,
    STRUCTURAL,
    SpringNetwork,
    grid_cells,
    network_from_grid,
    network_from_mesh,
    regular_patch,
)
from .rule import (
    ParticleFabric,
    SpringRule,
    buckled_force,
    compressive_force,
    fabric_from_material,
)

__all__ = [
    "FLEXION",
    "SHEAR",
    "STRUCTURAL",
    "Damping",
    "Energies",
    "ParticleFabric",
    "ParticleModel",
    "ParticleState",
    "SpringNetwork",
    "SpringRule",
    "StepInfo",
    "StrainLimit",
    "accelerations",
    "bodies",
    "buckled_force",
    "compressive_force",
    "energies",
    "fabric_from_material",
    "grid_cells",
    "integrate",
    "internal_forces",
    "limit_strain",
    "network_from_grid",
    "network_from_mesh",
    "regular_patch",
    "solve_static",
    "stable_time_step",
    "step_explicit",
    "step_implicit",
    "support_reaction",
    "tangent",
]
