"""Pants mesh (clothfem.pants_mesh): shell model, area, boundary lengths, orientation,
edge lengths, the .msh file, the same mesh on any number of ranks."""

import math

import dolfinx
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from clothfem.mesh import cylinder, load_msh
from clothfem.pants_mesh import pants, pants_lattice, write_pants_msh
from clothfem.shell import FabricMaterial, ShellModel

COMM = MPI.COMM_WORLD
# default dimensions, a coarse mesh: 8 cells around each leg, 6 along, 3 rows in the rise
GEOM = dict(
    waist_radius=0.14, leg_radius=0.09, leg_length=0.75, crotch_depth=0.25, leg_spacing=0.22
)
COARSE = dict(GEOM, n_around=8, n_along=6)


@pytest.fixture(scope="module")
def coarse():
    return pants(COMM, **COARSE)


def _integral(mesh, integrand, measure):
    value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand * measure))
    return mesh.comm.allreduce(value, op=MPI.SUM)


def _area(sm):
    return _integral(sm.mesh, dolfinx.fem.Constant(sm.mesh, 1.0), ufl.dx(domain=sm.mesh))


def _counts(sm):
    m = sm.mesh
    return m.topology.index_map(2).size_global, m.geometry.index_map().size_global


def test_shell_model_builds(coarse):
    """Consistently oriented: the nodal directors (averaged cell normals) do not cancel."""
    material = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1e5, rho=436.0)
    model = ShellModel(coarse, material=material, thickness=1e-3, warp=(0.0, 0.0, 1.0))
    D = model.D.x.array.reshape(-1, 3)
    assert np.allclose(np.linalg.norm(D, axis=1), 1.0)


def test_boundaries_have_the_circle_lengths(coarse):
    """Waist 2 pi R_w, each hem 2 pi R_leg, to the error of quadratic arcs of cell angle h
    (relative error < h^4 / 100)."""
    assert coarse.boundaries == {"waist": 1, "left_hem": 2, "right_hem": 3}
    ds = ufl.Measure("ds", domain=coarse.mesh, subdomain_data=coarse.facet_tags)
    one = dolfinx.fem.Constant(coarse.mesh, 1.0)
    radii_cells = {"waist": (0.14, 12), "left_hem": (0.09, 8), "right_hem": (0.09, 8)}
    for name, tag in coarse.boundaries.items():
        radius, cells = radii_cells[name]
        assert _integral(coarse.mesh, one, ds(tag)) == pytest.approx(
            2 * math.pi * radius, rel=(2 * math.pi / cells) ** 4 / 100
        )
    X = coarse.mesh.geometry.x
    for name, side in (("left_hem", 1.0), ("right_hem", -1.0)):
        V = dolfinx.fem.FunctionSpace(coarse.mesh, ("Q", 2))
        dofs = dolfinx.fem.locate_dofs_topological(V, 1, coarse.facets(name))
        xs = V.tabulate_dof_coordinates()[dofs]
        assert np.allclose(np.hypot(xs[:, 0] - side * 0.11, xs[:, 1]), 0.09, rtol=1e-12)
        assert np.allclose(xs[:, 2], -1.0, atol=1e-12)
    assert X.shape[1] == 3


def test_area_against_the_tubes(coarse):
    """The legs below the crotch band are exact tubes: their area is 2 pi R L to the Q2
    error of the circle; the whole area (16 x 20 cells per leg) lies within 3 % of the
    analytic tubes' (two legs of the inseam length plus the rise times the mean of the hip
    and waist girths)."""
    m = coarse.mesh
    X = ufl.SpatialCoordinate(m)
    z_cut = -0.25 - 0.45
    x = m.geometry.x
    z_top = m.comm.allreduce(np.max(x[x[:, 2] <= z_cut + 1e-9, 2], initial=-np.inf), op=MPI.MAX)
    below = ufl.conditional(ufl.lt(X[2], z_top + 1e-9), 1.0, 0.0)
    legs = _integral(m, below, ufl.dx(domain=m, metadata={"quadrature_degree": 4}))
    exact = 2 * 2 * math.pi * 0.09 * (z_top + 1.0)
    assert legs == pytest.approx(exact, rel=(2 * math.pi / 8) ** 4 / 100)
    default = pants_lattice(**GEOM, n_around=16, n_along=20)
    a, b = default.hip_semi_axes
    hip_girth = math.pi * (3 * (a + b) - math.sqrt((3 * a + b) * (a + 3 * b)))  # Ramanujan
    tubes = 2 * 2 * math.pi * 0.09 * 0.75 + 0.25 * 0.5 * (hip_girth + 2 * math.pi * 0.14)
    assert default.area() == pytest.approx(tubes, rel=0.03)


