"""Spring network on the nodes of a nine-node quadrilateral shell mesh.

Provot (1995), "Deformation constraints in a mass-spring model to describe rigid cloth
behavior", Proc. Graphics Interface, 147-154 (Man & Swan 2007, Sec. 2.1, Fig. 1): particles
joined by three kinds of linear springs,

* **structural** springs between neighbouring nodes along the grid lines (warp and weft),
* **shear** springs along the diagonals of the grid squares,
* **flexion** springs between every second node along the grid lines.

The particles are the geometry nodes of a second-order mesh, which are the degree-2 Lagrange
nodes of :class:`clothfem.shell.ShellModel` (the same points; tested). A nine-node cell is a
3 x 3 grid of nodes, i.e. four grid squares ("sub-squares"); flexion springs continue across
cell edges, so a structured mesh gives Provot's regular grid.

Parallel runs: the network is small next to the shell's system, so :func:`network_from_mesh`
gathers the whole mesh on every rank (collective) and every rank then holds and advances the
whole network redundantly. Nodes are numbered by their gmsh (input) index and cells by their
original index, so the network, and every result computed on it, is the same bit for bit on
any number of ranks.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "FLEXION",
    "SHEAR",
    "STRUCTURAL",
    "SpringNetwork",
    "grid_cells",
    "network_from_grid",
    "network_from_mesh",
    "regular_patch",
]

STRUCTURAL, SHEAR, FLEXION = 0, 1, 2
KIND_NAMES = {"structural": STRUCTURAL, "shear": SHEAR, "flexion": FLEXION}

IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False, kw_only=True)
class SpringNetwork:
    """Particles and springs of a fabric (reference configuration).

    Attributes
    ----------
    x0 : (n, 3) float array
        Reference (stress-free) node positions [m].
    grid : (c, 3, 3) int array
        Node indices of each nine-node cell as a grid: ``grid[c, i, j]`` is the node at the
        cell's reference point (xi, eta) = (i/2, j/2).
    pairs : (m, 2) int array
        End nodes of each spring, ``pairs[:, 0] < pairs[:, 1]``.
    kind : (m,) int array
        ``STRUCTURAL`` (0), ``SHEAR`` (1) or ``FLEXION`` (2).
    middle : (m,) int array
        Middle node of a flexion spring (the node it bends over), -1 for the other kinds.
    rest : (m,) float array
        Rest lengths [m] (distances in ``x0``).
    boundaries : dict of str -> int array
        Node indices of each named boundary of the mesh.
    """

    x0: NDArray[np.float64]
    grid: IntArray
    pairs: IntArray
    kind: IntArray
    middle: IntArray
    rest: NDArray[np.float64]
    boundaries: Mapping[str, IntArray] = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return self.x0.shape[0]

    @property
    def n_springs(self) -> int:
        return self.pairs.shape[0]

    def count(self, kind: str) -> int:
        """Number of springs of ``kind`` ("structural", "shear" or "flexion")."""
        return int(np.count_nonzero(self.kind == _kind(kind)))

    def nodes(self, where: str | Callable[[NDArray[np.float64]], ArrayLike]) -> IntArray:
        """Indices of the nodes on the named boundary ``where``, or where the callable of the
        reference coordinates (shape (3, n)) returns True."""
        if isinstance(where, str):
            if where not in self.boundaries:
                known = ", ".join(sorted(self.boundaries)) or "none"
                raise ValueError(f"unknown boundary {where!r}; this network has: {known}")
            return np.asarray(self.boundaries[where], dtype=np.int64)
        mask = np.asarray(where(self.x0.T.copy()), dtype=bool)
        if mask.shape != (self.n_nodes,):
            raise ValueError(f"where must return a bool mask of shape ({self.n_nodes},)")
        return np.flatnonzero(mask)


def _kind(name: str) -> int:
    if name not in KIND_NAMES:
        raise ValueError(f"spring kind must be one of {sorted(KIND_NAMES)}, got {name!r}")
    return KIND_NAMES[name]


def grid_cells(cells: ArrayLike, ref_points: ArrayLike) -> IntArray:
    """Nine-node cells (c, 9) with the cell's reference points (9, 2) in [0, 1]^2 ->
    (c, 3, 3) grids ``grid[c, i, j]`` = the node at (i/2, j/2)."""
    cells = np.asarray(cells, dtype=np.int64)
    pts = np.rint(2.0 * np.asarray(ref_points, dtype=float)).astype(int)
    if cells.ndim != 2 or cells.shape[1] != 9 or pts.shape != (9, 2):
        raise ValueError(f"cells must be (c, 9) nine-node quadrilaterals, got {cells.shape}")
    where = np.full((3, 3), -1)
    where[pts[:, 0], pts[:, 1]] = np.arange(9)
    if np.any(where < 0):
        raise ValueError("ref_points must be the 3 x 3 grid of a nine-node quadrilateral")
    return cells[:, where]


def _cell_springs(g: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """All spring candidates (duplicates on shared edges included): pairs, kinds, middles."""
    pairs, kinds, mids = [], [], []

    def add(a, b, kind, mid=None):
        pairs.append(np.stack([a, b], axis=1))
        kinds.append(np.full(a.shape[0], kind))
        mids.append(np.full(a.shape[0], -1) if mid is None else mid)

    for k in range(3):
        for i in range(2):
            add(g[:, i, k], g[:, i + 1, k], STRUCTURAL)  # along xi
            add(g[:, k, i], g[:, k, i + 1], STRUCTURAL)  # along eta
        add(g[:, 0, k], g[:, 2, k], FLEXION, g[:, 1, k])
        add(g[:, k, 0], g[:, k, 2], FLEXION, g[:, k, 1])
    for i in range(2):
        for j in range(2):
            add(g[:, i, j], g[:, i + 1, j + 1], SHEAR)
            add(g[:, i + 1, j], g[:, i, j + 1], SHEAR)
    a, b, m = _flexion_across_edges(g)
    add(a, b, FLEXION, m)
    return np.concatenate(pairs), np.concatenate(kinds), np.concatenate(mids)


def _flexion_across_edges(g: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Flexion springs over the nodes of shared cell edges: for each node ``b`` of an edge,
    its inward neighbours (perpendicular to the edge) in the two cells sharing the edge."""
    rec = []  # (edge mid node, edge node b, inward neighbour)
    for k in range(3):
        rec.append((g[:, 0, 1], g[:, 0, k], g[:, 1, k]))  # xi = 0
        rec.append((g[:, 2, 1], g[:, 2, k], g[:, 1, k]))  # xi = 1
        rec.append((g[:, 1, 0], g[:, k, 0], g[:, k, 1]))  # eta = 0
        rec.append((g[:, 1, 2], g[:, k, 2], g[:, k, 1]))  # eta = 1
    mid, node, inward = (np.concatenate([r[c] for r in rec]) for c in range(3))
    order = np.lexsort((inward, node, mid))
    mid, node, inward = mid[order], node[order], inward[order]
    same = (mid[1:] == mid[:-1]) & (node[1:] == node[:-1])
    first = np.flatnonzero(same)
    return inward[first], inward[first + 1], node[first]


