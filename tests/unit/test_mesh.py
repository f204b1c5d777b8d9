"""Mesh generators and user .msh files."""

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from clothfem import mesh as meshes

COMM = MPI.COMM_WORLD


def _global_count(sm, name):
    return COMM.allreduce(len(sm.facets(name)), op=MPI.SUM)


def test_cylinder_is_on_the_circle_with_tags():
    sm = meshes.cylinder(COMM, radius=0.06, length=0.5, n_around=8, n_along=4)
    x = sm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), 0.06, rtol=1e-7)  # incl. mid-side nodes
    assert sm.mesh.geometry.cmap.degree == 2
    # each boundary edge is counted by every rank that holds it: at least n_around
    assert _global_count(sm, "shoulder") >= 8 and _global_count(sm, "cuff") >= 8


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_strip_cells(cell):
    sm = meshes.strip(COMM, length=2.0, width=1.0, nx=4, ny=2, cell=cell)
    n = COMM.allreduce(sm.mesh.topology.index_map(2).size_local, op=MPI.SUM)
    assert n == (8 if cell == "quadrilateral" else 16)


def test_generator_input_errors():
    with pytest.raises(ValueError, match="n_around must be a multiple of 4"):
        meshes.cylinder(COMM, radius=0.06, length=0.5, n_around=6, n_along=2)
    with pytest.raises(ValueError, match="radius must be a finite number > 0"):
        meshes.cylinder(COMM, radius=-1.0, length=0.5, n_around=8, n_along=2)
    with pytest.raises(ValueError, match="cell must be"):
        meshes.strip(COMM, length=1.0, width=1.0, nx=2, ny=2, cell="hex")


def _write_msh(path, volume=False):
    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    if volume:
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [1], 1)
        gmsh.model.mesh.generate(3)
    else:
        gmsh.model.occ.addDisk(0, 0, 0, 1.0, 1.0)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [1], 1)
        tag = gmsh.model.addPhysicalGroup(1, [1], 7)
        gmsh.model.setPhysicalName(1, tag, "hem")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.3)
        gmsh.model.mesh.generate(2)
    gmsh.write(str(path))
    gmsh.finalize()


def test_load_user_msh(tmp_path):
    path = COMM.bcast(tmp_path / "disk.msh" if COMM.rank == 0 else None, root=0)
    bad = COMM.bcast(tmp_path / "box.msh" if COMM.rank == 0 else None, root=0)
    if COMM.rank == 0:
        _write_msh(path)
        _write_msh(bad, volume=True)
    COMM.barrier()
    sm = meshes.load_msh(path, COMM)
    assert sm.boundaries == {"hem": 7}
    area = sm.comm.allreduce(float(np.sum(sm.mesh.topology.index_map(2).size_local)), op=MPI.SUM)
    assert area > 0
    assert math.isclose(
        COMM.allreduce(np.max(np.linalg.norm(sm.mesh.geometry.x, axis=1)), op=MPI.MAX),
        1.0,
        rel_tol=1e-6,
    )
    with pytest.raises(ValueError, match="volume mesh"):
        meshes.load_msh(bad, COMM)
    with pytest.raises(ValueError, match="does not exist"):
        meshes.load_msh(tmp_path / "nope.msh", COMM)


def test_rcm_partitioner_chain_graph():
    """A chain of 10 cells on one rank: 2 contiguous parts of 5, the two cells at the cut
    ghosted on the other part; ranks without cells return an empty list."""
    import dolfinx.cpp.graph as cgraph

    self_comm = MPI.COMM_SELF
    nbrs = [[1]] + [[i - 1, i + 1] for i in range(1, 9)] + [[8]]
    data = np.array([j for row in nbrs for j in row], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum([len(r) for r in nbrs])]).astype(np.int32)
    graph = cgraph.AdjacencyList_int64(data, offsets)
    dest = meshes.rcm_partitioner(self_comm, 2, graph, True)
    owner = [dest.links(c)[0] for c in range(10)]
    assert sorted(owner) == [0] * 5 + [1] * 5
    # contiguous along the chain, whichever end RCM starts from
    assert owner in ([0] * 5 + [1] * 5, [1] * 5 + [0] * 5)
    ghosts = {c: list(dest.links(c)[1:]) for c in range(10) if len(dest.links(c)) > 1}
    assert ghosts == {4: [owner[5]], 5: [owner[4]]}
    plain = meshes.rcm_partitioner(self_comm, 2, graph, False)
    assert all(len(plain.links(c)) == 1 for c in range(10))


