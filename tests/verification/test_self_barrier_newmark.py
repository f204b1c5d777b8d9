"""Fabric self-contact in the Newmark integrator (the barrier of
:mod:`clothfem.contact.self_barrier` in :class:`clothfem.contact.dynamic.DynamicContact`):
two sheets pressed together by a uniform pressure, a strip falling onto a fixed sheet
under gravity, a sheet pulled over a sheet with friction, a tube squashed flat between
plates. Every configuration is checked by the independent intersection checker
(:mod:`clothfem.contact.intersections`); all assertions are on gathered or reduced values,
so the file runs unchanged under ``mpirun -n 2``."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.contact.dynamic import DynamicContact
from clothfem.contact.intersections import check_surface
from clothfem.contact.self_barrier import SelfBarrier, SelfBarrierParameters
from clothfem.mesh import load_msh
from clothfem.shell import FabricMaterial, ShellModel
from clothfem.shell.conditions import Clamp, Gravity, Pressure

COMM = MPI.COMM_WORLD
T = 1e-3  # thickness = activation distance d [m]
L = 0.04  # bottom sheet [m]
MAT = FabricMaterial(E1=1e5, E2=1e5, G12=2e4, rho=500.0)


def far_body(t):
    """A small sphere far from the fabric (DynamicContact needs a body)."""
    return [(np.full(3, 10.0), np.eye(3), np.full(3, 1e-3))], [(np.zeros(3), np.zeros(3))]


def _write_sheets(path, *, top, z0, n_bottom, n_top, shift, rise=0.0):
    """A square bottom sheet [0, L]^2 at z = 0 (edges: physical group "edges") and a top
    sheet ``top`` = (x0, x1, y0, y1) at z = z0 (z0 + ``rise`` along its edge x = x1),
    shifted in plane by ``shift``; normals +z."""
    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    geo = gmsh.model.geo

    def sheet(x0, x1, y0, y1, z, n, dz=0.0):
        xy = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
        p = [geo.addPoint(x, y, z + dz * (x == x1)) for x, y in xy]
        lines = [geo.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
        for ln in lines:
            geo.mesh.setTransfiniteCurve(ln, n + 1)
        s = geo.addPlaneSurface([geo.addCurveLoop(lines)])
        geo.mesh.setTransfiniteSurface(s, cornerTags=p)
        geo.mesh.setRecombine(2, s)
        return s, lines

    s0, edges = sheet(0.0, L, 0.0, L, 0.0, n_bottom)
    x0, x1, y0, y1 = top
    s1, _ = sheet(x0 + shift[0], x1 + shift[0], y0 + shift[1], y1 + shift[1], z0, n_top, rise)
    geo.synchronize()
    gmsh.model.addPhysicalGroup(2, [s0, s1], 1)
    gmsh.model.addPhysicalGroup(1, edges, 1)
    gmsh.model.setPhysicalName(1, 1, "edges")
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", 0)
    gmsh.model.mesh.generate(2)
    gmsh.model.mesh.setOrder(2)
    gmsh.write(str(path))
    gmsh.finalize()


def sheets(tmp, **kw):
    path = COMM.bcast(tmp / "sheets.msh" if COMM.rank == 0 else None)
    if COMM.rank == 0:
        _write_sheets(path, **kw)
    COMM.Barrier()
    return load_msh(path, COMM)


def recorded_run(dc, barrier, *, t_end, dt):
    """Run ``dc`` to ``t_end`` [s] in steps of ``dt`` [s]: all node positions and (step
    record, barrier record) at every accepted step."""
    frames, recs = [], []

    def on_step(r):
        frames.append(barrier.positions())
        recs.append((r, barrier.record()))

    dc.run(t_end=t_end, dt=dt, on_step=on_step)
    return frames, recs


PRESSURE = 200.0  # [Pa] on both sheets, towards -z (a negative Pressure value)
TOP = (0.005, 0.035, 0.005, 0.035)


def clamped_sheets(tmp, *, z0: float):
    """The two sheets ``z0`` [m] apart (the top one shifted), both clamped at their edges,
    unloaded: the model and its Newmark system."""
    sm = sheets(tmp, top=TOP, z0=z0, n_bottom=4, n_top=3, shift=(0.0013, 0.0007))
    model = ShellModel(sm, material=MAT, thickness=T, supports=[Clamp("edges")])
    return model, dy.ShellSystem(model)


@pytest.fixture(scope="module")
def pressed(tmp_path_factory):
    tmp = COMM.bcast(tmp_path_factory.mktemp("pressed") if COMM.rank == 0 else None)
    sm = sheets(tmp, top=TOP, z0=0.62 * T, n_bottom=4, n_top=3, shift=(0.0013, 0.0007))
    model = ShellModel(
        sm, material=MAT, thickness=T,
        loads=[Pressure(-PRESSURE, follower=False)], supports=[Clamp("edges")],
    )  # fmt: skip
    system = dy.ShellSystem(model, rotary_scale=100.0)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T))
    dc = DynamicContact(system, far_body, barrier=barrier, beta=0.49, gamma=0.9)
    frames, recs = recorded_run(dc, barrier, t_end=0.3, dt=0.05)
    return barrier, model, frames, recs


def test_pressed_sheets_force_balance(pressed):
    """At rest the fabric-fabric force on the top sheet (z-sum of the barrier gradient over
    its nodes) equals the pressure on its area, p (0.03 m)^2 = 0.18 N, within 0.1 %; the sheets
    are at rest (kinetic energy below 1e-9 J)."""
    barrier, model, frames, recs = pressed
    x = frames[-1]
    G = barrier.gradient(x)  # node-triangle and edge-edge pairs
    top = barrier.X[:, 2] > 0.5 * T
    on_top = -G[top, 2].sum()  # barrier force on the top sheet, +z [N]
    load = PRESSURE * (TOP[1] - TOP[0]) * (TOP[3] - TOP[2])
    print(f"contact force on top {on_top:.6g} N, load {load:.6g} N, pairs {recs[-1][1].pairs}")
    assert abs(on_top - load) <= 1e-3 * load
    assert recs[-1][0].kinetic_energy < 1e-9
    assert recs[-1][1].pairs > 0


def test_pressed_sheets_no_crossing(pressed):
    """Every step intersection-free by the independent checker, the layers at least 0.5 d
    apart, and the top sheet resting within d of the bottom one."""
    barrier, _, frames, recs = pressed
    for x in frames:
        chk = check_surface(x, barrier.surface.triangles, radius=4 * T)
        assert chk.intersections == 0
        assert chk.min_distance >= 0.5 * T
    dmin = recs[-1][1].min_distance
    print(f"min distance {dmin:.4g} m, checker {chk.min_distance:.4g} m")
    assert 0.5 * T <= dmin < T


def drop(tmp, with_barrier: bool):
    """The top sheet, tilted (3 mm to 5 mm above the clamped bottom one), falls under
    gravity for 60 ms: positions of every accepted step."""
    sm = sheets(tmp, top=TOP, z0=3 * T, n_bottom=4, n_top=3, shift=(0.0013, 0.0007), rise=2 * T)
    model = ShellModel(
        sm, material=MAT, thickness=T,
        loads=[Gravity((0.0, 0.0, -9.81))], supports=[Clamp("edges")],
    )  # fmt: skip
    system = dy.ShellSystem(model, rotary_scale=100.0)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T))
    dc = DynamicContact(
        system, far_body, barrier=barrier if with_barrier else None, beta=0.49, gamma=0.9
    )
    frames = []
    dc.run(t_end=0.06, dt=0.005, on_step=lambda r: frames.append(barrier.positions()))
    return barrier, frames


def test_sheet_dropped_onto_a_sheet(tmp_path_factory):
    """No intersection and layers at least 0.25 d apart at every step while the tilted
    sheet lands (corner first) and settles on the bottom one; the same fall without the
    barrier ends with the top sheet below the bottom one (it passed through)."""
    tmp = COMM.bcast(tmp_path_factory.mktemp("drop") if COMM.rank == 0 else None)
    barrier, frames = drop(tmp, True)
    tri = barrier.surface.triangles
    low = min(check_surface(x, tri, radius=4 * T).min_distance for x in frames)
    print(f"drop: {len(frames)} steps, smallest layer distance {low:.4g} m")
    for x in frames:
        assert check_surface(x, tri, radius=4 * T).intersections == 0
    assert 0.25 * T <= low < T  # the sheets did meet
    top = barrier.X[:, 2] > 0.5 * T
    assert frames[-1][top, 2].mean() > frames[-1][~top, 2].mean()
    _, free = drop(tmp, False)
    assert free[-1][top, 2].mean() < free[-1][~top, 2].mean()


def test_assembled_barrier_taylor(tmp_path_factory):
    """The barrier's PETSc residual and Jacobian as assembled for the Newton solve (owned
    rows, global columns; serial and 2 ranks) against its energy: along a random direction
    of the u rows |E(x + h v) - E - h f.v| and |f(x + h v) - f - h K v| fall as h^2 (orders
    > 1.8), with the layers 0.62 d apart."""
    tmp = COMM.bcast(tmp_path_factory.mktemp("taylor") if COMM.rank == 0 else None)
    model, system = clamped_sheets(tmp, z0=0.62 * T)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T))
    x = system.create_vector()
    system.get_state(x)
    n = model.n_owned
    v = x.duplicate()
    rng = np.random.default_rng(5 + COMM.rank)
    v.set(0.0)
    v.getArray()[: 3 * n] = rng.normal(size=3 * n) * 2e-5

    def grad(y):
        f = y.duplicate()
        f.set(0.0)
        barrier.add_residual(y, f)
        return f

    K = system.jacobian(x)
    H = barrier.jacobian(x, K).copy()
    H.axpy(-1.0, K, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    e0, f0 = barrier.energy(x), grad(x)
    assert barrier.record().pairs > 50
    Hv = x.duplicate()
    H.mult(v, Hv)
    e1, e2 = [], []
    for h in (0.5**k for k in range(5)):
        xh = x.copy()
        xh.axpy(h, v)
        e1.append(abs(barrier.energy(xh) - e0 - h * f0.dot(v)))
        e2.append((grad(xh) - f0 - h * Hv).norm())
    o1, o2 = np.log2(np.array(e1[:-1]) / e1[1:]), np.log2(np.array(e2[:-1]) / e2[1:])
    if COMM.rank == 0:
        print(f"assembled Taylor orders: energy {np.round(o1, 2)}, residual {np.round(o2, 2)}")
    assert np.all(o1 > 1.8) and np.all(o2 > 1.8)


STIFF = FabricMaterial(E1=1e9, E2=1e9, G12=4e8, rho=500.0)  # the bottom sheet barely sags
SLIDER = (0.004, 0.026, 0.005, 0.035)  # the top sheet, room to slide along +x
MU = 0.1


def pulled(tmp, g_x: float, mu: float):
    """The top sheet pressed onto the clamped bottom one by 200 Pa and pulled along +x by a
    body force rho t g_x per area, for 40 ms of 1 ms Newmark steps: the x-coordinate of the
    top sheet's centre of mass [m] at every step, the times, and the barrier."""
    sm = sheets(tmp, top=SLIDER, z0=0.62 * T, n_bottom=4, n_top=3, shift=(0.0013, 0.0007))
    model = ShellModel(
        sm, material=STIFF, thickness=T, supports=[Clamp("edges")],
        loads=[Pressure(-PRESSURE, follower=False), Gravity((g_x, 0.0, 0.0))],
    )  # fmt: skip
    system = dy.ShellSystem(model, rotary_scale=100.0)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T, mu=mu))
    dc = DynamicContact(system, far_body, barrier=barrier, beta=0.49, gamma=0.9)
    top = barrier.X[:, 2] > 0.5 * T
    xc, t, frames = [], [], []

    def on_step(r):
        x = barrier.positions()
        frames.append(x)
        xc.append(x[top, 0].mean())
        t.append(r.time)

    dc.run(t_end=0.04, dt=1e-3, on_step=on_step)
    return np.array(t), np.array(xc) - xc[0], barrier, frames


