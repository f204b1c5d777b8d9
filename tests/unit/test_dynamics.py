"""Time integrators on single-degree-of-freedom systems (closed-form answers), the shell
inertia against exact rigid-motion kinetic energies, step control and bad input."""

import logging
import math

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.shell import Clamp, FabricMaterial, ShellModel

COMM = MPI.COMM_WORLD


def _sdof(*, k: float = 1.0, m: float = 1.0, x0: float = 1.0, cls=dy.LinearSystem):
    """m x'' + k x = 0 with its one unknown on rank 0."""
    n = 1 if COMM.rank == 0 else 0
    mats = []
    for value in (k, m):
        A = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=1, comm=COMM)
        A.setUp()
        if n:
            A.setValue(0, 0, value)
        A.assemble()
        mats.append(A)
    s = cls(K=mats[0], M=mats[1])
    x = s.create_vector()
    x.getArray()[:] = x0
    s.commit(x)
    return s


def _value(s) -> float:
    x = s.create_vector()
    s.get_state(x)
    return COMM.bcast(float(x.getArray()[0]) if COMM.rank == 0 else None, root=0)


def _history(s, **kwargs) -> np.ndarray:
    xs = [_value(s)]
    dy.integrate_implicit(s, on_step=lambda r: xs.append(_value(s)), **kwargs)
    return np.array(xs)


def _amplification(scheme: dy.ImplicitScheme, Omega: float) -> np.ndarray:
    """Closed-form amplification matrix of the scheme on x'' + omega^2 x = 0, state
    (x, h v, h^2 a), Omega = omega h (Chung & Hulbert 1993)."""
    b, g, am, af = scheme.beta, scheme.gamma, scheme.alpha_m, scheme.alpha_f
    W = Omega**2
    # unknowns (x1, hv1, h2a1): rows = balance, displacement update, velocity update
    L = np.array([[(1 - af) * W, 0.0, 1 - am], [1.0, 0.0, -b], [0.0, 1.0, -g]])
    R = np.array([[-af * W, 0.0, -am], [1.0, 1.0, 0.5 - b], [0.0, 1.0, 1 - g]])
    return np.linalg.solve(L, R)


def _fitted_pair(x: np.ndarray) -> complex:
    """Principal root of the 2-term recurrence x_{n+2} = c1 x_{n+1} + c0 x_n fitted to a
    history dominated by one complex pair: lambda = c1/2 + i sqrt(-c0 - c1^2/4)."""
    A = np.column_stack([x[1:-1], x[:-2]])
    c1, c0 = np.linalg.lstsq(A, x[2:], rcond=None)[0]
    return complex(c1 / 2, math.sqrt(-c0 - c1 * c1 / 4))


# ---------------------------------------------------------------------------- schemes
@pytest.mark.parametrize(
    "scheme",
    [
        dy.ImplicitScheme.newmark(),
        dy.ImplicitScheme.generalized_alpha(rho_inf=0.8),
        "explicit",
    ],
    ids=["newmark", "alpha0.8", "central"],
)
def test_second_order_convergence(scheme):
    """Error at t = T = 5 of x'' + x = 0, x(0) = 1 against cos(T): observed order 2 (at a
    time where the phase error shows; at full periods it cancels to higher order)."""
    T = 5.0
    errors = []
    for n in (20, 40, 80):
        s = _sdof()
        if scheme == "explicit":
            dy.integrate_explicit(s, t_end=T, dt=T / n)
        else:
            dy.integrate_implicit(s, scheme=scheme, stepping=dy.TimeStepping(dt=T / n, t_end=T))
        errors.append(abs(_value(s) - math.cos(T)))
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert min(orders) > 1.95 and max(orders) < 2.05, orders


