"""Transient dynamics of the fabric shell (Man & Swan 2007, Sec. 3.1.3, Eq. 13).

Solves  M(x) a + C v + f_int(x) - f_ext(x, lam(t)) = 0  with

* :func:`integrate_implicit`: Newmark (beta, gamma; default average acceleration 1/4, 1/2)
  or the generalized-alpha method of Chung & Hulbert (1993, J. Appl. Mech. 60, 371-375)
  with a user spectral radius at infinity ``rho_inf``; Newton by PETSc SNES on the
  displacement x_{n+1}; adaptive step with cut-back and growth;
* :func:`integrate_explicit`: central difference (velocity-Verlet form) with the lumped
  mass, and :func:`stable_time_step`, the stability limit dt_crit = 2/omega_max of the
  current tangent stiffness by Lanczos (plus a rigorous Gershgorin lower bound).

Inertia (:mod:`clothfem.shell.inertia`): the kinetic energy of the shell is
T = 1/2 v_u . M_uu v_u + 1/2 d' . M_dd d' in the (u, d) layout, and the nodal director rate
is d'_A = T_A theta'_A with T_A = dd_A/dtheta_A, so in the (u, theta) unknowns

    M(x) = P(x)^T diag(M_uu, M_dd) P(x),      P = diag(I, dd_A/dtheta_A)   (the model's P).

Approximation: the inertia force used is M(x) a, i.e. the rotary part is T^T M_dd T theta''
at the current state; the velocity-quadratic (centripetal / gyroscopic) term
T^T M_dd T' theta' and the derivative of M with respect to x in the Jacobian are dropped.
Both scale with rho t^3/12, which relative to the midsurface mass rho t is (t/h)^2/12 for a
node spacing h: below 1e-3 for fabrics (t ~ 0.5 mm, h ~ 1 cm). The rotary inertia only
keeps the director equations regular; it carries a negligible share of the kinetic energy.

The time t enters through the load factor: lam = load(t) (``load`` a user function,
default lam = 1) scales every load and prescribed value of the model. Prescribed rows are
enforced as x - value(lam(t_{n+1})) = 0 (value rows of the Jacobian are unit rows).

Why not PETSc TS alpha2: TS ``alpha2`` does generalized-alpha with the I2 callbacks, but
(i) the energy bookkeeping here needs the acceleration and the support reactions of every
accepted step, which TS does not expose; (ii) per-step cut-back logging with the failed
residual history and a user ``on_step`` record after each accepted step needs a hook TS
only offers partially in petsc4py 3.18 (no ``TS.getAdapt``); (iii) the round-off floor of
the SVK residual needs the custom convergence test of :class:`clothfem.static.NewtonSolver`;
(iv) TS alpha2 has no way to pass the initial acceleration: it estimates it by two
backward-Euler steps (``TSAlpha_Restart``), which makes the scheme first order — measured
order 0.97 at t = 5 on x'' + x = 0 with Newmark parameters (error 1.5e-2 at 160 steps,
against 3.9e-4 and order 2.00 here). So the time loop is ours and each step is one SNES
solve (the same options mechanism). :func:`integrate_ts_alpha2` drives the same
callbacks through TS alpha2 (options ``dyn_ts_ts_alpha_radius``, ``dyn_ts_ts_adapt_type``)
for comparison.

PETSc options (prefix ``dyn_`` by default, e.g. ``-dyn_snes_monitor``):
``snes_rtol`` (1e-9, relative to max(first residual, force scale of the step)),
``snes_atol`` (1e-30), ``snes_stol`` (1e-12), ``snes_max_it`` (15),
``snes_linesearch_type`` (basic), the direct solve of
:func:`clothfem.petsc_options.direct_lu` (MUMPS LU; redundant on more than one rank),
``newton_floor_rtol`` (1e-7: accept a stagnating residual below this fraction of the force
scale).

Energy (each :class:`DynamicStep`): kinetic 1/2 v.M v, strain (the model's strain energy),
external work W_ext (trapezoidal, of the loads and of the support reactions on prescribed
motion), damping work W_damp (trapezoidal) and numerical dissipation
W_num = W_ext - W_damp - (K + U - K_0 - U_0): zero for an exactly conserving scheme.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import dolfinx.fem.petsc as fem_petsc
import numpy as np
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .petsc_options import direct_lu, set_defaults
from .shell import inertia, rotation
from .shell.model import ShellModel
from .static import SolverDivergence

__all__ = [
    "ShellSystem",
    "LinearSystem",
    "ImplicitScheme",
    "TimeStepping",
    "Damping",
    "DynamicStep",
    "StableStep",
    "DynamicsDivergence",
    "integrate_implicit",
    "integrate_explicit",
    "integrate_ts_alpha2",
    "stable_time_step",
]

log = logging.getLogger("clothfem.dynamics")

LoadFunction = Callable[[float], float]


class DynamicsDivergence(SolverDivergence):
    """Newton failed at the smallest allowed time step (records so far were delivered)."""


# ---------------------------------------------------------------------------- parameters
def _finite(name: str, value: float, lo: float, hi: float, *, lo_open=False, hi_open=False):
    ok = isinstance(value, int | float) and math.isfinite(value)
    ok = (
        ok and (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    )
    if not ok:
        lb, rb = "(" if lo_open else "[", ")" if hi_open else "]"
        raise ValueError(f"{name} must be in {lb}{lo:g}, {hi:g}{rb}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class ImplicitScheme:
    """Generalized-alpha / Newmark parameters (dimensionless).

    beta, gamma: Newmark parameters (0 < beta <= 1, 0.5 <= gamma <= 1.5).
    alpha_m, alpha_f: weights of the old acceleration / old state in the balance
    (Chung-Hulbert; both 0 for Newmark), alpha_m <= alpha_f <= 1/2.
    Use :meth:`newmark` or :meth:`generalized_alpha`.
    """

    beta: float = 0.25
    gamma: float = 0.5
    alpha_m: float = 0.0
    alpha_f: float = 0.0

    def __post_init__(self) -> None:
        _finite("ImplicitScheme beta", self.beta, 0.0, 1.0, lo_open=True)
        _finite("ImplicitScheme gamma", self.gamma, 0.5, 1.5)
        _finite("ImplicitScheme alpha_f", self.alpha_f, 0.0, 0.5)
        _finite("ImplicitScheme alpha_m", self.alpha_m, -1.0, self.alpha_f)

    @classmethod
    def newmark(cls, *, beta: float = 0.25, gamma: float = 0.5) -> ImplicitScheme:
        """Newmark's method; the default is the (energy-conserving) average acceleration."""
        return cls(beta=beta, gamma=gamma)

    @classmethod
    def generalized_alpha(cls, *, rho_inf: float) -> ImplicitScheme:
        """Chung-Hulbert parameters for the spectral radius ``rho_inf`` in [0, 1] at
        infinite frequency: second order, unconditionally stable, optimal dissipation."""
        _finite("generalized_alpha rho_inf", rho_inf, 0.0, 1.0)
        am = (2 * rho_inf - 1) / (rho_inf + 1)
        af = rho_inf / (rho_inf + 1)
        return cls(beta=0.25 * (1 - am + af) ** 2, gamma=0.5 - am + af, alpha_m=am, alpha_f=af)


@dataclass(frozen=True, kw_only=True)
class TimeStepping:
    """Time-step control [s].

    dt: first step; t_end: final time; dt_min / dt_max: bounds (defaults dt/1024 and dt);
    cut: factor in (0, 1) applied to dt after a failed Newton solve (the step is retried
    from the last accepted state); grow: factor >= 1 applied after ``easy_iterations``
    or fewer Newton iterations without cut-back.
    """

    dt: float
    t_end: float
    dt_min: float | None = None
    dt_max: float | None = None
    cut: float = 0.5
    grow: float = 1.5
    easy_iterations: int = 4

    def __post_init__(self) -> None:
        _finite("TimeStepping dt", self.dt, 0.0, math.inf, lo_open=True, hi_open=True)
        _finite("TimeStepping t_end", self.t_end, 0.0, math.inf, lo_open=True, hi_open=True)
        if self.dt_min is not None:
            _finite("TimeStepping dt_min", self.dt_min, 0.0, self.dt, lo_open=True)
        if self.dt_max is not None:
            _finite("TimeStepping dt_max", self.dt_max, self.dt, math.inf, hi_open=True)
        _finite("TimeStepping cut", self.cut, 0.0, 1.0, lo_open=True, hi_open=True)
        _finite("TimeStepping grow", self.grow, 1.0, math.inf, hi_open=True)
        if not (isinstance(self.easy_iterations, int) and self.easy_iterations >= 0):
            raise ValueError(
                f"TimeStepping easy_iterations must be >= 0, got {self.easy_iterations!r}"
            )

    @property
    def min_step(self) -> float:
        return self.dt / 1024 if self.dt_min is None else self.dt_min

    @property
    def max_step(self) -> float:
        return self.dt if self.dt_max is None else self.dt_max