def test_sheet_sliding_over_a_sheet_coulomb(tmp_path_factory):
    """Pulled by 1.25 x the Coulomb limit, the top sheet slides against Coulomb's force
    mu p A (A its area, the normal force the pressure's): its mean acceleration over the last
    20 ms (quadratic fit of its centre's x; the first 20 ms let the layers' normal ringing
    decay) gives a friction force m (g_x - a) = mu p A within 1 %; every written step is
    intersection-free; the friction's work is positive."""
    tmp = COMM.bcast(tmp_path_factory.mktemp("slide") if COMM.rank == 0 else None)
    limit = MU * PRESSURE / (STIFF.rho * T)  # mu p A / m [m/s^2]
    t, xc, barrier, frames = pulled(tmp, 1.25 * limit, MU)
    a = 2.0 * np.polyfit(t[-20:], xc[-20:], 2)[0]
    friction = 1.25 * limit - a  # per unit mass
    if COMM.rank == 0:
        print(f"sliding: friction / (mu p A) = {friction / limit:.5f}, moved {xc[-1]:.4g} m")
    assert friction == pytest.approx(limit, rel=1e-2)
    for x in frames[::5] + frames[-1:]:
        assert check_surface(x, barrier.surface.triangles, radius=4 * T).intersections == 0
    assert barrier.friction_work > 0


