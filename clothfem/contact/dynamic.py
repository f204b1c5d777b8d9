"""Implicit Newmark dynamics with Lagrange-multiplier contact (paper Sec. 3.1.3 + Eqs. 16-21).

Each time step solves the contact problem of :class:`~clothfem.contact.lagrange.LagrangeContact`
for the *dynamic* residual

    f_int(x) - f_ext(t) + M(x) a(x) + G^T lambda = 0,
    a(x) = (x - x~) / (beta dt^2),   x~ = x_n + dt v_n + dt^2 (1/2 - beta) a_n     (Newmark)

by handing the contact solver an operator whose residual and Jacobian are the shell's plus
the inertia of the step (Jacobian + M / (beta dt^2)); the active set, friction and the
multipliers are the contact solver's own. After the step, v_{n+1} = v_n + dt ((1 - gamma) a_n
+ gamma a_{n+1}). The mass keeps the tangent positive definite through wrinkling, which is
why the paper solves clothing as a dynamics problem. A step whose Newton or active-set
iteration fails is retried with half the time step (down to ``dt_min``).

The run starts at rest (v_0 = a_0 = 0): start from an equilibrium, e.g. a quasi-static
settling with :meth:`LagrangeContact.solve_step`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from petsc4py import PETSc

from .lagrange import (
    ContactDivergence,
    ContactStepRecord,
    LagrangeContact,
    LagrangeContactParameters,
)

__all__ = ["DynamicContact", "DynamicContactRecord"]

if TYPE_CHECKING:
    from .self_barrier import SelfBarrier

log = logging.getLogger("clothfem.contact.dynamic")

BodiesAt = Callable[[float], tuple[Sequence, Sequence]]


class _InertialOperator:
    """The shell's residual and tangent plus the inertia of one Newmark step (the
    :class:`clothfem.contact.lagrange.Operator` the contact solver solves), with the fabric
    self-contact barrier's terms when one is given."""

    def __init__(self, system, barrier: SelfBarrier | None = None) -> None:
        self._system, self._model = system, system.model
        self._barrier = barrier
        self._coef = 0.0  # 1 / (beta dt^2)
        self._xt = system.create_vector()
        self._tmp, self._Ma = self._xt.duplicate(), self._xt.duplicate()
        self._K: PETSc.Mat | None = None  # the shell's own tangent under a barrier

    def set_step(self, xtilde: PETSc.Vec, coef: float) -> None:
        xtilde.copy(self._xt)
        self._coef = coef

    def residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None:
        self._model.residual(x, f)  # leaves the model's state (and P) at x
        x.copy(self._tmp)
        self._tmp.axpy(-1.0, self._xt)
        self._tmp.scale(self._coef)  # a(x)
        self._system.mass_mult(self._tmp, self._Ma)
        f.axpy(1.0, self._Ma)
        if self._barrier is not None:
            self._barrier.add_residual(x, f)

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat | None = None) -> PETSc.Mat:
        if self._barrier is not None:  # K is the barrier's matrix: the shell's is kept here
            K = self._K = self._model.jacobian(x, self._K)
        else:
            K = self._model.jacobian(x, K)
        K.axpy(
            self._coef,
            self._system.mass_matrix(),
            structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN,
        )
        return K if self._barrier is None else self._barrier.jacobian(x, K)


@dataclass(frozen=True)
class DynamicContactRecord:
    """One accepted time step."""

    step: int
    time: float  # s
    dt: float  # s
    contact: ContactStepRecord
    kinetic_energy: float  # J
    strain_energy: float  # J
    cutbacks: int

    def line(self) -> str:
        c = self.contact
        return (
            f"step {self.step:4d}  t {self.time:9.5f} s  dt {self.dt:.2e}  active {c.n_active:4d}  "
            f"pen {c.max_penetration:.1e}  newton {c.newton_iterations:3d}  cut {self.cutbacks}  "
            f"KE {self.kinetic_energy:.3e} J"
        )