@dataclass(frozen=True, kw_only=True)
class Damping:
    """Rayleigh damping C = mass M(x) + stiffness K_0 (K_0: tangent at the initial state).

    mass [1/s] >= 0, stiffness [s] >= 0. Default: undamped.
    """

    mass: float = 0.0
    stiffness: float = 0.0

    def __post_init__(self) -> None:
        _finite("Damping mass", self.mass, 0.0, math.inf, hi_open=True)
        _finite("Damping stiffness", self.stiffness, 0.0, math.inf, hi_open=True)

    @property
    def active(self) -> bool:
        return self.mass > 0 or self.stiffness > 0


@dataclass(frozen=True)
class DynamicStep:
    """One accepted time step; energies [J] at the end of the step."""

    step: int
    time: float
    dt: float
    load_factor: float
    newton_iterations: int
    residual_first: float
    residual_final: float
    cutbacks: int
    kinetic: float
    strain: float
    external_work: float  # cumulative since t = 0
    damping_work: float  # cumulative
    dissipation: float  # numerical: W_ext - W_damp - (K + U - K0 - U0)
    wall_time: float
    # explicit: (t_base, step_base, h, n_end), the clock t = t_base + (step - step_base) h
    # up to step n_end after this step (to resume a run whose step shrank exactly)
    clock: tuple[float, int, float, int] | None = None

    @property
    def total(self) -> float:
        """Kinetic + strain energy [J]."""
        return self.kinetic + self.strain

    def line(self) -> str:
        return (
            f"step {self.step:5d}  t {self.time:10.4e}  dt {self.dt:9.3e}"
            f"  newton {self.newton_iterations:2d}"
            f"  cut {self.cutbacks}  K {self.kinetic:10.4e}  U {self.strain:10.4e}"
            f"  W {self.external_work:10.4e}  D_num {self.dissipation:10.3e}"
        )


@dataclass(frozen=True)
class StableStep:
    """Explicit stability estimate: dt_crit = 2/omega_max [s] (Lanczos, an estimate from
    below of omega_max), dt_bound <= the true dt_crit (Gershgorin, rigorous)."""

    dt_crit: float
    omega_max: float
    dt_bound: float
    iterations: int
    converged: bool  # the largest Ritz value's residual bound is below rtol


# rad: an explicit step that leaves a nodal rotation beyond this (every node starts the step
# at |theta| <= the re-basing threshold) has crossed the singularity of the total-rotation
# parametrisation within one step: the run stops there. (A 1-rad limit per step was tried
# and rejected: a sudden load on the physical rotary inertia turns an edge director by ~1
# rad in the first step of a stable run, the director mode being near the Nyquist limit.)
MAX_ROTATION = math.pi


# ---------------------------------------------------------------------------- systems
def _global_sum(comm, value: float) -> float:
    return comm.allreduce(float(value), op=MPI.SUM)


