"""Yarn friction (clothfem.shell.hysteresis): the Dahl step against its closed form, the
dissipation of every step >= 0, and on a strip cycled in tension-compression the energy
dissipated per cycle equal to the area of the force-displacement loop (from the samples)
and to the closed-form loop area; Taylor tests with history; bad input."""

import math

import numpy as np
import pytest
from _taylor import energy_orders, jacobian_orders, random_state
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.shell import (
    DecrimpingFabric,
    FabricMaterial,
    PointPin,
    Prescribed,
    Quadrature,
    ShellModel,
)
from clothfem.shell.hysteresis import DahlFriction, dahl_cycle_area, dahl_update
from clothfem.static import NewtonSolver

COMM = MPI.COMM_WORLD
K, S = 1.2e6, 0.03e6  # friction stiffness and sliding stress [Pa]


def test_dahl_step_matches_ode_and_dissipates():
    """One exact step equals many small ones (the ODE), work = int s dE (quadrature of the
    fine path), dissipation >= 0 for every start stress in [-S, S] and increment sign."""
    rng = np.random.default_rng(0)
    s0 = rng.uniform(-S, S, 200)
    d = rng.uniform(-0.1, 0.1, 200)
    s1, work, diss = dahl_update(d, s0, k=K, S=S)
    n = 2000
    s, w = s0.copy(), np.zeros_like(s0)
    for _ in range(n):
        s_new, dw, _ = dahl_update(d / n, s, k=K, S=S)
        w += dw
        s = s_new
    np.testing.assert_allclose(s1, s, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(work, w, rtol=1e-10, atol=1e-9)
    assert np.all(diss >= -1e-12 * S) and np.all(np.abs(s1) <= S)
    assert np.all(dahl_update(np.zeros(3), s0[:3], k=K, S=S)[0] == s0[:3])


def _simpson(f, x):
    """Simpson's rule on uniformly spaced samples (an even number of intervals)."""
    h = (x[-1] - x[0]) / (len(x) - 1)
    return h / 3.0 * (f[0] + f[-1] + 4.0 * f[1:-1:2].sum() + 2.0 * f[2:-1:2].sum())


@pytest.mark.parametrize("amplitude", [0.02, 0.1])
@pytest.mark.parametrize("scheme", ["psri", "mitc9"])
def test_strip_cycle_dissipation_equals_loop_area(amplitude, scheme):
    """Crimped cotton (E = 1.2 MPa, nu = 0) with yarn friction k = 1.2 MPa, S = 30 kPa, a
    strip of length L, width b, thickness t cycled by its tip displacement between warp
    strains 0 and 2 A (in tension throughout: a compressed fabric strip wrinkles), from the
    steady loop's lower turning point (friction stress -s*): every step dissipates >= 0
    (also at every quadrature point); over the cycle the dissipated energy equals t b L x
    the loop area of the stress-strain samples S11 = F / (t b lambda) (Simpson), t b L x
    the closed-form Dahl loop area, and the work of the tip force (trapezoid); the strain
    energy at a commit is the elastic energy plus the friction springs' stored energy.
    Both the partial selective element and MITC9 (the assumed strains of a homogeneous
    strain are exact on rectangular cells)."""
    L, b, t = 0.2, 0.05, 1e-3
    mat = FabricMaterial(
        E1=1.2e6,
        E2=1.2e6,
        G12=1e5,
        friction=DahlFriction(stiffness1=K, stiffness2=K, stress1=S, stress2=S),
    )
    sm = meshes.strip(COMM, length=L, width=b, nx=2, ny=1)
    d_ref = 0.01 * L  # the tip displacement at load factor 1
    model = ShellModel(
        sm,
        material=mat,
        thickness=t,
        quadrature=Quadrature(scheme=scheme),
        supports=[
            Prescribed("root", displacement=(0.0, 0.0, 0.0), components=(0, 2)),
            Prescribed("tip", displacement=(d_ref, 0.0, 0.0), components=(0, 2)),
            PointPin(point=(0.0, 0.0, 0.0), components=(1,)),
        ],
    )
    q = math.exp(-2.0 * K * amplitude / S)
    s_star = S * (1.0 - q) / (1.0 + q)
    model.friction.history.x.array.reshape(-1, 4)[:, 2] = -s_star  # warp friction stress
    tip = np.isclose(model.x_nodes[:, 0], L)
    solver = NewtonSolver(model)
    m = 20  # steps per branch
    up = np.linspace(0.0, 2.0 * amplitude, m + 1)
    strains = np.concatenate([up, up[::-1][1:]])  # 0 .. 2A .. 0
    n = model.n_owned
    x, r = model.create_vector(), model.create_vector()
    forces, disp, steps = [], [], []
    for k, e in enumerate(strains):
        delta = (math.sqrt(1.0 + 2.0 * e) - 1.0) * L
        ok, *_ = solver.solve(delta / d_ref)
        assert ok
        model.get_state(x)
        model.set_load_factor(0.0)
        model.residual(x, r)
        f = r.getArray(readonly=True)[: 3 * n].reshape(n, 3)[tip[:n], 0].sum()
        forces.append(COMM.allreduce(float(f), op=MPI.SUM))
        disp.append(delta)
        d = model.friction.commit()
        if k > 0:
            steps.append(d)
        assert model.friction.last_min_dissipation >= -1e-9 * S * amplitude
    steps = np.array(steps)
    assert np.all(steps >= -1e-15)
    stretch = np.sqrt(1.0 + 2.0 * strains)
    S11 = np.array(forces) / (t * b * stretch)  # from F = t b lambda S11
    assert S11[0] == pytest.approx(-s_star, rel=1e-9)
    area = t * b * L * (_simpson(S11[: m + 1], strains[: m + 1]) + _simpson(S11[m:], strains[m:]))
    dissipated = float(steps.sum())
    closed = t * b * L * dahl_cycle_area(amplitude, k=K, S=S)
    # the history update is exact for any step size
    assert dissipated == pytest.approx(closed, rel=1e-8)
    # Simpson's rule over 20 samples a branch: 1e-5 (A = 0.02), 5e-5 (A = 0.1) here
    assert area == pytest.approx(dissipated, rel=2e-4)
    F, u = np.array(forces), np.array(disp)
    assert float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(u))) == pytest.approx(area, rel=5e-3)
    assert model.friction.dissipated() == pytest.approx(dissipated, rel=1e-12)
    # back at E11 = 0 on the steady loop: the stored energy is that of -s* again
    stored = t * b * L * s_star**2 / (2.0 * K)
    assert model.friction.stored() == pytest.approx(stored, rel=1e-9)
    assert model.strain_energy() == pytest.approx(stored, rel=1e-9)


