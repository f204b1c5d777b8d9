"""Fabric surface meshes: gmsh generators (run on rank 0) and user ``.msh`` files.

Every generator returns a :class:`SurfaceMesh`: a dolfinx mesh of a 2-D manifold in 3-D,
its facet tags and the map from boundary names (``"root"``, ``"shoulder"``, ...) to tag
values. gmsh runs on rank 0 only; dolfinx distributes the mesh over the communicator.

Generated meshes are structured and consistently oriented (cell normals agree across
facets); :func:`check_orientation` verifies that for user meshes.

On more than one rank the cells are partitioned by :func:`rcm_partitioner`, not by
dolfinx's default (PT-Scotch), which measured three different partitions of the same mesh
in six runs on 2 ranks and so made parallel runs non-repeatable (docs/parallel.md).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import dolfinx
import numpy as np
from dolfinx.io import gmshio
from mpi4py import MPI
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["SurfaceMesh", "strip", "cylinder", "cylinder_panel", "load_msh", "rcm_partitioner"]


def rcm_partitioner(
    comm: MPI.Comm, nparts: int, graph: dolfinx.cpp.graph.AdjacencyList_int64, ghosting: bool
) -> dolfinx.cpp.graph.AdjacencyList_int32:
    """Deterministic graph partitioner (dolfinx 0.5 signature) for a mesh held on one rank.

    ``graph`` is this rank's part of the cells' dual graph (global cell numbers, cells
    sharing a facet); all cells must be on one rank, as gmsh meshes are before distribution.
    The cells are ordered by reverse Cuthill-McKee (SciPy, deterministic) and cut into
    ``nparts`` contiguous, equal chunks: on a sleeve the parts are bands across the tube.
    Returns each cell's destination ranks, the owner first; with ``ghosting`` also the ranks
    that hold a facet neighbour (for dolfinx's shared-facet ghost layer).
    """
    n = graph.num_nodes
    total = comm.allreduce(n, op=MPI.SUM)
    if n not in (0, total):
        raise RuntimeError("rcm_partitioner: the cells must all be on one rank")
    if n == 0:
        return dolfinx.cpp.graph.AdjacencyList_int32(np.zeros(0, np.int32), np.zeros(1, np.int32))
    nbr, offsets = np.asarray(graph.array, dtype=np.int64), np.asarray(graph.offsets)
    rows = np.repeat(np.arange(n), np.diff(offsets))
    dual = csr_matrix((np.ones(len(nbr), dtype=np.int8), (rows, nbr)), shape=(n, n))
    order = reverse_cuthill_mckee(dual, symmetric_mode=True)
    part = np.empty(n, dtype=np.int32)
    for p, chunk in enumerate(np.array_split(order, nparts)):
        part[chunk] = p
    dests = [[int(part[c])] for c in range(n)]
    if ghosting:
        cut = part[rows] != part[nbr]
        for c, q in sorted(set(zip(rows[cut].tolist(), part[nbr[cut]].tolist(), strict=True))):
            dests[c].append(q)
    data = np.array([q for d in dests for q in d], dtype=np.int32)
    offs = np.concatenate([[0], np.cumsum([len(d) for d in dests])]).astype(np.int32)
    return dolfinx.cpp.graph.AdjacencyList_int32(data, offs)


def _model_to_mesh(model, comm: MPI.Comm) -> tuple[dolfinx.mesh.Mesh, dolfinx.mesh.MeshTags]:
    """``gmshio.model_to_mesh`` (model on rank 0) with :func:`rcm_partitioner`.

    dolfinx 0.5's ``model_to_mesh`` takes no partitioner; its module-level ``create_mesh``
    is swapped for the duration of the call.
    """
    partitioner = dolfinx.mesh.create_cell_partitioner(rcm_partitioner)
    create_mesh = gmshio.create_mesh
    gmshio.create_mesh = functools.partial(create_mesh, partitioner=partitioner)
    try:
        mesh, _, facet_tags = gmshio.model_to_mesh(model, comm, 0, gdim=3)
    finally:
        gmshio.create_mesh = create_mesh
    return mesh, facet_tags


@dataclass(frozen=True)
class SurfaceMesh:
    """A fabric surface mesh.

    Attributes
    ----------
    mesh: dolfinx mesh, topological dimension 2, geometric dimension 3.
    facet_tags: boundary-edge tags (may be empty).
    boundaries: name -> tag value of each named boundary.
    """

    mesh: dolfinx.mesh.Mesh
    facet_tags: dolfinx.mesh.MeshTags
    boundaries: dict[str, int]

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    def facets(self, name: str) -> np.ndarray:
        """Local indices of the boundary edges named ``name`` (one-line error if unknown)."""
        if name not in self.boundaries:
            known = ", ".join(sorted(self.boundaries)) or "none"
            raise ValueError(f"unknown boundary tag {name!r}; this mesh has: {known}")
        return self.facet_tags.indices[self.facet_tags.values == self.boundaries[name]]


def _positive_int(name: str, value: int, minimum: int = 1) -> int:
    if int(value) != value or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0 (metres), got {value!r}")
    return float(value)


def _check_cell(cell: str, order: int) -> None:
    if cell not in ("quadrilateral", "triangle"):
        raise ValueError(f"cell must be 'quadrilateral' or 'triangle', got {cell!r}")
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")


def _gmsh_to_dolfinx(comm: MPI.Comm, build, *, order: int, cell: str) -> SurfaceMesh:
    """Run ``build(gmsh)`` on rank 0 (it must define physical groups), mesh, distribute."""
    import gmsh

    names: dict[str, int] = {}
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("clothfem")
        names = build(gmsh)
        if cell == "quadrilateral":
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)
            gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)  # 9-node quadrilaterals
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.setOrder(order)
    names = comm.bcast(names, root=0)
    try:
        mesh, facet_tags = _model_to_mesh(gmsh.model, comm)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    return SurfaceMesh(mesh=mesh, facet_tags=facet_tags, boundaries=names)


def strip(
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    length: float,
    width: float,
    nx: int,
    ny: int,
    cell: str = "quadrilateral",
    order: int = 2,
) -> SurfaceMesh:
    """Flat rectangular strip ``[0, length] x [-width/2, width/2]`` in the plane z = 0.

    Boundaries: ``root`` (x = 0), ``tip`` (x = length), ``sides`` (y = +-width/2).
    ``nx`` x ``ny`` structured cells (quadrilaterals, or each split into two triangles).
    """
    length, width = _positive("length", length), _positive("width", width)
    nx, ny = _positive_int("nx", nx), _positive_int("ny", ny)
    _check_cell(cell, order)

    def build(gmsh):
        geo = gmsh.model.geo
        h = width / 2
        p = [geo.addPoint(*xy, 0.0) for xy in ((0, -h), (length, -h), (length, h), (0, h))]
        lines = [geo.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
        loop = geo.addCurveLoop(lines)
        surf = geo.addPlaneSurface([loop])
        for line, n in zip(lines, (nx, ny, nx, ny), strict=True):
            geo.mesh.setTransfiniteCurve(line, n + 1)
        geo.mesh.setTransfiniteSurface(surf, cornerTags=p)
        if cell == "quadrilateral":
            geo.mesh.setRecombine(2, surf)
        geo.synchronize()
        gmsh.model.addPhysicalGroup(2, [surf], 1)
        tags = {"root": 1, "tip": 2, "sides": 3}
        gmsh.model.addPhysicalGroup(1, [lines[3]], tags["root"])
        gmsh.model.addPhysicalGroup(1, [lines[1]], tags["tip"])
        gmsh.model.addPhysicalGroup(1, [lines[0], lines[2]], tags["sides"])
        return tags

    return _gmsh_to_dolfinx(comm, build, order=order, cell=cell)


def cylinder(
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    radius: float,
    length: float,
    n_around: int,
    n_along: int,
    cell: str = "quadrilateral",
    order: int = 2,
) -> SurfaceMesh:
    """Open circular tube of axis +x from x = 0 to x = ``length`` (the sleeve).

    Boundaries: ``shoulder`` (the circle at x = 0) and ``cuff`` (x = ``length``).
    ``n_around`` cells around (a multiple of 4), ``n_along`` along. With ``order=2``
    the mid-side nodes lie on the exact circle. Cell normals point outwards.
    """
    radius, length = _positive("radius", radius), _positive("length", length)
    n_around = _positive_int("n_around", n_around, 4)
    n_along = _positive_int("n_along", n_along)
    if n_around % 4:
        raise ValueError(f"n_around must be a multiple of 4, got {n_around}")
    _check_cell(cell, order)

    def build(gmsh):
        geo = gmsh.model.geo
        centre = geo.addPoint(0, 0, 0)
        # Quarter-circle arcs in the plane x = 0, ordered so that extrusion along +x
        # gives outward cell normals.
        angles = [0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi]
        pts = [geo.addPoint(0.0, radius * math.cos(a), radius * math.sin(a)) for a in angles]
        arcs = [geo.addCircleArc(pts[i], centre, pts[(i + 1) % 4]) for i in range(4)]
        for arc in arcs:
            geo.mesh.setTransfiniteCurve(arc, n_around // 4 + 1)
        out = geo.extrude(
            [(1, a) for a in arcs],
            length,
            0,
            0,
            numElements=[n_along],
            recombine=cell == "quadrilateral",
        )
        geo.synchronize()
        surfaces = [tag for dim, tag in out if dim == 2]
        far = [out[i - 1][1] for i, (dim, _) in enumerate(out) if dim == 2]
        gmsh.model.addPhysicalGroup(2, surfaces, 1)
        tags = {"shoulder": 1, "cuff": 2}
        gmsh.model.addPhysicalGroup(1, arcs, tags["shoulder"])
        gmsh.model.addPhysicalGroup(1, far, tags["cuff"])
        return tags

    sm = _gmsh_to_dolfinx(comm, build, order=order, cell=cell)
    return sm


def cylinder_panel(
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    radius: float,
    length: float,
    angle: float,
    n_around: int,
    n_along: int,
    cell: str = "quadrilateral",
    order: int = 2,
) -> SurfaceMesh:
    """Cylindrical panel (roof) of axis +x: x in [0, length], polar angle in [-angle, angle]
    measured from +z (so the crest is at y = 0, z = radius).

    ``angle`` is the half-opening [rad], 0 < angle < pi: angle = pi/2 is a semi-cylinder
    (z >= 0), angles near pi an almost closed tube. The arc is built from pieces of at most
    pi/2 (gmsh arcs must span less than pi), ``n_around`` equal cells in all.
    Boundaries: ``start`` (x = 0), ``end`` (x = length) and ``sides`` (the straight edges).
    Used by the Scordelis-Lo roof and the pinched semi-cylinder benchmarks.
    """
    radius, length = _positive("radius", radius), _positive("length", length)
    if not (0 < angle < math.pi):
        raise ValueError(f"angle must be in (0, pi) radians (half-opening), got {angle!r}")
    n_around = _positive_int("n_around", n_around)
    n_along = _positive_int("n_along", n_along)
    _check_cell(cell, order)
    counts = _arc_cell_counts(2 * angle, n_around)

    def build(gmsh):
        geo = gmsh.model.geo
        centre = geo.addPoint(0, 0, 0)
        # From the +y side to the -y side so that extrusion along +x gives outward normals;
        # the breaks between the arcs fall on cell boundaries.
        phis = angle - 2 * angle * np.concatenate([[0], np.cumsum(counts)]) / n_around
        pts = [geo.addPoint(0.0, radius * math.sin(p), radius * math.cos(p)) for p in phis]
        arcs = [geo.addCircleArc(pts[i], centre, pts[i + 1]) for i in range(len(counts))]
        for arc, n in zip(arcs, counts, strict=True):
            geo.mesh.setTransfiniteCurve(arc, n + 1)
        out = geo.extrude(
            [(1, a) for a in arcs],
            length,
            0,
            0,
            numElements=[n_along],
            recombine=cell == "quadrilateral",
        )
        geo.synchronize()
        # per arc: far edge, surface, the lateral edges at the arc's end and at its start
        far = [out[4 * i][1] for i in range(len(arcs))]
        surfaces = [out[4 * i + 1][1] for i in range(len(arcs))]
        side_a, side_b = abs(out[3][1]), abs(out[4 * len(arcs) - 2][1])
        gmsh.model.addPhysicalGroup(2, surfaces, 1)
        tags = {"start": 1, "end": 2, "sides": 3}
        gmsh.model.addPhysicalGroup(1, arcs, tags["start"])
        gmsh.model.addPhysicalGroup(1, far, tags["end"])
        gmsh.model.addPhysicalGroup(1, [side_a, side_b], tags["sides"])
        return tags

    return _gmsh_to_dolfinx(comm, build, order=order, cell=cell)


def _arc_cell_counts(span: float, n_cells: int) -> list[int]:
    """Cells per gmsh arc: the fewest arcs of at most pi/2 each, cells spread evenly."""
    n_arcs = max(1, math.ceil(span / (0.5 * math.pi) - 1e-12))
    if n_cells < n_arcs:
        raise ValueError(
            f"n_around must be >= {n_arcs} for a panel of opening {span:.4g} rad, got {n_cells}"
        )
    return [len(c) for c in np.array_split(np.arange(n_cells), n_arcs)]


def sphere_quarter(
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    radius: float,
    hole_angle: float,
    n: int,
    cell: str = "quadrilateral",
    order: int = 2,
) -> SurfaceMesh:
    """A quarter of a hemisphere (x, y, z >= 0) of centre 0 with a polar hole: colatitude in
    [``hole_angle``, pi/2] [rad], longitude in [0, pi/2]; ``n`` x ``n`` cells.

    Boundaries: ``hole`` (the polar edge), ``equator`` (z = 0), ``xz`` (the meridian in the
    plane y = 0) and ``yz`` (x = 0). Used by the hemisphere benchmark (MacNeal & Harder
    1985: an 18-degree hole).
    """
    radius = _positive("radius", radius)
    if not (0 < hole_angle < 0.5 * math.pi):
        raise ValueError(f"hole_angle must be in (0, pi/2) radians, got {hole_angle!r}")
    n = _positive_int("n", n)
    _check_cell(cell, order)
    s, c = math.sin(hole_angle), math.cos(hole_angle)

    def build(gmsh):
        geo = gmsh.model.geo
        centre, pole = geo.addPoint(0, 0, 0), geo.addPoint(0, 0, radius * c)
        a, b = geo.addPoint(radius, 0, 0), geo.addPoint(0, radius, 0)
        ha, hb = geo.addPoint(radius * s, 0, radius * c), geo.addPoint(0, radius * s, radius * c)
        equator = geo.addCircleArc(a, centre, b)
        yz = geo.addCircleArc(b, centre, hb)
        hole = geo.addCircleArc(hb, pole, ha)
        xz = geo.addCircleArc(ha, centre, a)
        loop = geo.addCurveLoop([equator, yz, hole, xz])
        surf = geo.addSurfaceFilling([loop], sphereCenterTag=centre)
        for curve in (equator, yz, hole, xz):
            geo.mesh.setTransfiniteCurve(curve, n + 1)
        geo.mesh.setTransfiniteSurface(surf)
        if cell == "quadrilateral":
            geo.mesh.setRecombine(2, surf)
        geo.synchronize()
        gmsh.model.addPhysicalGroup(2, [surf], 1)
        tags = {"hole": 1, "equator": 2, "xz": 3, "yz": 4}
        for name, curve in (("hole", hole), ("equator", equator), ("xz", xz), ("yz", yz)):
            gmsh.model.addPhysicalGroup(1, [curve], tags[name])
        return tags

    return _gmsh_to_dolfinx(comm, build, order=order, cell=cell)


def load_msh(path: str | Path, comm: MPI.Comm = MPI.COMM_WORLD) -> SurfaceMesh:
    """Load a gmsh ``.msh`` surface mesh in 3-D with physical groups.

    The surface cells must be in a 2-D physical group; named 1-D physical groups become
    boundary tags (unnamed ones are called ``"tag<N>"``). One-line errors: missing file,
    no 2-D physical group, a volume mesh or a mesh in the plane without 3-D coordinates.
    """
    import gmsh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"mesh file {str(path)!r} does not exist")
    names: dict[str, int] = {}
    error = ""
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.merge(str(path))  # gmshio.read_from_msh is broken in dolfinx 0.5.2
        groups = gmsh.model.getPhysicalGroups()
        dims = {d for d, _ in groups}
        if 3 in dims or gmsh.model.getDimension() == 3:
            error = f"mesh file {path.name!r} is a volume mesh; a fabric needs a surface mesh"
        elif 2 not in dims:
            error = f"mesh file {path.name!r} has no 2-D physical group (the fabric surface)"
        for dim, tag in groups:
            if dim == 1:
                names[gmsh.model.getPhysicalName(dim, tag) or f"tag{tag}"] = tag
    error = comm.bcast(error, root=0)
    names = comm.bcast(names, root=0)
    if error:
        if comm.rank == 0:
            gmsh.finalize()
        raise ValueError(error)
    try:
        mesh, facet_tags = _model_to_mesh(gmsh.model, comm)
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    if mesh.topology.dim != 2:
        raise ValueError(f"mesh file {path.name!r}: topological dimension must be 2")
    return SurfaceMesh(mesh=mesh, facet_tags=facet_tags, boundaries=names)
