"""clothfem: finite-element analysis of functional clothing (Man & Swan 2007).

Subpackages
-----------
clothfem.shell    fabric shell physics in UFL (kinematics, material, energy) and its model
clothfem.body     rigid ellipsoid body segments posed from motion capture (no FEM imports)
clothfem.contact  fabric-body contact pipeline (detection, gaps, multipliers, friction)
"""

__version__ = "0.1.0"
