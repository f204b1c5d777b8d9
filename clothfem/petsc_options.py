"""PETSc option defaults shared by clothfem's solvers.

Every PETSc solve has its own options prefix (``static_``, ``contact_lagrange_``, ...);
:func:`set_defaults` sets an option only where the user gave none, so each default can be
overridden on the command line, e.g. ``-contact_lagrange_pc_type lu``.

The direct solver (:func:`direct_lu`) is MUMPS LU. In serial the matrix is factored as it is.
On more than one rank it is factored **redundantly** (PCREDUNDANT: every rank gathers the whole
matrix and factors it with sequential MUMPS). MUMPS's distributed factorisation hands work to
processes by dynamic scheduling, so its round-off differs from run to run; for frictional
contact that changes the Newton and active-set path (16x20 sleeve, 5 degrees, 2 ranks: 4
runs, 4 different histories; redundant: 4 runs, identical bits; docs/parallel.md).
Redundant factorisation repeats bit for bit, at the price of the solve's parallel speed-up
(``make bench-arm`` measures both). When the factor no longer fits on one rank, or speed
matters more, ``-<prefix>pc_type lu`` restores MUMPS's distributed LU (the same answers up
to round-off, not repeatable run to run).
"""

from __future__ import annotations

from collections.abc import Mapping

from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["describe_direct_lu", "direct_lu", "set_defaults"]


def direct_lu(comm: MPI.Comm) -> dict[str, str]:
    """Options (without prefix) for one sparse direct solve per ``KSPSolve`` on ``comm``."""
    options = {
        "ksp_type": "preonly",  # one direct solve, no Krylov iterations
        "pc_type": "lu",
        "pc_factor_mat_solver_type": "mumps",  # LU with pivoting (indefinite matrices)
    }
    if comm.size > 1:
        options["pc_type"] = "redundant"  # every rank factors the gathered matrix: repeatable
        options["redundant_pc_type"] = "lu"
        options["redundant_pc_factor_mat_solver_type"] = "mumps"  # sequential MUMPS per rank
    return options


def describe_direct_lu(comm: MPI.Comm) -> str:
    """One line for a run's log: the default direct solve on ``comm``."""
    if comm.size == 1:
        return "MUMPS LU"
    return (
        f"MUMPS LU, redundant (each of the {comm.size} ranks factors the gathered matrix: "
        "repeatable; -<prefix>pc_type lu for MUMPS's distributed LU)"
    )


def set_defaults(prefix: str, defaults: Mapping[str, object]) -> None:
    """Put ``defaults`` into PETSc's options database under ``prefix`` unless already given.

    ``direct_lu`` also sets ``pc_factor_mat_solver_type mumps`` on more than one rank, so
    ``-<prefix>pc_type lu`` alone switches to MUMPS's distributed LU; options of the family
    not chosen are ignored by PETSc.
    """
    opts = PETSc.Options()
    for key, value in defaults.items():
        if not opts.hasName(prefix + key):
            opts.setValue(prefix + key, value)
