"""Quasi-static load stepping with automatic cut-back (PETSc SNES).

The load factor goes from 0 to 1 in steps; a step whose Newton solve fails is retried from
the last converged state with half the increment. After a converged step the increment
follows the measured convergence: it is scaled by ``target_iterations / iterations`` (at
most ``grow``, at least 1/2; no growth after a cut-back), bounded by ``max_increment``; a
step stretches to the target load factor rather than leave less than a quarter increment.
Below ``min_increment`` the run stops with :class:`SolverDivergence`, keeping every
converged step already reported.

PETSc options can be given on the command line with the solver's prefix (default
``static_``), e.g. ``-static_snes_monitor -static_snes_linesearch_type bt``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from .petsc_options import direct_lu, set_defaults
from .shell.model import ShellModel

__all__ = ["LoadStepping", "StepRecord", "SolverDivergence", "NewtonSolver", "solve_static"]


class SolverDivergence(RuntimeError):
    """Newton failed at the smallest allowed increment."""


@dataclass(frozen=True, kw_only=True)
class LoadStepping:
    """Load-stepping controls (load factor lam in [0, 1], dimensionless).

    initial_increment: first increment of lam; max_increment / min_increment bound it.
    target_iterations: Newton iterations per step that keep the increment; after a step of
    n iterations the next increment is the last one x target_iterations / n, clipped to
    [1/2, grow] (and to at most 1 after a cut-back). Full Newton on shells to the default
    tolerances takes 7-14 iterations per step.
    grow: the largest growth factor of one step.
    """

    initial_increment: float = 0.1
    max_increment: float = 0.25
    min_increment: float = 1e-4
    target_iterations: int = 12
    grow: float = 2.0

    def __post_init__(self) -> None:
        if not (0 < self.min_increment <= self.initial_increment <= 1):
            raise ValueError(
                "LoadStepping needs 0 < min_increment <= initial_increment <= 1, got "
                f"{self.min_increment} and {self.initial_increment}"
            )
        if not (self.initial_increment <= self.max_increment <= 1):
            raise ValueError(
                "LoadStepping max_increment must be in [initial_increment, 1], "
                f"got {self.max_increment}"
            )
        if self.grow < 1:
            raise ValueError(f"LoadStepping grow must be >= 1, got {self.grow}")
        if not (isinstance(self.target_iterations, int) and self.target_iterations >= 1):
            raise ValueError(
                f"LoadStepping target_iterations must be an integer >= 1, "
                f"got {self.target_iterations!r}"
            )

    def next_increment(self, increment: float, iterations: int, cutbacks: int) -> float:
        """The increment after a step of ``increment`` that converged in ``iterations``
        Newton iterations after ``cutbacks`` cut-backs."""
        factor = min(self.grow, max(0.5, self.target_iterations / max(iterations, 1)))
        if cutbacks:
            factor = min(factor, 1.0)
        return min(max(increment * factor, self.min_increment), self.max_increment)


@dataclass(frozen=True)
class StepRecord:
    """One converged load step."""

    step: int
    load_factor: float
    newton_iterations: int
    residual_first: float
    residual_final: float
    cutbacks: int
    wall_time: float

    def line(self) -> str:
        return (
            f"step {self.step:3d}  lam {self.load_factor:8.5f}  "
            f"newton {self.newton_iterations:2d}  "
            f"|R| {self.residual_first:9.3e} -> {self.residual_final:9.3e}  "
            f"cutbacks {self.cutbacks}  {self.wall_time:7.2f} s"
        )


class NewtonSolver:
    """Newton's method on a :class:`ShellModel` with supports, through PETSc SNES.

    Default options (overridable with ``-<prefix>...``): Newton with full steps, MUMPS LU,
    relative tolerance 1e-9, step tolerance 1e-10, at most 25 iterations.
    """

    def __init__(self, model: ShellModel, *, prefix: str = "static_") -> None:
        self.model = model
        self.x = model.create_vector()
        model.get_state(self.x)
        self.f = self.x.duplicate()
        self.K = model.jacobian(self.x)
        self._rows = np.zeros(0, dtype=np.int32)
        self._values = np.zeros(0)
        snes = PETSc.SNES().create(model.comm)
        snes.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        defaults = {
            "snes_type": "newtonls",
            "snes_linesearch_type": "basic",  # full Newton steps
            "snes_rtol": 1e-9,  # relative to the step's first residual
            "snes_atol": 1e-12,
            "snes_stol": 1e-10,  # |dx| <= stol |x|: round-off floor
            "snes_max_it": 25,
            "snes_error_if_not_converged": False,
            **direct_lu(model.comm),  # MUMPS LU (redundant on > 1 rank: repeatable)
        }
        set_defaults(prefix, defaults)
        snes.setFunction(self._residual, self.f)
        snes.setJacobian(self._jacobian, self.K)
        snes.setFromOptions()
        # Accept a residual that has stopped decreasing below floor_rtol * |R0|: the
        # round-off floor of the SVK strain (|R| ~ eps_mach E t h per node) can lie above
        # snes_rtol * |R0| for stiff fabrics or small load increments.
        self.floor_rtol = opts.getReal(prefix + "newton_floor_rtol", 1e-6)
        snes.setConvergenceTest(self._converged)
        self.snes = snes
        self._norms: list[float] = []

    def _converged(self, snes, it, norms) -> int:
        xnorm, snorm, fnorm = norms
        self._norms.append(fnorm)
        rtol, atol, stol, max_it = snes.getTolerances()
        f0 = self._norms[0]
        if not np.isfinite(fnorm):
            return PETSc.SNES.ConvergedReason.DIVERGED_FNORM_NAN
        if fnorm <= atol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        if it == 0:
            return PETSc.SNES.ConvergedReason.ITERATING
        if fnorm <= rtol * f0:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_RELATIVE
        if snorm <= stol * xnorm:
            return PETSc.SNES.ConvergedReason.CONVERGED_SNORM_RELATIVE
        if it >= 2 and fnorm <= self.floor_rtol * f0 and fnorm > 0.5 * self._norms[-2]:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_RELATIVE
        if it >= max_it:
            return PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT
        return PETSc.SNES.ConvergedReason.ITERATING

    def _residual(self, snes, x, f) -> None:
        self.model.residual(x, f)
        if len(self._rows):
            xa, fa = x.getArray(readonly=True), f.getArray()
            fa[self._rows] = xa[self._rows] - self._values

    def _jacobian(self, snes, x, K, P) -> None:
        self.model.jacobian(x, K)
        # collective: every rank calls it, also with no constrained rows of its own
        K.zeroRows(self._rows + self.model.v_range[0], diag=1.0)

    def solve(self, lam: float) -> tuple[bool, int, float, float]:
        """Solve at load factor ``lam`` from the current state.

        Returns (converged, iterations, first residual norm, final residual norm).
        """
        m = self.model
        m.set_load_factor(lam)
        self._rows, self._values = m.bc_rows_and_values(lam)
        m.get_state(self.x)
        if len(self._rows):  # start from the prescribed values
            self.x.getArray()[self._rows] = self._values
        self._norms = []
        self.snes.solve(None, self.x)
        ok = self.snes.getConvergedReason() > 0
        norms = self._norms or [float("nan")]
        finite = np.all(np.isfinite(self.x.getArray(readonly=True)))
        ok = bool(m.comm.allreduce(ok and finite, op=_land()))
        if ok:
            m.set_state(self.x)
        return ok, self.snes.getIterationNumber(), norms[0], norms[-1]


def _land():
    from mpi4py import MPI

    return MPI.LAND


def solve_static(
    model: ShellModel,
    *,
    stepping: LoadStepping = LoadStepping(),
    solver: NewtonSolver | None = None,
    on_step: Callable[[StepRecord], None] | None = None,
    targets: np.ndarray | None = None,
    rebase: float | None = 0.5,
) -> list[StepRecord]:
    """Drive the load factor from 0 to 1 (or through ``targets``, increasing values that
    the stepping must hit exactly); returns the converged step records.

    ``on_step`` is called after each converged step (write results there: they survive a
    later failure). Raises :class:`SolverDivergence` below ``stepping.min_increment``.
    ``rebase``: after each converged step, nodes rotated by more than this [rad] get a new
    fibre basis on their current director (:meth:`ShellModel.rebase`); None disables it.
    """
    solver = solver or NewtonSolver(model)
    targets = np.array([1.0]) if targets is None else np.asarray(targets, dtype=float)
    lam, inc, step, records = 0.0, stepping.initial_increment, 0, []
    saved_u = model.u.x.array.copy()
    saved_t = model.theta.x.array.copy()
    for target in targets:
        while lam < target - 1e-14:
            trial = min(lam + inc, target)
            if target - trial < 0.25 * inc and target - lam <= stepping.max_increment:
                trial = target  # no sliver of a step left before the target
            cutbacks = 0
            t0 = time.perf_counter()
            while True:
                ok, its, r0, r1 = solver.solve(trial)
                if ok:
                    break
                model.u.x.array[:] = saved_u
                model.theta.x.array[:] = saved_t
                model.update_director()
                cutbacks += 1
                inc = (trial - lam) / 2
                if inc < stepping.min_increment:
                    raise SolverDivergence(
                        f"Newton failed at load factor {trial:.6g} with increment "
                        f"{trial - lam:.3g} below min_increment {stepping.min_increment:g} "
                        f"after {cutbacks} cut-backs "
                        f"(last residual {r1:.3e})"
                    )
                trial = lam + inc
            lam = trial
            step += 1
            if rebase is not None:
                model.rebase(threshold=rebase)
            saved_u[:] = model.u.x.array
            saved_t[:] = model.theta.x.array
            rec = StepRecord(step, lam, its, r0, r1, cutbacks, time.perf_counter() - t0)
            records.append(rec)
            if on_step is not None:
                on_step(rec)
            inc = stepping.next_increment(inc, its, cutbacks)
    return records