def test_sheet_sticking_below_the_limit(tmp_path_factory):
    """Pulled by half the Coulomb limit the top sheet sticks: its centre creeps by less than
    the smoothing's slip speed x time (1e-3 m/s x 40 ms = 0.04 mm) where without friction it
    would move g_x t^2 / 2 = 16 mm."""
    tmp = COMM.bcast(tmp_path_factory.mktemp("stick") if COMM.rank == 0 else None)
    limit = MU * PRESSURE / (STIFF.rho * T)
    t, xc, barrier, _ = pulled(tmp, 0.5 * limit, MU)
    creep = np.max(np.abs(xc))
    if COMM.rank == 0:
        print(f"sticking: creep {creep:.3g} m, free {0.25 * limit * t[-1] ** 2:.3g} m")
    assert creep < barrier.params.slip_velocity * t[-1]


def test_jacobian_pattern_takes_pairs_beyond_the_near_list(tmp_path_factory):
    """A candidate list built with a wide skin (as the step filter builds one for a long
    step) gives the Jacobian only its near pairs' blocks; when the sheets then come within
    d by pairs that were farther at build, the Jacobian takes their blocks (on every rank
    together) and still passes the Taylor test of the residual (order > 1.8)."""
    from clothfem.contact.self_contact import build_candidates

    tmp = COMM.bcast(tmp_path_factory.mktemp("wide") if COMM.rank == 0 else None)
    model, system = clamped_sheets(tmp, z0=3.0 * T)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T))
    x0 = barrier.positions()
    barrier.candidates = build_candidates(x0, barrier.surface, distance=T, skin=6.0 * T)
    reach = T + barrier.params.skin_length
    assert np.all(barrier.candidates.pt_dist[barrier.X[barrier.candidates.pt_node, 2] > T] > reach)
    x = system.create_vector()
    system.get_state(x)
    n = model.n_owned
    top = (model.x_nodes[:n, 2] > 0.5 * T).astype(float)
    x.getArray()[2 : 3 * n : 3] = -2.4 * T * top  # the top sheet 0.6 d above the bottom
    assert barrier.candidates.valid(barrier.positions(x))  # no rebuild: the wide list holds
    K = system.jacobian(x)
    H = barrier.jacobian(x, K).copy()
    H.axpy(-1.0, K, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    def grad(y):
        f = y.duplicate()
        f.set(0.0)
        barrier.add_residual(y, f)
        return f

    f0 = grad(x)
    assert barrier.record().pairs > 50
    v = x.duplicate()
    v.set(0.0)
    v.getArray()[: 3 * n] = np.random.default_rng(3 + COMM.rank).normal(size=3 * n) * 2e-5
    Hv = x.duplicate()
    H.mult(v, Hv)
    e2 = []
    for h in (0.5**k for k in range(5)):
        xh = x.copy()
        xh.axpy(h, v)
        e2.append((grad(xh) - f0 - h * Hv).norm())
    o2 = np.log2(np.array(e2[:-1]) / e2[1:])
    assert np.all(o2 > 1.8), o2


def _same_list(a, b) -> bool:
    """Every array and number of two candidate lists (and of their tiles) equal."""
    from dataclasses import fields

    pairs = [(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.name != "tiles"]
    pairs += list(zip(a.tiles, b.tiles, strict=True))
    return all(np.array_equal(x, y) for x, y in pairs)


def test_barrier_state_restores_the_list_and_the_pattern(tmp_path_factory):
    """The barrier's checkpoint state: a list built with a wide skin whose Jacobian took the
    blocks of far pairs in use (as in the test above), restored into a new barrier of the
    same system, gives the same list (every array, rebuilt at the saved build positions
    and skin) and the same Jacobian (pattern and values, bit for bit) without another
    extension; a barrier that has built no list restores to none."""
    from clothfem.contact.self_contact import build_candidates

    tmp = COMM.bcast(tmp_path_factory.mktemp("state") if COMM.rank == 0 else None)
    model, system = clamped_sheets(tmp, z0=3.0 * T)
    params = SelfBarrierParameters(distance=T)
    barrier = SelfBarrier(system, params=params)
    empty = SelfBarrier(system, params=params)
    empty.restore_arrays(barrier.state_arrays())
    assert empty.candidates is None
    barrier.candidates = build_candidates(
        barrier.positions(), barrier.surface, distance=T, skin=6.0 * T
    )
    y = system.create_vector()
    system.get_state(y)
    x = y.copy()
    n = model.n_owned
    top = (model.x_nodes[:n, 2] > 0.5 * T).astype(float)
    x.getArray()[2 : 3 * n : 3] = -2.4 * T * top  # within d by pairs far at build
    K = system.jacobian(x)
    barrier.jacobian(x, K)
    data = barrier.state_arrays()
    assert len(data["need"]) > 0  # the pattern took pairs beyond the near ones
    restored = SelfBarrier(system, params=params)
    restored.restore_arrays({k: v.copy() for k, v in data.items()})
    assert restored.candidates is not barrier.candidates
    assert _same_list(restored.candidates, barrier.candidates)
    for z in (y, x):  # first at the build positions: no pair within d asks for the blocks
        a, b = (bar.jacobian(z, K).getValuesCSR() for bar in (barrier, restored))
        assert all(np.array_equal(u, v) for u, v in zip(a, b, strict=True))
    assert np.array_equal(restored.state_arrays()["need"], data["need"])


def test_tube_squashed_flat_between_plates():
    """A tube (R = 10 mm, 8 x 2 cells) squashed flat between two rigid plates (flat
    ellipsoids, Lagrange contact) closing smoothly to 0.6 d apart in 0.2 s: the barrier
    carries the walls' contact over the whole flat zone (>1000 pairs) without upsetting the
    body contact; the independent checker finds no intersection at any step and the walls
    end exactly at the plates' gap; the tube comes to rest."""
    R, length, half = 0.01, 0.02, 0.3 * T
    radii = np.array([0.2, 0.2, 0.02])
    sm = meshes.cylinder(COMM, radius=R, length=length, n_around=8, n_along=2)
    model = ShellModel(sm, material=MAT, thickness=T)
    system = dy.ShellSystem(model, rotary_scale=100.0)
    barrier = SelfBarrier(system, params=SelfBarrierParameters(distance=T))

    def plates(t):
        s = min(t / 0.2, 1.0)
        z = R + (half - R) * s * s * (3 - 2 * s)
        v = (half - R) * 6 * s * (1 - s) / 0.2
        c = np.array([length / 2, 0.0, 0.0])
        geo = [
            (c + [0, 0, z + radii[2]], np.eye(3), radii),
            (c - [0, 0, z + radii[2]], np.eye(3), radii),
        ]
        return geo, [(np.array([0, 0, v]), np.zeros(3)), (np.array([0, 0, -v]), np.zeros(3))]

    dc = DynamicContact(system, plates, barrier=barrier, beta=0.49, gamma=0.9)
    frames, recs = recorded_run(dc, barrier, t_end=0.3, dt=0.01)
    tri = barrier.surface.triangles
    checks = [check_surface(x, tri, radius=4 * T) for x in frames]
    low = min(c.min_distance for c in checks)
    if COMM.rank == 0:
        print(
            f"squash: {len(frames)} steps, pairs {recs[-1][1].pairs}, smallest distance {low:.6g} m"
        )
    assert all(c.intersections == 0 for c in checks)
    assert recs[-1][1].pairs > 1000
    assert low == pytest.approx(2 * half, rel=1e-6)
    assert recs[-1][0].kinetic_energy < 1e-10


def test_scene_keys_set_the_barrier(tmp_path_factory):
    """contact.self_distance, self_mu and self_pressure reach the barrier a Newmark scene
    builds (its stiffness kappa = pressure / (c d), c fixed by the barrier's shape); the
    defaults are the thickness, contact.mu and 1 kPa."""
    from pathlib import Path

    from clothfem import scene as scenes

    tmp = COMM.bcast(tmp_path_factory.mktemp("keys") if COMM.rank == 0 else None)
    _, system = clamped_sheets(tmp, z0=3.0 * T)
    arm = Path(__file__).parents[2] / "demos" / "scenes" / "arm_sleeve.toml"
    nm = ["solver.integrator='newmark'", "contact.self_contact=true"]
    default = SelfBarrier.from_scene(system, scenes.load(arm, nm).contact).params
    sets = ["contact.self_distance=2e-3", "contact.self_mu=0.3", "contact.self_pressure=4e3"]
    given = SelfBarrier.from_scene(system, scenes.load(arm, nm + sets).contact).params
    assert (default.distance, default.mu, default.pressure) == (T, 0.1, 1e3)
    assert (given.distance, given.mu, given.pressure) == (2e-3, 0.3, 4e3)
    assert given.kappa == pytest.approx(4.0 * default.kappa / 2.0, rel=1e-14)
