"""A pair of pants as a structured fabric shell mesh (gmsh model built on rank 0).

Geometry (SI units, metres): z points up, the waist is the circle of radius
``waist_radius`` in the plane z = 0 centred on the z axis, the legs hang along -z. The
wearer faces -y, so the front is at y < 0 and the left leg is the one at x > 0. Each leg is
a straight circular tube of radius ``leg_radius`` whose axis is the vertical line
x = +-``leg_spacing``/2, y = 0, from the crotch (z = -``crotch_depth``) down to its hem
(z = -``crotch_depth`` - ``leg_length``).

Above the crotch the torso is a tube of elliptical cross-section: at hip level (from the
crotch up to 40 % of the rise) the ellipse of semi-axes ``leg_spacing``/2 + ``leg_radius``
(x) and b (y) that encloses both legs, b from ``hip_radius`` (the ellipse's perimeter is
2 pi ``hip_radius``) or, by default, 5 % more than the smallest b that encloses the legs;
from there it narrows smoothly (smoothstep, vertical at both ends) to the waist circle.

The nodes lie exactly on these tubes except in a band of rows around the crotch (about
0.2 m below and 0.12 m above it), the thin-plate fill of the tubes around it: the discrete
biharmonic equation on the lattice of all mesh nodes (graph Laplacian with edge weights
1 / h^2 of the nominal steps, so that the fill depends little on the cells' aspect
ratio), two rows of fixed nodes on each side making it meet the tubes with a continuous
tangent plane. The fill is a saddle: the legs meet along a short seam (the bridge, in the
plane x = 0, from the front crotch point to the back one, its middle horizontal and
sagging a few cm below the crotch points), which the inner sides of both legs reach from
below as an arch, so that no cells meet back to back. The rows are placed so that the
crotch points lie at z = -``crotch_depth``; the band's nodes are then spaced evenly along
the lattice columns, so that the cells under the crotch are about as tall as the others.
The band's shape depends a little on the row counts (areas within 0.6 % from 12 x 15 to
48 x 60 cells per leg, 3.5 % less with 8 x 10).

Cell layout: ``n_around`` cells around each leg, of which ``n_bridge`` (default a quarter,
even) meet the other leg at the bridge; the other ``n_around - n_bridge`` continue into the
torso, which has ``2 (n_around - n_bridge)`` cells around. ``n_along`` rows of cells along
each leg, ``n_rise`` rows from the crotch to the waist (by default as many as give rows as
tall as the leg's rows). The two crotch points are the only irregular nodes (six cells
each). Cells are oriented with outward normals. Boundaries: ``waist``, ``left_hem``,
``right_hem``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI

from clothfem.mesh import SurfaceMesh, _check_cell, _model_to_mesh, _positive, _positive_int

__all__ = ["PantsLattice", "pants", "pants_lattice", "write_pants_msh"]

BOUNDARY_TAGS = {"waist": 1, "left_hem": 2, "right_hem": 3}
_HIP_TOP = 0.4  # fraction of the rise (crotch to waist) where the hip section ends
_BAND_BELOW, _BAND_ABOVE = 0.2, 0.12  # [m] thin-plate band below and above the crotch


@dataclass(frozen=True)
class PantsLattice:
    """All mesh nodes and cells of a pair of pants (numpy only, no gmsh).

    Attributes
    ----------
    x: (n_nodes, 3) node coordinates.
    cells: (n_cells, 4 or 9) node indices per quadrilateral in gmsh order (corners
        counter-clockwise seen from outside, then mid-sides, then centre).
    boundaries: name -> (n_edges, 2 or 3) node indices of the boundary edges (ends, mid).
    hip_semi_axes: (a, b) of the hip ellipse [m].
    """

    x: np.ndarray
    cells: np.ndarray
    boundaries: dict[str, np.ndarray]
    hip_semi_axes: tuple[float, float]

    def edge_lengths(self) -> np.ndarray:
        """Lengths of the cell edges (corner to corner; shared edges counted twice)."""
        corners = self.cells[:, :4]
        return np.linalg.norm(
            self.x[corners] - self.x[np.roll(corners, -1, axis=1)], axis=2
        ).ravel()

    def area(self) -> float:
        """Area of the mesh surface (Gauss rule of 5 x 5 points on each cell)."""
        x = self.x[self.cells]
        order = 2 if x.shape[1] == 9 else 1
        gauss, weights = np.polynomial.legendre.leggauss(5)
        total = 0.0
        for u, wu in zip(gauss, weights, strict=True):
            for v, wv in zip(gauss, weights, strict=True):
                du, dv = _shape_derivatives(u, v, order)
                t1, t2 = np.einsum("k,ckd->cd", du, x), np.einsum("k,ckd->cd", dv, x)
                total += wu * wv * np.linalg.norm(np.cross(t1, t2), axis=1).sum()
        return float(total)


def _shape_derivatives(u: float, v: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """d/du, d/dv of the gmsh Lagrange quadrilateral's shape functions on [-1, 1]^2."""
    if order == 1:
        f, df = [(1 - u) / 2, (1 + u) / 2], [-0.5, 0.5]
        g, dg = [(1 - v) / 2, (1 + v) / 2], [-0.5, 0.5]
        nodes = [(0, 0), (1, 0), (1, 1), (0, 1)]
    else:
        f, df = [u * (u - 1) / 2, 1 - u * u, u * (u + 1) / 2], [u - 0.5, -2 * u, u + 0.5]
        g, dg = [v * (v - 1) / 2, 1 - v * v, v * (v + 1) / 2], [v - 0.5, -2 * v, v + 0.5]
        nodes = [(0, 0), (2, 0), (2, 2), (0, 2), (1, 0), (2, 1), (1, 2), (0, 1), (1, 1)]
    du = np.array([df[i] * g[j] for i, j in nodes])
    dv = np.array([f[i] * dg[j] for i, j in nodes])
    return du, dv