def test_average_acceleration_conserves_energy_sdof():
    s = _sdof(k=4.0, m=0.5)
    recs = dy.integrate_implicit(s, stepping=dy.TimeStepping(dt=0.1, t_end=10.0))
    E0 = 0.5 * 4.0
    assert max(abs(r.total - E0) for r in recs) < 1e-12 * E0
    assert max(abs(r.dissipation) for r in recs) < 1e-12 * E0


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 0.9])
@pytest.mark.parametrize("Omega", [0.5, 2.0, 1e4])
def test_generalized_alpha_spectral_radius(rho_inf, Omega):
    """The decay per step of a free vibration equals the closed-form spectral radius; at
    high frequency it is rho_inf (Chung & Hulbert 1993), with damping ratio
    xi = -ln|lambda| / arg(lambda) of the principal root."""
    scheme = dy.ImplicitScheme.generalized_alpha(rho_inf=rho_inf)
    h = 1.0
    exact = np.linalg.eigvals(_amplification(scheme, Omega))
    rho_exact = max(abs(exact))
    s = _sdof(k=Omega**2)
    if Omega < 10:
        ref = exact[np.argmax(exact.imag)]
        spurious = exact[np.argmin(abs(exact.imag))]
        # skip the steps where the spurious root still shows (|ratio|^n0 < 1e-10)
        n0 = max(4, math.ceil(-10 / math.log10(abs(spurious) / abs(ref))))
        x = _history(s, scheme=scheme, stepping=dy.TimeStepping(dt=h, t_end=(n0 + 12) * h))
        principal = _fitted_pair(x[n0:])
        assert abs(principal) == pytest.approx(rho_exact, rel=1e-7)
        xi = -math.log(abs(principal)) / np.angle(principal)
        xi_ref = -math.log(abs(ref)) / np.angle(ref)
        assert xi == pytest.approx(xi_ref, rel=1e-5, abs=1e-8)
    else:
        x = _history(s, scheme=scheme, stepping=dy.TimeStepping(dt=h, t_end=12 * h))
        assert rho_exact == pytest.approx(rho_inf, abs=3e-3)
        # triple root -rho_inf: x_n = (-rho_inf)^n (c0 + c1 n + c2 n^2); remove it and fit
        n = np.arange(len(x))
        if rho_inf > 0:
            y = x / (-rho_inf) ** n
            c = np.polyfit(n, y, 2)
            assert np.max(np.abs(np.polyval(c, n) - y)) < 1e-3 * np.max(np.abs(y))
        else:  # annihilates the high-frequency response in two steps
            assert np.max(np.abs(x[3:])) < 1e-6
    if rho_inf < 1:
        assert rho_exact < 1


def test_newmark_is_undamped():
    for Omega in (0.5, 2.0, 1e3):
        exact = np.linalg.eigvals(_amplification(dy.ImplicitScheme.newmark(), Omega))
        assert max(abs(exact)) == pytest.approx(1.0, abs=1e-12)
        s = _sdof(k=Omega**2)
        x = _history(s, stepping=dy.TimeStepping(dt=1.0, t_end=12.0))
        assert max(abs(x)) == pytest.approx(1.0, rel=1e-6)


# ---------------------------------------------------------------------------- explicit
def test_explicit_stable_step_and_refusal():
    s = _sdof(k=4.0, m=1.0)  # omega = 2: dt_crit = 1
    st = dy.stable_time_step(s)
    assert st.dt_crit == pytest.approx(1.0, rel=1e-12)
    assert st.dt_bound == pytest.approx(1.0, rel=1e-12)
    assert st.converged
    with pytest.raises(ValueError, match="exceeds the stable estimate dt_crit = 1 s"):
        dy.integrate_explicit(s, t_end=10.0, dt=1.01)
    recs, _ = dy.integrate_explicit(s, t_end=20.0, dt=0.99)
    assert max(r.kinetic + r.strain for r in recs) < 100 * 2.0  # bounded
    s = _sdof(k=4.0, m=1.0)
    with pytest.warns(UserWarning, match="exceeds the stable estimate"):
        recs, _ = dy.integrate_explicit(s, t_end=60.0, dt=1.05, check="warn")
    assert recs[-1].strain > 1e3 * 2.0  # it does blow up


# ---------------------------------------------------------------------------- step control
class _Fragile(dy.LinearSystem):
    """Residual NaN when a step moves x by more than ``limit`` (forces Newton failures)."""

    limit = 0.15
    fail_after = math.inf

    def residual(self, x, f):
        super().residual(x, f)
        xa, xo = x.getArray(readonly=True), self._x.getArray(readonly=True)
        bad = len(xa) and (abs(xa[0] - xo[0]) > self.limit or self._lam > self.fail_after)
        if bad:
            f.getArray()[0] = np.nan