def _material(decrimping: bool):
    friction = DahlFriction(stiffness1=K, stiffness2=0.5 * K, stress1=S, stress2=2 * S)
    common = dict(E1=1.0e6, E2=0.6e6, G12=0.2e6, nu12=0.3, rho=500.0, friction=friction)
    if not decrimping:
        return FabricMaterial(**common)
    # transitions that the random test states cross (as in test_material_decrimping)
    return DecrimpingFabric(
        **common,
        E1_decrimped=50e6,
        E2_decrimped=20e6,
        transition1=0.02,
        transition2=0.03,
        width1=0.015,
        width2=0.02,
    )


@pytest.fixture(scope="module", params=[False, True], ids=["linear", "decrimping"])
def panel_model(request):
    """A curved panel with yarn friction whose history was committed at a random state."""
    sm = meshes.cylinder_panel(
        COMM, radius=1.0, length=1.5, angle=math.radians(50), n_around=4, n_along=3
    )
    model = ShellModel(sm, material=_material(request.param), thickness=0.01, warp=(1.0, 0.3, 0.0))
    model.set_state(random_state(model, 0.05, 7))
    model.friction.commit()
    assert model.friction.stored() > 0
    return model


def test_residual_is_energy_gradient_with_history(panel_model):
    """|Pi(x + h dx) - Pi(x) - h R . dx| = O(h^2) with a committed friction history."""
    model = panel_model
    model.set_load_factor(0.0)
    x, dx = random_state(model, 0.05, 2), random_state(model, 1.0, 3)

    steps = (1e-4, 5e-5, 2.5e-5, 1.25e-5)
    assert min(energy_orders(model, x, dx, steps, model.strain_energy)) > 1.9


def test_jacobian_taylor_with_history(panel_model):
    """|R(x + h dx) - R(x) - h K dx| = O(h^2) with a committed friction history."""
    model = panel_model
    model.set_load_factor(0.0)
    x, dx = random_state(model, 0.05, 0), random_state(model, 1.0, 1)
    assert min(jacobian_orders(model, x, dx, (1e-4, 5e-5, 2.5e-5, 1.25e-5))) > 1.9


def test_checkpoint_arrays_restore_the_history(panel_model):
    """state_arrays / restore_arrays give back the forces and the totals of a committed
    history after further commits; a wrong shape is a one-line error."""
    model = panel_model
    model.set_load_factor(0.0)
    saved = model.friction.state_arrays()
    x = random_state(model, 0.05, 11)
    f0, f1 = x.duplicate(), x.duplicate()
    model.residual(x, f0)
    totals = (model.friction.dissipated(), model.friction.stored())
    model.set_state(x)
    model.friction.commit()
    model.friction.restore_arrays(saved)
    model.residual(random_state(model, 0.05, 12), f1)  # (the model caches R by state)
    model.residual(x, f1)
    assert (f1 - f0).norm() == 0.0
    assert (model.friction.dissipated(), model.friction.stored()) == totals
    with pytest.raises(ValueError, match="friction_history must have shape"):
        model.friction.restore_arrays({**saved, "friction_history": np.zeros(3)})