@dataclass(frozen=True)
class _Dims:
    waist: float
    leg: float
    spacing: float
    leg_length: float
    depth: float
    hip_a: float
    hip_b: float


def _hip_semi_axes(leg: float, spacing: float, hip_radius: float | None) -> tuple[float, float]:
    """Semi-axes (a, b) of the hip ellipse: a = spacing/2 + leg; b encloses the legs."""
    a = 0.5 * spacing + leg
    b_min = leg / math.sqrt(1.0 - (0.5 * spacing / a) ** 2)
    if hip_radius is None:
        return a, 1.05 * b_min

    def perimeter(b: float) -> float:  # Ramanujan's second approximation
        h = ((a - b) / (a + b)) ** 2
        return math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))

    if perimeter(b_min) >= 2 * math.pi * hip_radius:
        raise ValueError(
            f"hip_radius must exceed {perimeter(b_min) / (2 * math.pi):.4g} m (an ellipse round "
            f"both legs), got {hip_radius!r}"
        )
    lo, hi = b_min, 10.0 * a
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if perimeter(mid) < 2 * math.pi * hip_radius else (lo, mid)
    return a, 0.5 * (lo + hi)


def _torso_section(dims: _Dims, z: float, u: np.ndarray) -> np.ndarray:
    """Points of the torso section at height z at arc-length fractions u (0 = front centre,
    increasing towards +x)."""
    t = (z + dims.depth) / dims.depth
    s = min(max((t - _HIP_TOP) / (1.0 - _HIP_TOP), 0.0), 1.0)
    s = s * s * (3.0 - 2.0 * s)
    a = dims.hip_a + (dims.waist - dims.hip_a) * s
    b = dims.hip_b + (dims.waist - dims.hip_b) * s
    phi = np.linspace(0.0, 2.0 * math.pi, 4097)
    pts = np.stack([a * np.sin(phi), -b * np.cos(phi)], axis=1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    ph = np.interp(np.asarray(u) * arc[-1], arc, phi)
    return np.stack([a * np.sin(ph), -b * np.cos(ph), np.full_like(ph, z)], axis=1)


@dataclass(frozen=True)
class _Grid:
    """Node numbers of the refined lattice: ``order`` lattice steps per cell edge."""

    left: np.ndarray  # (rows, columns) of the left leg, row 0 at the hem
    right: np.ndarray  # the right leg, its column a the mirror image of the left's
    torso: np.ndarray  # (rows, columns), row 0 at the crotch, column 0 at the front
    n_nodes: int


def _grid(n_around: int, n_bridge: int, n_along: int, n_rise: int, order: int) -> _Grid:
    """Number the lattice nodes; the legs' top rows are the torso's row 0 and the bridge."""
    na, kb, nl, nr = (order * n for n in (n_around, n_bridge, n_along, n_rise))
    nt = 2 * (na - kb)
    torso = np.arange((nr + 1) * nt).reshape(nr + 1, nt)
    n = torso.size
    left = np.full((nl + 1, na), -1)
    right = np.full((nl + 1, na), -1)
    left[:nl] = n + np.arange(nl * na).reshape(nl, na)
    right[:nl] = n + nl * na + np.arange(nl * na).reshape(nl, na)
    n += 2 * nl * na
    half = kb // 2
    outer = np.arange(half, na - half + 1)  # front crotch point, outer side, back crotch point
    left[nl, outer % na] = torso[0, np.arange(len(outer))]
    right[nl, outer % na] = torso[0, -np.arange(len(outer)) % nt]
    inner = np.arange(-half + 1, half) % na  # the bridge between the crotch points
    left[nl, inner] = right[nl, inner] = n + np.arange(len(inner))
    return _Grid(left, right, torso, n + len(inner))


def _quad_blocks(ids: np.ndarray, order: int, periodic: bool, flip: bool) -> np.ndarray:
    """Cells of one lattice block in gmsh order (corners, mid-sides, centre)."""
    rows, cols = ids.shape
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]  # (column, row) offsets in cells
    if flip:
        corners = corners[::-1]
    offsets = [(order * c, order * r) for c, r in corners]
    if order == 2:
        offsets += [
            (
                (offsets[i][0] + offsets[(i + 1) % 4][0]) // 2,
                (offsets[i][1] + offsets[(i + 1) % 4][1]) // 2,
            )
            for i in range(4)
        ]
        offsets.append((1, 1))
    n_cols = cols // order if periodic else (cols - 1) // order
    c0 = order * np.arange(n_cols)
    r0 = order * np.arange((rows - 1) // order)
    cc, rr = np.meshgrid(c0, r0, indexing="xy")
    cc, rr = cc.ravel(), rr.ravel()
    return np.stack([ids[rr + dr, (cc + dc) % cols] for dc, dr in offsets], axis=1)


def _edges(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lattice edges of a block periodic in its columns: along the rows, along the columns."""
    right = np.stack([ids, np.roll(ids, -1, axis=1)], axis=-1).reshape(-1, 2)
    up = np.stack([ids[:-1], ids[1:]], axis=-1).reshape(-1, 2)
    return right, up


def _fixed_positions(
    dims: _Dims, grid: _Grid, band: tuple[int, int], z_crotch: float
) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of the nodes on the exact tubes (NaN elsewhere) and the free-node mask.

    ``band``: lattice rows of the legs and of the torso left free next to the crotch. The
    rows are evenly spaced from the hems to ``z_crotch`` and from there to the waist.
    """
    x = np.full((grid.n_nodes, 3), np.nan)
    nl, na = grid.left.shape[0] - 1, grid.left.shape[1]
    z_hem = -dims.depth - dims.leg_length
    theta = 2.0 * math.pi * np.arange(na) / na
    for b in range(nl + 1 - band[0]):
        z = z_hem + (z_crotch - z_hem) * b / nl
        for sign, ids in ((1.0, grid.left), (-1.0, grid.right)):
            xs = sign * (0.5 * dims.spacing - dims.leg * np.cos(theta))
            x[ids[b]] = np.stack([xs, -dims.leg * np.sin(theta), np.full(na, z)], axis=1)
    nr, nt = grid.torso.shape[0] - 1, grid.torso.shape[1]
    for e in range(band[1], nr + 1):
        z = z_crotch * (nr - e) / nr
        x[grid.torso[e]] = _torso_section(dims, z, np.arange(nt) / nt)
    return x, np.isnan(x[:, 0])


def _thin_plate_fill(
    grid: _Grid, steps: tuple[float, ...], x: np.ndarray, free: np.ndarray
) -> np.ndarray:
    """Fill the free nodes by the discrete biharmonic equation: the square of the graph
    Laplacian whose edge weights are 1 / h^2, h the nominal lattice step of the edge
    (``steps``: around and along the legs, around and along the torso)."""
    pairs, weights = [], []
    for block, (h_row, h_col) in zip(
        (grid.left, grid.right, grid.torso), (steps[:2], steps[:2], steps[2:]), strict=True
    ):
        for edges, h in zip(_edges(block), (h_row, h_col), strict=True):
            pairs.append(np.sort(edges, axis=1))
            weights.append(np.full(len(edges), h**-2))
    pairs, first = np.unique(np.concatenate(pairs), axis=0, return_index=True)
    weights = np.concatenate(weights)[first]
    n = grid.n_nodes
    adj = sp.coo_matrix((weights, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    adj = (adj + adj.T).tocsr()
    lap = sp.diags(1.0 / np.asarray(adj.sum(axis=1)).ravel()) @ adj - sp.identity(n)
    bi = (lap @ lap).tocsr()
    f, c = np.flatnonzero(free), np.flatnonzero(~free)
    out = x.copy()
    out[f] = spla.splu(bi[f][:, f].tocsc()).solve(-(bi[f][:, c] @ x[c]))
    return out


def _place_nodes(dims: _Dims, grid: _Grid, order: int) -> np.ndarray:
    """Node coordinates: exact tubes plus the thin-plate band, the crotch at z = -depth.

    The fill is linear in the fixed nodes, which are affine in the height ``z_crotch`` at
    which their rows meet (:func:`_fixed_positions`); so the crotch point of the fill is
    affine in it, and two fills give the height that puts the crotch point at -depth.
    """
    nl = (grid.left.shape[0] - 1) // order
    nr = (grid.torso.shape[0] - 1) // order
    h_leg, h_torso = dims.leg_length / nl, dims.depth / nr
    band = (
        order * min(max(2, round(_BAND_BELOW / h_leg)), nl - 1),
        order * min(max(2, round(_BAND_ABOVE / h_torso)), nr - 1),
    )
    heights = (-dims.depth, -dims.depth + 0.1 * min(h_leg, h_torso))
    na, nt = grid.left.shape[1], grid.torso.shape[1]
    girth = 0.5 * (
        2 * math.pi * dims.waist + 2 * math.pi * math.hypot(dims.hip_a, dims.hip_b) / math.sqrt(2)
    )
    steps = (2 * math.pi * dims.leg / na, h_leg / order, girth / nt, h_torso / order)
    fills = [_thin_plate_fill(grid, steps, *_fixed_positions(dims, grid, band, z)) for z in heights]
    crotch = grid.torso[0, 0]
    z0, z1 = fills[0][crotch, 2], fills[1][crotch, 2]
    w = (-dims.depth - z0) / (z1 - z0)
    x = (1.0 - w) * fills[0] + w * fills[1]
    _even_out(x, grid, band)
    return x


def pants_lattice(
    *,
    waist_radius: float = 0.14,
    hip_radius: float | None = None,
    leg_radius: float = 0.09,
    leg_length: float = 0.75,
    crotch_depth: float = 0.25,
    leg_spacing: float = 0.22,
    n_around: int = 16,
    n_along: int = 20,
    n_rise: int | None = None,
    n_bridge: int | None = None,
    order: int = 2,
) -> PantsLattice:
    """Nodes and quadrilateral cells of :func:`pants` (same arguments), without gmsh."""
    if leg_spacing < 2.2 * leg_radius:
        raise ValueError(
            f"leg_spacing must be >= 2.2 leg_radius = {2.2 * leg_radius:.4g} m (a gap between "
            f"the legs for the crotch arch), got {leg_spacing!r}"
        )
    if hip_radius is not None:
        _positive("hip_radius", hip_radius)
    a, b = _hip_semi_axes(_positive("leg_radius", leg_radius), leg_spacing, hip_radius)
    dims = _Dims(
        waist=_positive("waist_radius", waist_radius),
        leg=leg_radius,
        spacing=_positive("leg_spacing", leg_spacing),
        leg_length=_positive("leg_length", leg_length),
        depth=_positive("crotch_depth", crotch_depth),
        hip_a=a,
        hip_b=b,
    )
    n_around, n_along, n_rise, n_bridge = _cell_counts(
        n_around, n_along, n_rise, n_bridge, crotch_depth / leg_length
    )
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    grid = _grid(n_around, n_bridge, n_along, n_rise, order)
    x = _place_nodes(dims, grid, order)
    cells = np.concatenate(
        [
            _quad_blocks(grid.left, order, True, False),
            _quad_blocks(grid.right, order, True, True),
            _quad_blocks(grid.torso, order, True, False),
        ]
    )
    return PantsLattice(x, cells, _boundary_edges(grid, order), (a, b))


def _cell_counts(
    n_around: int, n_along: int, n_rise: int | None, n_bridge: int | None, rise_ratio: float
) -> tuple[int, int, int, int]:
    """Checked cell counts, the defaults of ``n_rise`` and ``n_bridge`` filled in."""
    n_around = _positive_int("n_around", n_around, 8)
    if n_around % 4:
        raise ValueError(f"n_around must be a multiple of 4, got {n_around}")
    n_along = _positive_int("n_along", n_along, 3)
    if n_bridge is None:
        n_bridge = max(2, 2 * (n_around // 8))
    if int(n_bridge) != n_bridge or n_bridge % 2 or not 2 <= n_bridge <= n_around // 2:
        raise ValueError(f"n_bridge must be even, 2 <= n_bridge <= n_around / 2, got {n_bridge!r}")
    if n_rise is None:
        n_rise = max(3, round(rise_ratio * n_along))
    return n_around, n_along, _positive_int("n_rise", n_rise, 3), int(n_bridge)


def _boundary_edges(grid: _Grid, order: int) -> dict[str, np.ndarray]:
    out = {}
    for name, row in (
        ("waist", grid.torso[-1]),
        ("left_hem", grid.left[0]),
        ("right_hem", grid.right[0]),
    ):
        start = np.arange(0, len(row), order)
        cols = [start, (start + order) % len(row)] + ([start + 1] if order == 2 else [])
        out[name] = np.stack([row[c] for c in cols], axis=1)
    return out


def _respace(x: np.ndarray, path: np.ndarray, moving: slice) -> None:
    """Move the nodes ``path[moving]`` along the curve through all of ``path`` (cubic spline
    in chord length) so that the nodes from ``path[moving.start - 1]`` to ``path[moving.stop]``
    are evenly spaced in arc length; the rest of ``path`` only shapes the curve."""
    from scipy.interpolate import CubicSpline

    p = x[path]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    curve = CubicSpline(s, p)
    fine = np.linspace(s[moving.start - 1], s[moving.stop], 64 * (moving.stop - moving.start + 1))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve(fine), axis=0), axis=1))])
    n = moving.stop - moving.start + 1
    target = np.interp(arc[-1] * np.arange(1, n) / n, arc, fine)
    x[path[moving]] = curve(target)


def _even_out(x: np.ndarray, grid: _Grid, band: tuple[int, int]) -> None:
    """Space the band's nodes evenly along each lattice column: from the last fixed row of
    a leg to the bridge or the crotch row, and from the crotch row to the first fixed row
    of the torso (the rows themselves stay where the fill put them: moving nodes along
    the rows sheared the thin rows of fine meshes into folded cells)."""
    nl, na = grid.left.shape[0] - 1, grid.left.shape[1]
    b0, e1 = nl - band[0], band[1]
    lo = max(b0 - 2, 0)
    for c in range(grid.torso.shape[1]):
        _respace(x, grid.torso[: e1 + 3, c], slice(1, e1))
    for leg in (grid.left, grid.right):
        for a in range(na):
            _respace(x, leg[lo : nl + 1, a], slice(b0 - lo + 1, nl - lo))


def _triangles(cells: np.ndarray) -> np.ndarray:
    """Each quadrilateral cut along its diagonal 0-2 (the 9-node centre is the diagonal's
    mid-node); gmsh order, same orientation."""
    if cells.shape[1] == 4:
        return np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])
    return np.concatenate([cells[:, [0, 1, 2, 4, 5, 8]], cells[:, [0, 2, 3, 8, 6, 7]]])


