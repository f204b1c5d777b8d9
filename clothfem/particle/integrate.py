"""Time steps of the particle fabric: explicit (velocity Verlet) and implicit (backward Euler).

Explicit step (the leapfrog/kick-drift-kick form of the central difference, symplectic and
second order without damping; the shell's explicit integrator uses the same form):

    v+ = v + dt/2 a(x, v);   x* = x + dt v+            (predictor, supports prescribed)
    x* <- strain limit (Provot 1995);  v+ = (x* - x) / dt
    x, v+ <- FILM correction (clothfem.contact.explicit.film_step, Eqs. 22-25)
    a' = a(x', v+);  v' = v+ + dt/2 a'

Damping forces are evaluated with the half-step velocity ``v+`` (first order in the
damping). Implicit step (Baraff & Witkin 1998 style, with Newton iterations): backward
Euler ``M (v' - v) = dt F(x + dt v', v')``, linearised with ``K = dF/dx``, ``C = dF/dv``
(:func:`clothfem.particle.model.tangent`) and solved with ``scipy.sparse`` (serial: every
rank solves the same system); the strain limit and the FILM correction then act on its
result as on the explicit predictor.

Every rank holds the whole network and does the same work (no communication): results are
the same on any number of ranks.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import diags
from scipy.sparse.linalg import MatrixRankWarning, spsolve

from .model import (
    ParticleModel,
    ParticleState,
    accelerations,
    energies,
    internal_forces,
    tangent,
)
from .network import KIND_NAMES

__all__ = [
    "StepInfo",
    "bodies",
    "integrate",
    "limit_strain",
    "solve_static",
    "step_explicit",
    "step_implicit",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StepInfo:
    """Diagnostics of one step: time [s] at its end; contact nodes; contact force on the
    fabric [N] (sum over nodes, (3,)); smallest gap after the correction [m] (inf without
    contact); strain-limit sweeps; Newton iterations (0 for explicit); the contact force on
    the fabric at every node [N] ((n, 3), zero off contact; the body gets its negative, as
    in Eq. 28) and the ellipsoid each node touches ((n,), -1: none)."""

    t: float
    active: int
    contact_force: FloatArray
    min_gap: float
    limit_sweeps: int
    newton: int
    node_force: FloatArray
    node_body: NDArray[np.intp]


def bodies(source):
    """``t -> (ellipsoids, velocities)`` for the FILM step from a
    :class:`clothfem.body.Body` (moving), a sequence of :class:`clothfem.body.Ellipsoid`
    (at rest) or such a callable."""
    from clothfem.body import Body, Ellipsoid
    from clothfem.contact.film import body_state

    if isinstance(source, Body):
        return body_state(source)
    if callable(source):
        return source
    items = list(source)
    if not items or not all(isinstance(e, Ellipsoid) for e in items):
        raise ValueError("bodies source must be a Body, Ellipsoids or a callable t -> bodies")
    geo = [(e.centre, e.axes.T, e.radii) for e in items]
    vel = [(np.zeros(3), np.zeros(3)) for _ in items]
    return lambda t: (geo, vel)


def limit_strain(model: ParticleModel, x: FloatArray) -> int:
    """Provot's correction of over-stretched springs on ``x`` (in place); returns the sweeps.
    Jacobi sweeps: each over-stretched spring asks to move its ends towards each other by
    the excess, split in inverse proportion to the masses (supported nodes: none of it);
    a node's requests are averaged."""
    lim = model.strain_limit
    if lim is None:
        return 0
    net = model.network
    sel = np.isin(net.kind, [KIND_NAMES[k] for k in lim.kinds])
    pairs, L0 = net.pairs[sel], net.rest[sel]
    w = np.where(model.fixed, 0.0, 1.0 / model.mass)
    wi, wj = w[pairs[:, 0]], w[pairs[:, 1]]
    wsum = wi + wj
    Lmax = (1.0 + lim.max_stretch) * L0
    for sweep in range(lim.iterations):
        d = x[pairs[:, 1]] - x[pairs[:, 0]]
        L = np.linalg.norm(d, axis=1)
        over = np.flatnonzero((L > Lmax * (1.0 + lim.tol)) & (wsum > 0))
        if over.size == 0:
            return sweep
        corr = ((L[over] - Lmax[over]) / (L[over] * wsum[over]))[:, None] * d[over]
        move = np.zeros_like(x)
        count = np.zeros(len(x))
        for end, sign, wt in ((0, 1.0, wi), (1, -1.0, wj)):
            nodes = pairs[over, end]
            for c in range(3):
                move[:, c] += np.bincount(nodes, sign * wt[over] * corr[:, c], len(x))
            count += np.bincount(nodes, wt[over] > 0, len(x))
        x += move / np.maximum(count, 1.0)[:, None]
    return lim.iterations