def test_cutback_and_growth(caplog):
    s = _sdof(k=1.0, x0=0.0, cls=_Fragile)
    v = s.create_vector()
    v.set(1.0)
    stepping = dy.TimeStepping(dt=0.2, t_end=1.0, dt_max=0.4, grow=1.5, easy_iterations=3)
    with caplog.at_level(logging.WARNING, logger="clothfem.dynamics"):
        recs = dy.integrate_implicit(s, stepping=stepping, velocity=v)
    assert recs[0].cutbacks == 1 and recs[0].dt == pytest.approx(0.1)
    assert recs[1].dt == pytest.approx(0.1)  # kept after a cut-back
    assert recs[2].dt == pytest.approx(0.15)  # grown after an easy step
    assert recs[-1].time == pytest.approx(1.0)
    assert sum(r.cutbacks for r in recs) == sum("Newton failed" in m for m in caplog.messages)
    assert max(abs(_value(s) - math.sin(1.0)), 0) < 1e-2


def test_divergence_below_dt_min_keeps_records():
    s = _sdof(k=1.0, cls=_Fragile)
    s.fail_after = 0.5000001  # every step beyond t = 0.5 fails (load(t) = t)
    seen = []
    stepping = dy.TimeStepping(dt=0.1, t_end=1.0, dt_min=0.01)
    with pytest.raises(dy.DynamicsDivergence, match=r"below dt_min 0.01 .* 5 accepted steps"):
        dy.integrate_implicit(s, stepping=stepping, load=lambda t: t, on_step=seen.append)
    assert [r.step for r in seen] == [1, 2, 3, 4, 5]


@pytest.mark.parametrize("recheck", [0, 5])
def test_explicit_recheck_shrinks_the_step_when_the_system_stiffens(recheck):
    """m x'' + k x = 0 with k x4 after step 10 (omega 1 -> 2, dt_crit 2 -> 1 s): the step
    0.9 dt_crit(0) = 1.8 s is then unstable (|amplification| > 1) and the energy grows by
    orders of magnitude; with recheck_every = 5 the step shrinks to 0.9 x the new dt_crit at
    step 10 and the energy stays bounded: near the limit K + U of the central difference
    swings between E* (1 - (omega h / 2)^2) and E* (E* its conserved modified energy), a
    ratio of 1 / (1 - 0.9^2) = 5.3 at h = 0.9 dt_crit, so 6 bounds it."""
    s = _sdof(k=1.0, m=1.0)
    t_end = 120.0
    energy = {}

    def on_step(r):
        if r.step == 10:
            s.K.scale(4.0)
        if r.step >= 11:
            energy.setdefault("after", r.kinetic + r.strain)
            energy["max"] = max(energy.get("max", 0.0), r.kinetic + r.strain)

    recs, st = dy.integrate_explicit(s, t_end=t_end, on_step=on_step, recheck_every=recheck)
    assert st.dt_crit == pytest.approx(2.0, rel=1e-12)
    assert recs[-1].time == pytest.approx(t_end, rel=1e-12)
    assert all(r.dt == pytest.approx(t_end / math.ceil(t_end / 1.8), rel=1e-12) for r in recs[:10])
    if recheck:
        assert all(r.dt <= 0.9 * 1.0 * (1 + 1e-9) for r in recs[10:])
        assert energy["max"] <= 6.0 * energy["after"]
    else:
        assert energy["max"] > 1e6 * energy["after"]


# ---------------------------------------------------------------------------- shell inertia
@pytest.fixture(scope="module")
def strip_system():
    sm = meshes.strip(COMM, length=2.0, width=0.5, nx=4, ny=2)
    mat = FabricMaterial.isotropic(E=1.0e6, nu=0.3, rho=400.0)
    model = ShellModel(sm, material=mat, thickness=0.02, supports=[Clamp("root")])
    return dy.ShellSystem(model)


def test_shell_mass_rigid_motions(strip_system):
    """1/2 v.M v of a uniform translation / uniform director rate, consistent and lumped,
    equals 1/2 rho t A |v|^2 and 1/2 rho t^3/12 A |theta'|^2 (exact at theta = 0)."""
    s, rho, t, area = strip_system, 400.0, 0.02, 1.0
    n = s.n
    v = s.create_vector()
    arr = v.getArray()
    arr[: 3 * n] = np.tile([1.0, -2.0, 0.5], n)
    arr[3 * n :] = 0.0
    Mv = v.duplicate()
    s.mass_mult(v, Mv)
    exact = rho * t * area * 5.25
    assert Mv.dot(v) == pytest.approx(exact, rel=1e-12)
    lumped = COMM.allreduce(float(np.dot(arr, s.lumped_mult(arr))), op=MPI.SUM)
    assert lumped == pytest.approx(exact, rel=1e-12)
    arr[: 3 * n] = 0.0
    arr[3 * n :] = np.tile([0.3, -0.4], n)
    s.mass_mult(v, Mv)
    exact = rho * t**3 / 12 * area * 0.25
    assert Mv.dot(v) == pytest.approx(exact, rel=1e-12)
    lumped = COMM.allreduce(float(np.dot(arr, s.lumped_mult(arr))), op=MPI.SUM)
    assert lumped == pytest.approx(exact, rel=1e-12)
    assert s.total_mass == pytest.approx(rho * t * area, rel=1e-12)
    assert np.all(s.lumped_u > 0) and np.all(s.lumped_d > 0)


