r"""The bordered (KKT) matrix of the Lagrange-multiplier contact solve, with a fixed pattern.

For the active (node, ellipsoid) pairs of one Newton pass the linear system is

.. math::

    \begin{bmatrix} K + K_t & C \\ B & D \end{bmatrix}
    \begin{bmatrix} \Delta x \\ \Delta\lambda \end{bmatrix} = \begin{bmatrix} -r \\ g \end{bmatrix}

with K the fabric tangent (owned rows of the (u, theta) layout, global columns), C one column
per pair on the node's three u rows, B one row per pair on the same columns, K_t a 3x3 block
per pair (curvature of the constraint and friction), D diagonal (0 for a rigid body, minus
the compliance of a soft one) and Dirichlet rows replaced by identity rows. The multiplier
rows of rank r follow its fabric rows in the global numbering.

:class:`BorderedMatrix` builds the sparsity pattern for a set of multiplier *slots* (pairs)
and refreshes the values in place at every Newton iteration: the same PETSc matrix object
is kept, so the direct solver reuses its symbolic analysis (ordering) and only refactors
numerically. A slot whose pair is not active has the identity row ``dlam = 0`` and no
coupling, so one pattern serves every active set inside its slots (the active set changes
between Newton passes; rebuilding the pattern each time cost more than the factorisation
it saved). :func:`bordered_dense` is its dense NumPy twin (one process, tests).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from petsc4py import PETSc

__all__ = ["BorderedMatrix", "bordered_dense"]

FloatArray = NDArray[np.float64]


def _u_rows(nodes: NDArray[np.intp]) -> NDArray[np.intp]:
    return (3 * np.asarray(nodes)[:, None] + np.arange(3)).ravel()


class BorderedMatrix:
    """[[K + K_t, C], [B, D]] as one PETSc AIJ matrix whose pattern is fixed for the slots
    on ``nodes`` (owned node index per slot, repeated nodes allowed) and the Dirichlet rows
    ``bc_rows`` (owned rows of the fabric block); D is given on active slots (0 by
    default), 1 on the others.

    Collective on ``K``'s communicator. ``K`` must keep its nonzero pattern between calls
    (the pattern is taken from the first ``K`` and checked at every :meth:`update`).
    """

    def __init__(self, K: PETSc.Mat, nodes: NDArray[np.intp], bc_rows: NDArray[np.int32]):
        comm = K.getComm().tompi4py()
        self.comm = comm
        self.nodes = np.asarray(nodes, dtype=np.intp).copy()
        self.bc_rows = np.asarray(bc_rows).copy()
        n5 = K.getLocalSize()[0]
        m = len(self.nodes)
        ms = np.array(comm.allgather(m))
        moff = np.concatenate([[0], np.cumsum(ms)])
        kr = np.array(K.getOwnershipRanges())
        ntot = int(kr[-1] + moff[-1])
        r0 = int(kr[comm.rank] + moff[comm.rank])  # first global row of this rank
        k_indptr, k_indices, _ = K.getValuesCSR()
        self._k_indptr, self._k_indices = k_indptr.copy(), k_indices.copy()
        all_rows = np.repeat(np.arange(n5), np.diff(k_indptr))
        # Dirichlet rows keep only their identity entry (no explicit zeros for the LU)
        is_bc = np.zeros(n5, dtype=bool)
        is_bc[self.bc_rows] = True
        self._sel = ~is_bc[all_rows] | (k_indices == kr[comm.rank] + all_rows)
        k_rows, k_cols = all_rows[self._sel], k_indices[self._sel]
        counts = np.bincount(k_rows, minlength=n5)
        fptr = np.concatenate([[0], np.cumsum(counts)])
        # The pattern is K's (columns shifted past the multipliers of lower ranks) with, in
        # each u row of a pair, the pair's multiplier column inserted after the row's own-rank
        # columns (the multipliers of this rank follow its fabric unknowns), and one row of
        # three entries per pair. Built by counting, without sorting.
        owner = np.searchsorted(kr, k_cols, side="right") - 1
        later = owner > comm.rank  # entries right of this rank's multiplier columns
        urows = _u_rows(self.nodes)
        self._keep_c = ~is_bc[urows]
        c_rows = urows[self._keep_c]
        extra = np.bincount(c_rows, minlength=n5)  # multiplier entries per fabric row
        indptr = np.concatenate([[0], np.cumsum(np.concatenate([counts + extra, np.full(m, 4)]))])
        within = np.arange(len(k_cols)) - fptr[k_rows]
        self._pos_k = indptr[k_rows] + within + np.where(later, extra[k_rows], 0)
        # multiplier entries of a row: right after its last own-rank entry, in pair order
        n_later = np.bincount(k_rows[later], minlength=n5)
        order = np.argsort(c_rows, kind="stable")
        rank_in_row = np.empty(len(c_rows), dtype=np.intp)
        rank_in_row[order] = np.arange(len(c_rows)) - np.searchsorted(c_rows[order], c_rows[order])
        self._pos_c = indptr[c_rows] + (counts - n_later)[c_rows] + rank_in_row
        self._pos_b = indptr[n5 + np.repeat(np.arange(m), 3)] + np.tile(np.arange(3), m)
        self._pos_d = indptr[n5 : n5 + m] + 3  # the slot's own column comes after its u columns
        # K_t blocks and the Dirichlet identity land on K's own entries (sorted keys)
        stride = np.int64(kr[-1] + 1)
        keys = k_rows.astype(np.int64) * stride + k_cols
        t_rows = np.repeat(urows.reshape(m, 3), 3, axis=1).ravel()
        t_cols = kr[comm.rank] + np.tile(urows.reshape(m, 3), (1, 3)).ravel()
        self._keep_t = ~is_bc[t_rows]
        want_rows = np.concatenate([t_rows[self._keep_t], self.bc_rows]).astype(np.int64)
        want = want_rows * stride + np.concatenate(
            [t_cols[self._keep_t], kr[comm.rank] + self.bc_rows]
        )
        at = np.searchsorted(keys, want)
        if np.any(at >= len(keys)) or np.any(keys[np.minimum(at, len(keys) - 1)] != want):
            raise RuntimeError("the fabric tangent lacks a node's diagonal block")
        n_t = int(self._keep_t.sum())
        self._pos_t, self._pos_e = self._pos_k[at[:n_t]], self._pos_k[at[n_t:]]
        self._nnz = int(indptr[-1])
        indices = np.empty(self._nnz, dtype=np.int64)
        indices[self._pos_k] = k_cols + moff[owner]
        indices[self._pos_c] = r0 + n5 + np.repeat(np.arange(m), 3)[self._keep_c]
        indices[self._pos_b] = r0 + urows
        indices[self._pos_d] = r0 + n5 + np.arange(m)
        self._indptr = indptr.astype(PETSc.IntType)
        self._indices = indices.astype(PETSc.IntType)
        nrows = n5 + m
        size = ((nrows, ntot), (nrows, ntot))
        self._data = np.zeros(self._nnz)
        if comm.size == 1:  # SeqAIJ on our arrays: update() writes the values in place
            A = PETSc.Mat().createAIJWithArrays(
                size, (self._indptr, self._indices, self._data), comm=comm
            )
        else:  # MPIAIJ copies into its diagonal / off-diagonal parts: update() sets rows
            A = PETSc.Mat().createAIJ(size=size, comm=comm)
            A.setPreallocationCSR((self._indptr, self._indices, self._data))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATION_ERR, True)
        A.assemble()
        self.mat = A

    def matches(self, K: PETSc.Mat) -> bool:
        """Whether ``K`` has the nonzero pattern this matrix was built for."""
        indptr, indices, _ = K.getValuesCSR()
        return np.array_equal(indptr, self._k_indptr) and np.array_equal(indices, self._k_indices)

    def update(
        self,
        K: PETSc.Mat,
        col: FloatArray,
        row: FloatArray,
        blocks: FloatArray,
        active: NDArray[np.bool_] | None = None,
        diag: FloatArray | None = None,
    ) -> PETSc.Mat:
        """Write the values at the current iterate into :attr:`mat` and return it: ``col``
        (m, 3) the multiplier columns, ``row`` (m, 3) the constraint rows, ``blocks``
        (m, 3, 3) the K_t blocks, per slot in the order of ``nodes``; ``active`` (m,) marks
        the slots in use (default all), the others get the row ``dlam = 0``; ``diag`` (m,)
        is D on the slots in use (default 0; a compliant constraint's -c in m/N)."""
        if not self.matches(K):
            raise RuntimeError("the fabric tangent changed its sparsity pattern")
        _, _, kdata = K.getValuesCSR()
        on = np.ones(len(self.nodes), dtype=bool) if active is None else np.asarray(active)
        col = np.where(on[:, None], col, 0.0)
        row = np.where(on[:, None], row, 0.0)
        blocks = np.where(on[:, None, None], blocks, 0.0)
        data = self._data
        data[:] = 0.0
        data[self._pos_k] = kdata[self._sel]
        data[self._pos_c] = col.ravel()[self._keep_c]
        data[self._pos_b] = row.ravel()
        data[self._pos_d] = np.where(on, 0.0 if diag is None else diag, 1.0)
        np.add.at(data, self._pos_t, blocks.ravel()[self._keep_t])
        data[self._pos_e] = 1.0
        if self.comm.size > 1:
            self.mat.setValuesCSR(self._indptr, self._indices, data)
        self.mat.assemble()  # also marks new values for the factorisation
        return self.mat

    def destroy(self) -> None:
        self.mat.destroy()


def bordered_dense(
    K: FloatArray,
    urows: NDArray[np.intp],
    col: FloatArray,
    row: FloatArray,
    blocks: FloatArray,
    bc_rows: NDArray[np.intp],
    active: NDArray[np.bool_] | None = None,
    diag: FloatArray | None = None,
) -> FloatArray:
    """Dense twin of :class:`BorderedMatrix` (one process): K (n, n) with the slots' u rows
    ``urows`` (m, 3) and the multipliers appended as rows and columns n..n+m-1."""
    n5, m = K.shape[0], len(urows)
    A = np.zeros((n5 + m, n5 + m))
    A[:n5, :n5] = K
    for j, u in enumerate(np.asarray(urows)):
        if active is not None and not active[j]:
            A[n5 + j, n5 + j] = 1.0
            continue
        A[u, n5 + j] += col[j]
        A[np.ix_(u, u)] += blocks[j]
        A[n5 + j, u] += row[j]
        A[n5 + j, n5 + j] = 0.0 if diag is None else diag[j]
    A[bc_rows, :] = 0.0
    A[bc_rows, bc_rows] = 1.0
    return A