class DynamicContact:
    """Newmark (beta, gamma) time stepping of a :class:`clothfem.dynamics.ShellSystem` with
    Lagrange-multiplier contact against the ellipsoids ``bodies_at(t) -> (ellipsoids,
    velocities)`` (see :func:`clothfem.contact.film.body_state`).

    ``rebase`` [rad]: after every accepted step, nodes rotated by more than this are re-based
    on their current director (:meth:`ShellSystem.rebase`); None never re-bases.
    ``non_resilient``: after every step the nodes in contact take the body's normal velocity
    (:meth:`_stick_normal`); False keeps plain Newmark velocities.
    ``barrier``: fabric self-contact (:class:`clothfem.contact.self_barrier.SelfBarrier` on
    the same system): its energy joins every step's Newton system and its step filter the
    line search; None: no self-contact."""

    def __init__(
        self,
        system,
        bodies_at: BodiesAt,
        *,
        params: LagrangeContactParameters | None = None,
        beta: float = 0.25,
        gamma: float = 0.5,
        slaves=None,
        rebase: float | None = 0.5,
        non_resilient: bool = True,
        barrier: SelfBarrier | None = None,
    ) -> None:
        if not (0 < beta <= 0.5):
            raise ValueError(f"DynamicContact beta must be in (0, 0.5], got {beta!r}")
        if not (0.5 <= gamma <= 1.0):
            raise ValueError(f"DynamicContact gamma must be in [0.5, 1], got {gamma!r}")
        self.system, self.beta, self.gamma = system, beta, gamma
        self.rebase, self.non_resilient = rebase, non_resilient
        self.h: float | None = None  # current step [s] (adaptive), set by run()
        self.streak, self.grow_after = 0, 3
        self.bodies_at = bodies_at
        self.barrier = barrier
        self.view = _InertialOperator(system, barrier)
        geo, _ = bodies_at(0.0)
        params = params if params is not None else LagrangeContactParameters()
        self.contact = LagrangeContact(
            system.model,
            geo,
            params=params,
            slaves=slaves,
            operator=self.view,
            step_filter=barrier.max_step if barrier is not None else None,
        )
        self.x = system.create_vector()
        system.get_state(self.x)
        self.v, self.a = self.x.duplicate(), self.x.duplicate()
        self.v.set(0.0)
        self.a.set(0.0)
        self.t = 0.0
        self.steps_taken = 0  # accepted steps of this object (records' step)
        self._xt = self.x.duplicate()

    def state_arrays(self) -> dict:
        """Everything a resumed run needs (rank-local): time, x, v, a, the shell's, the
        contact solver's and the self-contact barrier's state."""
        out = {"t": np.array(self.t), "h": np.array(self.h or 0.0), "streak": np.array(self.streak)}
        for k in ("x", "v", "a"):
            out[k] = getattr(self, k).getArray(readonly=True).copy()
        out.update({f"model_{k}": v for k, v in self.system.model.state_arrays().items()})
        out.update({f"contact_{k}": v for k, v in self.contact.state_arrays().items()})
        if self.barrier is not None:
            out.update({f"barrier_{k}": v for k, v in self.barrier.state_arrays().items()})
        return out

    def restore_arrays(self, data) -> None:
        """Inverse of :meth:`state_arrays` (collective). A checkpoint without the barrier's
        state (written before it was saved) leaves the barrier to build a fresh list."""
        self.system.model.restore_arrays({k[6:]: data[k] for k in data if k.startswith("model_")})
        self.contact.restore_arrays({k[8:]: data[k] for k in data if k.startswith("contact_")})
        if self.barrier is not None and "barrier_x_build" in data:
            self.barrier.restore_arrays({k[8:]: data[k] for k in data if k.startswith("barrier_")})
        for k in ("x", "v", "a"):
            arr = getattr(self, k).getArray()
            if data[k].shape != arr.shape:
                raise ValueError("checkpoint does not match this mesh / number of ranks")
            arr[:] = data[k]
        self.t = float(data["t"])
        self.h = float(data["h"]) or None
        self.streak = int(data["streak"])

    def kinetic_energy(self) -> float:
        Mv = self.v.duplicate()
        self.system.mass_mult(self.v, Mv)
        return 0.5 * Mv.dot(self.v)

    def _set_poses(self, t: float) -> None:
        geo, _ = self.bodies_at(t)
        for k, (c, Q, r) in enumerate(geo):
            self.contact.set_pose(k, centre=c, axes=Q, radii=r)

    def _stick_normal(self, t: float) -> None:
        """Non-resilient contact (paper, end of Sec. 3.2): a node in contact moves with the
        body surface along the normal, so its normal velocity relative to the body point is
        set to zero and the normal part of its acceleration dropped. Without this, Newmark
        carries the impact's velocity jump into the next predictor and the multipliers (and
        the torque) oscillate from step to step."""
        c = self.contact
        nodes, body, _, nrm = c.pair_forces()
        if not len(nodes):
            return
        n = c.n
        _, vel = self.bodies_at(t)
        x = c.X[nodes] + self.x.getArray(readonly=True)[: 3 * n].reshape(n, 3)[nodes]
        vb = np.array(
            [
                vel[b][0] + np.cross(vel[b][1], p - c.bodies[b][0])
                for b, p in zip(body, x, strict=True)
            ]
        )
        for vec, target in ((self.v, vb), (self.a, np.zeros_like(vb))):
            arr = vec.getArray()[: 3 * n].reshape(n, 3)
            for j in range(len(nodes)):  # one pair at a time: a crease node has two normals
                i = nodes[j]
                arr[i] -= ((arr[i] - target[j]) @ nrm[j]) * nrm[j]

    def step(self, dt: float, lam: float) -> ContactStepRecord:
        """Advance by ``dt`` [s] at load factor ``lam`` (raises ContactDivergence, state kept)."""
        b, g = self.beta, self.gamma
        xt = self._xt
        self.x.copy(xt)
        xt.axpy(dt, self.v)
        xt.axpy(dt * dt * (0.5 - b), self.a)
        self.view.set_step(xt, 1.0 / (b * dt * dt))
        self.system.set_time_step(dt)
        self._set_poses(self.t + dt)
        if self.barrier is not None:  # the layer friction's pairs at the step's start
            self.barrier.begin_step(self.x, dt)
        try:
            rec = self.contact.solve_step(lam)
        except ContactDivergence:
            self._set_poses(self.t)
            raise
        x_new = self.x.duplicate()
        self.system.get_state(x_new)
        if self.barrier is not None:
            self.barrier.end_step(x_new)
        a_new = x_new.copy()
        a_new.axpy(-1.0, xt)
        a_new.scale(1.0 / (b * dt * dt))
        self.v.axpy(dt * (1 - g), self.a)
        self.v.axpy(dt * g, a_new)
        a_new.copy(self.a)
        x_new.copy(self.x)
        self.t += dt
        if self.non_resilient:
            self._stick_normal(self.t)
        if self.rebase is not None:  # keep |theta| away from pi at folds (ShellModel.rebase)
            self.system.rebase(self.x, self.v, self.a, threshold=self.rebase)
        return rec

    def run(
        self,
        *,
        t_end: float,
        dt: float,
        dt_min: float | None = None,
        load: Callable[[float], float] = lambda t: 1.0,
        on_step: Callable[[DynamicContactRecord], None] | None = None,
    ) -> list[DynamicContactRecord]:
        """Step to ``t_end`` [s] with :meth:`advance` (steps of at most ``dt`` [s], halved on
        failure down to ``dt_min``; accepted steps went to ``on_step`` when it raises)."""
        records: list[DynamicContactRecord] = []
        while not self.reached(t_end):
            r = self.advance(t_end=t_end, dt=dt, dt_min=dt_min, load=load)
            records.append(r)
            if on_step is not None:
                on_step(r)
        return records

    def reached(self, t_end: float) -> bool:
        """Whether the state is at ``t_end`` [s]."""
        return self.t >= t_end - 1e-12 * t_end

    def advance(
        self,
        *,
        t_end: float,
        dt: float,
        dt_min: float | None = None,
        load: Callable[[float], float] = lambda t: 1.0,
    ) -> DynamicContactRecord:
        """One accepted step towards ``t_end`` [s] of at most ``dt`` [s] with the load factor
        ``load(t)``: a failed step is halved down to ``dt_min`` (default dt / 64), then
        ContactDivergence is raised. A halved step is kept and doubled again after
        ``grow_after`` steps without a failure."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        dt_min = dt / 64 if dt_min is None else dt_min
        if self.h is None:
            self.h = dt
        h, cut = min(self.h, dt, t_end - self.t), 0
        while True:
            try:
                rec = self.step(h, load(self.t + h))
                break
            except ContactDivergence as exc:
                cut += 1
                h /= 2
                log.info("dynamic contact: step failed (%s); retry with dt = %.3e s", exc, h)
                if h < dt_min:
                    raise ContactDivergence(
                        f"dynamic contact failed at t = {self.t:.6g} s with dt below "
                        f"dt_min = {dt_min:.3g} s (last failure: {exc})"
                    ) from exc
        # keep a cut step; double it again after `grow_after` steps without a cut
        self.streak = 0 if cut else self.streak + 1
        self.h = h
        if self.streak >= self.grow_after and self.h < dt:
            self.h, self.streak = min(2 * self.h, dt), 0
        self.steps_taken += 1
        return DynamicContactRecord(
            self.steps_taken,
            self.t,
            h,
            rec,
            self.kinetic_energy(),
            self.system.strain_energy(),
            cut,
        )
