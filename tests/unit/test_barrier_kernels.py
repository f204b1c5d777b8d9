"""The barrier's compiled block sum (clothfem.contact.barrier_kernels.add_blocks) against a
dense sum of the same Hessians, on a pattern with rows of two ranks' nodes."""

import numpy as np

from clothfem.contact.barrier_kernels import add_blocks


def _pattern(blocks: set, *, lo: int, n: int, row0: np.ndarray):
    """CSR (local rows of nodes lo .. lo + n - 1, global columns) of 3 x 3 node blocks."""
    rows = [
        sorted(int(row0[b]) + c for (a, b) in blocks if a == node for c in range(3))
        for node in range(lo, lo + n)
        for _ in range(3)
    ]
    indptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int32)
    return indptr, np.concatenate(rows).astype(np.int32)


def test_add_blocks_sums_this_ranks_rows_in_place_and_reports_a_missing_block():
    rng = np.random.default_rng(0)
    n_nodes, lo, n = 9, 3, 4  # this rank owns nodes 3..6
    row0 = 10 + 3 * np.arange(n_nodes, dtype=np.int64)[::-1].copy()  # any column numbering
    node = np.array([[0, 4, 5, 6], [3, 4, 8, 1], [6, 5, 4, 3], [2, 7, 0, 1]], dtype=np.int64)
    hess = rng.normal(size=(len(node), 12, 12))
    blocks = {(int(a), int(b)) for g in node for a in g for b in g}
    indptr, indices = _pattern(blocks, lo=lo, n=n, row0=row0)
    base = rng.normal(size=len(indices))
    data = base.copy()
    assert add_blocks(hess, node, lo, n, row0, indptr, indices, data)

    dense = np.zeros((3 * n, 10 + 3 * n_nodes))
    for m, g in enumerate(node):
        for a in range(4):
            if lo <= g[a] < lo + n:
                for b in range(4):
                    r, c = 3 * (g[a] - lo), row0[g[b]]
                    dense[r : r + 3, c : c + 3] += hess[m, 3 * a : 3 * a + 3, 3 * b : 3 * b + 3]
    rows = np.repeat(np.arange(3 * n), np.diff(indptr))
    np.testing.assert_allclose(data - base, dense[rows, indices], rtol=0, atol=1e-13)
    assert np.count_nonzero(dense) == np.count_nonzero(dense[rows, indices])  # none left out

    blocks.discard((4, 8))  # a block of pair 1 missing from the pattern
    indptr, indices = _pattern(blocks, lo=lo, n=n, row0=row0)
    assert not add_blocks(hess, node, lo, n, row0, indptr, indices, np.zeros(len(indices)))