def _contact(model: ParticleModel, x: FloatArray, v: FloatArray, t: float, dt: float):
    """FILM correction (in place) of the predictor; returns (active, force sum, min gap,
    nodal forces on the fabric, contact ellipsoid per node or -1)."""
    if model.bodies is None:
        return 0, np.zeros(3), math.inf, np.zeros_like(x), np.full(len(x), -1, dtype=np.intp)
    from clothfem.contact.explicit import film_step

    geo, vel = model.bodies(t)
    p = model.contact
    res = film_step(
        x, v, model.mass, dt, geo, body_velocities=vel, mu=p.mu, offset=p.offset,
        max_passes=p.max_passes, fixed=model.fixed, kernel=p.kernel,
    )  # fmt: skip
    act = np.flatnonzero(res.active)
    x[act], v[act] = res.x[act], res.v[act]
    gap = float(np.min(res.gap[~model.fixed], initial=math.inf))
    nodal = np.zeros_like(x)
    nodal[act] = res.force[act]
    body = np.full(len(x), -1, dtype=np.intp)
    body[act] = res.body[act]
    return act.size, nodal[act].sum(axis=0), gap, nodal, body


def _finish(model, x_old, x, v_half, t1, dt) -> tuple[int, tuple]:
    """Supports, strain limit and contact on the predictor ``x`` (in place)."""
    x[model.fixed] = model.fixed_positions(t1)
    sweeps = limit_strain(model, x)
    v_half[:] = (x - x_old) / dt
    return sweeps, _contact(model, x, v_half, t1, dt)


def step_explicit(model: ParticleModel, state: ParticleState, dt: float) -> tuple:
    """One velocity-Verlet step of ``dt`` [s]; returns (new state, :class:`StepInfo`)."""
    _check_dt(dt)
    v_half = state.v + 0.5 * dt * state.a
    x = state.x + dt * v_half
    t1 = state.t + dt
    sweeps, (act, force, gap, nodal, body) = _finish(model, state.x, x, v_half, t1, dt)
    a = accelerations(model, x, v_half)
    v = v_half + 0.5 * dt * a
    v[model.fixed] = v_half[model.fixed]
    new = ParticleState(t=t1, x=x, v=v, a=a)
    return new, StepInfo(t1, act, force, gap, sweeps, 0, nodal, body)


def step_implicit(
    model: ParticleModel, state: ParticleState, dt: float, *, rtol: float = 1e-8, max_iter: int = 20
) -> tuple:
    """One backward-Euler step of ``dt`` [s] by Newton's method on the velocities (converged
    when the residual is below ``rtol`` x the momentum scale); returns (state, StepInfo)."""
    _check_dt(dt)
    x0, v0, m3 = state.x, state.v, np.repeat(model.mass, 3)
    t1 = state.t + dt
    free = np.repeat(~model.fixed, 3)
    v = v0.copy()
    v[model.fixed] = (model.fixed_positions(t1) - x0[model.fixed]) / dt
    g = np.asarray(model.gravity)
    scale = max(float(np.abs(m3 * v0.ravel()).max()), float(m3.max() * np.linalg.norm(g) * dt))
    newton = 0
    while True:
        x = x0 + dt * v
        f = internal_forces(model, x, v) + model.mass[:, None] * g
        r = (m3 * (v - v0).ravel() - dt * f.ravel())[free]
        if np.abs(r).max(initial=0.0) <= rtol * max(scale, 1e-300):
            break
        newton += 1
        if newton > max_iter:
            raise RuntimeError(f"step_implicit: Newton did not converge in {max_iter} iterations")
        K, C = tangent(model, x, v)
        J = (diags(m3) - dt * C - dt * dt * K).tocsr()[free][:, free]
        v.reshape(-1)[free] -= spsolve(J.tocsc(), r)
    x = x0 + dt * v
    sweeps, (act, force, gap, nodal, body) = _finish(model, x0, x, v, t1, dt)
    new = ParticleState(t=t1, x=x, v=v, a=accelerations(model, x, v))
    return new, StepInfo(t1, act, force, gap, sweeps, newton, nodal, body)


def _check_dt(dt: float) -> None:
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be a finite time step > 0 s, got {dt!r}")