def test_area_matches_the_lattice(coarse):
    """dolfinx's integral equals a Gauss rule on the generator's own 9-node cells (to the
    quadrature error of the two rules)."""
    assert _area(coarse) == pytest.approx(pants_lattice(**COARSE).area(), rel=1e-7)


def test_area_depends_little_on_resolution():
    """The crotch band is a fill on the mesh lattice, so its shape changes a little with the
    row counts: 12 x 15, 16 x 20, 16 x 40 and 32 x 40 cells per leg give areas within 1 %."""
    sizes = ((12, 15), (16, 20), (16, 40), (32, 40))
    areas = [pants_lattice(**GEOM, n_around=n, n_along=m).area() for n, m in sizes]
    assert max(areas) / min(areas) < 1.01


def test_normals_point_outwards(coarse):
    """The cell normal at every cell's centre points away from the leg's axis (below the
    crotch) or from the z axis (above it); on the exact tubes it is the radial direction."""
    m = coarse.mesh
    n_cells = m.topology.index_map(2).size_local
    centre = np.array([[0.5, 0.5]])
    normal = dolfinx.fem.Expression(ufl.CellNormal(m), centre)
    position = dolfinx.fem.Expression(ufl.SpatialCoordinate(m), centre)
    cells = np.arange(n_cells, dtype=np.int32)
    n, p = normal.eval(cells).reshape(-1, 3), position.eval(cells).reshape(-1, 3)
    axis = np.zeros_like(p)
    legs = p[:, 2] < -0.25
    axis[legs, 0] = np.sign(p[legs, 0]) * 0.11
    radial = p - axis
    radial[:, 2] = 0.0
    cos = np.einsum("ij,ij->i", n, radial) / np.linalg.norm(radial, axis=1)
    assert COMM.allreduce(np.min(cos, initial=1.0), op=MPI.MIN) > 0.2
    exact = p[:, 2] < -0.25 - 0.45
    assert np.all(cos[exact] > 1 - 1e-12)


@pytest.mark.parametrize("n_around, n_along, bound", [(8, 6, 0.3), (16, 20, 0.4), (32, 40, 0.35)])
def test_edge_lengths(n_around, n_along, bound):
    """No short edges at the crotch: the shortest edge is at least 0.6 of the shortest edge
    of the exact leg tubes (0.66, 0.75, 0.78 measured), and min/max over the whole mesh is
    above ``bound`` (the longest edges are along the crotch row next to the crotch
    points)."""
    lattice = pants_lattice(**GEOM, n_around=n_around, n_along=n_along)
    lengths = lattice.edge_lengths()
    tube = min(2 * 0.09 * math.sin(math.pi / n_around), 0.75 / n_along)
    assert lengths.min() > 0.6 * tube
    assert lengths.min() / lengths.max() > bound


def test_stable_step_as_on_a_leg_tube(coarse):
    """The explicit method's stable step (lumped mass) is that of a plain leg tube with the
    same cells: the crotch has no short edges."""
    from clothfem.dynamics import stable_time_step

    material = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1e5, rho=436.0)
    tube = cylinder(COMM, radius=0.09, length=0.75, n_around=8, n_along=6)
    steps = [
        stable_time_step(ShellModel(sm, material=material, thickness=1e-3, warp=warp)).dt_crit
        for sm, warp in ((coarse, (0.0, 0.0, 1.0)), (tube, (1.0, 0.0, 0.0)))
    ]
    assert steps[0] > 0.9 * steps[1]


def test_same_mesh_on_every_rank_count(coarse):
    """The mesh on all ranks of COMM_WORLD equals the one built on a single rank."""
    single = pants(MPI.COMM_SELF, **COARSE)
    assert _counts(coarse) == _counts(single) == (132, 555)
    assert _area(coarse) == pytest.approx(_area(single), rel=1e-12)


def test_msh_file_loads(tmp_path, coarse):
    path = COMM.bcast(str(tmp_path / "pants.msh") if COMM.rank == 0 else None, root=0)
    if COMM.rank == 0:
        write_pants_msh(path, **COARSE)
    COMM.barrier()
    sm = load_msh(path, COMM)
    assert sm.boundaries == {"waist": 1, "left_hem": 2, "right_hem": 3}
    assert sm.mesh.geometry.cmap.degree == 2
    assert _counts(sm) == _counts(coarse)
    assert _area(sm) == pytest.approx(_area(coarse), rel=1e-12)


def test_input_errors():
    with pytest.raises(ValueError, match="leg_spacing must be >= 2.2 leg_radius"):
        pants_lattice(leg_spacing=0.18)
    with pytest.raises(ValueError, match="n_around must be a multiple of 4"):
        pants_lattice(n_around=10)
    with pytest.raises(ValueError, match="hip_radius must exceed"):
        pants_lattice(hip_radius=0.1)
    with pytest.raises(ValueError, match="cell must be"):
        pants(COMM, cell="hex")