def network_from_grid(
    x0: ArrayLike, grid: ArrayLike, *, boundaries: Mapping[str, ArrayLike] | None = None
) -> SpringNetwork:
    """Network of nodes ``x0`` (n, 3) [m] and nine-node cells as (c, 3, 3) grids."""
    x0 = np.ascontiguousarray(x0, dtype=float)
    g = np.asarray(grid, dtype=np.int64)
    if x0.ndim != 2 or x0.shape[1] != 3 or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be finite (n, 3) positions in m, got shape {x0.shape}")
    if g.ndim != 3 or g.shape[1:] != (3, 3) or g.min(initial=0) < 0 or g.max() >= len(x0):
        raise ValueError(f"grid must be (c, 3, 3) node indices in [0, {len(x0)}), got {g.shape}")
    pairs, kinds, mids = _cell_springs(g)
    lo, hi = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    _, first = np.unique(lo * len(x0) + hi, return_index=True)
    pairs = np.stack([lo[first], hi[first]], axis=1)
    rest = np.linalg.norm(x0[pairs[:, 1]] - x0[pairs[:, 0]], axis=1)
    if np.any(rest <= 0.0):
        raise ValueError("x0 must not have coincident nodes joined by a spring (rest length 0)")
    bnd = {k: np.unique(np.asarray(v, dtype=np.int64)) for k, v in (boundaries or {}).items()}
    return SpringNetwork(
        x0=x0, grid=g, pairs=pairs, kind=kinds[first], middle=mids[first], rest=rest,
        boundaries=bnd,
    )  # fmt: skip