def integrate(
    model: ParticleModel,
    state: ParticleState,
    *,
    t_end: float,
    dt: float,
    method: str = "explicit",
    every: int = 0,
) -> tuple[ParticleState, list]:
    """Steps of ``dt`` [s] (the last one shortened) to ``t_end`` [s] with ``method``
    "explicit" or "implicit"; returns the final state and, if ``every`` > 0, a record
    ``(t, Energies, StepInfo)`` every ``every`` steps."""
    if method not in ("explicit", "implicit"):
        raise ValueError(f"method must be 'explicit' or 'implicit', got {method!r}")
    step = step_explicit if method == "explicit" else step_implicit
    records, k = [], 0
    while state.t < t_end - 1e-12 * max(1.0, abs(t_end)):
        h = min(dt, t_end - state.t)
        state, info = step(model, state, h)
        k += 1
        if every and k % every == 0:
            records.append((state.t, energies(model, state), info))
    return state, records


def solve_static(
    model: ParticleModel,
    state: ParticleState | None = None,
    *,
    gtol: float = 1e-6,
    accept: float = 1e-2,
    max_iter: int = 200,
) -> tuple[ParticleState, int]:
    """Static equilibrium (spring + gravity forces, supports at their positions at
    ``state.t``): the minimum of the potential energy by Newton's method with the exact
    sparse tangent and a Levenberg-Marquardt shift ``mu M`` (a backward-Euler step of
    ``1 / sqrt(mu)`` with the velocity reset: pseudo-transient continuation), raised until
    the step lowers the energy (or, within the energy's round-off, the out-of-balance force).
    From ``state`` (default: the reference); converged when the largest out-of-balance
    force of a free node is below ``gtol`` x the largest nodal weight or the round-off floor
    of the spring forces (100 eps k_max |x|_max). Where no step makes progress any more
    (Choi & Ko's tension-free flexion springs switch off at their rest length: the forces
    have a kink there), or five steps reduce the force by less than 10 %, the state is
    accepted if that force is below ``accept`` x the largest nodal weight (``state.a`` gives
    the imbalance). Returns the state at rest and the Newton iterations."""
    state = state or ParticleState.at_rest(model)
    free = np.repeat(~model.fixed, 3)
    x = state.x.copy()
    x[model.fixed] = model.fixed_positions(state.t)
    fg = model.mass[:, None] * np.asarray(model.gravity)
    ref = float(model.mass.max()) * max(float(np.linalg.norm(model.gravity)), 1.0)
    floor = 100.0 * np.finfo(float).eps * float(np.max(model.fabric.stiffness))
    m3 = np.repeat(model.mass, 3)[free]
    zero = np.zeros_like(x)

    def residual(y):
        return (internal_forces(model, y) + fg).ravel()[free]

    def energy(y):
        e = energies(model, ParticleState(t=state.t, x=y, v=zero, a=zero))
        return e.spring + e.gravity, 1e-12 * (abs(e.spring) + abs(e.gravity))

    r, (e, _) = residual(x), energy(x)
    mu = 0.0
    mu0 = 1e-6 * float(np.max(model.fabric.stiffness)) / float(model.mass.min())
    norms = [float(np.linalg.norm(r))]
    for it in range(1, max_iter + 1):
        if np.abs(r).max(initial=0.0) <= max(gtol * ref, floor * np.abs(x).max()):
            return _at_rest(model, state.t, x), it - 1
        stalled = len(norms) > 5 and norms[-1] > 0.9 * norms[-6]
        if stalled and np.abs(r).max() <= accept * ref:
            return _at_rest(model, state.t, x), it - 1
        H = (-tangent(model, x, zero)[0]).tocsr()[free][:, free]
        while True:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MatrixRankWarning)  # singular: shift it
                dz = spsolve((H + diags(mu * m3)).tocsc(), r)
            trial = x.copy()
            trial.reshape(-1)[free] += dz
            rt, (et, tol) = residual(trial), energy(trial)
            smaller = np.linalg.norm(rt) < np.linalg.norm(r)
            if np.all(np.isfinite(rt)) and (et < e - tol or (et <= e + tol and smaller)):
                x, r, e, mu = trial, rt, et, 0.1 * mu if mu > 10 * mu0 else 0.0
                norms.append(float(np.linalg.norm(r)))
                break
            mu = max(10.0 * mu, mu0)
            if mu > 1e12 * mu0:
                if np.abs(r).max() <= accept * ref:
                    return _at_rest(model, state.t, x), it
                raise RuntimeError("solve_static: no step lowers the energy (singular tangent)")
    raise RuntimeError(f"solve_static: not converged in {max_iter} Newton iterations")


def _at_rest(model: ParticleModel, t: float, x: FloatArray) -> ParticleState:
    v = np.zeros_like(x)
    return ParticleState(t=t, x=x, v=v, a=accelerations(model, x, v))
