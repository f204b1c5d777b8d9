"""Yarn friction (clothfem.shell.hysteresis): the Dahl step against its closed form, the
dissipation of every step >= 0, and on a strip cycled in tension-compression the energy
dissipated per cycle equal to the area of the force-displacement loop (from the samples)
and to the closed-form loop area; Taylor tests with history; bad input."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.shell import FabricMaterial, PointPin, Prescribed, ShellModel
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


def _cycle_path(amplitude, cycles, n_quarter):
    """Green strains 0 -> 2A -> 0 -> 2A ... (``cycles`` full cycles after the first
    loading): a loop of amplitude A about the mean strain A, in tension throughout (a
    compressed fabric strip wrinkles: its compressive stress exceeds G12 at a few percent)."""
    up = np.linspace(0.0, 2 * amplitude, 2 * n_quarter + 1)[1:]
    return np.concatenate([up] + [np.concatenate([up[::-1][1:], [0.0], up])] * cycles)


@pytest.mark.parametrize("amplitude", [0.02, 0.1])
def test_strip_cycle_dissipation_equals_loop_area(amplitude):
    """Crimped cotton (E = 1.2 MPa, nu = 0) with yarn friction k = 1.2 MPa, S = 30 kPa, a
    strip of length L, width b, thickness t cycled between warp strains 0 and 2 A by its tip
    displacement: every step dissipates >= 0 (also at every quadrature point); over the
    last cycle the dissipated energy equals t b L x the loop area of the stress-strain
    samples S11 = F / (t b lambda) (Simpson), t b L x the closed-form Dahl loop area, and
    the work of the tip force (trapezoid); the strain energy at a commit is the elastic
    energy plus the friction springs' stored energy."""
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
        supports=[
            Prescribed("root", displacement=(0.0, 0.0, 0.0), components=(0, 2)),
            Prescribed("tip", displacement=(d_ref, 0.0, 0.0), components=(0, 2)),
            PointPin(point=(0.0, 0.0, 0.0), components=(1,)),
        ],
    )
    tip = np.isclose(model.x_nodes[:, 0], L)
    solver = NewtonSolver(model)
    strains = _cycle_path(amplitude, 4, 10)
    n = model.n_owned
    x, r = model.create_vector(), model.create_vector()
    forces, disp, steps = [], [], []
    for e in strains:
        delta = (math.sqrt(1.0 + 2.0 * e) - 1.0) * L
        ok, *_ = solver.solve(delta / d_ref)
        assert ok
        model.get_state(x)
        model.set_load_factor(0.0)
        model.residual(x, r)
        f = r.getArray(readonly=True)[: 3 * n].reshape(n, 3)[tip[:n], 0].sum()
        forces.append(COMM.allreduce(float(f), op=MPI.SUM))
        disp.append(delta)
        steps.append(model.friction.commit())
        assert model.friction.last_min_dissipation >= -1e-9 * S * amplitude
    steps = np.array(steps)
    assert np.all(steps >= -1e-15)
    # the last full cycle: samples last-1 .. end, two monotone branches of 2 n intervals
    last = len(strains) - 4 * 10
    E = np.asarray(strains[last - 1 :])
    stretch = np.sqrt(1.0 + 2.0 * E)
    S11 = np.array(forces[last - 1 :]) / (t * b * stretch)  # from F = t b lambda S11
    area = t * b * L * (_simpson(S11[:21], E[:21]) + _simpson(S11[20:], E[20:]))
    dissipated = float(steps[last:].sum())
    closed = t * b * L * dahl_cycle_area(amplitude, k=K, S=S)
    # the history is exact for any step, so only the start-up transient (q^8 of the first
    # loop's mismatch, q = exp(-2 k A / S)) separates the last cycle from the steady loop
    assert dissipated == pytest.approx(closed, rel=1e-6)
    # Simpson's rule over 20 samples a branch: 1e-5 (A = 0.02) and 5e-5 (A = 0.1) here
    assert area == pytest.approx(dissipated, rel=2e-4)
    # the loop: the work of the tip force over the cycle, trapezoid in the tip displacement
    F, u = np.array(forces[last - 1 :]), np.array(disp[last - 1 :])
    assert float(np.sum(0.5 * (F[1:] + F[:-1]) * np.diff(u))) == pytest.approx(area, rel=5e-3)
    # stored energy: the model's strain energy = elastic + friction springs at a commit
    elastic = 0.5 * t * b * L * 1.2e6 * strains[-1] ** 2  # (E22 = E12 = 0: nu12 = 0)
    assert model.strain_energy() == pytest.approx(elastic + model.friction.stored(), rel=1e-9)
    assert model.friction.dissipated() == pytest.approx(steps.sum(), rel=1e-12)


