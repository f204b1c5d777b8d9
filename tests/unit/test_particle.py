"""Particle (mass-spring) fabric: network, stiffness rule, forces, steps (clothfem.particle).

Everything here is NumPy on every rank (the network is held redundantly), so the tests run
unchanged on 2 MPI ranks; the mesh-based ones are collective.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import particle as pm
from clothfem.particle.network import regular_patch
from clothfem.shell import FabricMaterial

T = 1e-3  # thickness [m]
MAT = FabricMaterial(E1=1.2e6, E2=0.8e6, G12=1.0e5, rho=436.0)


def oscillator(k=50.0, m=0.02, length=0.1):
    """Node 0 fixed, node 1 of mass m on a spring of stiffness k (no gravity)."""
    net = pm.SpringNetwork(
        x0=np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0]]),
        grid=np.zeros((0, 3, 3), dtype=np.int64),
        pairs=np.array([[0, 1]]),
        kind=np.array([pm.STRUCTURAL]),
        middle=np.array([-1]),
        rest=np.array([length]),
    )
    fab = pm.ParticleFabric(
        stiffness=np.array([k]), rigidity=np.zeros(1), buckling=np.zeros(1, bool),
        tension=np.ones(1, bool), mass=np.array([m, m]), area=np.ones(2), thickness=T,
        rule=pm.SpringRule(),
    )  # fmt: skip
    return pm.ParticleModel(network=net, fabric=fab, gravity=(0, 0, 0), fixed=np.array([0]))


def patch_model(nx=4, ny=2, length=0.2, width=0.1, rule=None, **kw):
    net = regular_patch(length=length, width=width, nx=nx, ny=ny)
    fab = pm.fabric_from_material(net, material=MAT, thickness=T, rule=rule or pm.SpringRule())
    return pm.ParticleModel(network=net, fabric=fab, **kw)


def test_spring_counts_of_a_regular_grid():
    """Provot's grid: structural to neighbours, two diagonals per square, flexion to every
    second node along the grid lines (also across the cell edges)."""
    nx, ny = 3, 2
    net = regular_patch(length=0.3, width=0.2, nx=nx, ny=ny)
    px, py = 2 * nx + 1, 2 * ny + 1
    assert net.n_nodes == px * py
    assert net.count("structural") == (px - 1) * py + px * (py - 1)
    assert net.count("shear") == 2 * (px - 1) * (py - 1)
    assert net.count("flexion") == (px - 2) * py + px * (py - 2)
    flex = net.kind == pm.FLEXION
    mid = 0.5 * (net.x0[net.pairs[flex, 0]] + net.x0[net.pairs[flex, 1]])
    assert np.allclose(mid, net.x0[net.middle[flex]])  # the middle node lies between
    assert np.all(net.pairs[:, 0] < net.pairs[:, 1])
    assert len(np.unique(net.pairs, axis=0)) == net.n_springs


def test_lumped_masses_are_rho_t_area():
    model = patch_model()
    assert model.mass.sum() == pytest.approx(MAT.rho * T * 0.2 * 0.1, rel=1e-12)
    corner = np.argmin(np.linalg.norm(model.network.x0, axis=1))
    assert model.mass[corner] == pytest.approx(MAT.rho * T * 0.025 * 0.025 / 4, rel=1e-12)


def _cut_force(model, x, axis, cut):
    """Force [N] the springs exert on the nodes beyond the plane x[axis] = cut."""
    beyond = model.network.x0[:, axis] > cut + 1e-12
    return pm.internal_forces(model, x)[beyond, axis].sum()


@pytest.mark.parametrize("axis, modulus, width", [(0, MAT.E1, 0.1), (1, MAT.E2, 0.2)])
def test_uniform_stretch_gives_the_membrane_stiffness(axis, modulus, width):
    """Affine stretch (the other direction held): membrane force E t per unit width, linear
    limit (nu12 = 0), and the rule's exact finite-stretch value spring by spring."""
    model = patch_model()
    net, fab = model.network, model.fabric
    cut = 0.5 * net.x0[:, axis].max() + 0.0125  # between two node columns
    eps = 1e-7
    x = net.x0.copy()
    x[:, axis] *= 1 + eps
    assert -_cut_force(model, x, axis, cut) / (width * eps) == pytest.approx(modulus * T, rel=1e-6)
    eps = 0.05  # nonlinear: sum over the springs crossing the cut of k (L - L0) n_axis
    x = net.x0.copy()
    x[:, axis] *= 1 + eps
    d = x[net.pairs[:, 1]] - x[net.pairs[:, 0]]
    L = np.linalg.norm(d, axis=1)
    a, b = net.x0[net.pairs[:, 0], axis], net.x0[net.pairs[:, 1], axis]
    cross = (np.minimum(a, b) < cut) & (np.maximum(a, b) > cut)
    exact = np.sum((fab.stiffness * (L - net.rest) * np.abs(d[:, axis]) / L)[cross])
    assert -_cut_force(model, x, axis, cut) == pytest.approx(exact, rel=1e-12)
    assert exact / (width * eps) == pytest.approx(modulus * T, rel=0.05)