def _add_to_gmsh(gmsh, lattice: PantsLattice, cell: str) -> dict[str, int]:
    """Put the lattice into the current gmsh model as discrete entities with physical
    groups: the surface (2-D group 1, "fabric") and the named boundaries."""
    cells = lattice.cells if cell == "quadrilateral" else _triangles(lattice.cells)
    cell_type = {(True, 4): 3, (True, 9): 10, (False, 3): 2, (False, 6): 9}[
        (cell == "quadrilateral", cells.shape[1])
    ]
    surface = gmsh.model.addDiscreteEntity(2)
    n = len(lattice.x)
    gmsh.model.mesh.addNodes(2, surface, np.arange(1, n + 1), lattice.x.ravel())
    gmsh.model.mesh.addElementsByType(
        surface, cell_type, np.arange(1, len(cells) + 1), (cells + 1).ravel()
    )
    gmsh.model.addPhysicalGroup(2, [surface], 1)
    gmsh.model.setPhysicalName(2, 1, "fabric")
    next_tag = len(cells) + 1
    for name, tag in BOUNDARY_TAGS.items():
        edges = lattice.boundaries[name]
        curve = gmsh.model.addDiscreteEntity(1)
        line_type = 1 if edges.shape[1] == 2 else 8
        tags = np.arange(next_tag, next_tag + len(edges))
        gmsh.model.mesh.addElementsByType(curve, line_type, tags, (edges + 1).ravel())
        next_tag += len(edges)
        gmsh.model.addPhysicalGroup(1, [curve], tag)
        gmsh.model.setPhysicalName(1, tag, name)
    return dict(BOUNDARY_TAGS)


