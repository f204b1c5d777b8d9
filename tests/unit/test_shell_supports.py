"""Supports and point selection of the shell model, and the load stepper's increment control:
two Symmetry planes at one node, PointForce / displacement_at on a named boundary (a slit),
PointPin against rigid-body modes, increments that follow Newton's convergence."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem import verification as V
from clothfem.shell import (
    Clamp,
    EdgeTraction,
    FabricMaterial,
    PointForce,
    PointPin,
    Pressure,
    Quadrature,
    ShellModel,
    Symmetry,
)
from clothfem.static import LoadStepping, NewtonSolver, solve_static

COMM = MPI.COMM_WORLD


def _solve(model, lam=1.0):
    ok, *_ = NewtonSolver(model).solve(lam)
    assert ok
    return model


def _theta_rows_at(model, point):
    """How many of the two rotations of the node nearest to ``point`` are constrained."""
    rows, _ = model.bc_rows_and_values(0.0)
    i, _ = model._nearest_node(point, on=None)
    mine = 0
    if i >= 0:
        mine = len(set(rows.tolist()) & {3 * model.n_owned + 2 * i, 3 * model.n_owned + 2 * i + 1})
    return COMM.allreduce(mine, op=MPI.SUM)


# ---------------------------------------------------------------- two symmetry planes
# Clamped square plate a x a under uniform pressure q, t/a = 1/100, nu = 0.3. Kirchhoff
# centre deflection 0.00126532 q a^4 / D (Timoshenko & Woinowsky-Krieger, Table 35); the
# Reissner-Mindlin correction at t/a = 1/100 is ~ +0.2 %.
PLATE = dict(a=1.0, t=0.01, E=1.0e7, nu=0.3, q=1.0e-2)


def _plate_material():
    return FabricMaterial.isotropic(E=PLATE["E"], nu=PLATE["nu"])


def _full_plate(n):
    a = PLATE["a"]
    sm = meshes.strip(COMM, length=a, width=a, nx=2 * n, ny=2 * n)
    model = ShellModel(
        sm,
        material=_plate_material(),
        thickness=PLATE["t"],
        loads=[Pressure(PLATE["q"], follower=False)],
        supports=[Clamp("root"), Clamp("tip"), Clamp("sides")],
    )
    return _solve(model).displacement_at((a / 2, 0.0, 0.0))[2]


def _quarter_plate(n, order):
    """x in [0, a/2], y in [-a/4, a/4]: clamped at x = 0 and y = -a/4, symmetry planes
    x = a/2 (normal x) and y = a/4 (normal y) meeting at the plate centre (a/2, a/4)."""
    a = PLATE["a"]
    sm = meshes.strip(COMM, length=a / 2, width=a / 2, nx=n, ny=n)
    sym = [Symmetry("tip", axis=0), Symmetry(lambda x: np.abs(x[1] - a / 4) < 1e-9, axis=1)]
    model = ShellModel(
        sm,
        material=_plate_material(),
        thickness=PLATE["t"],
        loads=[Pressure(PLATE["q"], follower=False)],
        supports=[Clamp("root"), Clamp(lambda x: np.abs(x[1] + a / 4) < 1e-9), *sym[::order]],
    )
    return _solve(model)


def test_two_symmetry_planes_fix_both_rotations_in_either_order():
    """The quarter plate's centre node (on both symmetry planes) has both rotations fixed and
    its edge nodes on one plane one rotation, whatever the order of the two supports; the
    quarter model then reproduces the full model on the same cells exactly, and the
    Kirchhoff deflection."""
    a, n = PLATE["a"], 4
    centre = (a / 2, a / 4, 0.0)
    w = []
    for order in (1, -1):
        model = _quarter_plate(n, order)
        assert _theta_rows_at(model, centre) == 2
        assert _theta_rows_at(model, (a / 2, 0.0, 0.0)) == 1  # on the plane x = a/2 only
        assert _theta_rows_at(model, (a / 4, a / 4, 0.0)) == 1  # on the plane y = a/4 only
        w.append(model.displacement_at(centre)[2])
    assert w[0] == pytest.approx(w[1], rel=1e-12)
    w_full = _full_plate(n)
    assert w[0] == pytest.approx(w_full, rel=1e-8)
    D = PLATE["E"] * PLATE["t"] ** 3 / (12 * (1 - PLATE["nu"] ** 2))
    assert w[0] == pytest.approx(0.00126532 * PLATE["q"] * a**4 / D, rel=1e-2)


# ---------------------------------------------------------------- a slit
SLIT = dict(L=2.0, c=0.2, s=0.5, t=0.02, E=1.0e7)  # length, half-width, slit start, thickness


def _write_slit_msh(path):
    """Strip [0, L] x [-c, c] cut along y = 0 from x = s to x = L: the lips ``lip_lower``
    and ``lip_upper`` have coincident but distinct nodes; ``root`` x = 0, ``tip`` x = L."""
    import gmsh

    L, c, s = SLIT["L"], SLIT["c"], SLIT["s"]
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    geo = gmsh.model.geo
    xy = [(0, -c), (s, -c), (L, -c), (L, 0), (s, 0), (L, 0), (L, c), (s, c), (0, c), (0, 0)]
    p = [geo.addPoint(x, y, 0.0) for x, y in xy]  # p[3] and p[5] coincide: the slit's end
    lines = {}

    def line(i, j, n):
        if (j, i) in lines:
            return -lines[(j, i)]
        lines[(i, j)] = geo.addLine(p[i], p[j])
        geo.mesh.setTransfiniteCurve(lines[(i, j)], n + 1)
        return lines[(i, j)]

    def quad(a, b, c_, d, nx):  # counter-clockwise: normals +z
        loop = [line(a, b, nx), line(b, c_, 1), line(c_, d, nx), line(d, a, 1)]
        surf = geo.addPlaneSurface([geo.addCurveLoop(loop)])
        geo.mesh.setTransfiniteSurface(surf)
        geo.mesh.setRecombine(2, surf)
        return surf

    surfaces = [quad(0, 1, 4, 9, 2), quad(1, 2, 3, 4, 6), quad(9, 4, 7, 8, 2), quad(4, 5, 6, 7, 6)]
    geo.synchronize()
    gmsh.model.addPhysicalGroup(2, surfaces, 1)
    groups = {
        "root": [(9, 0), (8, 9)],
        "tip": [(2, 3), (5, 6)],
        "lip_lower": [(3, 4)],
        "lip_upper": [(4, 5)],
    }
    for tag, (name, ends) in enumerate(groups.items(), start=1):
        gmsh.model.addPhysicalGroup(1, [lines[e] for e in ends], tag)
        gmsh.model.setPhysicalName(1, tag, name)
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
    gmsh.model.mesh.generate(2)
    gmsh.model.mesh.setOrder(2)
    gmsh.write(str(path))
    gmsh.finalize()


@pytest.fixture(scope="module")
def slit(tmp_path_factory):
    path = COMM.bcast(tmp_path_factory.mktemp("slit") / "slit.msh" if COMM.rank == 0 else None)
    if COMM.rank == 0:
        _write_slit_msh(path)
    COMM.barrier()
    return meshes.load_msh(path, COMM)


def _slit_model(sm, lip_of_upper_force):
    """Clamped root; the tip shear P as the consistent nodal forces of a uniform edge load
    on each finger's 3-node tip edge (P/2 x (1/6, 2/3, 1/6)); the two forces at the slit's
    end go to the lips named ``lip_lower`` and ``lip_of_upper_force``."""
    L, c = SLIT["L"], SLIT["c"]
    P = _slit_load()
    f = [P / 12, P / 3, P / 12]
    forces = [PointForce((L, -c + k * c / 2, 0.0), (0.0, 0.0, f[k])) for k in (0, 1)]
    forces += [PointForce((L, c - k * c / 2, 0.0), (0.0, 0.0, f[k])) for k in (0, 1)]
    forces += [
        PointForce((L, 0.0, 0.0), (0.0, 0.0, P / 12), on="lip_lower"),
        PointForce((L, 0.0, 0.0), (0.0, 0.0, P / 12), on=lip_of_upper_force),
    ]
    mat = FabricMaterial.isotropic(E=SLIT["E"], nu=0.0)
    return ShellModel(sm, material=mat, thickness=SLIT["t"], loads=forces, supports=[Clamp("root")])


def _slit_load():
    """Tip shear [N] giving a deflection of ~1e-4 L (linear range)."""
    return 1e-4 * SLIT["L"] * 3 * _slit_EI() / SLIT["L"] ** 3


def _slit_EI():
    return SLIT["E"] * 2 * SLIT["c"] * SLIT["t"] ** 3 / 12


def test_point_forces_and_displacements_on_the_lips_of_a_slit(slit):
    """With nu = 0 a uniform tip shear bends the cantilever cylindrically with no stress
    across y = 0, so a slit there changes nothing: each lip, and the whole tip, deflects as
    the Timoshenko beam P L^3 / (3 EI) + P L / (k G A). Loading the same lip twice gives
    the lips different deflections, which ``displacement_at(on=...)`` tells apart."""
    L, c, t = SLIT["L"], SLIT["c"], SLIT["t"]
    model = _solve(_slit_model(slit, "lip_upper"))
    P = _slit_load()
    w_beam = P * L**3 / (3 * _slit_EI()) + P * L / (5 / 6 * SLIT["E"] / 2 * 2 * c * t)
    w_low = model.displacement_at((L, 0.0, 0.0), on="lip_lower")[2]
    w_up = model.displacement_at((L, 0.0, 0.0), on="lip_upper")[2]
    assert w_low == pytest.approx(w_beam, rel=1e-3)
    assert w_up == pytest.approx(w_low, rel=1e-9)
    assert model.displacement_at((L, c, 0.0))[2] == pytest.approx(w_beam, rel=1e-3)
    both_low = _solve(_slit_model(slit, "lip_lower"))
    w_low = both_low.displacement_at((L, 0.0, 0.0), on="lip_lower")[2]
    w_up = both_low.displacement_at((L, 0.0, 0.0), on="lip_upper")[2]
    assert w_low > 1.1 * w_up  # measured 1.17: the lower finger carries P/12 more


def test_unknown_boundary_names_are_one_line_errors(slit):
    mat = FabricMaterial.isotropic(E=1e6, nu=0.0)
    bad = PointForce((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), on="lip")
    with pytest.raises(ValueError, match="unknown boundary tag 'lip'; this mesh has: lip_lower"):
        ShellModel(slit, material=mat, thickness=0.01, loads=[bad])
    with pytest.raises(ValueError, match="unknown boundary tag 'cuff'"):
        ShellModel(
            slit, material=mat, thickness=0.01, supports=[PointPin(point=(0, 0, 0), on="cuff")]
        )
    model = ShellModel(slit, material=mat, thickness=0.01, supports=[Clamp("root")])
    with pytest.raises(ValueError, match="unknown boundary tag 'lips'"):
        model.displacement_at((0.0, 0.0, 0.0), on="lips")
    with pytest.raises(ValueError, match="PointPin components must be distinct among 0, 1, 2"):
        PointPin(point=(0.0, 0.0, 0.0), components=(2, 2))
    with pytest.raises(ValueError, match="PointForce on must be a boundary name or None"):
        PointForce((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), on=3)


# ---------------------------------------------------------------- point pins
BAR = dict(L=1.0, b=0.2, t=0.01, E=1.0e7, nu=0.3, strain=1e-3)


def _half_bar(pins):
    """The half x in [0, L] of a free bar [0, 2L] pulled by equal and opposite end
    tractions: symmetry plane x = L, traction on x = 0; nothing else holds it. Full
    quadrature everywhere, so that the only zero-energy modes are the rigid ones."""
    L, b, t, E = BAR["L"], BAR["b"], BAR["t"], BAR["E"]
    sm = meshes.strip(COMM, length=L, width=b, nx=4, ny=2)
    traction = (-BAR["strain"] * E * t, 0.0, 0.0)  # [N/m]: nominal stress strain x E
    return ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=BAR["nu"]),
        thickness=t,
        loads=[EdgeTraction("root", traction)],
        supports=[Symmetry("tip", axis=0), *pins],
        quadrature=Quadrature(full=4, reduced=4),
    )


PINS = [
    PointPin(point=(BAR["L"], 0.0, 0.0), components=(1, 2)),
    PointPin(point=(BAR["L"], BAR["b"] / 2, 0.0), components=(2,)),
]


@pytest.mark.serial  # dense eigenvalues of the whole matrix, gathered on one rank
def test_point_pins_remove_the_rigid_modes_of_a_symmetric_model():
    """The half bar has 3 rigid modes (translations y, z, rotation about x) and 3 pinned
    components remove them: zero eigenvalues of the constrained stiffness 3 -> 0."""
    counts = []
    for pins in ([], PINS):
        model = _half_bar(pins)
        K = model.jacobian(model.create_vector()).convert("dense").getDenseArray()
        rows, _ = model.bc_rows_and_values(0.0)
        free = np.setdiff1d(np.arange(K.shape[0]), rows)
        w = np.linalg.eigvalsh(0.5 * (K + K.T)[np.ix_(free, free)])
        counts.append(int(np.sum(np.abs(w) < 1e-10 * w.max())))
    assert counts == [3, 0]


def test_point_pins_give_the_uniaxial_stretch():
    """Dead nominal stress s = E e0 on x = 0: the St Venant-Kirchhoff bar stretches
    uniformly, lam E (lam^2 - 1)/2 = s (S11 = E E11), and contracts laterally with
    E22 = -nu E11 (S22 = 0), which a pin at one point leaves free; the pins' reactions
    are zero, so the answer is that of the free bar."""
    L, b, nu = BAR["L"], BAR["b"], BAR["nu"]
    model = _solve(_half_bar(PINS))
    lam = np.roots([0.5, 0.0, -0.5, -BAR["strain"]])
    lam = float(lam[np.isreal(lam)].real.max())
    E11 = 0.5 * (lam**2 - 1)
    lam2 = math.sqrt(1 - 2 * nu * E11)
    corner = model.displacement_at((0.0, b / 2, 0.0))
    assert corner == pytest.approx([-(lam - 1) * L, (lam2 - 1) * b / 2, 0.0], rel=1e-8, abs=1e-14)
    mid = model.displacement_at((L / 2, -b / 4, 0.0))
    assert mid == pytest.approx([-(lam - 1) * L / 2, (1 - lam2) * b / 4, 0.0], rel=1e-8, abs=1e-14)


# ---------------------------------------------------------------- load stepping
def test_increment_follows_the_newton_iterations():
    st = LoadStepping(initial_increment=0.1, max_increment=0.5, target_iterations=12, grow=2.0)
    assert st.next_increment(0.1, 6, 0) == pytest.approx(0.2)  # 12/6
    assert st.next_increment(0.1, 3, 0) == pytest.approx(0.2)  # capped at grow
    assert st.next_increment(0.1, 8, 0) == pytest.approx(0.15)
    assert st.next_increment(0.1, 16, 0) == pytest.approx(0.075)
    assert st.next_increment(0.1, 25, 0) == pytest.approx(0.05)  # at least 1/2
    assert st.next_increment(0.1, 6, 1) == pytest.approx(0.1)  # no growth after a cut-back
    assert st.next_increment(0.4, 6, 0) == pytest.approx(0.5)  # max_increment
    with pytest.raises(ValueError, match="target_iterations must be an integer >= 1"):
        LoadStepping(target_iterations=0)


def test_elastica_in_fewer_load_steps_at_the_same_answer():
    """Cantilever under a dead end shear PL^2/EI = 4 (20x2 mesh): at the default settings
    each step takes 7-10 Newton iterations, so the increment grows from 0.1 (a constant
    0.1 needs 10 steps); the tip is the same equilibrium and the exact elastica."""
    L, b = V.STRIP["length"], V.STRIP["width"]
    P = 4 * V._EI() / L**2
    tips, steps = [], []
    for stepping in (LoadStepping(), LoadStepping(initial_increment=0.1, max_increment=0.1)):
        model = V._strip_model(COMM, 20, 2, [EdgeTraction("tip", (0.0, 0.0, P / b))])
        recs = solve_static(model, stepping=stepping)
        steps.append(len(recs))
        assert sum(r.cutbacks for r in recs) == 0
        tips.append(model.displacement_at((L, 0.0, 0.0)))
    assert steps[1] == 10 and steps[0] <= 6
    assert tips[0] == pytest.approx(tips[1], rel=1e-7)
    u_ex, w_ex = V.elastica_tip(4.0)
    assert -tips[0][0] / L == pytest.approx(u_ex, rel=2e-4)
    assert tips[0][2] / L == pytest.approx(w_ex, rel=2e-4)