def test_uniform_shear_gives_g12_t():
    model = patch_model()
    gamma = 1e-7
    x = model.network.x0.copy()
    x[:, 0] += gamma * x[:, 1]
    force = -_cut_force(model, x, 1, 0.05)  # y-face resultant, along x below
    top = model.network.x0[:, 1] > 0.05 + 1e-12
    fx = -pm.internal_forces(model, x)[top, 0].sum()
    assert fx / (0.2 * gamma) == pytest.approx(MAT.G12 * T, rel=1e-6)
    assert abs(force) < 1e-9 * MAT.E1 * T * 0.2 * gamma * 1e3


@pytest.mark.parametrize("bending", ["provot", "choi-ko"])
def test_rigid_motion_gives_no_spring_force(bending):
    model = patch_model(rule=pm.SpringRule(bending=bending), gravity=(0, 0, 0))
    a, b, c = 0.7, -1.1, 2.3
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    ry = np.array([[math.cos(c), 0, math.sin(c)], [0, 1, 0], [-math.sin(c), 0, math.cos(c)]])
    x = model.network.x0 @ (rz @ rx @ ry).T + np.array([0.3, -2.0, 5.0])
    f = pm.internal_forces(model, x)
    scale = model.fabric.stiffness.max() * 1e-15 * 10
    assert np.abs(f).max() < scale
    state = pm.ParticleState(t=0.0, x=x, v=np.zeros_like(x), a=np.zeros_like(x))
    assert pm.energies(model, state).spring < 1e-15  # round-off (k L0^2 ~ 1 J)


@pytest.mark.parametrize("bending", ["provot", "choi-ko"])
def test_tangent_is_the_derivative_of_the_forces(bending):
    model = patch_model(nx=2, ny=1, rule=pm.SpringRule(bending=bending))
    rng = np.random.default_rng(1)
    x = model.network.x0 + 0.004 * rng.standard_normal(model.network.x0.shape)
    K, _ = pm.tangent(model, x, np.zeros_like(x))
    f0 = pm.internal_forces(model, x).ravel()
    h = 1e-7
    cols = rng.choice(x.size, 8, replace=False)
    for c in cols:
        xp = x.copy().ravel()
        xp[c] += h
        fd = (pm.internal_forces(model, xp.reshape(-1, 3)).ravel() - f0) / h
        assert np.abs(K[:, [c]].toarray().ravel() - fd).max() < 1e-5 * np.abs(K).max()


@pytest.mark.parametrize("bending", ["provot", "choi-ko"])
def test_forces_are_minus_the_energy_gradient(bending):
    """Energy bookkeeping: F = -dE/dx (also on Choi & Ko's buckled branch)."""
    model = patch_model(nx=2, ny=1, rule=pm.SpringRule(bending=bending))
    rng = np.random.default_rng(2)
    x = model.network.x0 * 0.97 + 0.002 * rng.standard_normal(model.network.x0.shape)
    z = np.zeros_like(x)
    f = pm.internal_forces(model, x)
    h = 1e-8
    for i in rng.choice(model.network.n_nodes, 5, replace=False):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, c] += h
            xm[i, c] -= h
            ep = pm.energies(model, pm.ParticleState(t=0, x=xp, v=z, a=z)).spring
            em = pm.energies(model, pm.ParticleState(t=0, x=xm, v=z, a=z)).spring
            assert -(ep - em) / (2 * h) == pytest.approx(f[i, c], abs=1e-4 * np.abs(f).max())


def test_buckled_column_of_choi_and_ko():
    """f_b -> 12 B / L0^2 at the onset (circular arc), 4 pi^2 B / L0^2 as the ends meet,
    increasing with the compression."""
    B, L0 = 2e-5, 0.02
    s = np.array([1.0 - 1e-9, 0.9, 0.5, 0.1, 1e-4])
    fb, dfb = pm.buckled_force(s * L0, np.full(5, L0), np.full(5, B))
    assert fb[0] == pytest.approx(12 * B / L0**2, rel=1e-6)
    assert fb[-1] == pytest.approx(4 * math.pi**2 * B / L0**2, rel=1e-3)
    assert np.all(np.diff(fb) > 0) and np.all(dfb < 0)
    x = 1.2  # |x| = L0 sinc(x) for the arc: f = B (2x/L0)^2 / (sinc x - cos x)
    sx = math.sin(x) / x
    f, _ = pm.buckled_force(np.array([sx * L0]), np.array([L0]), np.array([B]))
    assert f[0] == pytest.approx(B * (2 * x / L0) ** 2 / (sx - math.cos(x)), rel=1e-6)