def _material(**kw):
    return FabricMaterial(
        E1=1.0e6,
        E2=0.6e6,
        G12=0.2e6,
        nu12=0.3,
        rho=500.0,
        friction=DahlFriction(stiffness1=K, stiffness2=0.5 * K, stress1=S, stress2=2 * S),
        **kw,
    )


def _random_state(model, scale, seed):
    rng = np.random.default_rng(seed + COMM.rank)
    x = model.create_vector()
    x.setArray(rng.normal(size=x.getLocalSize()) * scale)
    return x


def _orders(errors):
    return [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]


@pytest.fixture(scope="module")
def panel_model():
    """A curved panel with yarn friction whose history was committed at a random state."""
    sm = meshes.cylinder_panel(
        COMM, radius=1.0, length=1.5, angle=math.radians(50), n_around=4, n_along=3
    )
    model = ShellModel(sm, material=_material(), thickness=0.01, warp=(1.0, 0.3, 0.0))
    model.set_state(_random_state(model, 0.05, 7))
    model.friction.commit()
    assert model.friction.stored() > 0
    return model


def test_residual_is_energy_gradient_with_history(panel_model):
    """|Pi(x + h dx) - Pi(x) - h R . dx| = O(h^2) with a committed friction history."""
    model = panel_model
    model.set_load_factor(0.0)
    x, dx = _random_state(model, 0.05, 2), _random_state(model, 1.0, 3)

    def energy(v):
        model.set_state(v)
        return model.strain_energy()

    f = x.duplicate()
    model.residual(x, f)
    slope = f.dot(dx)
    e0 = energy(x)
    errs = []
    for h in (1e-4, 5e-5, 2.5e-5, 1.25e-5):
        xh = x.copy()
        xh.axpy(h, dx)
        errs.append(abs(energy(xh) - e0 - h * slope))
    assert min(_orders(errs)) > 1.9


def test_jacobian_taylor_with_history(panel_model):
    """|R(x + h dx) - R(x) - h K dx| = O(h^2) with a committed friction history."""
    model = panel_model
    model.set_load_factor(0.0)
    x, dx = _random_state(model, 0.05, 0), _random_state(model, 1.0, 1)
    f0 = x.duplicate()
    model.residual(x, f0)
    Kdx = x.duplicate()
    model.jacobian(x).mult(dx, Kdx)
    errs = []
    for h in (1e-4, 5e-5, 2.5e-5, 1.25e-5):
        xh = x.copy()
        xh.axpy(h, dx)
        fh = x.duplicate()
        model.residual(xh, fh)
        errs.append((fh - f0 - h * Kdx).norm())
    assert min(_orders(errs)) > 1.9


def test_bad_input_one_line_errors():
    with pytest.raises(ValueError, match=r"friction stress2 must be a finite number > 0 Pa"):
        DahlFriction(stiffness1=1.0, stiffness2=1.0, stress1=1.0, stress2=0.0)
    with pytest.raises(ValueError, match="material friction must be a DahlFriction or None"):
        FabricMaterial(E1=1.0, E2=1.0, G12=1.0, friction=(1.0, 1.0))