def _block_mult(B: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Blockwise B_A x_A of 2x2 blocks B (n, 2, 2) and x (2 n,) -> (2 n,)."""
    x0, x1 = x[0::2], x[1::2]
    out = np.empty_like(x)
    out[0::2] = B[:, 0, 0] * x0 + B[:, 0, 1] * x1
    out[1::2] = B[:, 1, 0] * x0 + B[:, 1, 1] * x1
    return out


class ShellSystem:
    """The nonlinear :class:`ShellModel` with its inertia, as seen by the integrators.

    rotary_scale (>= 1, dimensionless) multiplies the rotary inertia rho t^3/12 (mass
    scaling of the director equations, which otherwise set the explicit stable step);
    1 is physical.
    """

    def __init__(self, model: ShellModel, *, rotary_scale: float = 1.0) -> None:
        _finite("rotary_scale", rotary_scale, 1.0, math.inf, hi_open=True)
        if not model.material.rho > 0:
            raise ValueError(
                f"material rho must be > 0 kg/m^3 for dynamics, got {model.material.rho!r}"
            )
        self.model, self.comm = model, model.comm
        self.offset = model.v_range[0]
        n = self.n = model.n_owned
        dx = model.dx_full  # N_A N_B of quadratic elements: exact with the full rule
        scale = fem.Constant(model.mesh, float(rotary_scale))
        forms = fem.form(
            [
                [inertia.translational_mass(model.V, model.rho, model.t, dx), None],
                [None, inertia.rotary_mass(model.V, model.rho, model.t, dx, scale)],
            ]
        )
        Mw = fem_petsc.create_matrix_block(forms)
        fem_petsc.assemble_matrix_block(Mw, forms)
        Mw.assemble()
        assert Mw.getOwnershipRange() == model._Kw.getOwnershipRange()
        self._Mw = Mw
        self._w1, self._w2 = Mw.createVecRight(), Mw.createVecRight()
        self._M: PETSc.Mat | None = None
        # HRZ lumping: the diagonal of the consistent mass scaled to the exact total mass
        # (row sums give zero or negative corner masses on quadratic triangles)
        diag = Mw.getDiagonal().getArray(readonly=True)
        m_tot = _global_sum(
            self.comm, fem.assemble_scalar(fem.form(inertia.mass_density(model.rho, model.t, dx)))
        )
        j_tot = _global_sum(
            self.comm,
            fem.assemble_scalar(
                fem.form(inertia.director_mass_density(model.rho, model.t, dx, scale))
            ),
        )
        du, dd = diag[0 : 3 * n : 3], diag[3 * n : 6 * n : 3]
        self.lumped_u = np.repeat(du * m_tot / _global_sum(self.comm, du.sum()), 3)
        self.lumped_d = dd * j_tot / _global_sum(self.comm, dd.sum())
        self.total_mass = m_tot
        self._blocks: np.ndarray | None = None
        self._blocks_at = np.zeros(0)
        self._inverse: np.ndarray | None = None  # of the blocks at _blocks_at

    # state and loads
    def create_vector(self) -> PETSc.Vec:
        return self.model.create_vector()

    def get_state(self, x: PETSc.Vec) -> None:
        self.model.get_state(x)

    def commit(self, x: PETSc.Vec) -> None:
        """Make ``x`` the model's state (outputs, energies, mass at x)."""
        m, n = self.model, self.n
        arr = x.getArray(readonly=True)
        same = np.array_equal(arr[: 3 * n], m.u.x.array[: 3 * n]) and np.array_equal(
            arr[3 * n :], m.theta.x.array[: 2 * n]
        )
        if not self.comm.allreduce(same, op=MPI.LAND):
            m.set_state(x)

    def set_load(self, lam: float) -> None:
        self.model.set_load_factor(lam)

    def set_time_step(self, dt: float) -> None:
        """The size [s] of the step about to be taken (rate-dependent material terms)."""
        self.model.set_time_step(dt)

    def bc(self, lam: float) -> tuple[np.ndarray, np.ndarray]:
        return self.model.bc_rows_and_values(lam)

    # forces and matrices
    def residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None:
        """f = f_int(x) - f_ext(x, lam) (state set to x)."""
        self.model.residual(x, f)

    def forces(self, x: PETSc.Vec, lam: float, r: PETSc.Vec, fe: PETSc.Vec) -> None:
        """r = f_int - f_ext and fe = f_ext at (x, lam) (one internal-force assembly)."""
        self.set_load(lam)
        self.model.forces(x, r, fe)

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat | None = None) -> PETSc.Mat:
        return self.model.jacobian(x, K)

    def mass_mult(self, a: PETSc.Vec, out: PETSc.Vec) -> None:
        """out = M(x) a at the current state of the model."""
        P = self.model.rotation_map()
        P.mult(a, self._w1)
        self._Mw.mult(self._w1, self._w2)
        P.multTranspose(self._w2, out)

    def mass_matrix(self) -> PETSc.Mat:
        """M(x) = P^T M_w P at the current state (the matrix is reused)."""
        if self._M is None:
            self._M = self._Mw.ptap(self.model.rotation_map())
        else:
            self._Mw.ptap(self.model.rotation_map(), result=self._M)
        return self._M

    def _theta_blocks(self) -> np.ndarray:
        """Lumped 2x2 rotary blocks m_A T_A^T T_A at the current rotations (cached)."""
        n = self.n
        th = self.model.theta.x.array[: 2 * n]
        if self._blocks is None or not np.array_equal(th, self._blocks_at):
            T = self.model.director_jacobian()
            t1, t2 = T[:, :, 0], T[:, :, 1]  # (component formulas: einsum is ~4x slower here)
            B = np.empty((n, 2, 2))
            B[:, 0, 0] = (t1 * t1).sum(axis=1)
            B[:, 0, 1] = B[:, 1, 0] = (t1 * t2).sum(axis=1)
            B[:, 1, 1] = (t2 * t2).sum(axis=1)
            self._blocks = self.lumped_d[:, None, None] * B
            self._blocks_at = th.copy()
            self._inverse = None
        return self._blocks

    def _theta_inverse(self) -> np.ndarray:
        """Inverses of the 2x2 rotary blocks (Cramer's rule: one NumPy pass, no LAPACK call
        per block); ``LinAlgError`` if a block is singular (det 0 or not finite)."""
        B = self._theta_blocks()
        if self._inverse is None:
            a, b, c, d = B[:, 0, 0], B[:, 0, 1], B[:, 1, 0], B[:, 1, 1]
            det = a * d - b * c
            if not np.all(np.isfinite(det) & (det != 0.0)):
                raise np.linalg.LinAlgError("a lumped 2x2 rotary block is singular")
            inv = np.empty_like(B)
            inv[:, 0, 0], inv[:, 0, 1], inv[:, 1, 0], inv[:, 1, 1] = d, -b, -c, a
            self._inverse = inv / det[:, None, None]
        return self._inverse

    def max_rotation(self) -> float:
        """The largest nodal director rotation |theta| [rad] over all ranks (collective)."""
        th = self.model.theta.x.array[: 2 * self.n].reshape(self.n, 2)
        local = float(np.hypot(th[:, 0], th[:, 1]).max(initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)

    def rebase(self, x: PETSc.Vec, v: PETSc.Vec, a: PETSc.Vec, *, threshold: float) -> None:
        """Re-base the model's strongly rotated nodes (:meth:`ShellModel.rebase`) at the
        committed state ``x`` and express the rotation rates ``v`` and accelerations ``a`` in
        the new bases through the director rate, d' = T(theta) theta' (the second-derivative
        term of a is neglected, as the gyroscopic inertia is)."""
        m, n = self.model, self.n
        th = m.theta.x.array[: 2 * n].reshape(n, 2)
        T = rotation.director_tangent(m.basis[:n], th)
        va, aa = v.getArray()[3 * n :].reshape(n, 2), a.getArray()[3 * n :].reshape(n, 2)
        d_rate = np.einsum("nka,na->nk", T, va)
        d_acc = np.einsum("nka,na->nk", T, aa)
        nodes = m.rebase(threshold=threshold)
        own = nodes[nodes < n]
        if len(own):
            e1, e2 = m.basis[own, 0], m.basis[own, 1]  # dd/dtheta at 0: (-e2, e1)
            for arr, rate in ((va, d_rate), (aa, d_acc)):
                arr[own, 0] = -np.einsum("nk,nk->n", e2, rate[own])
                arr[own, 1] = np.einsum("nk,nk->n", e1, rate[own])
            x.getArray()[3 * n :].reshape(n, 2)[own] = 0.0

    def lumped_solve(self, f: np.ndarray) -> np.ndarray:
        """M_L^{-1} f (local owned arrays) at the current state."""
        n = self.n
        out = np.empty_like(f)
        out[: 3 * n] = f[: 3 * n] / self.lumped_u
        out[3 * n :] = _block_mult(self._theta_inverse(), f[3 * n :])
        return out

    def lumped_mult(self, v: np.ndarray) -> np.ndarray:
        n = self.n
        out = np.empty_like(v)
        out[: 3 * n] = v[: 3 * n] * self.lumped_u
        out[3 * n :] = _block_mult(self._theta_blocks(), v[3 * n :])
        return out

    def lumped_min(self) -> np.ndarray:
        """A diagonal D <= M_L (per row) for the Gershgorin bound."""
        eig = np.linalg.eigvalsh(self._theta_blocks())[:, 0]
        return np.concatenate([self.lumped_u, np.repeat(eig, 2)])

    def strain_energy(self) -> float:
        return self.model.strain_energy()

    def start_vector(self, x: PETSc.Vec) -> None:
        """A deterministic, partition-independent start vector (from node coordinates)."""
        n = self.n
        X = self.model.x_nodes[:n]
        s = X @ np.array([1.37, 2.11, 3.07])
        arr = x.getArray()
        arr[: 3 * n] = np.sin(s[:, None] * 7.1 + np.arange(3)).ravel()
        arr[3 * n :] = np.cos(s[:, None] * 5.3 + np.arange(2)).ravel()


class LinearSystem:
    """A linear system M a + K x = lam(t) f with fixed matrices (PETSc, same row layout).

    ``bc`` returns (local rows, values) at a load factor, as the shell model's supports;
    ``lumped`` is the lumped mass (local array; default: row sums of M). Use
    :meth:`linearised` for the shell linearised about its current (unloaded) state.
    ``model`` (optional) receives the state on :meth:`commit` (for outputs).
    """

    def __init__(
        self,
        *,
        K: PETSc.Mat,
        M: PETSc.Mat,
        f: PETSc.Vec | None = None,
        bc: Callable[[float], tuple[np.ndarray, np.ndarray]] | None = None,
        lumped: np.ndarray | None = None,
        model: ShellModel | None = None,
    ) -> None:
        self.K, self.M, self.comm = K, M, K.getComm().tompi4py()
        self.offset = K.getOwnershipRange()[0]
        self.f = f if f is not None else K.createVecRight()
        self._bc = bc
        if lumped is None:
            ones = K.createVecRight()
            ones.set(1.0)
            out = K.createVecRight()
            M.mult(ones, out)
            lumped = out.getArray().copy()
        self.lumped = np.asarray(lumped, dtype=float)
        if np.any(self.lumped <= 0):
            raise ValueError("LinearSystem lumped mass must be > 0 in every row")
        self.model = model
        self._x = K.createVecRight()
        self._tmp = K.createVecRight()
        self._lam = 0.0

    @classmethod
    def linearised(cls, model: ShellModel, *, rotary_scale: float = 1.0) -> LinearSystem:
        """The shell linearised about its current state (unloaded: lam = 0)."""
        sys = ShellSystem(model, rotary_scale=rotary_scale)
        x0 = model.create_vector()
        model.get_state(x0)
        r, fe = x0.duplicate(), x0.duplicate()
        sys.forces(x0, 1.0, r, fe)
        model.set_load_factor(0.0)
        K = model.jacobian(x0)
        M = sys.mass_matrix().copy()
        lumped = sys.lumped_mult(np.ones(x0.getLocalSize()))
        return cls(K=K, M=M, f=fe, bc=model.bc_rows_and_values, lumped=lumped, model=model)

    def create_vector(self) -> PETSc.Vec:
        return self.K.createVecRight()

    def get_state(self, x: PETSc.Vec) -> None:
        self._x.copy(x)

    def commit(self, x: PETSc.Vec) -> None:
        x.copy(self._x)
        if self.model is not None:
            self.model.set_state(x)

    def set_load(self, lam: float) -> None:
        self._lam = float(lam)

    def set_time_step(self, dt: float) -> None:
        """Nothing: the linear system has no rate-dependent terms."""

    def bc(self, lam: float) -> tuple[np.ndarray, np.ndarray]:
        if self._bc is None:
            return np.zeros(0, dtype=np.int32), np.zeros(0)
        return self._bc(lam)

    def residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None:
        self.K.mult(x, f)
        f.axpy(-self._lam, self.f)

    def forces(self, x: PETSc.Vec, lam: float, r: PETSc.Vec, fe: PETSc.Vec) -> None:
        self.set_load(lam)
        self.f.copy(fe)
        fe.scale(lam)
        self.residual(x, r)

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat | None = None) -> PETSc.Mat:
        if K is None:
            K = self.K.copy()
            K.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)  # zeroRows keeps it
            return K
        self.K.copy(K, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        return K

    def mass_mult(self, a: PETSc.Vec, out: PETSc.Vec) -> None:
        self.M.mult(a, out)

    def mass_matrix(self) -> PETSc.Mat:
        return self.M

    def lumped_solve(self, f: np.ndarray) -> np.ndarray:
        return f / self.lumped

    def lumped_mult(self, v: np.ndarray) -> np.ndarray:
        return v * self.lumped

    def lumped_min(self) -> np.ndarray:
        return self.lumped

    def strain_energy(self) -> float:
        self.K.mult(self._x, self._tmp)
        return 0.5 * self._tmp.dot(self._x)

    def start_vector(self, x: PETSc.Vec) -> None:
        r0, r1 = x.getOwnershipRange()
        x.setArray(np.sin(7.1 * np.arange(r0, r1) + 0.3))


def rotation_note(s) -> str:
    """A diagnosis to append to a failure message when some nodal director rotation is near
    pi, where the total-rotation parametrisation of :mod:`clothfem.shell.rotation` is
    singular (dd/dtheta loses rank and the dropped inertia terms stop being small). Planar
    rotations pass pi without harm, so this explains failures rather than forbidding them."""
    if not isinstance(s, ShellSystem):
        return ""
    worst = s.max_rotation()
    if math.isfinite(worst) and abs(worst - math.pi) > 0.15 * math.pi:
        return ""
    return (
        f"; a nodal director rotation is at |theta| = {worst:.3f} rad, near the singularity at "
        "pi of the total-rotation parametrisation"
    )


def _as_system(obj) -> ShellSystem | LinearSystem:
    return ShellSystem(obj) if isinstance(obj, ShellModel) else obj


def _load_fn(load: LoadFunction | None) -> LoadFunction:
    if load is None:
        return lambda t: 1.0

    def checked(t: float) -> float:
        lam = float(load(t))
        if not math.isfinite(lam):
            raise ValueError(f"load(t) must be finite, got {lam!r} at t = {t:g}")
        return lam

    return checked


# ---------------------------------------------------------------------------- bookkeeping
class _Energy:
    """Kinetic, strain, external and damping work; numerical dissipation."""

    def __init__(self, system, x, v, a, lam, damping: Damping, K0, lumped: bool) -> None:
        self.s, self.damping, self.K0, self.lumped = system, damping, K0, lumped
        self.g = x.duplicate()  # generalised force doing work on x
        self.tmp, self.r, self.fe, self.Ma = (
            x.duplicate(),
            x.duplicate(),
            x.duplicate(),
            x.duplicate(),
        )
        self.W_ext = 0.0
        self.ready = False  # True: self.r, self.fe already hold the forces at the new state
        self.W_damp = 0.0
        self.K, self.U = self._measure(x, v, a, lam, self.g)
        self.E0 = self.K + self.U
        self.cvv = self._cvv(v)

    def _kinetic(self, v) -> float:
        if self.lumped:
            return 0.5 * _global_sum(
                self.s.comm,
                np.dot(v.getArray(readonly=True), self.s.lumped_mult(v.getArray(readonly=True))),
            )
        self.s.mass_mult(v, self.tmp)
        return 0.5 * self.tmp.dot(v)

    def _cvv(self, v) -> float:
        if not self.damping.active:
            return 0.0
        out = 0.0
        if self.damping.mass > 0:
            out += self.damping.mass * 2 * self._kinetic(v)
        if self.damping.stiffness > 0:
            self.K0.mult(v, self.tmp)
            out += self.damping.stiffness * self.tmp.dot(v)
        return out

    def _measure(self, x, v, a, lam, g, strain: bool = True) -> tuple[float, float]:
        """Energies at (x, v, a) and the generalised force g (loads; reactions on bc rows);
        ``strain=False``: the strain energy is not assembled (nan)."""
        s = self.s
        if not self.ready:
            s.forces(x, lam, self.r, self.fe)  # state at x
        self.fe.copy(g)
        rows, _ = s.bc(lam)
        # collective calls on every rank, whether it owns prescribed rows or not
        if self.lumped:
            ma = s.lumped_mult(a.getArray(readonly=True))
        else:
            s.mass_mult(a, self.Ma)
            ma = self.Ma.getArray(readonly=True)
        reaction = ma + self.r.getArray(readonly=True) + self.fe.getArray(readonly=True)
        if self.damping.active:
            reaction = reaction + self._damping_force(v)
        g.getArray()[rows] = reaction[rows]
        if not self.lumped:  # force scale for the Newton tolerances of the implicit step
            f_int = self.r.copy()
            f_int.axpy(1.0, self.fe)
            self.fscale = max(self.fe.norm(), f_int.norm())
            f_int.destroy()
        return self._kinetic(v), s.strain_energy() if strain else math.nan

    def _damping_force(self, v) -> np.ndarray:
        out = np.zeros(v.getLocalSize())
        if self.damping.mass > 0:
            if self.lumped:
                out += self.damping.mass * self.s.lumped_mult(v.getArray(readonly=True))
            else:
                self.s.mass_mult(v, self.tmp)
                out += self.damping.mass * self.tmp.getArray(readonly=True)
        if self.damping.stiffness > 0:
            self.K0.mult(v, self.tmp)
            out += self.damping.stiffness * self.tmp.getArray(readonly=True)
        return out

    def advance(
        self, x_old, x, v, a, lam, dt, strain: bool = True
    ) -> tuple[float, float, float, float, float]:
        """The energies after a step; ``strain=False`` skips the strain energy's assembly
        (U and the dissipation are then nan; the work is accumulated all the same)."""
        g_old = self.g.copy()
        self.K, self.U = self._measure(x, v, a, lam, self.g, strain)
        dx = x.copy()
        dx.axpy(-1.0, x_old)
        g_old.axpy(1.0, self.g)
        self.W_ext += 0.5 * g_old.dot(dx)
        cvv = self._cvv(v)
        self.W_damp += 0.5 * dt * (self.cvv + cvv)
        self.cvv = cvv
        g_old.destroy()
        dx.destroy()
        diss = self.W_ext - self.W_damp - (self.K + self.U - self.E0)
        return self.K, self.U, self.W_ext, self.W_damp, diss


# ---------------------------------------------------------------------------- implicit
_SNES_DEFAULTS = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "basic",
    "snes_rtol": 1e-9,
    "snes_atol": 1e-30,
    "snes_stol": 1e-12,
    "snes_max_it": 15,
    "snes_error_if_not_converged": False,
}