def test_partition_repeats():
    """The same generated mesh twice: the same cells and nodes on each rank, bit for bit."""
    a = meshes.cylinder(COMM, radius=0.06, length=0.5, n_around=16, n_along=20).mesh
    b = meshes.cylinder(COMM, radius=0.06, length=0.5, n_around=16, n_along=20).mesh
    assert np.array_equal(a.geometry.x, b.geometry.x)
    assert np.array_equal(a.geometry.dofmap.array, b.geometry.dofmap.array)


@pytest.mark.parametrize(
    "angle, n_around", [(0.5 * math.pi, 8), (0.5 * math.pi, 7), (0.9 * math.pi, 9)]
)
def test_cylinder_panel_spans_the_asked_angle(angle, n_around):
    """A semi-cylinder (half-opening pi/2) and wider panels: every node (mid-side nodes
    too) on the circle of radius R, polar angles from -angle to +angle in equal cells,
    area 2 angle R L, outward normals, the straight ``sides`` at +-angle."""
    R, L = 2.0, 3.0
    sm = meshes.cylinder_panel(COMM, radius=R, length=L, angle=angle, n_around=n_around, n_along=3)
    x = sm.mesh.geometry.x
    assert np.allclose(np.hypot(x[:, 1], x[:, 2]), R, rtol=1e-12)
    phi = np.arctan2(x[:, 1], x[:, 2])  # from +z
    lo = COMM.allreduce(phi.min(), op=MPI.MIN)
    hi = COMM.allreduce(phi.max(), op=MPI.MAX)
    assert lo == pytest.approx(-angle, abs=1e-12) and hi == pytest.approx(angle, abs=1e-12)
    step = angle / n_around  # order 2: nodes every half cell
    assert np.allclose(np.round((phi + angle) / step), (phi + angle) / step, atol=1e-9)
    one = dolfinx.fem.form(dolfinx.fem.Constant(sm.mesh, 1.0) * ufl.dx(domain=sm.mesh))
    area = COMM.allreduce(dolfinx.fem.assemble_scalar(one), op=MPI.SUM)
    # the Q2 interpolation of an arc of cell angle h loses an area fraction < h^4 / 100
    tol = (2 * angle / n_around) ** 4 / 100
    assert area == pytest.approx(2 * angle * R * L, rel=tol)
    # every arc's cells oriented alike: the cell normal is the outward radial direction
    X, n = ufl.SpatialCoordinate(sm.mesh), ufl.CellNormal(sm.mesh)
    outward = dolfinx.fem.form((n[1] * X[1] + n[2] * X[2]) / R * ufl.dx(domain=sm.mesh))
    flux = COMM.allreduce(dolfinx.fem.assemble_scalar(outward), op=MPI.SUM)
    assert flux == pytest.approx(area, rel=tol)  # a flipped arc: -2 x its area
    V = dolfinx.fem.FunctionSpace(sm.mesh, ("Q", 2))
    xs = V.tabulate_dof_coordinates()[dolfinx.fem.locate_dofs_topological(V, 1, sm.facets("sides"))]
    assert np.allclose(np.abs(np.arctan2(xs[:, 1], xs[:, 2])), angle, atol=1e-12)
    assert _global_count(sm, "sides") >= 6


def test_cylinder_panel_angle_errors():
    with pytest.raises(ValueError, match=r"angle must be in \(0, pi\) radians \(half-opening\)"):
        meshes.cylinder_panel(COMM, radius=1.0, length=1.0, angle=math.pi, n_around=8, n_along=2)
    with pytest.raises(ValueError, match="n_around must be >= 3 for a panel of opening 4 rad"):
        meshes.cylinder_panel(COMM, radius=1.0, length=1.0, angle=2.0, n_around=1, n_along=2)
