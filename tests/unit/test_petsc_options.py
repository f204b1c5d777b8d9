"""The shared direct-solver defaults (clothfem.petsc_options): which options, who wins, and
that the default solve of an indefinite system repeats bit for bit on any number of ranks."""

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from clothfem.petsc_options import describe_direct_lu, direct_lu, set_defaults

COMM = MPI.COMM_WORLD


def test_direct_lu_is_mumps_and_redundant_in_parallel() -> None:
    serial = direct_lu(MPI.COMM_SELF)
    assert serial == {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    assert describe_direct_lu(MPI.COMM_SELF) == "MUMPS LU"
    if COMM.size > 1:
        par = direct_lu(COMM)
        assert par["pc_type"] == "redundant"
        assert par["redundant_pc_type"] == "lu"
        assert par["redundant_pc_factor_mat_solver_type"] == "mumps"
        # -<prefix>pc_type lu alone must give a working distributed LU
        assert par["pc_factor_mat_solver_type"] == "mumps"
        assert "redundant" in describe_direct_lu(COMM)


def test_set_defaults_keeps_user_options() -> None:
    opts = PETSc.Options()
    opts["test_popt_pc_type"] = "lu"  # the user's choice
    try:
        set_defaults("test_popt_", {"pc_type": "redundant", "ksp_type": "preonly"})
        assert opts.getString("test_popt_pc_type") == "lu"
        assert opts.getString("test_popt_ksp_type") == "preonly"
    finally:
        for key in ("pc_type", "ksp_type"):
            opts.delValue("test_popt_" + key)


def _saddle_solve(prefix: str) -> np.ndarray:
    """Solve [[K, B^T], [B, 0]] x = 1 (K SPD tridiagonal, B: 1 constraint per 4 unknowns)."""
    n, m = 40, 10
    A = PETSc.Mat().createAIJ(((None, n + m), (None, n + m)), nnz=8, comm=COMM)
    r0, r1 = A.getOwnershipRange()
    for i in range(r0, r1):
        if i < n:
            A[i, i] = 4.0 + 0.01 * i
            if i > 0:
                A[i, i - 1] = -1.0
            if i < n - 1:
                A[i, i + 1] = -1.0
            A[i, n + i // 4] = 1.0 + 0.1 * (i % 4)
        else:
            for j in range(4 * (i - n), 4 * (i - n) + 4):
                A[i, j] = 1.0 + 0.1 * (j % 4)
    A.assemble()
    ksp = PETSc.KSP().create(COMM)
    ksp.setOptionsPrefix(prefix)
    set_defaults(prefix, direct_lu(COMM))
    ksp.setFromOptions()
    ksp.setOperators(A)
    b, x = A.createVecs()
    b.set(1.0)
    ksp.solve(b, x)
    res = b.duplicate()
    A.mult(x, res)
    res.axpy(-1.0, b)
    assert res.norm() < 1e-12 * b.norm()  # the zero block needs pivoting: solved
    out = x.getArray().copy()
    for obj in (ksp, A, b, x, res):
        obj.destroy()
    return out


def test_default_solve_repeats_bit_for_bit() -> None:
    first = _saddle_solve("test_popt_a_")
    for k in range(3):
        assert np.array_equal(_saddle_solve(f"test_popt_{k}_"), first)