def test_lumped_solve_inverts_lumped_mult_at_large_rotations():
    """M_L^-1 (M_L v) = v with the rotary blocks m T^T T at rotations up to 2.5 rad (their
    inverses by Cramer's rule), against LAPACK's solve of the same blocks; a singular block
    raises LinAlgError (as LAPACK's solve did)."""
    sm = meshes.strip(COMM, length=2.0, width=0.5, nx=4, ny=2)
    mat = FabricMaterial.isotropic(E=1.0e6, nu=0.3, rho=400.0)
    s = dy.ShellSystem(ShellModel(sm, material=mat, thickness=0.02))
    n = s.n
    rng = np.random.default_rng(4 + COMM.rank)
    th = s.model.theta.x.array[: 2 * n].reshape(n, 2)
    th[:] = rng.uniform(-1.8, 1.8, (n, 2))
    v = rng.normal(size=5 * n)
    back = s.lumped_solve(s.lumped_mult(v))
    np.testing.assert_allclose(back, v, rtol=0, atol=1e-12 * np.abs(v).max())
    f = rng.normal(size=5 * n)
    ref = np.linalg.solve(s._theta_blocks(), f[3 * n :].reshape(n, 2, 1)).ravel()
    np.testing.assert_allclose(s.lumped_solve(f)[3 * n :], ref, rtol=1e-12)
    s._theta_blocks()[0] = [[1.0, 2.0], [2.0, 4.0]]  # rank 1 (cached at these rotations)
    s._inverse = None
    with pytest.raises(np.linalg.LinAlgError, match="rotary block is singular"):
        s.lumped_solve(f)


def test_shell_stable_step_bounds(strip_system):
    st = dy.stable_time_step(strip_system, iterations=1000)
    assert 0 < st.dt_bound <= st.dt_crit < math.inf
    assert st.converged, st
    assert st.iterations < 100, st  # Lanczos (the power iteration needed > 1000 here)
    with pytest.raises(ValueError, match="exceeds the stable estimate"):
        dy.integrate_explicit(strip_system, t_end=1.0, dt=1.01 * st.dt_crit, stable=st)


@pytest.mark.serial
def test_shell_stable_step_is_the_largest_generalised_eigenvalue():
    """omega_max^2 of the Lanczos estimate = the largest eigenvalue of K v = w^2 M_L v on the
    free rows by a dense solve (scipy.linalg.eigh), on a strip bent into a curved state."""
    from scipy.linalg import eigh

    sm = meshes.strip(COMM, length=1.0, width=0.3, nx=3, ny=2)
    mat = FabricMaterial.isotropic(E=1.0e6, nu=0.3, rho=400.0)
    model = ShellModel(sm, material=mat, thickness=0.01, supports=[Clamp("root")])
    s = dy.ShellSystem(model, rotary_scale=10.0)
    model.u.x.array[2::3] = 0.05 * model.x_nodes[:, 0] ** 2  # a curved (non-zero) state
    model.u.x.scatter_forward()
    st = dy.stable_time_step(s, rtol=1e-10, iterations=500)
    x = s.create_vector()
    s.get_state(x)
    K = s.jacobian(x)
    Kd = K.convert("dense").getDenseArray()
    N = Kd.shape[0]
    Md = np.column_stack([s.lumped_mult(np.eye(N)[:, j]) for j in range(N)])
    free = np.setdiff1d(np.arange(N), s.bc(0.0)[0])
    w2 = eigh(Kd[np.ix_(free, free)], Md[np.ix_(free, free)], eigvals_only=True)[-1]
    assert st.converged
    assert st.omega_max**2 == pytest.approx(w2, rel=1e-8)