def test_oscillator_period_and_bounded_energy_error():
    """One mass on one spring: period 2 pi sqrt(m/k); velocity Verlet keeps the energy error
    bounded (no drift) and O(dt^2)."""
    k, m = 50.0, 0.02
    period = 2 * math.pi * math.sqrt(m / k)
    errors = []
    for n_per in (100, 200):
        model = oscillator(k, m)
        s0 = pm.ParticleState.at_rest(model)
        x = s0.x.copy()
        x[1, 0] += 0.01
        state = pm.ParticleState(t=0.0, x=x, v=s0.v, a=pm.accelerations(model, x, s0.v))
        e0 = pm.energies(model, state).total
        dt = period / n_per
        xs, es = [], []
        for _ in range(5 * n_per):
            state, _ = pm.step_explicit(model, state, dt)
            xs.append(state.x[1, 0] - 0.1)
            es.append(pm.energies(model, state).total)
        xs = np.array(xs)
        up = np.flatnonzero((xs[:-1] < 0) & (xs[1:] >= 0))
        frac = -xs[up] / (xs[up + 1] - xs[up])  # zero crossings, linear interpolation
        measured = np.mean(np.diff((up + 1 + frac) * dt))
        omega_h = 2 / dt * math.asin(math.sqrt(k / m) * dt / 2)  # the scheme's own frequency
        assert measured == pytest.approx(2 * math.pi / omega_h, rel=1e-4)
        assert measured == pytest.approx(period, rel=2e-3)
        err = np.abs(np.array(es) - e0) / e0
        assert err[-n_per:].max() <= 1.05 * err[:n_per].max()  # bounded: no drift
        errors.append(err.max())
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


def test_backward_euler_damps_the_oscillator_as_predicted():
    """Implicit step: energy ratio per step 1 / (1 + (omega dt)^2) on a linear oscillator."""
    k, m = 50.0, 0.02
    model = oscillator(k, m)
    s0 = pm.ParticleState.at_rest(model)
    v = s0.v.copy()
    v[1, 0] = 0.5
    state = pm.ParticleState(t=0.0, x=s0.x, v=v, a=s0.a)
    e0 = pm.energies(model, state).total
    dt, n = 0.002, 40
    for _ in range(n):
        state, info = pm.step_implicit(model, state, dt)
        assert info.newton <= 3
    wdt2 = k / m * dt * dt
    assert pm.energies(model, state).total / e0 == pytest.approx((1 + wdt2) ** -n, rel=1e-6)


def hanging(nx=4, nz=4, **kw):
    """A vertical sheet (x-z plane) held along its top edge, gravity -z."""
    net = regular_patch(length=0.2, width=0.2, nx=nx, ny=nz)
    x0 = net.x0[:, [0, 2, 1]]  # y -> z: the sheet hangs in the x-z plane
    net = pm.network_from_grid(x0, net.grid, boundaries=net.boundaries)
    fab = pm.fabric_from_material(net, material=kw.pop("material", MAT), thickness=T)
    return pm.ParticleModel(network=net, fabric=fab, fixed=net.nodes("top"), **kw)


def test_hanging_cloth_reaction_equals_its_weight():
    model = hanging()
    state, iters = pm.solve_static(model)
    weight = model.mass.sum() * 9.81
    assert np.allclose(pm.support_reaction(model, state), [0, 0, weight], rtol=1e-9, atol=1e-9)
    assert np.abs(state.a[~model.fixed]).max() < 1e-5 * 9.81
    # the damped implicit dynamics end at the same equilibrium
    damped = hanging(damping=pm.Damping(alpha=50.0))
    end, _ = pm.integrate(damped, pm.ParticleState.at_rest(damped), t_end=1.0, dt=0.01,
                          method="implicit")  # fmt: skip
    assert np.abs(end.x - state.x).max() < 1e-6 * np.abs(state.x - model.network.x0).max()