def test_bad_input_one_line_errors():
    with pytest.raises(ValueError, match=r"friction stress2 must be a finite number > 0 Pa"):
        DahlFriction(stiffness1=1.0, stiffness2=1.0, stress1=1.0, stress2=0.0)
    with pytest.raises(ValueError, match="material friction must be a DahlFriction or None"):
        FabricMaterial(E1=1.0, E2=1.0, G12=1.0, friction=(1.0, 1.0))


def test_explicit_vibration_dissipates_by_friction():
    """A strip set into axial vibration (central difference, history committed from
    ``integrate_explicit``'s on_step): without friction the energy is conserved (numerical
    dissipation ~ 0); with friction the kinetic energy decays and the energy missing from
    the balance (the records' numerical dissipation) is the friction dissipation (the last
    step's share is inside the records' strain energy, which is taken before the commit),
    to the central difference's O((omega h)^2) energy error (4e-4 at 0.3 dt_crit, 4e-3 at
    0.9 dt_crit)."""
    from clothfem.dynamics import ShellSystem, integrate_explicit

    L, b, t, rho = 0.2, 0.05, 1e-3, 436.0
    period = 4 * L / math.sqrt(1.2e6 / rho)  # of the first axial mode (crimped modulus)
    out = []
    for friction in (None, DahlFriction(stiffness1=K, stiffness2=K, stress1=S, stress2=S)):
        mat = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1e5, rho=rho, friction=friction)
        sm = meshes.strip(COMM, length=L, width=b, nx=4, ny=1)
        model = ShellModel(
            sm,
            material=mat,
            thickness=t,
            supports=[
                Prescribed("root", displacement=(0.0, 0.0, 0.0), components=(0, 2)),
                Prescribed("tip", displacement=(0.0, 0.0, 0.0), components=(2,)),
                PointPin(point=(0.0, 0.0, 0.0), components=(1,)),
            ],
        )
        system = ShellSystem(model, rotary_scale=100.0)
        v = system.create_vector()
        n = model.n_owned
        v.getArray()[: 3 * n].reshape(n, 3)[:, 0] = 2.0 * np.sin(
            0.5 * math.pi * model.x_nodes[:n, 0] / L
        )
        steps = []

        def on_step(rec, model=model, steps=steps):
            if model.friction is not None:
                steps.append(model.friction.commit())
                assert steps[-1] >= -1e-15

        recs, _ = integrate_explicit(
            system, t_end=2 * period, velocity=v, on_step=on_step, safety=0.3
        )
        out.append((recs, steps, model))
    (lin, _, _), (fr, steps, model) = out
    K0 = lin[0].kinetic
    assert abs(lin[-1].dissipation) < 1e-5 * K0
    D = model.friction.dissipated()
    assert D > 0.5 * K0 and fr[-1].kinetic < 0.1 * K0
    assert fr[-1].dissipation + steps[-1] == pytest.approx(D, rel=1e-3)


def test_cotton_friction_preset_loop():
    """COTTON_FRICTION with the crimped cotton (E = 1.2 MPa): a tensile cycle 0 -> e_max ->
    zero stress recovers 58 % of the loading work and leaves 1.4 % (e_max = 5 %) and 2.3 %
    (10 %) residual strain, as its comment states; the band is 2 S = 60 kPa wide at large
    amplitude (closed-form steady loop of a large cycle: height -> 2 S)."""
    from clothfem.shell.hysteresis import COTTON_FRICTION

    E = 1.2e6
    k, Sf = COTTON_FRICTION.stiffness1, COTTON_FRICTION.stress1
    for e_max, rt, residual in ((0.05, 0.58, 0.014), (0.1, 0.58, 0.023)):
        n = 4000
        de = e_max / n
        s, w_load = 0.0, 0.0
        for i in range(n):
            s1, w, _ = dahl_update(de, s, k=k, S=Sf)
            w_load += float(w) + E * ((i + 1) ** 2 - i**2) * de**2 / 2
            s = float(s1)
        e, w_back = e_max, 0.0
        while True:
            s1, w, _ = dahl_update(-de, s, k=k, S=Sf)
            if E * (e - de) + float(s1) < 0:
                break
            w_back += -(float(w) + E * ((e - de) ** 2 - e**2) / 2)
            e, s = e - de, float(s1)
        assert w_back / w_load == pytest.approx(rt, abs=0.01)
        assert e == pytest.approx(residual, abs=0.001)
    # a cycle of amplitude 0.5 about any mean strain, from its lower turning point: the
    # gap between the loading and unloading branches at the mean strain is 2 S to 1e-7
    A = 0.5
    q = math.exp(-2 * k * A / Sf)
    s_bottom = -Sf * (1 - q) / (1 + q)
    s_up = float(dahl_update(A, s_bottom, k=k, S=Sf)[0])
    s_top = float(dahl_update(A, s_up, k=k, S=Sf)[0])
    s_down = float(dahl_update(-A, s_top, k=k, S=Sf)[0])
    assert s_top == pytest.approx(-s_bottom, rel=1e-12)
    assert s_up - s_down == pytest.approx(2 * Sf, rel=1e-7)
