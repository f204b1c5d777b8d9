"""Forward-increment Lagrange multipliers for the explicit shell integrator (Eqs. 22-25).

Carpenter et al. (1991) as used by Man & Swan (2007), Sec. 3.2: central difference predicts
the fabric positions without contact (Eq. 23); the multipliers that make the predictor
admissible follow from Eq. 25. With a lumped mass and each fabric node constrained by one
rigid ellipsoid, ``G M^-1 G^T`` is diagonal and Eq. 25 decouples per node: the corrected node
is the exact closest point on the body surface and ``lambda = m (x - x*) / dt^2``
(:func:`clothfem.contact.explicit.film_step`). A corrected node's half-step velocity
``v_n+1/2`` (the predictor's chord velocity, leapfrog form of the central difference) becomes
the velocity of the body surface point (the paper's non-resilient impact), or a
Coulomb-limited change of it when ``mu`` is given; ``v_n+1 = v_n+1/2 + dt/2 a_n+1`` as for
every node, so the position and velocity updates stay one symplectic scheme.

:class:`FilmContact` connects that NumPy step to :func:`clothfem.dynamics.integrate_explicit`:
it reads and corrects the translational unknowns of the owned nodes (rotations are not
constrained), skips nodes with prescribed displacements, and keeps per-step diagnostics and
the contact forces for Eq. 28.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from .explicit import FilmResult, _Buffers, _check_velocities, _film_compiled, film_step
from .forces import joint_torque
from .geometry import _check_bodies

__all__ = ["FilmParameters", "FilmContact", "FilmRecord", "body_state"]

BodiesAt = Callable[[float], tuple[Sequence, Sequence]]


@dataclass(frozen=True, kw_only=True)
class FilmParameters:
    """mu: None for the paper's non-resilient rule (the node moves with the body), or a
    Coulomb coefficient >= 0 limiting the tangential velocity change; offset: contact
    thickness [m] kept between node and surface (>= 0); max_passes: projection passes at
    overlapping ellipsoids (>= 1); kernel: "compiled" (the C loop) or "numpy" (the vectorised
    reference) implementation of :func:`clothfem.contact.explicit.film_step`."""

    mu: float | None = None
    offset: float = 0.0
    max_passes: int = 3
    kernel: str = "compiled"

    def __post_init__(self) -> None:
        if self.mu is not None and not (np.isfinite(self.mu) and self.mu >= 0):
            raise ValueError(f"FilmParameters mu must be None or >= 0, got {self.mu!r}")
        if not (np.isfinite(self.offset) and self.offset >= 0):
            raise ValueError(f"FilmParameters offset must be >= 0 m, got {self.offset!r}")
        if int(self.max_passes) != self.max_passes or self.max_passes < 1:
            raise ValueError(
                f"FilmParameters max_passes must be an integer >= 1, got {self.max_passes!r}"
            )
        if self.kernel not in ("compiled", "numpy"):
            raise ValueError(
                f"FilmParameters kernel must be 'compiled' or 'numpy', got {self.kernel!r}"
            )


@dataclass(frozen=True)
class FilmRecord:
    """Contact diagnostics of the explicit steps since the previous
    :meth:`FilmContact.collect` (a window of ``steps`` steps), reduced over ranks."""

    time: float  # of the window's last step [s]
    steps: int  # explicit steps in the window
    active: int  # nodes corrected in the last step
    max_penetration: float  # largest predictor penetration in the window [m] (>= 0)
    sum_lambda: float  # sum of the normal multipliers, mean over the window's steps [N]
    min_gap_after: float  # smallest gap after correction in the window [m]
    n_stick: int  # corrected nodes that stick in the last step (all of them if mu is None)
    dissipation: float  # frictional dissipation of the window [J]


def body_state(body) -> BodiesAt:
    """Adapter from a :class:`clothfem.body.Body` to ``t -> (ellipsoids, velocities)``:
    ellipsoids as (centre, axes as columns, radii), velocities as (v_centre, omega)."""

    def at(t: float):
        poses = body.poses(t)
        geo = [(poses[s.name].centre, poses[s.name].rotation, s.radii) for s in body.segments]
        vel = [(poses[s.name].velocity, poses[s.name].angular_velocity) for s in body.segments]
        return geo, vel

    return at


class FilmContact:
    """FILM contact of a :class:`clothfem.dynamics.ShellSystem` against moving ellipsoids.

    ``bodies_at(t)`` returns the ellipsoids and their velocities at time ``t`` [s].
    """

    def __init__(self, system, bodies_at: BodiesAt, *, params: FilmParameters = FilmParameters()):
        self.system, self.model, self.comm = system, system.model, system.model.comm
        self.bodies_at, self.params = bodies_at, params
        n = self.n = self.model.n_owned
        self.X = self.model.x_nodes[:n]
        self.mass = np.ascontiguousarray(system.lumped_u[0 : 3 * n : 3])  # kg per node
        if not (np.all(np.isfinite(self.mass)) and np.all(self.mass > 0.0)):
            raise ValueError("FilmContact: the lumped nodal masses must be finite and > 0 kg")
        self._buffers = _Buffers(n)  # the compiled step's outputs (reused every step)
        self.last: FilmResult | None = None
        self.history: list[FilmRecord] = []  # one record per collect()
        self.dissipation_total = 0.0  # frictional dissipation up to the last collect() [J]
        self.time = 0.0  # of the last corrected step [s]
        self._window = self._empty_window()
        self.wall = 0.0  # seconds spent in the contact corrections
        self._fixed = np.zeros(n, dtype=bool)  # nodes with prescribed displacements
        self._rows: np.ndarray | None = None  # the prescribed rows _fixed was built from
        self._act = np.zeros(0, dtype=np.intp)  # nodes corrected in the last step

    def correct_positions(self, x: PETSc.Vec, v_pred: PETSc.Vec, t: float, h: float, rows) -> None:
        """Project the penetrating nodes of the predictor ``x`` (in place)."""
        t0 = time.perf_counter()
        n = self.n
        rows = np.asarray(rows)
        if self._rows is None or not np.array_equal(rows, self._rows):
            # nodes with a prescribed displacement row are not corrected (rebuilt only when
            # the prescribed rows change, i.e. once for a scene's supports)
            self._rows = rows.copy()
            self._fixed = np.zeros(n, dtype=bool)
            self._fixed[rows[rows < 3 * n] // 3] = True
        u = x.getArray()[: 3 * n].reshape(n, 3)
        v = v_pred.getArray(readonly=True)[: 3 * n].reshape(n, 3)
        geo, vel = self.bodies_at(t)
        p = self.params
        if p.kernel == "compiled":
            # film_step's C path without its per-call checks of what does not change (masses,
            # fixed nodes, parameters: checked once) and into output arrays allocated once
            ells = _check_bodies(geo)
            vc, om = _check_velocities(vel, len(ells))
            xs = self.X + u
            res = _film_compiled(
                xs, v, self.mass, h, ells, vc, om, p.mu, p.offset, p.max_passes, self._fixed,
                self._buffers,
            )  # fmt: skip
        else:
            res = film_step(
                self.X + u,
                v,
                self.mass,
                h,
                geo,
                body_velocities=vel,
                mu=p.mu,
                offset=p.offset,
                max_passes=p.max_passes,
                fixed=self._fixed,
                kernel=p.kernel,
            )
        act = np.flatnonzero(res.active)
        u[act] = res.x[act] - self.X[act]  # the other nodes' unknowns are left bit for bit
        self.last, self._act = res, act
        # rank-local diagnostics, reduced once per window by collect() (no collective call
        # in the step: the explicit step's other reductions set the pace)
        w = self._window
        w["steps"] += 1
        w["last"][:] = (act.size, np.count_nonzero(res.stick[act]))  # active, sticking
        w["lam"] += float(res.lam_n.sum())
        w["diss"] += float(res.dissipation.sum())
        # predictor penetration of each corrected node: lambda dt^2 / m (Eq. 24)
        pen = float(np.max(res.lam_n[act] * h * h / self.mass[act], initial=0.0))
        w["peaks"][0] = max(w["peaks"][0], pen)
        w["peaks"][1] = max(w["peaks"][1], -float(np.min(res.gap, initial=np.inf)))
        self.time = t
        self.wall += time.perf_counter() - t0

    @staticmethod
    def _empty_window() -> dict:
        return {
            "steps": 0,
            "last": np.zeros(2),  # of the last step: active, sticking nodes
            "lam": 0.0,
            "diss": 0.0,
            "peaks": np.array([0.0, -np.inf]),  # predictor penetration, -gap after
        }

    def collect(self) -> FilmRecord:
        """Reduce the diagnostics of the steps since the previous call over ranks, append
        them to :attr:`history` and return them (collective; at least one step)."""
        w = self._window
        if w["steps"] == 0:
            raise RuntimeError("FilmContact.collect: no contact step since the last collect")
        sums = np.concatenate([w["last"], [w["lam"], w["diss"]]])
        self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        peaks = w["peaks"].copy()
        self.comm.Allreduce(MPI.IN_PLACE, peaks, op=MPI.MAX)
        self.dissipation_total += float(sums[3])
        rec = FilmRecord(
            time=self.time,
            steps=w["steps"],
            active=int(sums[0]),
            max_penetration=float(peaks[0]),
            sum_lambda=float(sums[2]) / w["steps"],
            min_gap_after=float(-peaks[1]),
            n_stick=int(sums[1]),
            dissipation=float(sums[3]),
        )
        self.history.append(rec)
        self._window = self._empty_window()
        return rec

    def correct_velocities(self, v: PETSc.Vec) -> None:
        """Post-impact half-step velocities of the nodes corrected in this step (in place)."""
        if self.last is None:
            return
        t0 = time.perf_counter()
        n = self.n
        va = v.getArray()[: 3 * n].reshape(n, 3)
        va[self._act] = self.last.v[self._act]
        self.wall += time.perf_counter() - t0

    def forces_on_body(self) -> np.ndarray:
        """Nodal contact forces on the body [N] of the last step, (n_owned, 3)."""
        return np.zeros((self.n, 3)) if self.last is None else -self.last.force

    def nodal_multipliers(self) -> np.ndarray:
        """Normal multipliers of the last step per owned node [N] (0 where not in contact)."""
        return np.zeros(self.n) if self.last is None else self.last.lam_n.copy()

    def contact_body(self) -> np.ndarray:
        """Index of the ellipsoid each owned node touched in the last step (-1: none)."""
        return np.full(self.n, -1, dtype=np.intp) if self.last is None else self.last.body.copy()

    def resultant(self) -> np.ndarray:
        """Total contact force on the body(ies) of the last step [N], reduced over ranks."""
        return self.comm.allreduce(self.forces_on_body().sum(axis=0), op=MPI.SUM)

    def torque(self, joint, *, nodes=None) -> np.ndarray:
        """Eq. 28 about ``joint`` [m] over ``nodes`` (mask/indices of owned nodes, or a
        function of the reference coordinates, shape (3, n), -> mask, as for
        :meth:`clothfem.contact.lagrange.LagrangeContact.torque`), reduced over ranks [N m]."""
        u = self.model.u.x.array[: 3 * self.n].reshape(self.n, 3)
        sel = np.asarray(nodes(self.X.T.copy()), dtype=bool) if callable(nodes) else nodes
        tau = joint_torque(self.X + u, self.forces_on_body(), np.asarray(joint, float), nodes=sel)
        return self.comm.allreduce(np.asarray(tau), op=MPI.SUM)