# ---------------------------------------------------------------------------- bad input
def test_bad_input_one_line_errors(strip_system):
    with pytest.raises(ValueError, match=r"TimeStepping dt must be in \(0, inf\)"):
        dy.TimeStepping(dt=0.0, t_end=1.0)
    with pytest.raises(ValueError, match=r"TimeStepping dt_min must be in \(0, 0.1\]"):
        dy.TimeStepping(dt=0.1, t_end=1.0, dt_min=0.2)
    with pytest.raises(ValueError, match=r"TimeStepping cut must be in \(0, 1\)"):
        dy.TimeStepping(dt=0.1, t_end=1.0, cut=1.0)
    with pytest.raises(ValueError, match=r"generalized_alpha rho_inf must be in \[0, 1\]"):
        dy.ImplicitScheme.generalized_alpha(rho_inf=1.5)
    with pytest.raises(ValueError, match=r"ImplicitScheme gamma must be in \[0.5, 1.5\]"):
        dy.ImplicitScheme.newmark(gamma=0.4)
    with pytest.raises(ValueError, match=r"Damping mass must be in \[0, inf\)"):
        dy.Damping(mass=-1.0)
    with pytest.raises(ValueError, match="check must be 'error', 'warn' or 'off'"):
        dy.integrate_explicit(strip_system, t_end=1.0, check="maybe")
    with pytest.raises(ValueError, match=r"rotary_scale must be in \[1, inf\)"):
        dy.ShellSystem(strip_system.model, rotary_scale=0.5)
    massless = ShellModel(
        strip_system.model.surface,
        material=FabricMaterial.isotropic(E=1.0e6, nu=0.3),
        thickness=0.02,
    )
    with pytest.raises(ValueError, match="material rho must be > 0 kg/m\\^3 for dynamics"):
        dy.ShellSystem(massless)


# ---------------------------------------------------------------------------- energy balance
def _chain(*, prescribed: bool):
    """Two unit masses, springs ground-1 (k=3) and 1-2 (k=2); unknown 0 is mass 1."""
    n = 2 if COMM.rank == 0 else 0
    K = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=2, comm=COMM)
    M = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=2, comm=COMM)
    K.setUp()
    M.setUp()
    if n:
        K.setValues([0, 1], [0, 1], [[5.0, -2.0], [-2.0, 2.0]])
        M.setValues([0, 1], [0, 1], [[1.0, 0.0], [0.0, 1.0]])
    K.assemble()
    M.assemble()
    f = K.createVecRight()
    if n:
        f.getArray()[1] = 1.0

    def bc(lam):
        if prescribed and n:
            return np.array([0], dtype=np.int32), np.array([0.3 * lam])
        return np.zeros(0, dtype=np.int32), np.zeros(0)

    return dy.LinearSystem(K=K, M=M, f=f, bc=bc)


@pytest.mark.parametrize("prescribed", [False, True], ids=["load", "support-motion"])
def test_energy_balance_with_work(prescribed):
    """Average acceleration on a linear system: K + U - K0 - U0 = W_ext (loads and the
    reaction on a prescribed moving row, both trapezoidal) to round-off."""
    s = _chain(prescribed=prescribed)
    recs = dy.integrate_implicit(
        s, stepping=dy.TimeStepping(dt=0.05, t_end=6.0), load=lambda t: math.sin(1.3 * t)
    )
    scale = max(abs(r.external_work) for r in recs)
    assert scale > 1e-3
    assert max(abs(r.dissipation) for r in recs) < 1e-10 * scale
    assert max(abs(r.total - r.external_work) for r in recs) < 1e-10 * scale


def test_explicit_measure_skips_only_the_strain_energy():
    """measure(step, t) picks the records that carry the strain energy: the motion, kinetic
    energy and work are those of the run that measures every step, the measured records'
    strain energy and energy balance too; the others have nan there."""
    # (load only: with the prescribed row, an explicit run of this chain, which lives on
    # rank 0, deadlocks PETSc's garbage cleanup at interpreter exit on 2 ranks, also with
    # the code of commit 7138b2c; not understood)
    kw = dict(t_end=3.0, dt=0.05, load=lambda t: math.sin(1.3 * t))
    full, _ = dy.integrate_explicit(_chain(prescribed=False), **kw)
    part, _ = dy.integrate_explicit(_chain(prescribed=False), measure=lambda k, t: k % 7 == 0, **kw)
    assert len(part) == len(full) == 60
    for a, b in zip(full, part, strict=True):
        assert (b.time, b.kinetic, b.external_work) == (a.time, a.kinetic, a.external_work)
        if b.step % 7 == 0:
            assert (b.strain, b.dissipation) == (a.strain, a.dissipation)
            assert math.isfinite(b.strain) and b.strain > 0
        else:
            assert math.isnan(b.strain) and math.isnan(b.dissipation)