def test_strain_limit_caps_the_stretch():
    """A very soft sheet would stretch by ~40 %; Provot's correction keeps every structural
    and shear spring within 10 % at the end of every step."""
    soft = FabricMaterial(E1=2e2, E2=2e2, G12=40.0, rho=436.0)
    stretches = {}
    for limit in (None, pm.StrainLimit(max_stretch=0.1, tol=1e-6)):
        model = hanging(nx=2, nz=2, material=soft, strain_limit=limit,
                        damping=pm.Damping(alpha=20.0))  # fmt: skip
        net = model.network
        sel = net.kind != pm.FLEXION
        state = pm.ParticleState.at_rest(model)
        worst = 0.0
        for _ in range(300):
            state, info = pm.step_explicit(model, state, 1e-3)
            d = state.x[net.pairs[sel, 1]] - state.x[net.pairs[sel, 0]]
            worst = max(worst, float((np.linalg.norm(d, axis=1) / net.rest[sel]).max() - 1))
        stretches[limit is None] = worst
    assert stretches[True] > 0.2
    assert stretches[False] <= 1.1 * (1 + 1e-6) - 1 + 1e-12


def test_network_on_the_shell_nodes_and_the_same_on_every_rank():
    """The particles are the geometry nodes of a second-order mesh, i.e. the shell's Q2
    nodes; the network (gathered) is identical on every rank."""
    from clothfem.mesh import strip
    from clothfem.shell import ShellModel

    comm = MPI.COMM_WORLD
    sm = strip(comm, length=0.3, width=0.1, nx=3, ny=2)
    net = pm.network_from_mesh(sm)
    shell = ShellModel(sm, material=MAT, thickness=T)
    xs = np.concatenate(comm.allgather(shell.x_nodes[: shell.n_owned]))
    assert len(xs) == net.n_nodes
    d = np.linalg.norm(xs[:, None, :] - net.x0[None, :, :], axis=2).min(axis=1)
    assert d.max() < 1e-12
    ref = regular_patch(length=0.3, width=0.1, nx=3, ny=2)
    assert net.count("flexion") == ref.count("flexion")
    assert len(net.nodes("root")) == 5 and np.allclose(net.x0[net.nodes("root"), 0], 0.0)
    digest = (net.pairs.tobytes(), net.x0.tobytes())
    assert all(g == digest for g in comm.allgather(digest))


def test_bad_parameters():
    with pytest.raises(ValueError, match="bending must be 'provot' or 'choi-ko'"):
        pm.SpringRule(bending="linear")
    with pytest.raises(ValueError, match=r"fold_angle must be in \(0, pi\]"):
        pm.SpringRule(fold_angle=4.0)
    with pytest.raises(ValueError, match="Damping alpha must be a finite number >= 0"):
        pm.Damping(alpha=-1.0)
    with pytest.raises(ValueError, match="StrainLimit max_stretch must be > 0"):
        pm.StrainLimit(max_stretch=0.0)
    with pytest.raises(ValueError, match="dt must be a finite time step > 0 s"):
        pm.step_explicit(oscillator(), pm.ParticleState.at_rest(oscillator()), 0.0)
    net = regular_patch(length=0.01, width=0.01, nx=4, ny=4)
    with pytest.raises(ValueError, match="structural stiffness <= 0"):
        pm.fabric_from_material(net, material=MAT, thickness=2e-3)
    with pytest.raises(ValueError, match="rho must be > 0"):
        pm.fabric_from_material(net, material=FabricMaterial(E1=1, E2=1, G12=1), thickness=T)


def test_particle_arm_settled_torque_is_the_weight_beyond_the_elbow(tmp_path):
    """The arm-sleeve scene with the particle fabric (8 x 10, 1 degree of flexion): rows of
    0.01 s, the settle rows at angle 0, and the settled Eq. 28 torque about the elbow close
    to the moment of the weight of the sleeve past the elbow plane about the elbow, carried
    by the forearm: rho t 2 pi R g l^2 / 2 with l = 0.2 m (0.0322 N m; measured 0.0335, and
    the shell's runner gives 0.035-0.036 on 8x10 to 24x30): within 15 %. The same on every
    rank (each holds the whole network)."""
    from clothfem.particle.arm import run_arm

    scene = str(Path(__file__).resolve().parents[2] / "demos" / "scenes" / "arm_sleeve.toml")
    run = run_arm(scene_path=scene, mesh=(8, 10), angle=1.0)
    settle = run.time <= 0.2 + 1e-12
    assert settle.sum() >= 19 and np.all(run.angle[settle] == 0.0)
    assert run.angle[-1] == pytest.approx(1.0)
    estimate = 436.0 * 1e-3 * 2 * math.pi * 0.06 * 9.81 * 0.2**2 / 2
    assert run.torque_mag[settle][-1] == pytest.approx(estimate, rel=0.15)
    tau = MPI.COMM_WORLD.allgather(run.torque_mag[-1])
    assert all(t == tau[0] for t in tau)
