"""A run that starts from given node positions (``[initial] positions``), e.g. pants donned
with the particle model (``python -m clothfem.particle.donning``): the shell's stress-free
reference stays the pattern mesh, the given positions become its initial displacement and
the directors follow the deformed surface (:meth:`clothfem.shell.ShellModel.start_at`).

The file is a NumPy ``.npz`` with ``X`` (N, 3), the reference (pattern) positions of the
nodes [m], and ``x`` (N, 3), their positions at the start [m]. Nodes are matched to the
mesh's by their reference positions (any order, any rank layout).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = ["displacement_at_nodes", "read_positions"]

FloatArray = NDArray[np.float64]


def read_positions(path: Path) -> tuple[FloatArray, FloatArray]:
    """``(X, x)`` of an ``.npz`` file; ``ValueError`` (one line) when it does not hold two
    finite (N, 3) arrays ``X`` and ``x``."""
    try:
        with np.load(path) as data:
            missing = [k for k in ("X", "x") if k not in data]
            if missing:
                raise ValueError(f"{path.name} has no array {missing[0]!r} (needs X and x)")
            X, x = (np.asarray(data[k], dtype=float) for k in ("X", "x"))
    except (OSError, EOFError) as exc:
        raise ValueError(f"{path.name} cannot be read as .npz: {exc}") from None
    if X.ndim != 2 or X.shape[1] != 3 or x.shape != X.shape:
        raise ValueError(f"{path.name}: X and x must both be (N, 3), got {X.shape}, {x.shape}")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(x))):
        raise ValueError(f"{path.name}: X and x must be finite")
    return X, x


def displacement_at_nodes(
    *, nodes: FloatArray, X: FloatArray, x: FloatArray, rel_tol: float = 1e-6
) -> FloatArray:
    """``x - X`` at every mesh node of reference position ``nodes`` (n, 3) [m], matched to
    the file's nearest ``X`` within ``rel_tol`` x the size of the file's bounding box;
    ``ValueError`` (one line) naming the unmatched nodes (another mesh)."""
    size = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0)))
    dist, idx = cKDTree(X).query(nodes)
    far = dist > rel_tol * max(size, 1e-300)
    if far.any():
        worst = int(np.argmax(dist))
        raise ValueError(
            f"{int(far.sum())} mesh node(s) are not in the file (another mesh?): the farthest, "
            f"at {np.round(nodes[worst], 6).tolist()} m, is {dist[worst]:.3g} m from the file's "
            "nearest node"
        )
    return x[idx] - X[idx]