# ---------------------------------------------------------------------------- PETSc TS
def test_ts_alpha2_backend():
    """TS alpha2 with the same callbacks: Newmark parameters conserve the energy after the
    first step; the backward-Euler start-up of TS makes the error first order (documented
    reason for integrate_implicit), and rho_inf < 1 dissipates."""
    T = 5.0
    errors = []
    for n in (40, 80, 160):
        s = _sdof()
        recs = dy.integrate_ts_alpha2(s, dt=T / n, t_end=T)
        assert len(recs) == n and recs[-1].time == pytest.approx(T)
        totals = np.array([r.total for r in recs[1:]])
        assert np.ptp(totals) < 1e-9 * totals[0]
        errors.append(abs(_value(s) - math.cos(T)))
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert 0.85 < min(orders) and max(orders) < 1.15, orders
    s = _sdof(k=100.0)
    recs = dy.integrate_ts_alpha2(
        s, dt=1.0, t_end=20.0, scheme=dy.ImplicitScheme.generalized_alpha(rho_inf=0.5)
    )
    assert recs[-1].total < 1e-6 * recs[0].total


# ---------------------------------------------------------------------------- damping
@pytest.mark.parametrize("method", ["newmark", "alpha0.8", "central"])
def test_rayleigh_damping_sdof(method):
    """x'' + c x' + 4 x = 0 with C = 0.1 M + 0.05 K (xi = 0.125): the damped analytic
    solution at t = 3, and the damping work closes the energy balance."""
    w, a0, a1 = 2.0, 0.1, 0.05
    xi = a0 / (2 * w) + a1 * w / 2
    wd = w * math.sqrt(1 - xi * xi)
    t_end = 3.0
    exact = math.exp(-xi * w * t_end) * (math.cos(wd * t_end) + xi * w / wd * math.sin(wd * t_end))
    s = _sdof(k=w * w)
    damping = dy.Damping(mass=a0, stiffness=a1)
    if method == "central":
        recs, _ = dy.integrate_explicit(s, t_end=t_end, dt=0.002, damping=damping)
    else:
        scheme = (
            dy.ImplicitScheme.newmark()
            if method == "newmark"
            else dy.ImplicitScheme.generalized_alpha(rho_inf=0.8)
        )
        recs = dy.integrate_implicit(
            s, scheme=scheme, damping=damping, stepping=dy.TimeStepping(dt=0.01, t_end=t_end)
        )
    assert _value(s) == pytest.approx(exact, abs=1e-3)
    E0 = 0.5 * w * w
    assert recs[-1].damping_work == pytest.approx(E0 - recs[-1].total, rel=1e-2)
    assert abs(recs[-1].dissipation) < 1e-2 * recs[-1].damping_work


def test_damping_until_switches_to_the_free_oscillation():
    """Central difference with mass damping a0 for t <= T1 only, on x'' + a0 x' + w^2 x = 0:
    at T1 the state is the damped solution; afterwards the undamped oscillation from that
    state (amplitude constant, energy constant), and the damping work stops growing."""
    w, a0, T1, t_end = 2.0, 0.4, 1.5, 4.0
    xi = a0 / (2 * w)
    wd = w * math.sqrt(1 - xi * xi)

    def damped(t: float) -> tuple[float, float]:
        e = math.exp(-xi * w * t)
        x = e * (math.cos(wd * t) + xi * w / wd * math.sin(wd * t))
        v = -e * (w * w / wd) * math.sin(wd * t)
        return x, v

    x1, v1 = damped(T1)
    exact = x1 * math.cos(w * (t_end - T1)) + v1 / w * math.sin(w * (t_end - T1))
    s = _sdof(k=w * w)
    recs, _ = dy.integrate_explicit(
        s, t_end=t_end, dt=0.001, damping=dy.Damping(mass=a0), damping_until=T1
    )
    assert _value(s) == pytest.approx(exact, abs=2e-3)
    E1 = 0.5 * (v1 * v1 + w * w * x1 * x1)
    after = [r for r in recs if r.time > T1 + 0.01]
    assert max(abs(r.total - E1) for r in after) < 2e-3 * E1
    assert after[-1].damping_work == pytest.approx(after[0].damping_work, rel=1e-12)
    assert after[0].damping_work == pytest.approx(0.5 * w * w - E1, rel=1e-2)