class _ImplicitStepper:
    """One generalized-alpha step x_n -> x_{n+1} solved by SNES on x_{n+1}."""

    def __init__(self, system, scheme: ImplicitScheme, damping: Damping, K0, prefix: str) -> None:
        self.s, self.sc, self.damping, self.K0 = system, scheme, damping, K0
        x = system.create_vector()
        self.x = x
        self.xn, self.vn, self.an = x.duplicate(), x.duplicate(), x.duplicate()
        self.a1, self.v1, self.xa, self.va, self.aa = (x.duplicate() for _ in range(5))
        self.tmp, self.f = x.duplicate(), x.duplicate()
        system.get_state(self.x)
        self.J = system.jacobian(self.x)
        self.h = 1.0
        self.lam_a = 0.0
        self.rows = np.zeros(0, dtype=np.int32)
        self.values = np.zeros(0)
        self.fscale = 0.0
        opts = PETSc.Options()
        set_defaults(prefix, {**_SNES_DEFAULTS, **direct_lu(system.comm)})
        self.floor_rtol = opts.getReal(prefix + "newton_floor_rtol", 1e-7)
        snes = PETSc.SNES().create(system.comm)
        snes.setOptionsPrefix(prefix)
        snes.setFunction(self._residual, self.f)
        snes.setJacobian(self._jacobian, self.J)
        snes.setFromOptions()
        snes.setConvergenceTest(self._converged)
        self.snes = snes
        self.norms: list[float] = []

    # kinematics of the scheme
    def _update(self, x) -> None:
        b, g, h = self.sc.beta, self.sc.gamma, self.h
        am, af = self.sc.alpha_m, self.sc.alpha_f
        # a1 = (x - xn - h vn)/(b h^2) - (1/(2b) - 1) an
        x.copy(self.a1)
        self.a1.axpy(-1.0, self.xn)
        self.a1.axpy(-h, self.vn)
        self.a1.scale(1.0 / (b * h * h))
        self.a1.axpy(-(0.5 / b - 1.0), self.an)
        # v1 = vn + h ((1-g) an + g a1)
        self.vn.copy(self.v1)
        self.v1.axpy(h * (1 - g), self.an)
        self.v1.axpy(h * g, self.a1)
        # alpha-level quantities
        self.xa.set(0.0)
        self.xa.axpy(1 - af, x)
        self.xa.axpy(af, self.xn)
        self.va.set(0.0)
        self.va.axpy(1 - af, self.v1)
        self.va.axpy(af, self.vn)
        self.aa.set(0.0)
        self.aa.axpy(1 - am, self.a1)
        self.aa.axpy(am, self.an)

    def _residual(self, snes, x, f) -> None:
        self._update(x)
        self.s.residual(self.xa, f)  # state at x_alpha, load at lam_alpha
        self.s.mass_mult(self.aa, self.tmp)
        f.axpy(1.0, self.tmp)
        if self.damping.mass > 0:
            self.s.mass_mult(self.va, self.tmp)
            f.axpy(self.damping.mass, self.tmp)
        if self.damping.stiffness > 0:
            self.K0.mult(self.va, self.tmp)
            f.axpy(self.damping.stiffness, self.tmp)
        if len(self.rows):
            xa, fa = x.getArray(readonly=True), f.getArray()
            fa[self.rows] = xa[self.rows] - self.values

    def _jacobian(self, snes, x, J, P) -> None:
        b, g, h = self.sc.beta, self.sc.gamma, self.h
        am, af = self.sc.alpha_m, self.sc.alpha_f
        self._update(x)
        self.s.jacobian(self.xa, J)
        J.scale(1 - af)
        c_v = (1 - af) * g / (b * h)
        c_m = (1 - am) / (b * h * h) + self.damping.mass * c_v
        J.axpy(c_m, self.s.mass_matrix(), structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        if self.damping.stiffness > 0:
            J.axpy(
                self.damping.stiffness * c_v,
                self.K0,
                structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN,
            )
        J.zeroRows(self.rows + self.s.offset, diag=1.0)  # collective

    def _converged(self, snes, it, norms) -> int:
        xnorm, snorm, fnorm = norms
        self.norms.append(fnorm)
        rtol, atol, stol, max_it = snes.getTolerances()
        ref = max(self.norms[0], self.fscale)
        C = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return C.DIVERGED_FNORM_NAN
        if fnorm <= atol:
            return C.CONVERGED_FNORM_ABS
        if it == 0:
            return C.ITERATING
        if fnorm <= rtol * ref:
            return C.CONVERGED_FNORM_RELATIVE
        if snorm <= stol * xnorm:
            return C.CONVERGED_SNORM_RELATIVE
        if it >= 2 and fnorm <= self.floor_rtol * ref and fnorm > 0.5 * self.norms[-2]:
            return C.CONVERGED_FNORM_RELATIVE
        if it >= max_it:
            return C.DIVERGED_MAX_IT
        return C.ITERATING

    def solve(self, h: float, lam_a: float, lam1: float) -> tuple[bool, int, float, float]:
        """Solve for x_{n+1} (in self.x) from (xn, vn, an); loads at lam_a, bcs at lam1."""
        self.h = h
        self.s.set_load(lam_a)
        self.rows, self.values = self.s.bc(lam1)
        # predictor: same acceleration
        self.xn.copy(self.x)
        self.x.axpy(h, self.vn)
        self.x.axpy(0.5 * h * h, self.an)
        if len(self.rows):
            self.x.getArray()[self.rows] = self.values
        self.norms = []
        self.snes.solve(None, self.x)
        ok = self.snes.getConvergedReason() > 0
        finite = bool(np.all(np.isfinite(self.x.getArray(readonly=True))))
        ok = bool(self.s.comm.allreduce(ok and finite, op=MPI.LAND))
        norms = self.norms or [float("nan")]
        if ok:
            self._update(self.x)
        return ok, self.snes.getIterationNumber(), norms[0], norms[-1]


def _initial_acceleration(system, x, v, lam, damping: Damping, K0, prefix: str) -> PETSc.Vec:
    """Solve M(x0) a0 = f_ext - f_int - C v0 on the free rows; a0 = 0 on prescribed rows."""
    system.set_load(lam)
    rhs = x.duplicate()
    system.residual(x, rhs)  # state at x
    rhs.scale(-1.0)
    a = x.duplicate()
    tmp = x.duplicate()
    if damping.mass > 0:
        system.mass_mult(v, tmp)
        rhs.axpy(-damping.mass, tmp)
    if damping.stiffness > 0:
        K0.mult(v, tmp)
        rhs.axpy(-damping.stiffness, tmp)
    M = system.mass_matrix().copy()
    rows, _ = system.bc(lam)
    M.zeroRows(rows + system.offset, diag=1.0)  # collective
    rhs.getArray()[rows] = 0.0
    ksp = PETSc.KSP().create(system.comm)
    ksp.setOptionsPrefix(prefix + "mass_")
    ksp.setOperators(M)
    set_defaults(prefix + "mass_", direct_lu(system.comm))
    ksp.setFromOptions()
    ksp.solve(rhs, a)
    ksp.destroy()
    M.destroy()
    return a


def _start(system, velocity):
    x = system.create_vector()
    system.get_state(x)
    v = x.duplicate()
    if velocity is not None:
        velocity.copy(v)
    return x, v


def _initial_K0(system, x, damping: Damping):
    if damping.stiffness > 0:
        K0 = system.jacobian(x)
        rows, _ = system.bc(0.0)
        K0.zeroRows(rows + system.offset, diag=0.0)  # collective
        return K0
    return None


def integrate_implicit(
    system: ShellModel | ShellSystem | LinearSystem,
    *,
    stepping: TimeStepping,
    scheme: ImplicitScheme = ImplicitScheme(),
    load: LoadFunction | None = None,
    damping: Damping = Damping(),
    velocity: PETSc.Vec | None = None,
    on_step: Callable[[DynamicStep], None] | None = None,
    prefix: str = "dyn_",
    rebase: float | None = 0.5,
) -> list[DynamicStep]:
    """Integrate from t = 0 (displacement: the system's current state; velocity:
    ``velocity`` or zero; acceleration from the balance at t = 0) to ``stepping.t_end``.

    A failed Newton solve restores the last accepted state and retries with dt * cut
    (logged); below ``stepping.min_step`` raises :class:`DynamicsDivergence` after the
    accepted steps were passed to ``on_step``. Returns the accepted step records.
    """
    stepper = ImplicitStepper(
        system,
        stepping=stepping,
        scheme=scheme,
        load=load,
        damping=damping,
        velocity=velocity,
        prefix=prefix,
        rebase=rebase,
    )
    records = []
    while not stepper.done:
        rec = stepper.step()
        records.append(rec)
        log.info(rec.line())
        if on_step is not None:
            on_step(rec)
    return records


class ImplicitStepper:
    """The implicit integration of :func:`integrate_implicit` one accepted step per
    :meth:`step` call (Newton with cut-backs inside), from t = 0 or, to continue a run,
    from ``time`` [s] after ``first_step`` steps with the state's ``velocity`` and
    ``acceleration``, the step ``dt`` [s] in use and the ``work`` (external, damping) [J]
    done so far; the state is the system's and ``v``, ``a``."""

    def __init__(
        self,
        system: ShellModel | ShellSystem | LinearSystem,
        *,
        stepping: TimeStepping,
        scheme: ImplicitScheme = ImplicitScheme(),
        load: LoadFunction | None = None,
        damping: Damping = Damping(),
        velocity: PETSc.Vec | None = None,
        acceleration: PETSc.Vec | None = None,
        time: float = 0.0,
        first_step: int = 0,
        dt: float | None = None,
        work: tuple[float, float] = (0.0, 0.0),
        prefix: str = "dyn_",
        rebase: float | None = 0.5,
    ) -> None:
        s = self.system = _as_system(system)
        self.lam_of, self.stepping, self.rebase = _load_fn(load), stepping, rebase
        x, v = _start(s, velocity)
        self.lam_n = self.lam_of(time)
        K0 = _initial_K0(s, x, damping)
        if acceleration is None:
            acceleration = _initial_acceleration(s, x, v, self.lam_n, damping, K0, prefix)
        self.st = _ImplicitStepper(s, scheme, damping, K0, prefix)
        x.copy(self.st.xn)
        v.copy(self.st.vn)
        acceleration.copy(self.st.an)
        self.energy = _Energy(s, x, v, acceleration, self.lam_n, damping, K0, lumped=False)
        self.energy.W_ext, self.energy.W_damp = (float(w) for w in work)
        s.commit(x)
        self.t, self.h = float(time), stepping.dt if dt is None else float(dt)
        self.step_index = first_step

    @property
    def done(self) -> bool:
        """Whether ``stepping.t_end`` is reached."""
        return self.t >= self.stepping.t_end * (1 - 1e-12)

    @property
    def v(self) -> PETSc.Vec:
        return self.st.vn

    @property
    def a(self) -> PETSc.Vec:
        return self.st.an

    def step(self) -> DynamicStep:
        """One accepted step: a failed Newton solve restores the last accepted state and
        retries with dt * cut; below ``stepping.min_step`` raises :class:`DynamicsDivergence`."""
        s, st, stepping = self.system, self.st, self.stepping
        t, af = self.t, st.sc.alpha_f
        h_try = min(self.h, stepping.t_end - t)
        cutbacks = 0
        t0 = time.perf_counter()
        while True:
            lam1 = self.lam_of(t + h_try)
            lam_a = (1 - af) * lam1 + af * self.lam_n
            st.fscale = self.energy.fscale
            s.set_time_step(h_try)
            ok, its, r0, r1 = st.solve(h_try, lam_a, lam1)
            if ok:
                break
            cutbacks += 1
            log.warning(
                "t = %.6g: Newton failed with dt = %.4g after %d iterations (|R| %.3e -> %.3e); "
                "retrying with dt = %.4g",
                t,
                h_try,
                its,
                r0,
                r1,
                h_try * stepping.cut,
            )
            s.commit(st.xn)
            h_try *= stepping.cut
            if h_try < stepping.min_step * (1 - 1e-12):
                raise DynamicsDivergence(
                    f"Newton failed at t = {t:.6g} with dt = {h_try / stepping.cut:.3g}: next dt "
                    f"{h_try:.3g} below dt_min {stepping.min_step:.3g} after {cutbacks} cut-backs "
                    f"(last residual {r1:.3e}); {self.step_index} accepted steps were delivered"
                    + rotation_note(s)
                )
        self.t = t = t + h_try
        self.step_index += 1
        s.commit(st.x)
        K, U, W, Wd, diss = self.energy.advance(st.xn, st.x, st.v1, st.a1, lam1, h_try)
        st.x.copy(st.xn)
        st.v1.copy(st.vn)
        st.a1.copy(st.an)
        if self.rebase is not None and isinstance(s, ShellSystem):
            s.rebase(st.xn, st.vn, st.an, threshold=self.rebase)
            st.xn.copy(st.x)
        self.lam_n = lam1
        wall = time.perf_counter() - t0
        rec = DynamicStep(
            self.step_index, t, h_try, lam1, its, r0, r1, cutbacks, K, U, W, Wd, diss, wall
        )
        if its <= stepping.easy_iterations and cutbacks == 0:
            self.h = min(h_try * stepping.grow, stepping.max_step)
        else:
            self.h = h_try
        return rec


# ---------------------------------------------------------------------------- PETSc TS alpha2
def integrate_ts_alpha2(
    system: ShellModel | ShellSystem | LinearSystem,
    *,
    dt: float,
    t_end: float,
    scheme: ImplicitScheme = ImplicitScheme(),
    load: LoadFunction | None = None,
    velocity: PETSc.Vec | None = None,
    on_step: Callable[[DynamicStep], None] | None = None,
    prefix: str = "dyn_ts_",
) -> list[DynamicStep]:
    """The same equations through PETSc TS ``alpha2`` (for comparison with
    :func:`integrate_implicit`; prefer that one: TS estimates the initial acceleration by
    backward Euler, so the answers are only first-order accurate in dt, see the module
    docstring).

    ``scheme`` is passed as ``<prefix>ts_alpha_alpha_m/alpha_f/gamma/beta`` in PETSc's
    convention (alpha = 1 - the Chung-Hulbert alpha: 1, 1 is Newmark); any of them, or
    ``<prefix>ts_alpha_radius``, given on the command line wins. Other options:
    ``<prefix>ts_adapt_type`` (default none: fixed dt; TS still cuts dt after a failed
    Newton solve, ``ts_max_snes_failures`` unlimited), ``<prefix>snes_*``, ``<prefix>ksp_*``.
    Prescribed rows are enforced at the stage (alpha-level) time.
    Step records: kinetic and strain energy; ``external_work`` counts the loads only (TS does
    not expose the acceleration needed for the reactions: exact for fixed supports);
    ``cutbacks`` counts the steps TS rejected; no damping (``damping_work`` = 0).
    """
    _finite("dt", dt, 0.0, math.inf, lo_open=True, hi_open=True)
    _finite("t_end", t_end, 0.0, math.inf, lo_open=True, hi_open=True)
    s = _as_system(system)
    lam_of = _load_fn(load)
    x, v = _start(s, velocity)
    lam0 = lam_of(0.0)
    a = _initial_acceleration(s, x, v, lam0, Damping(), None, prefix)
    opts = PETSc.Options()
    if not opts.hasName(prefix + "ts_alpha_radius"):  # the scheme argument, unless a radius
        opts.setValue(prefix + "ts_alpha_alpha_m", 1.0 - scheme.alpha_m)
        opts.setValue(prefix + "ts_alpha_alpha_f", 1.0 - scheme.alpha_f)
        opts.setValue(prefix + "ts_alpha_gamma", scheme.gamma)
        opts.setValue(prefix + "ts_alpha_beta", scheme.beta)
    set_defaults(prefix, {"ts_adapt_type": "none", **_SNES_DEFAULTS, **direct_lu(s.comm)})
    tmp, f_res = x.duplicate(), x.duplicate()
    J = s.jacobian(x)

    def bc(t):
        return s.bc(lam_of(t))

    def i2function(ts, t, U, V, A, F):
        s.set_load(lam_of(t))
        s.residual(U, F)
        s.mass_mult(A, tmp)
        F.axpy(1.0, tmp)
        rows, values = bc(t)
        F.getArray()[rows] = U.getArray(readonly=True)[rows] - values

    def i2jacobian(ts, t, U, V, A, shift_v, shift_a, Jm, P):
        s.jacobian(U, Jm)
        Jm.axpy(shift_a, s.mass_matrix(), structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        rows, _ = bc(t)
        Jm.zeroRows(rows + s.offset, diag=1.0)  # collective

    ts = PETSc.TS().create(comm=s.comm)
    ts.setOptionsPrefix(prefix)
    ts.setType(PETSc.TS.Type.ALPHA2)
    ts.setI2Function(i2function, f_res)
    ts.setI2Jacobian(i2jacobian, J)
    ts.setTime(0.0)
    ts.setTimeStep(dt)
    ts.setMaxTime(t_end)
    ts.setExactFinalTime(PETSc.TS.ExactFinalTime.MATCHSTEP)
    ts.setMaxSNESFailures(-1)
    ts.setFromOptions()
    energy = _Energy(s, x, v, a, lam0, Damping(), None, lumped=False)
    s.commit(x)
    records: list[DynamicStep] = []
    state = {"t": 0.0, "x": x.copy(), "its": 0, "rej": 0, "wall": time.perf_counter()}
    zero = x.duplicate()

    def post_step(ts) -> None:
        U, V = ts.getSolution2()
        t = ts.getTime()
        lam = lam_of(t)
        s.commit(U)
        rows, _ = s.bc(lam)
        g_old = energy.g.copy()
        K, Ue = energy._measure(U, V, zero, lam, energy.g)
        energy.g.getArray()[rows] = 0.0
        g_old.axpy(1.0, energy.g)
        dx = U.copy()
        dx.axpy(-1.0, state["x"])
        energy.W_ext += 0.5 * g_old.dot(dx)
        U.copy(state["x"])
        its, rej = ts.getSNESIterations(), ts.getStepRejections()
        now = time.perf_counter()
        rec = DynamicStep(
            len(records) + 1, t, t - state["t"], lam, its - state["its"], math.nan, math.nan,
            rej - state["rej"], K, Ue, energy.W_ext, 0.0, energy.W_ext - (K + Ue - energy.E0),
            now - state["wall"],
        )  # fmt: skip
        state.update(t=t, its=its, rej=rej, wall=now)
        records.append(rec)
        log.info(rec.line())
        if on_step is not None:
            on_step(rec)

    energy.g.getArray()[s.bc(lam0)[0]] = 0.0
    ts.setPostStep(post_step)
    ts.setSolution2(x, v)
    ts.solve(x)
    if ts.getConvergedReason() < 0:
        raise DynamicsDivergence(
            f"TS alpha2 stopped at t = {ts.getTime():.6g} ({ts.getConvergedReason()}); "
            f"{len(records)} accepted steps were delivered"
        )
    ts.destroy()
    return records


# ---------------------------------------------------------------------------- explicit
def stable_time_step(
    system: ShellModel | ShellSystem | LinearSystem,
    *,
    iterations: int = 300,
    rtol: float = 1e-4,
    lam: float = 0.0,
) -> StableStep:
    """Stable step of the central difference with the lumped mass at the current state.

    omega_max^2 = the largest eigenvalue of M_L^-1 K on the free rows (K: tangent at the
    current state and load factor ``lam``), by Lanczos in the M_L inner product with full
    reorthogonalisation (at most ``iterations`` steps), stopping when the largest Ritz value
    theta has the residual bound |beta_k s_k| <= ``rtol`` theta (an eigenvalue lies within
    it). Ritz values approach omega_max^2 from below, so ``dt_crit`` can be slightly
    optimistic if not converged; ``dt_bound`` (Gershgorin: omega_max^2 <= max_i sum_j
    |K_ij| / m_i) is a safe step. Measured on the arm sleeve (16x20 / 32x40 meshes, against
    the value converged to 1e-9): rtol 1e-4 stops after 119 / 142 steps with omega_max^2 low
    by 3.1e-5 / 2.8e-5 (dt_crit high by half that); the power iteration used before did not
    meet a change of 1e-6 in 300 iterations there (clustered top eigenvalues).
    Undamped limit: mass damping lowers the limit to (2/omega)(sqrt(1 + xi^2) - xi).
    """
    from scipy.linalg import eigh_tridiagonal

    if not (isinstance(iterations, int) and iterations >= 1):
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    s = _as_system(system)
    x = s.create_vector()
    s.get_state(x)
    s.set_load(lam)
    K = s.jacobian(x)
    rows, _ = s.bc(lam)
    z, y = x.duplicate(), x.duplicate()
    s.start_vector(z)
    q = z.getArray().copy()
    q[rows] = 0.0
    nrm = math.sqrt(_global_sum(s.comm, np.dot(q, s.lumped_mult(q))))
    # Lanczos vectors q_j as the columns of one array (filled in place: the
    # reorthogonalisation reads its first k columns) and M_L q_j (local rows)
    basis, mbasis = np.empty((len(q), iterations)), []
    alpha, beta = [], []
    lam_k, k, converged = 0.0, 0, False
    w = q / nrm if nrm > 0 else q
    for k in range(1, iterations + 1):  # noqa: B007
        qk = w
        basis[:, k - 1] = qk
        mbasis.append(s.lumped_mult(qk))
        z.setArray(qk)
        K.mult(z, y)
        ky = y.getArray(readonly=True).copy()
        ky[rows] = 0.0
        alpha.append(_global_sum(s.comm, np.dot(qk, ky)))  # q.K q (q.M q = 1)
        w = s.lumped_solve(ky)  # M^-1 K q; bc rows zeroed (exact when M_L does not couple
        w[rows] = 0.0  # a fixed and a free row of a node, as for the clamps here)
        # full reorthogonalisation against every q_i (twice is enough), one reduction each
        for _ in range(2):
            c = np.array([np.dot(mq, w) for mq in mbasis])
            c = s.comm.allreduce(c, op=MPI.SUM)
            w = w - basis[:, :k] @ c
        b_k = math.sqrt(max(_global_sum(s.comm, np.dot(w, s.lumped_mult(w))), 0.0))
        if k == 1:
            theta, vecs = np.array(alpha), np.ones((1, 1))
        else:
            theta, vecs = eigh_tridiagonal(
                np.array(alpha), np.array(beta), select="i", select_range=(k - 1, k - 1)
            )
        lam_k = float(theta[0])
        if b_k * abs(vecs[-1, 0]) <= rtol * abs(lam_k) or b_k <= 1e-14 * abs(lam_k):
            converged = True  # (b_k ~ 0: the Krylov space is invariant, theta is exact)
            break
        beta.append(b_k)
        w = w / b_k
    # Gershgorin on D^-1 K, D <= M_L diagonal, free rows
    indptr, _, vals = K.getValuesCSR()
    absrow = np.add.reduceat(np.abs(vals), indptr[:-1]) if len(vals) else np.zeros(0)
    absrow[np.diff(indptr) == 0] = 0.0
    absrow[rows] = 0.0
    g_loc = float(np.max(absrow / s.lumped_min())) if len(absrow) else 0.0
    g = s.comm.allreduce(g_loc, op=MPI.MAX)
    K.destroy()
    omega = math.sqrt(max(lam_k, 0.0))
    return StableStep(
        dt_crit=2.0 / omega if omega > 0 else math.inf,
        omega_max=omega,
        dt_bound=2.0 / math.sqrt(g) if g > 0 else math.inf,
        iterations=k,
        converged=converged,
    )


def integrate_explicit(
    system: ShellModel | ShellSystem | LinearSystem,
    *,
    t_end: float,
    dt: float | None = None,
    load: LoadFunction | None = None,
    damping: Damping = Damping(),
    velocity: PETSc.Vec | None = None,
    on_step: Callable[[DynamicStep], None] | None = None,
    check: str = "error",
    safety: float = 0.9,
    stable: StableStep | None = None,
    contact=None,
    rebase: float | None = 0.5,
    first_step: int = 0,
    acceleration: PETSc.Vec | None = None,
    on_state: Callable[[DynamicStep, PETSc.Vec, PETSc.Vec], None] | None = None,
    recheck_every: int = 0,
    clock: tuple[float, int, float, int] | None = None,
    measure: Callable[[int, float], bool] | None = None,
    work: tuple[float, float] = (0.0, 0.0),
    damping_until: float = math.inf,
) -> tuple[list[DynamicStep], StableStep]:
    """Central difference (velocity Verlet) with the lumped mass, fixed step (or shrinking
    with the state's stable step, ``recheck_every``).

    ``damping`` acts on the steps that end at t <= ``damping_until`` [s] only (e.g. the
    dynamic relaxation of a started state while the body rests); the damping work stays in
    the records.

    ``measure(step, t)``: whether the record of the step to ``t`` carries the strain energy
    (one assembly of the energy form, ~10 % of a sleeve step); other steps' records have
    ``strain`` and ``dissipation`` nan. None (default): every step. Kinetic energy and work
    are kept every step, and a step whose kinetic energy (or measured strain energy) is not
    finite stops the run as before (a NaN anywhere in the state reaches the velocities).

    ``contact``: a :class:`clothfem.contact.film.FilmContact`; the contact-free predictor is
    corrected by forward-increment Lagrange multipliers (Eqs. 22-25) before the forces are
    evaluated, and the corrected nodes' half-step velocity becomes the post-impact velocity.
    Contact impulses appear in the records' numerical dissipation.

    ``dt`` [s] defaults to ``safety * dt_crit`` of :func:`stable_time_step` at t = 0 (or of
    ``stable`` if given). ``check``: "error" raises ValueError when dt > dt_crit, "warn"
    warns, "off" skips the check. Damping uses the predicted velocity v_n+1/2 + dt/2 a_n
    (explicit; = v_n + dt a_n without contact).
    Prescribed rows follow their values; their velocity is the difference quotient.

    ``recheck_every`` N > 0: after every step whose index is a multiple of N the stable step
    of the current state is estimated again (:func:`stable_time_step`, Lanczos); if
    ``safety`` x that is below the step in use, the step shrinks to it (the remaining span
    is split evenly) and never grows back. A deforming shell's stable step can fall below
    its value at t = 0 (the sleeve of docs/stiff_cases.md: to 0.85 x by t = 0.15 s, so 0.9
    dt_crit(0) goes unstable). The step in use is each record's ``dt``.

    Restart: ``first_step`` k > 0 continues a run of the same ``t_end`` and ``dt`` from the
    end of its step k (t = k h), the model holding that state, with its ``velocity`` and
    ``acceleration``; energies and work are then counted from there, the external and
    damping work from ``work`` = (external_work, damping_work) of step k's record (a resumed
    run then repeats the uninterrupted one's records bit for bit). After the step has
    shrunk, also give ``clock`` = the ``clock`` of step k's record: the run continues with
    the same steps and times (``dt`` is then not used). ``on_state(record, v,
    a)`` sees the velocity and acceleration after every step (e.g. to checkpoint them).
    Returns (records, the stability estimate at the start).
    """
    stepper = ExplicitStepper(
        system,
        t_end=t_end,
        dt=dt,
        load=load,
        damping=damping,
        velocity=velocity,
        check=check,
        safety=safety,
        stable=stable,
        contact=contact,
        rebase=rebase,
        first_step=first_step,
        acceleration=acceleration,
        recheck_every=recheck_every,
        clock=clock,
        work=work,
        damping_until=damping_until,
    )
    records = []
    while not stepper.done:
        rec = stepper.step(measure=measure)
        records.append(rec)
        if on_step is not None:
            on_step(rec)
        if on_state is not None:
            on_state(rec, stepper.v, stepper.a)
    return records, stepper.stable


class ExplicitStepper:
    """The central difference of :func:`integrate_explicit` one step at a time: built with
    the same arguments (but the callbacks), :meth:`step` advances one step and returns its
    record; the state is ``v``, ``a`` and the system's (positions, directors); ``done``
    once ``t_end`` is reached; ``stable`` is the stability estimate at the start."""

    def __init__(
        self,
        system: ShellModel | ShellSystem | LinearSystem,
        *,
        t_end: float,
        dt: float | None = None,
        load: LoadFunction | None = None,
        damping: Damping = Damping(),
        velocity: PETSc.Vec | None = None,
        check: str = "error",
        safety: float = 0.9,
        stable: StableStep | None = None,
        contact=None,
        rebase: float | None = 0.5,
        first_step: int = 0,
        acceleration: PETSc.Vec | None = None,
        recheck_every: int = 0,
        clock: tuple[float, int, float, int] | None = None,
        work: tuple[float, float] = (0.0, 0.0),
        damping_until: float = math.inf,
    ) -> None:
        if check not in ("error", "warn", "off"):
            raise ValueError(f"check must be 'error', 'warn' or 'off', got {check!r}")
        _finite("safety", safety, 0.0, 1.0, lo_open=True)
        _finite("t_end", t_end, 0.0, math.inf, lo_open=True, hi_open=True)
        s = self.system = _as_system(system)
        self.lam_of = _load_fn(load)
        st = self.stable = stable or stable_time_step(s, lam=self.lam_of(0.0))
        dt = _checked_step(st, dt, safety, check)
        if not (isinstance(first_step, int) and first_step >= 0):
            raise ValueError(f"first_step must be an integer >= 0, got {first_step!r}")
        if not (isinstance(recheck_every, int) and recheck_every >= 0):
            raise ValueError(f"recheck_every must be an integer >= 0, got {recheck_every!r}")
        if clock is not None and not (len(clock) == 4 and clock[1] <= first_step < clock[3]):
            raise ValueError(
                f"clock must be (t_base, step_base <= first_step, h, n_end), got {clock}"
            )
        self.t_end, self.safety, self.contact, self.rebase = t_end, safety, contact, rebase
        self.recheck_every, self.damping, self.damping_until = recheck_every, damping, damping_until
        self.x, self.v = _start(s, velocity)
        self.K0 = _initial_K0(s, self.x, damping)
        self.singular = False  # a lumped rotary block was singular on this rank
        self.tmp = self.x.duplicate()
        # the clock: t = t_base + (step - step_base) h up to step n_end (t = step h for a run
        # that never shrank its step); a shrink re-bases it; ``clock`` restores it
        if clock is None:
            self.t_base, self.step_base = 0.0, 0
            self.n_end = max(1, math.ceil(t_end / dt - 1e-9))
            self.h = t_end / self.n_end
            if first_step > self.n_end:
                raise ValueError(f"first_step {first_step} is past the last step {self.n_end}")
        else:
            self.t_base, self.step_base = float(clock[0]), int(clock[1])
            self.h, self.n_end = float(clock[2]), int(clock[3])
        t_start = self.t_base + (first_step - self.step_base) * self.h
        self.damp = damping.active and t_start < damping_until * (1 - 1e-12)
        self.lam = self.lam_of(t_start)
        self.r, self.fe = self.x.duplicate(), self.x.duplicate()
        self.a = self.x.duplicate()
        self._accel(self.x, self.v, self.lam, self.a)  # also the forces at x (energies)
        if acceleration is not None:
            acceleration.copy(self.a)
        self.energy = _Energy(
            s, self.x, self.v, self.a, self.lam, damping if self.damp else Damping(), self.K0,
            lumped=True,
        )  # fmt: skip
        self.energy.W_ext, self.energy.W_damp = (float(w) for w in work)
        self.r, self.fe = self.energy.r, self.energy.fe  # _accel fills them: no second assembly
        self.energy.ready = True
        s.commit(self.x)
        self.xo, self.vp = self.x.duplicate(), self.x.duplicate()
        self.step_index = first_step

    @property
    def done(self) -> bool:
        """Whether the last step (to ``t_end``) is taken."""
        return self.step_index >= self.n_end

    def _accel(self, x, vpred, lam, a) -> None:
        s = self.system
        s.forces(x, lam, self.r, self.fe)  # state at x
        ra = -self.r.getArray(readonly=True)
        if self.damp:
            ra = ra - self._damp(vpred)
        try:
            aa = s.lumped_solve(ra)
        except np.linalg.LinAlgError:
            # rank-local: raising here would leave the other ranks waiting in the next
            # collective call. NaN makes the (global) energy check below fail on every rank.
            self.singular = True
            aa = np.full_like(ra, np.nan)
        rows, _ = s.bc(lam)
        aa[rows] = 0.0
        a.setArray(aa)

    def _damp(self, vv) -> np.ndarray:
        out = np.zeros(vv.getLocalSize())
        if self.damping.mass > 0:
            out += self.damping.mass * self.system.lumped_mult(vv.getArray(readonly=True))
        if self.damping.stiffness > 0:
            self.K0.mult(vv, self.tmp)
            out += self.damping.stiffness * self.tmp.getArray(readonly=True)
        return out

    def _recheck(self) -> None:
        """After every ``recheck_every`` steps (absolute indices: a resumed run rechecks where
        the uninterrupted one did), shrink the step to ``safety`` x the state's stable step
        if that is smaller (the remaining span split evenly)."""
        step = self.step_index
        if not (self.recheck_every and step > 0 and step % self.recheck_every == 0):
            return
        now = stable_time_step(self.system, lam=self.lam)
        if self.safety * now.dt_crit < self.h:
            self.t_base = self.t_base + (step - self.step_base) * self.h
            self.step_base = step
            n_rem = max(
                1, math.ceil((self.t_end - self.t_base) / (self.safety * now.dt_crit) - 1e-9)
            )
            self.h, self.n_end = (self.t_end - self.t_base) / n_rem, step + n_rem
            log.info(
                "explicit: at t = %.6g s dt_crit = %.4e s (%.3f x at the start): dt %.4e s",
                self.t_base,
                now.dt_crit,
                now.dt_crit / self.stable.dt_crit,
                self.h,
            )

    def step(self, *, measure: Callable[[int, float], bool] | None = None) -> DynamicStep:
        """One step; ``measure(step, t)``: whether its record carries the strain energy
        (None: yes). Raises :class:`DynamicsDivergence` or ``FloatingPointError`` when the
        state blows up."""
        s, x, v, a, xo, vp = self.system, self.x, self.v, self.a, self.xo, self.vp
        self._recheck()
        self.step_index += 1
        step, h = self.step_index, self.h
        t0 = time.perf_counter()
        t = self.t_base + (step - self.step_base) * h
        lam = self.lam = self.lam_of(t)
        if self.damp and t > self.damping_until * (1 + 1e-12):  # from this step on: undamped
            self.damp = False
            self.energy.damping = Damping()
        x.copy(xo)
        v.axpy(0.5 * h, a)  # v: the half-step velocity v_n+1/2 (leapfrog form of the update)
        x.axpy(h, v)  # x + h v_n + h^2/2 a_n: the contact-free predictor (Eq. 23)
        rows, values = s.bc(lam)
        if len(rows):
            xa = x.getArray()
            xa[rows] = values
        s.set_time_step(h)
        if self.contact is not None:
            # FILM on the predictor; the corrected nodes' half-step velocity becomes the
            # post-impact one. Correcting the full-step velocity instead (v_n + h a_n) made the
            # tangential update explicit Euler, whose energy grows by 1 + (h omega)^2 / 2 a step
            self.contact.correct_positions(x, v, t, h, rows)
            self.contact.correct_velocities(v)
        v.copy(vp)
        vp.axpy(0.5 * h, a)  # predicted v_n+1 for the damping forces
        a_new = a.duplicate()
        self._accel(x, vp, lam, a_new)
        v.axpy(0.5 * h, a_new)
        if len(rows):
            va = v.getArray()
            va[rows] = (x.getArray(readonly=True)[rows] - xo.getArray(readonly=True)[rows]) / h
        a_new.copy(a)
        a_new.destroy()
        s.commit(x)  # (free for the shell: _accel() left its state at x)
        measured = measure is None or measure(step, t)
        K, U, W, Wd, diss = self.energy.advance(xo, x, v, a, lam, h, strain=measured)
        self._check(K + (U if measured else 0.0), t)
        wall = time.perf_counter() - t0
        clock = (self.t_base, self.step_base, h, self.n_end)
        return DynamicStep(step, t, h, lam, 0, 0.0, 0.0, 0, K, U, W, Wd, diss, wall, clock)

    def _check(self, energy: float, t: float) -> None:
        """Stop on a non-finite state or a director turned past the parametrisation's reach;
        re-base the directors turned beyond ``rebase``."""
        s, h = self.system, self.h
        if not math.isfinite(energy):
            if s.comm.allreduce(self.singular, op=MPI.LOR):
                raise DynamicsDivergence(
                    f"explicit: the lumped rotary mass became singular at t = {t:.6g}"
                    + rotation_note(s)
                )
            raise FloatingPointError(
                f"explicit integration blew up at t = {t:.6g} (dt = {h:.4g})" + rotation_note(s)
            )
        if self.rebase is not None and isinstance(s, ShellSystem):
            turn = s.max_rotation()  # (collective)
            if turn > MAX_ROTATION:
                raise DynamicsDivergence(
                    f"explicit: a director rotation reached |theta| = {turn:.3g} rad >= pi in "
                    f"the step to t = {t:.6g} s (from <= {self.rebase:g} rad; dt = {h:.4g} s, "
                    f"dt_crit at the start {self.stable.dt_crit:.4g} s): the step does not "
                    "resolve the director motion and crossed the singularity of the rotation "
                    "parametrisation (an unstable step, e.g. the state's stable step fell "
                    "below dt: lower solver.safety or set solver.recheck_every)"
                )
            if turn > self.rebase:  # (same on every rank)
                s.rebase(self.x, self.v, self.a, threshold=self.rebase)


def _checked_step(st: StableStep, dt: float | None, safety: float, check: str) -> float:
    """The explicit step [s]: ``dt`` or ``safety`` x the stable step, logged and checked
    against the stable step (``check``: error, warn or off)."""
    if not st.converged:
        log.warning(
            "explicit: the Lanczos estimate did not converge in %d iterations; dt_crit = %.4e s "
            "may be optimistic (Gershgorin bound %.4e s)",
            st.iterations,
            st.dt_crit,
            st.dt_bound,
        )
    if dt is None:
        dt = safety * st.dt_crit
    _finite("dt", dt, 0.0, math.inf, lo_open=True, hi_open=True)
    log.info(
        "explicit: dt_crit = %.4e s (omega_max = %.4e rad/s, %d Lanczos iterations), "
        "Gershgorin bound %.4e s, dt = %.4e s",
        st.dt_crit,
        st.omega_max,
        st.iterations,
        st.dt_bound,
        dt,
    )
    if dt > st.dt_crit and check != "off":
        msg = f"explicit dt = {dt:.4g} s exceeds the stable estimate dt_crit = {st.dt_crit:.4g} s"
        if check == "error":
            raise ValueError(msg)
        warnings.warn(msg, stacklevel=3)
    return dt
