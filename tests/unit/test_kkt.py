"""The bordered contact matrix with a fixed pattern against its dense twin (serial and MPI)."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from clothfem.contact.kkt import BorderedMatrix, bordered_dense
from clothfem.petsc_options import direct_lu, set_defaults

COMM = MPI.COMM_WORLD
N_NODES = 12  # global; 5 unknowns per node


def _value(r: np.ndarray, c: np.ndarray, salt: float) -> np.ndarray:
    return np.sin(1.3 * r + 0.7 * c + salt) + 4.0 * (r == c)


def _fabric_tangent(salt: float):
    """A distributed K in the shell's owned layout (rank q: 3 n_q u rows, then 2 n_q theta
    rows), coupling every unknown of neighbouring nodes; also the global dense K and the
    owned node ranges."""
    per = np.array_split(np.arange(N_NODES), COMM.size)
    nq = [len(p) for p in per]
    start = np.concatenate([[0], np.cumsum([5 * k for k in nq])])

    def dofs(node: int) -> list[int]:
        q = next(i for i, p in enumerate(per) if node in p)
        k, n = node - per[q][0], nq[q]
        base = start[q]
        return [base + 3 * k + a for a in range(3)] + [base + 3 * n + 2 * k + a for a in range(2)]

    n5 = 5 * N_NODES
    dense = np.zeros((n5, n5))
    for i in range(N_NODES):
        for j in range(max(0, i - 1), min(N_NODES, i + 2)):
            r, c = np.meshgrid(dofs(i), dofs(j), indexing="ij")
            dense[r, c] = _value(r, c, salt)
    lo, hi = start[COMM.rank], start[COMM.rank + 1]
    K = PETSc.Mat().createAIJ(((hi - lo, None), (hi - lo, None)), comm=COMM)
    rows = []
    for r in range(lo, hi):
        rows.append(np.flatnonzero(dense[r]))
    indptr = np.concatenate([[0], np.cumsum([len(c) for c in rows])]).astype(PETSc.IntType)
    idx = np.concatenate(rows).astype(PETSc.IntType)
    vals = np.concatenate([dense[r, c] for r, c in zip(range(lo, hi), rows, strict=True)])
    K.setPreallocationCSR((indptr, idx, vals))
    K.assemble()
    return K, dense, per, start


def _global_order(start, ms):
    """Global row of every fabric row and multiplier in the bordered numbering."""
    moff = np.concatenate([[0], np.cumsum(ms)])
    fab = np.concatenate([np.arange(start[q], start[q + 1]) + moff[q] for q in range(len(ms))])
    lam = np.concatenate(
        [start[q + 1] + moff[q] + np.arange(ms[q]) for q in range(len(ms))]
    ).astype(int)
    return fab, lam


def _expected(dense, start, nodes, col, row, blocks, bc, active, diag):
    """The dense twin on the gathered data, permuted to the bordered global numbering."""
    ms = COMM.allgather(len(nodes))
    fab, lam = _global_order(start, ms)
    g = [np.concatenate(COMM.allgather(a)) for a in (col, row, blocks, active, diag)]
    urows = np.concatenate(
        [start[q] + 3 * nq[:, None] + np.arange(3) for q, nq in enumerate(COMM.allgather(nodes))]
    )
    g_bc = np.concatenate([start[q] + b for q, b in enumerate(COMM.allgather(bc))])
    ref = bordered_dense(dense, urows, *g[:3], g_bc, g[3], g[4])
    perm = np.concatenate([fab, lam])
    expect = np.zeros_like(ref)
    expect[np.ix_(perm, perm)] = ref
    return expect


@pytest.mark.parametrize("repeat_node", [False, True])
def test_bordered_matrix_matches_dense_twin(repeat_node: bool) -> None:
    K, dense, per, start = _fabric_tangent(0.3)
    n_own = len(per[COMM.rank])
    rng = np.random.default_rng(7 + COMM.rank)
    # node 0 is in contact and has a Dirichlet u row on rank 0 (a partly supported node)
    nodes = np.unique(np.concatenate([[0], rng.choice(n_own, size=min(3, n_own), replace=False)]))
    if repeat_node:  # one node against two ellipsoids: two multiplier columns on its rows
        nodes = np.sort(np.concatenate([nodes, nodes[:1]]))
    m = len(nodes)
    col, row = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    blocks = rng.normal(size=(m, 3, 3))
    bc = np.array([3 * n_own + 1, 0], dtype=np.int32) if COMM.rank == 0 else np.zeros(0, np.int32)
    active = np.ones(m, dtype=bool)
    active[-1] = False  # a slot not in use: identity row
    diag = -rng.uniform(0.1, 1.0, size=m)  # compliant constraints (a soft body)
    B = BorderedMatrix(K, nodes, bc)
    A = B.update(K, col, row, blocks, active, diag)
    r0, r1 = A.getOwnershipRange()
    ncol = A.getSize()[1]
    expect = _expected(dense, start, nodes, col, row, blocks, bc, active, diag)
    assert np.array_equal(A.getValues(range(r0, r1), range(ncol)), expect[r0:r1])
    # the LU of the same matrix object follows new values (factorisation refreshed, the
    # symbolic analysis reused): solve, update, solve again, against NumPy
    # with clothfem's direct solve (MUMPS LU; redundant on > 1 rank)
    ksp = PETSc.KSP().create(COMM)
    ksp.setOptionsPrefix("test_kkt_")
    set_defaults("test_kkt_", direct_lu(COMM))
    ksp.setFromOptions()
    rhs, sol = A.createVecs()
    rhs.set(1.0)
    rigid = np.zeros(m)
    for salt, scale, on, d in ((0.3, 1.0, active, diag), (1.1, 2.0, ~active, rigid)):
        K2, dense2, _, _ = _fabric_tangent(salt)
        assert B.update(K2, scale * col, row, blocks, on, None if d is rigid else d) is A
        ksp.setOperators(A)
        ksp.solve(rhs, sol)
        expect = _expected(dense2, start, nodes, scale * col, row, blocks, bc, on, d)
        x = np.linalg.solve(expect, np.ones(len(expect)))
        assert np.allclose(sol.getArray(), x[r0:r1], rtol=1e-10, atol=1e-12)
    ksp.destroy()
    B.destroy()


@pytest.mark.serial
def test_dense_twin_is_the_textbook_saddle_point_matrix() -> None:
    K = np.arange(100.0).reshape(10, 10)
    one = np.ones((1, 3))
    A = bordered_dense(K, np.array([[3, 4, 5]]), one, 2 * one, np.zeros((1, 3, 3)), np.array([0]))
    assert A.shape == (11, 11)
    assert np.array_equal(A[3:6, 10], np.ones(3)) and np.array_equal(A[10, 3:6], 2 * np.ones(3))
    assert A[10, 10] == 0.0 and A[0, 0] == 1.0 and not A[0, 1:].any()
    soft = bordered_dense(
        K, np.array([[3, 4, 5]]), one, 2 * one, np.zeros((1, 3, 3)), np.array([0]), None, [-0.5]
    )
    assert soft[10, 10] == -0.5 and np.array_equal(soft[:10, :10], A[:10, :10])