def pants(
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    waist_radius: float = 0.14,
    hip_radius: float | None = None,
    leg_radius: float = 0.09,
    leg_length: float = 0.75,
    crotch_depth: float = 0.25,
    leg_spacing: float = 0.22,
    n_around: int = 16,
    n_along: int = 20,
    n_rise: int | None = None,
    n_bridge: int | None = None,
    order: int = 2,
    cell: str = "quadrilateral",
) -> SurfaceMesh:
    """A pair of pants as a fabric surface mesh (geometry in the module docstring).

    waist_radius: radius of the waist circle (z = 0) [m].
    hip_radius: hip girth / (2 pi) [m], the perimeter of the hip ellipse (its x semi-axis is
        leg_spacing/2 + leg_radius); None: the ellipse 5 % deeper than the smallest one
        round both legs (semi-axes 0.200 x 0.113 m, girth 1.00 m with the defaults).
    leg_radius: radius of the leg tubes [m]; leg_length: crotch to hem (inseam) [m].
    crotch_depth: waist to crotch (the rise) [m].
    leg_spacing: distance between the leg axes [m], at least 2.2 leg_radius.
    n_around: cells around each leg (a multiple of 4, >= 8); n_along: rows along each leg;
    n_rise: rows from the crotch to the waist (default: rows as tall as the legs');
    n_bridge: cells of each leg's top row shared with the other leg at the crotch (even,
        default 2 * (n_around // 8), at least 2).
    order: 1 or 2 (9-node quadrilaterals, 6-node triangles); cell: "quadrilateral" or
        "triangle" (each quadrilateral cut in two).

    Boundaries ``waist``, ``left_hem`` (x > 0) and ``right_hem``. gmsh runs on rank 0;
    the mesh is distributed as by the other generators of :mod:`clothfem.mesh`.
    """
    import gmsh

    _check_cell(cell, order)
    lattice = pants_lattice(  # on every rank (cheap): the same one-line errors everywhere
        waist_radius=waist_radius,
        hip_radius=hip_radius,
        leg_radius=leg_radius,
        leg_length=leg_length,
        crotch_depth=crotch_depth,
        leg_spacing=leg_spacing,
        n_around=n_around,
        n_along=n_along,
        n_rise=n_rise,
        n_bridge=n_bridge,
        order=order,
    )
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("pants")
        _add_to_gmsh(gmsh, lattice, cell)
    try:
        mesh, facet_tags = _model_to_mesh(gmsh.model, comm)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    return SurfaceMesh(mesh=mesh, facet_tags=facet_tags, boundaries=dict(BOUNDARY_TAGS))


def write_pants_msh(
    path: str | Path, *, cell: str = "quadrilateral", **geometry: float | int | None
) -> PantsLattice:
    """Write the pants of :func:`pants` (keyword arguments ``geometry``, ``order`` among
    them) to a gmsh ``.msh`` file with physical groups, readable by
    :func:`clothfem.mesh.load_msh` (scene key ``mesh.generator = "file"``). Serial."""
    import gmsh

    _check_cell(cell, geometry.get("order", 2))
    lattice = pants_lattice(**geometry)
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("pants")
        _add_to_gmsh(gmsh, lattice, cell)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return lattice