def network_from_mesh(surface) -> SpringNetwork:
    """Network on the geometry nodes of a :class:`clothfem.mesh.SurfaceMesh` of nine-node
    quadrilaterals (collective: the whole mesh is gathered on every rank)."""
    import basix
    import dolfinx

    mesh = surface.mesh
    if mesh.topology.cell_type != dolfinx.mesh.CellType.quadrilateral:
        raise ValueError("surface must be a quadrilateral mesh (9-node cells, order=2)")
    dofmap = mesh.geometry.dofmap
    n_cells = mesh.topology.index_map(2).size_local
    local = np.asarray(dofmap.array, dtype=np.int64).reshape(-1, len(dofmap.links(0)))
    if local.shape[1] != 9:
        raise ValueError(f"surface must have 9-node cells (order=2), got {local.shape[1]} nodes")
    gid = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    comm = mesh.comm
    cells = np.concatenate(comm.allgather(gid[local[:n_cells]]))
    orig = np.concatenate(comm.allgather(np.asarray(mesh.topology.original_cell_index[:n_cells])))
    ids = np.concatenate(comm.allgather(gid))
    xs = np.concatenate(comm.allgather(np.asarray(mesh.geometry.x)))
    uid, first = np.unique(ids, return_index=True)
    x0 = xs[first]
    cells = np.searchsorted(uid, cells[np.argsort(orig, kind="stable")])
    ref = basix.create_element(
        basix.ElementFamily.P, basix.CellType.quadrilateral, 2, basix.LagrangeVariant.equispaced
    ).points
    grid = grid_cells(cells, ref)
    bnd = {}
    for name in sorted(surface.boundaries):
        # the facets' end nodes (dolfinx 0.5 returns the vertices only), then the grid edges
        ends = dolfinx.cpp.mesh.entities_to_geometry(
            getattr(mesh, "_mesh", mesh), 1, surface.facets(name), False
        )
        mine = gid[np.asarray(ends, dtype=np.int64).reshape(-1, 2)]
        pairs = np.searchsorted(uid, np.concatenate(comm.allgather(mine)).reshape(-1, 2))
        bnd[name] = _edge_nodes(grid, pairs, len(x0))
    return network_from_grid(x0, grid, boundaries=bnd)


def _edge_nodes(grid: IntArray, ends: IntArray, n: int) -> IntArray:
    """All nodes (ends and mid-side) of the cell edges whose end nodes are the rows of
    ``ends``."""
    edges = np.concatenate(
        [grid[:, 0, :], grid[:, 2, :], grid[:, :, 0], grid[:, :, 2]]
    )  # (4c, 3): end, mid, end
    key = np.minimum(edges[:, 0], edges[:, 2]) * n + np.maximum(edges[:, 0], edges[:, 2])
    want = np.minimum(ends[:, 0], ends[:, 1]) * n + np.maximum(ends[:, 0], ends[:, 1])
    return np.unique(edges[np.isin(key, want)])


def regular_patch(
    *, length: float, width: float, nx: int, ny: int, origin=(0.0, 0.0, 0.0)
) -> SpringNetwork:
    """Flat rectangle ``[0, length] x [0, width]`` (+ origin) in a z = const plane of
    ``nx`` x ``ny`` nine-node cells, without a mesh (NumPy only). Boundaries: ``left``
    (x = 0), ``right``, ``bottom`` (y = 0), ``top``."""
    for name, v in (("length", length), ("width", width)):
        if not (np.isfinite(v) and v > 0.0):
            raise ValueError(f"{name} must be a finite number > 0 m, got {v!r}")
    for name, v in (("nx", nx), ("ny", ny)):
        if int(v) != v or v < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
    px, py = 2 * nx + 1, 2 * ny + 1
    X, Y = np.meshgrid(np.linspace(0, length, px), np.linspace(0, width, py), indexing="ij")
    x0 = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1) + np.asarray(origin, float)
    node = np.arange(px * py).reshape(px, py)
    ci, cj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    grid = np.stack(
        [np.stack([node[2 * ci + i, 2 * cj + j] for j in range(3)], -1) for i in range(3)], -2
    ).reshape(-1, 3, 3)
    bnd = {"left": node[0], "right": node[-1], "bottom": node[:, 0], "top": node[:, -1]}
    return network_from_grid(x0, grid, boundaries=bnd)
