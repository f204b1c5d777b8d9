"""One runner for the time integrators of a scene (Model / State / Control).

:func:`run_dynamic` advances any dynamic scene — a garment on a moving body or a free drape —
with the scene's integrator and writes the same outputs for each. Its parts:

* **Model**: the shell (:class:`clothfem.shell.ShellModel`, forms built once) and what the
  integrator builds from it for this scene only (contact when the scene has a body,
  self-contact when asked); the build log names what was left out.
* **Control** (:class:`Control`): what the scene prescribes at time t — the load factor and
  the body poses (at rest until ``solver.settle_time``, then each segment's motion).
* **State**: the integrator's arrays (positions, velocities, accelerations, directors,
  material histories, contact state: ``Integrator.state_arrays``) and the runner's counters
  (:class:`_Counters`), saved together in one ``.npz`` per rank
  (:func:`clothfem.run_output.save_checkpoint`) and restored by ``--resume``.
* **Integrators** behind one interface (:class:`Integrator`): ``explicit`` (central
  difference with forward-increment Lagrange multipliers, Sec. 3.2) and ``newmark``
  (Newmark with Lagrange multipliers and an active set, Sec. 3.1.3). The runner owns the
  time loop: it asks for one accepted step at a time (``step``), then reads the step's
  contact forces on the body per node (or per node-ellipsoid pair, ``body_forces``).
* **Measures**, the same for every integrator: the Eq. 28 torque
  (:class:`clothfem.torque_measure.TorqueMeasure`), the ``[[torques]]`` table, the work of
  the measured joint (:class:`_JointWork`), energies and dissipation.

History rows: one per accepted step for an integrator whose contact forces are a state
(Newmark), one per ``output.interval`` for one whose forces are impulses (explicit: the
torque, resultant and multiplier sum are then the means over the row's steps). The columns
are :data:`clothfem.history.COLUMNS` for both. Fields every ``output.every`` rows and at the
end; a checkpoint every ``output.checkpoint_every`` rows.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from .contact.forces import joint_torque
from .history import yarn_strain_columns
from .io import Progress, ResultWriter, rank0_print
from .report import joint_power, joint_work
from .run_output import (
    SCENE_RECORD,
    end_together,
    load_checkpoint,
    plot_torque_angle,
    progress_snapshots,
    save_checkpoint,
    scene_record,
    stop_with_fields,
    torque_columns,
    write_animation,
    write_snapshot,
)
from .scene_body import (
    aj_mask,
    body_motions,
    body_poses,
    measured_hinge,
    run_plan,
    summary_events,
    torque_centre,
    write_events,
)
from .shell import ShellModel
from .spec import Scene
from .static import SolverDivergence
from .torque_measure import pinched, torque_segment_index
from .torque_table import TorqueTable
from .torque_table import append as append_torques
from .torque_table import keep_rows as keep_torque_rows
from .torque_table import plot as plot_torques

__all__ = ["BodyForces", "Control", "Integrator", "run_dynamic"]


@dataclass(frozen=True)
class Control:
    """What a scene prescribes at time t [s]: the load factor ``load(t)`` (0..1, ramped over
    ``solver.ramp_time``) and the body ``bodies_at(t) -> (ellipsoids, velocities)``; the body
    rests until ``t_settle`` [s]; the run ends at ``t_end`` [s]."""

    load: Callable[[float], float]
    bodies_at: Callable[[float], tuple[list, list]]
    t_settle: float
    t_end: float

    def stage(self, t: float) -> str:
        """``settle`` while the body rests, then ``motion``."""
        return "settle" if t <= self.t_settle + 1e-12 else "motion"


def control_from_scene(scene: Scene, motions: list, t_end: float) -> Control:
    """The :class:`Control` of a validated dynamic scene."""
    t_ramp = scene.solver.ramp_time
    return Control(
        load=(lambda t: min(t / t_ramp, 1.0)) if t_ramp > 0 else (lambda t: 1.0),
        bodies_at=body_poses(scene, motions),
        t_settle=scene.solver.settle_time,
        t_end=t_end,
    )


@dataclass(frozen=True)
class BodyForces:
    """The contact forces of one accepted step on this rank: points ``x`` (m, 3) [m], the
    forces they exert on the body ``force_on_body`` (m, 3) [N], the ellipsoid each touches
    ``body`` (m,) (-1: none), and ``nodes`` (m,), their owned node indices (None: the
    points are the owned nodes in order)."""

    x: np.ndarray
    force_on_body: np.ndarray
    body: np.ndarray
    nodes: np.ndarray | None = None


@dataclass(frozen=True)
class StepInfo:
    """An accepted step as the runner sees it."""

    time: float  # at its end [s]
    dt: float  # [s]


class Integrator(Protocol):
    """A time integrator of the generic runner, built as ``cls(scene, model, control, comm,
    data=checkpoint or None)`` (a checkpoint's arrays restore its state)."""

    impulsive: bool  # contact forces are impulses of a step (rows average them)
    label: str  # for messages: "explicit run", "dynamic contact"
    failures: tuple[type[BaseException], ...]  # errors that stop the run as a divergence
    X: np.ndarray | None  # owned nodes' reference positions (n, 3) [m] (None: no body)

    @property
    def done(self) -> bool:
        """Whether the state is at ``control.t_end``."""

    def step(self, *, ends_row: Callable[[float], bool]) -> StepInfo:
        """Advance the state by one accepted step; ``ends_row(t)``: whether the step to t
        ends a history row (its energies are then measured)."""

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The state to checkpoint (rank-local arrays; a checkpoint's ``data`` restores it)."""

    def body_forces(self) -> BodyForces | None:
        """The last step's contact forces on the body (None without a body)."""

    def pressure(self) -> np.ndarray | None:
        """Contact pressure [Pa] per owned node (collective; None without a body)."""

    def row(self, *, frame: bool) -> dict[str, float]:
        """The integrator's history columns of a row (collective); ``frame``: fields are
        written with it."""

    def summary(self) -> dict[str, Any]:
        """Its entries of ``summary.json`` so far."""

    def progress(self) -> str:
        """Its part of the progress line."""


@dataclass
class _Counters:
    """The runner's part of the state (checkpointed as ``run_<name>``)."""

    step: int = 0  # accepted steps
    row: int = 0  # history rows written
    snap: int = 0  # progress snapshots taken
    pen: float = 0.0  # largest penetration after correction [m]
    time: float = 0.0  # of the last row [s]

    def arrays(self) -> dict[str, np.ndarray]:
        return {f"run_{k}": np.array(v) for k, v in vars(self).items()}

    @classmethod
    def from_arrays(cls, data: dict[str, np.ndarray]) -> _Counters:
        kinds = {"step": int, "row": int, "snap": int, "pen": float, "time": float}
        return cls(**{k: kind(data[f"run_{k}"]) for k, kind in kinds.items()})


@dataclass
class _JointWork:
    """The work [J] the measured joint (a hinge) does against the garment,
    -int tau_seg . omega dt with tau_seg the torque of the contact forces on its segment about
    its joint: one impulse per step for impulsive forces, else the trapezoid rule over the
    hinge angle of :func:`clothfem.report.joint_work` (the segment torque is a state)."""

    motion: Any  # HingeMotion or None
    k: int | None  # its segment
    axis: np.ndarray
    t_settle: float
    impulsive: bool
    work: float = 0.0  # up to the last row
    theta: float = 0.0  # hinge angle at the last row [rad]
    tau_axis: float = 0.0  # segment torque about the axis at the last row [N m]
    local: np.ndarray = field(default_factory=lambda: np.zeros(4))  # impulse work, seg (3)

    def add(self, *, t: float, dt: float, forces: BodyForces) -> None:
        """This step's local part (summed over the row's steps, reduced by the runner)."""
        if self.motion is None:
            return
        on = forces.body == self.k
        if not on.any():
            if not self.impulsive:
                self.local[1:] = 0.0
            return
        seg = joint_torque(forces.x[on], forces.force_on_body[on], self.motion.joint)
        if not self.impulsive:
            self.local[1:] = seg
        elif t > self.t_settle:
            omega = self.motion.pose(t - self.t_settle).angular_velocity
            if omega.any():
                self.local[0] += float(joint_power(seg, omega)) * dt

    def close_row(self, reduced: np.ndarray, t: float) -> float:
        """The work up to this row from the row's ``reduced`` local parts."""
        if self.motion is not None and not self.impulsive:
            tau_axis = float(reduced[1:] @ self.axis)
            theta = self.motion.angle(max(t - self.t_settle, 0.0))
            th, ta = np.array([self.theta, theta]), np.array([self.tau_axis, tau_axis])
            self.work += float(joint_work(th, ta, 1.0)[-1])
            self.theta, self.tau_axis = theta, tau_axis
        else:
            self.work += float(reduced[0])
        self.local[:] = 0.0
        return self.work

    def arrays(self) -> dict[str, np.ndarray]:
        return {f"run_{k}": np.array(getattr(self, k)) for k in ("work", "theta", "tau_axis")}

    def restore(self, data: dict[str, np.ndarray]) -> None:
        self.work, self.theta, self.tau_axis = (
            float(data[f"run_{k}"]) for k in ("work", "theta", "tau_axis")
        )


class _Explicit:
    """Central difference with the lumped mass and forward-increment Lagrange multipliers
    (:class:`clothfem.contact.film.FilmContact`, built only with a body), fixed step
    ``solver.safety`` x the stable step at t = 0 (shrinking with ``solver.recheck_every``);
    fabric self-contact when ``contact.self_contact``; mass damping while settling
    (``solver.settle_damping``)."""

    impulsive = True
    label = "explicit run"

    def __init__(self, scene: Scene, model: ShellModel, control: Control, comm, *, data) -> None:
        from .contact.film import FilmContact, FilmParameters
        from .contact.self_contact import SelfContact
        from .dynamics import DynamicsDivergence, ShellSystem

        self.failures = (DynamicsDivergence, FloatingPointError)
        self.scene, self.model, self.control, self.comm = scene, model, control, comm
        sv, c = scene.solver, scene.contact
        self.system = ShellSystem(model, rotary_scale=sv.rotary_scale)
        self.start: dict[str, Any] = {"step": 0, "v": None, "a": None, "clock": None}
        self.start["work"] = (0.0, 0.0)
        self.self_max = self.self_left = 0
        if data is not None:
            self._restore(data)
        else:
            self._stable_step()
        rank0_print(
            f"  explicit: dt_crit {self.st.dt_crit:.4e} s (Lanczos "
            f"{'converged' if self.st.converged else 'not converged'} in {self.st.iterations}), "
            f"dt {self.dt:.4e} s"
        )
        self.fc = None
        if scene.body:
            self.fc = FilmContact(
                self.system,
                control.bodies_at,
                params=FilmParameters(mu=c.mu, kernel=c.kernel),
            )
            if data is not None:
                self.fc.dissipation_total = float(data["contact_dissipation"])
        # fabric self-contact (contact.self_contact): FILM, then the self-contact correction
        self.sc = SelfContact.from_scene(self.system, c, film=self.fc) if scene.body else None
        rank0_print(f"  self-contact: {'built' if self.sc is not None else 'not built'}")
        if self.sc is not None and data is not None and "run_self_friction" in data:
            self.sc.friction_loss = float(data["run_self_friction"])
        self.X = self.fc.X if self.fc is not None else None
        self.area = None
        if self.fc is not None:  # reference lumped areas [m^2]
            self.area = self.fc.mass / (model.material.rho * model.thickness)
        self.last = None
        self.wall = 0.0  # contact wall time up to the last row [s]
        self.window = _NO_CONTACT  # the contact diagnostics of the last row
        self.stepper = self._stepper()

    def _stable_step(self) -> None:
        from .dynamics import stable_time_step
        from .shell.viscosity import explicit_step_factor

        self.st = stable_time_step(self.system, lam=self.control.load(0.0), iterations=600)
        self.dt = self.scene.solver.safety * self.st.dt_crit
        visc, mat = self.model.material.viscosity, self.model.material
        if visc is not None:  # the damped central difference's smaller stable step
            factor = explicit_step_factor(
                omega=self.st.omega_max, viscosity=visc, E1=mat.E1, E2=mat.E2, G12=mat.G12
            )
            self.dt *= factor
            rank0_print(f"  explicit: membrane viscosity, step x {factor:.3f}")

    def _restore(self, data) -> None:
        from .dynamics import StableStep

        self.start["v"], self.start["a"] = _restore_motion(self.model, self.system, data)
        self.st = StableStep(
            *(float(data[f"st_{k}"]) for k in ("dt_crit", "omega_max", "dt_bound")),
            int(data["st_iterations"]),
            bool(data["st_converged"]),
        )
        self.dt = float(data["dt"])
        self.start["step"] = int(data["run_step"])
        if "run_clock_h" in data:  # the step had shrunk: continue its clock
            c0 = [data[f"run_clock_{k}"] for k in _CLOCK]
            self.start["clock"] = (float(c0[0]), int(c0[1]), float(c0[2]), int(c0[3]))
        self.start["work"] = (float(data["run_external_work"]), float(data["run_damping_work"]))
        if "run_self_max" in data:
            self.self_max, self.self_left = int(data["run_self_max"]), int(data["run_self_left"])

    def _stepper(self):
        """The central difference from the start (or the checkpoint's) state."""
        from .dynamics import Damping, ExplicitStepper

        sv = self.scene.solver
        return ExplicitStepper(
            self.system,
            t_end=self.control.t_end,
            dt=self.dt,
            load=self.control.load,
            stable=self.st,
            contact=self.fc if self.sc is None else self.sc,
            safety=sv.safety,
            recheck_every=sv.recheck_every,
            clock=self.start["clock"],
            work=self.start["work"],
            first_step=self.start["step"],
            velocity=self.start["v"],
            acceleration=self.start["a"],
            damping=Damping(mass=sv.settle_damping),
            damping_until=self.control.t_settle,
        )

    @property
    def done(self) -> bool:
        return self.stepper.done

    def step(self, *, ends_row: Callable[[float], bool]) -> StepInfo:
        # the strain energy only for the steps that end a row
        self.last = self.stepper.step(measure=lambda _k, t: ends_row(t))
        return StepInfo(time=self.last.time, dt=self.last.dt)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return self._arrays(self.last, self.stepper.v, self.stepper.a)

    def _arrays(self, r, v, a) -> dict[str, np.ndarray]:
        from .dynamics import StableStep

        run: dict[str, Any] = {"run_external_work": r.external_work}
        run["run_damping_work"] = r.damping_work
        if r.clock is not None and r.clock[1] > 0:  # the step shrank: save its clock
            run.update({f"run_clock_{k}": val for k, val in zip(_CLOCK, r.clock, strict=True)})
        run["contact_dissipation"] = self.fc.dissipation_total if self.fc is not None else 0.0
        run["dt"] = self.dt
        if self.sc is not None:  # the run's self-contact totals (summary)
            run.update(run_self_max=self.self_max, run_self_left=self.self_left)
            run["run_self_friction"] = self.sc.friction_loss
        run.update({f"st_{k}": getattr(self.st, k) for k in StableStep.__dataclass_fields__})
        data = _motion_arrays(self.model, v, a)
        return {**data, **{k: np.array(x) for k, x in run.items()}}

    def body_forces(self) -> BodyForces | None:
        if self.fc is None:
            return None
        n = self.model.n_owned
        x = self.fc.X + self.model.u.x.array[: 3 * n].reshape(n, 3)
        return BodyForces(x=x, force_on_body=self.fc.forces_on_body(), body=self.fc.contact_body())

    def pressure(self) -> np.ndarray | None:
        return None if self.fc is None else self.fc.nodal_multipliers() / self.area

    def row(self, *, frame: bool) -> dict[str, float]:
        r = self.last
        h = self.fc.collect() if self.fc is not None else _NO_CONTACT  # collective
        pen_after = max(0.0, -h.min_gap_after) if math.isfinite(h.min_gap_after) else 0.0
        wall = self.fc.wall if self.fc is not None else 0.0
        row = {
            "load_factor": r.load_factor,
            "n_active": h.active,
            "max_penetration": pen_after,
            "predictor_penetration": h.max_penetration,
            "sum_lam": h.sum_lambda,
            "n_stick": h.n_stick,
            "n_slip": h.active - h.n_stick,
            "kinetic_energy": r.kinetic,
            "strain_energy": r.strain,
            "external_work": r.external_work,
            "dissipation_total": self.fc.dissipation_total if self.fc is not None else 0.0,
            "t_contact": wall - self.wall,
            **self._self_contact_columns(frame=frame),
        }
        self.wall, self.window = wall, h
        return row

    def _self_contact_columns(self, *, frame: bool) -> dict[str, float]:
        """The correction's diagnostics since the last row and, at a field frame, the
        independent intersection count of the written surface (collective)."""
        if self.sc is None:
            return {}
        rec = self.sc.collect()
        row = {
            "self_pairs": rec.contacts,
            "self_min_gap": rec.min_gap if math.isfinite(rec.min_gap) else math.nan,
            "self_crossings": rec.crossings,
            "self_crossings_left": rec.crossings_left,
            "self_zone_nodes": rec.zone_nodes,
            "self_friction_work": self.sc.friction_loss,
            "t_self_contact": rec.wall,
        }
        self.self_left += rec.crossings_left
        if frame:
            t0 = time.perf_counter()
            row["self_intersections"] = self.sc.intersections()
            self.self_max = max(self.self_max, row["self_intersections"])
            row["t_self_contact"] += time.perf_counter() - t0
        return row

    def summary(self) -> dict[str, Any]:
        out = {"cutbacks": 0, "dt": self.last.dt, "dt_crit": self.st.dt_crit}
        out["newton_iterations"] = 0
        if self.sc is not None:
            out.update(self_intersections_max=self.self_max, self_crossings_left=self.self_left)
            out["self_contact_wall"] = self.sc.wall
            out["self_friction_work"] = self.sc.friction_loss
        return out

    def progress(self) -> str:
        if self.fc is None:
            return f"kinetic energy {self.last.kinetic:.3e} J"
        return f"active {self.window.active}"


_CLOCK = ("t_base", "step_base", "h", "n_end")


def _motion_arrays(model: ShellModel, v, a) -> dict[str, np.ndarray]:
    """The shell's state arrays (``model_*``) with the velocity and acceleration vectors."""
    data = {f"model_{k}": val for k, val in model.state_arrays().items()}
    data.update(v=v.getArray(readonly=True).copy(), a=a.getArray(readonly=True).copy())
    return data


def _restore_motion(model: ShellModel, system, data: dict[str, np.ndarray]) -> tuple:
    """Inverse of :func:`_motion_arrays`: the shell restored, (v, a) as new vectors of
    ``system`` (SceneError if the checkpoint is of another mesh or number of ranks)."""
    from .scene import SceneError

    model.restore_arrays({k[6:]: data[k] for k in data if k.startswith("model_")})
    vectors = []
    for k in ("v", "a"):
        vec = system.create_vector()
        if data[k].shape != vec.getArray().shape:
            raise SceneError("--resume: the checkpoint does not match this mesh / ranks")
        vec.getArray()[:] = data[k]
        vectors.append(vec)
    return tuple(vectors)


@dataclass(frozen=True)
class _NoContact:
    """The contact diagnostics of a row without a body."""

    active: int = 0
    n_stick: int = 0
    max_penetration: float = 0.0
    min_gap_after: float = math.inf
    sum_lambda: float = 0.0


_NO_CONTACT = _NoContact()


class _Newmark:
    """Newmark (gamma = ``solver.gamma``, beta = (gamma + 1/2)^2 / 4) with Lagrange-multiplier
    contact and an active set (:class:`clothfem.contact.dynamic.DynamicContact`), steps of
    ``solver.dt`` halved on failure down to ``solver.dt_min``."""

    impulsive = False
    label = "dynamic contact"

    def __init__(self, scene: Scene, model: ShellModel, control: Control, comm, *, data) -> None:
        from .contact.dynamic import DynamicContact
        from .contact.lagrange import ContactDivergence, LagrangeContactParameters
        from .contact.self_barrier import SelfBarrier
        from .dynamics import ShellSystem

        self.failures = (ContactDivergence,)
        self.scene, self.model, self.control, self.comm = scene, model, control, comm
        c, sv = scene.contact, scene.solver
        gamma = sv.gamma
        system = ShellSystem(model, rotary_scale=sv.rotary_scale)
        # fabric self-contact (contact.self_contact): a barrier in every step's Newton system
        self.sc = SelfBarrier.from_scene(system, c)
        rank0_print(f"  self-contact: {'built' if self.sc is not None else 'not built'}")
        self.self_max = 0
        self.dc = DynamicContact(
            system,
            control.bodies_at,
            params=LagrangeContactParameters(
                mu=c.mu,
                tangential_penalty=c.tangential_penalty,
                semismooth_passes=c.semismooth_passes,
                newton_stall_limit=c.newton_stall_limit,
                tissue_stiffness=c.tissue_stiffness,
            ),
            beta=(gamma + 0.5) ** 2 / 4,
            gamma=gamma,
            barrier=self.sc,
        )
        self.contact = self.dc.contact
        self.X = self.contact.X
        self.cut = self.newton = 0  # totals of the run
        if data is not None:
            self.dc.restore_arrays(data)
            self.cut, self.newton = int(data["run_cut"]), int(data["run_newton"])
            if "run_self_max" in data:
                self.self_max = int(data["run_self_max"])
            if "run_self_friction" in data:
                self.sc.friction_work = float(data["run_self_friction"])
        self.timers = dict(self.contact.timers)
        self.last = None

    @property
    def done(self) -> bool:
        return self.dc.reached(self.control.t_end)

    def step(self, *, ends_row: Callable[[float], bool]) -> StepInfo:
        sv = self.scene.solver
        r = self.last = self.dc.advance(
            t_end=self.control.t_end, dt=sv.dt, dt_min=sv.dt_min, load=self.control.load
        )
        self.cut += r.cutbacks
        self.newton += r.contact.newton_iterations
        return StepInfo(time=r.time, dt=r.dt)

    def state_arrays(self) -> dict[str, np.ndarray]:
        out = {
            **self.dc.state_arrays(),
            "run_cut": np.array(self.cut),
            "run_newton": np.array(self.newton),
        }
        if self.sc is not None:
            out["run_self_max"] = np.array(self.self_max)
            out["run_self_friction"] = np.array(self.sc.friction_work)
        return out

    def body_forces(self) -> BodyForces:
        nodes, body, f_pairs, _ = self.contact.pair_forces()  # per (node, ellipsoid) pair
        n = self.contact.n
        x = self.X[nodes] + self.model.u.x.array[: 3 * n].reshape(n, 3)[nodes]
        return BodyForces(x=x, force_on_body=-f_pairs, body=body, nodes=nodes)

    def pressure(self) -> np.ndarray:
        return self.contact.state().pressure  # collective (areas)

    def row(self, *, frame: bool) -> dict[str, float]:
        r, cr = self.last, self.last.contact
        tm = {k: self.contact.timers[k] - self.timers[k] for k in self.timers}
        self.timers.update(self.contact.timers)
        return {
            "load_factor": float(self.model.lam.value),
            "n_active": cr.n_active,
            "max_penetration": cr.max_penetration,
            **(
                {"tissue_indentation": cr.max_indentation}
                if self.scene.contact.tissue_stiffness is not None
                else {}
            ),
            "min_multiplier": cr.min_multiplier,
            "complementarity": cr.complementarity,
            "sum_lam": cr.total_normal_force,
            "n_stick": cr.n_stick,
            "n_slip": cr.n_slip,
            "cutbacks": r.cutbacks,
            "active_set_iterations": cr.active_set_iterations,
            "newton_iterations": cr.newton_iterations,
            "kinetic_energy": r.kinetic_energy,
            "strain_energy": r.strain_energy,
            "dissipation_total": self.contact.dissipation_total,
            "t_assembly": tm["assembly"],
            "t_contact": tm["contact"],
            "t_solve": tm["solve"],
            **self._self_contact_columns(frame=frame),
        }

    def _self_contact_columns(self, *, frame: bool) -> dict[str, float]:
        """The barrier's diagnostics at the row's step (its wall time since the last row,
        part of t_assembly) and, at a field frame, the independent intersection count of the
        written surface (collective)."""
        if self.sc is None:
            return {}
        rec = self.sc.record()
        row = {
            "self_pairs": rec.pairs,
            "self_min_gap": rec.min_distance if math.isfinite(rec.min_distance) else math.nan,
            "self_crossings": 0,  # the step filter admits no crossing iterate
            "self_crossings_left": 0,
            "self_friction_work": self.sc.friction_work,
            "t_self_contact": rec.wall,
        }
        if frame:
            t0 = time.perf_counter()
            row["self_intersections"] = self.sc.intersections()
            self.self_max = max(self.self_max, row["self_intersections"])
            row["t_self_contact"] += time.perf_counter() - t0
        return row

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cutbacks": self.cut, "newton_iterations": self.newton}
        if self.sc is not None:
            out.update(self_intersections_max=self.self_max, self_crossings_left=0)
            out["self_friction_work"] = self.sc.friction_work
        return out

    def progress(self) -> str:
        r, cr = self.last, self.last.contact
        return (
            f"dt {r.dt:.2e}  cut {r.cutbacks}  active {cr.n_active}  newton {cr.newton_iterations}"
        )


@dataclass(frozen=True)
class _ImplicitStart:
    """Where an implicit run starts: t = 0 at rest, or a checkpoint's state (velocity and
    acceleration vectors, time [s], steps taken, step in use [s], external and damping
    work [J])."""

    v: Any = None
    a: Any = None
    t: float = 0.0
    step: int = 0
    h: float | None = None
    work: tuple[float, float] = (0.0, 0.0)


class _NewmarkFree:
    """Newmark without a body (no contact): :class:`clothfem.dynamics.ImplicitStepper` with
    gamma = ``solver.gamma``, beta = (gamma + 1/2)^2 / 4, steps of ``solver.dt`` cut on a
    failed Newton solve down to ``solver.dt_min`` (default dt / 1024)."""

    impulsive = False
    label = "newmark run"
    X = None

    def __init__(self, scene: Scene, model: ShellModel, control: Control, comm, *, data) -> None:
        from .dynamics import (
            DynamicsDivergence,
            ImplicitScheme,
            ImplicitStepper,
            ShellSystem,
            TimeStepping,
        )

        self.failures = (DynamicsDivergence,)
        self.model, self.control = model, control
        sv = scene.solver
        system = ShellSystem(model, rotary_scale=sv.rotary_scale)
        gamma = sv.gamma
        self.cut = self.newton = 0  # totals of the run
        start = self._restore(system, data) if data is not None else _ImplicitStart()
        self.stepper = ImplicitStepper(
            system,
            stepping=TimeStepping(dt=sv.dt, t_end=control.t_end, dt_min=sv.dt_min),
            scheme=ImplicitScheme.newmark(beta=(gamma + 0.5) ** 2 / 4, gamma=gamma),
            load=control.load,
            velocity=start.v,
            acceleration=start.a,
            time=start.t,
            first_step=start.step,
            dt=start.h,
            work=start.work,
        )
        self.last = None

    def _restore(self, system, data) -> _ImplicitStart:
        v, a = _restore_motion(self.model, system, data)
        self.cut, self.newton = int(data["run_cut"]), int(data["run_newton"])
        return _ImplicitStart(
            v=v,
            a=a,
            t=float(data["newmark_t"]),
            step=int(data["run_step"]),
            h=float(data["newmark_h"]),
            work=(float(data["newmark_work_ext"]), float(data["newmark_work_damp"])),
        )

    @property
    def done(self) -> bool:
        return self.stepper.done

    def step(self, *, ends_row: Callable[[float], bool]) -> StepInfo:
        r = self.last = self.stepper.step()
        self.cut += r.cutbacks
        self.newton += r.newton_iterations
        return StepInfo(time=r.time, dt=r.dt)

    def state_arrays(self) -> dict[str, np.ndarray]:
        st, e = self.stepper, self.stepper.energy
        data = _motion_arrays(self.model, st.v, st.a)
        scalars = dict(newmark_t=st.t, newmark_h=st.h, newmark_work_ext=e.W_ext)
        scalars.update(newmark_work_damp=e.W_damp, run_cut=self.cut, run_newton=self.newton)
        return {**data, **{k: np.array(v) for k, v in scalars.items()}}

    def body_forces(self) -> None:
        return None

    def pressure(self) -> None:
        return None

    def row(self, *, frame: bool) -> dict[str, float]:
        r = self.last
        return {
            "load_factor": r.load_factor,
            "n_active": 0,
            "max_penetration": 0.0,
            "sum_lam": 0.0,
            "cutbacks": r.cutbacks,
            "newton_iterations": r.newton_iterations,
            "kinetic_energy": r.kinetic,
            "strain_energy": r.strain,
            "external_work": r.external_work,
            "dissipation_total": 0.0,
        }

    def summary(self) -> dict[str, Any]:
        return {"cutbacks": self.cut, "newton_iterations": self.newton}

    def progress(self) -> str:
        r = self.last
        return (
            f"kinetic energy {r.kinetic:.3e} J  dt {r.dt:.2e}  cut {r.cutbacks}  "
            f"newton {r.newton_iterations}"
        )


def _integrator(scene: Scene) -> type:
    """The integrator class of a scene (Newmark without a body: no contact)."""
    name = scene.solver.integrator
    if name == "newmark" and not scene.body:
        return _NewmarkFree
    return {"explicit": _Explicit, "newmark": _Newmark}[name]


class _Run:
    """The runner's loop body: measures, rows, fields, checkpoints, progress and stop checks
    of any :class:`Integrator` (see :func:`run_dynamic`)."""

    def __init__(self, scene: Scene, out: Path, *, model, comm, plan, control, integ, data, t0,
                 check_stop, summary):  # fmt: skip
        motions = plan.motions
        self.plan, self.control = plan, control
        self.scene, self.out, self.model, self.comm = scene, out, model, comm
        self.integ, self.t0, self.check_stop, self.summary = integ, t0, check_stop, summary
        self.n = model.n_owned
        self.record = np.array(json.dumps(scene_record(scene)))  # checked on --resume
        self.c = _Counters.from_arrays(data) if data is not None else _Counters()
        self.fixed = plan.measure.fixed_mask(integ.X) if plan.measure is not None else None
        self.table = None  # the [[torques]] measures (a body is required by the validation)
        if scene.torques:
            self.table = TorqueTable(scene, motions, integ.X, aj_mask=aj_mask, centre=torque_centre)
        hinge = measured_hinge(motions, plan.k_torque)
        self.work = _JointWork(
            hinge, plan.k_torque, plan.hinge_axis, plan.t_settle, integ.impulsive
        )
        if data is not None:
            self.work.restore(data)
        # this rank's torque (3), resultant (3), flexion and its pinched part of the row
        self.local = np.zeros(8)
        # per-pair forces (implicit) on two or more segments: a node can press on two at once
        self.pinch = not integ.impulsive and len(scene.body) > 1
        self.k = 0  # steps in the row
        self.pressure = None  # Pa, nodal (multipliers / reference lumped area)
        if scene.body:
            S = fem.FunctionSpace(model.mesh, model.V.ufl_element().sub_elements()[0])
            self.pressure = fem.Function(S, name="contact_pressure")
        self.t_row = time.perf_counter()
        self.t_last = self.c.time  # of the last accepted step [s]
        self.due = False  # a checkpoint after this step

    def ends_row(self, t: float) -> bool:
        """Whether the step to ``t`` ends a history row (every step of a non-impulsive
        integrator; else one per ``output.interval`` and the last step)."""
        if not self.integ.impulsive:
            return True
        interval = self.scene.output.interval
        return t >= (self.c.row + 1) * interval - 1e-12 or t >= self.plan.t_end - 1e-12

    def fields(self) -> tuple[fem.Function, ...]:
        """The fields written besides the displacement (collective: the pressure's areas)."""
        if self.pressure is None:
            return ()
        self.pressure.x.array[: self.n] = self.integ.pressure()
        self.pressure.x.scatter_forward()
        return (self.pressure,)

    def snapshot(self, tag: str, t: float) -> None:
        """``snapshot_<tag>.png`` of the state at ``t`` (collective)."""
        self.fields()
        bodies = self.control.bodies_at(t)[0] if self.scene.body else []
        write_snapshot(
            self.scene, self.model, self.out, self.comm, tag, bodies, pressure=self.pressure
        )

    def on_step(self, info: StepInfo, writer: ResultWriter, progress: Progress) -> None:
        self.model.commit_material()  # the step is accepted: material histories to x_n+1
        self.c.step += 1
        self.t_last = info.time
        forces = self.integ.body_forces()
        if forces is not None:
            self._measure(info, forces)
        self.k += 1
        if self.ends_row(info.time):
            self._row(info, writer, progress)

    def _measure(self, info: StepInfo, forces: BodyForces) -> None:
        fixed = self.fixed
        if fixed is not None and forces.nodes is not None:
            fixed = fixed[forces.nodes]
        f, m = forces, self.plan.measure
        tau, flex = m.local(t=info.time, x=f.x, force_on_body=f.force_on_body, body=f.body,
                            fixed=fixed)  # fmt: skip
        self.local[:3] += tau
        self.local[3:6] += f.force_on_body.sum(axis=0)
        self.local[6] += flex
        if self.pinch and f.nodes is not None and len(f.nodes):
            two = pinched(f.nodes)
            _, flex_p = m.local(t=info.time, x=f.x, force_on_body=f.force_on_body * two[:, None],
                                body=f.body, fixed=fixed)  # fmt: skip
            self.local[7] += flex_p
        if self.table is not None:
            self.table.add(
                t=info.time, x=f.x, force_on_body=f.force_on_body, body=f.body, nodes=f.nodes
            )
        self.work.add(t=info.time, dt=info.dt, forces=f)

    def _reduce(self) -> tuple[np.ndarray, np.ndarray, float, float, int, np.ndarray]:
        """The row's torque, resultant, flexion and its pinched part (means over its steps),
        its step count and the joint work's reduced parts (one reduction per row)."""
        sums = np.concatenate([self.local, self.work.local])
        self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        k, self.k = self.k, 0
        self.local[:] = 0.0
        tau, res, flex = sums[:3] / k, sums[3:6] / k, float(sums[6]) / k
        return tau, res, flex, float(sums[7]) / k, k, sums[8:]

    def _row(self, info: StepInfo, writer: ResultWriter, progress: Progress) -> None:
        t, c, o = info.time, self.c, self.scene.output
        frame = (c.row + 1) % o.every == 0 or t >= self.plan.t_end - 1e-12  # and the last
        integ_row = self.integ.row(frame=frame)  # collective
        c.row += 1
        tau, res, flex, flex_pinched, k, work_parts = self._reduce()
        work = self.work.close_row(work_parts, t)
        if self.table is not None:
            rows = self.table.rows(comm=self.comm, steps=k, increment=c.row, time=t)
            append_torques(self.out, rows, self.comm)
        angle = self.plan.angle_at(t)
        tio = time.perf_counter()
        if frame:
            writer.write_fields(t, self.fields())
        t_io = time.perf_counter() - tio
        now = time.perf_counter()
        row = {
            "stage": self.control.stage(t),
            "increment": c.row,
            "time": t,
            "dt": info.dt,
            "angle_deg": angle,
            **torque_columns(tau, res, flex),
            **({"torque_flex_pinched": flex_pinched} if self.pinch else {}),
            **({"substeps": k} if self.integ.impulsive else {}),
            **yarn_strain_columns(self.model),
            "joint_work": work,
            "dissipation_material": self.model.dissipated_material(),
            **integ_row,
            "t_io": t_io,
            "wall_time": now - self.t_row,
            "elapsed": now - self.t0,
        }
        self.t_row = now
        c.pen, c.time = max(c.pen, row["max_penetration"]), t
        writer.append_row(row)
        every = o.checkpoint_every
        self.due = bool(every) and c.row % every == 0
        self.summary.update(final_angle_deg=angle, time=t, steps=c.step, max_penetration=c.pen)
        self.summary.update(self.integ.summary())
        self._progress(row, progress)
        c.snap = progress_snapshots(self.plan, c.snap, row["stage"], angle,
                                     lambda tag: self.snapshot(tag, t), t=t)  # fmt: skip
        where = f"row {c.row} (t = {t:.6g} s)"
        stop_with_fields(self.check_stop, where, writer, t, self.fields)

    def _progress(self, row: dict[str, Any], progress: Progress) -> None:
        t, end = row["time"], self.plan.t_end
        head = f"t {t:7.4f} s  "
        if self.scene.body:
            head += f"angle {row['angle_deg']:6.2f} deg  |tau| {row['torque_mag']:.4f} N m  "
        frac = min(max(t / end, 0.0), 1.0) if end > 0 else 1.0
        progress.update(
            frac, head + self.integ.progress() + f"  row {self.c.row}  steps {self.c.step}"
        )

    def after_step(self, arrays: Callable[[], dict[str, np.ndarray]]) -> None:
        """Checkpoint the state when the last row asked for it."""
        if self.due:
            self.due = False
            data = {**arrays(), **self.c.arrays(), **self.work.arrays()}
            data[SCENE_RECORD] = self.record
            save_checkpoint(self.out, self.comm, data)


def run_dynamic(
    scene: Scene,
    out: Path,
    *,
    model: ShellModel,
    comm: MPI.Comm,
    t0: float,
    check_stop: Callable[[str], None],
    resume: bool,
    summary: dict[str, Any],
) -> Path:
    """Run a dynamic scene (``solver.integrator`` explicit or newmark) from t = 0 or, with
    ``resume``, from the checkpoint in ``out``; write ``history.csv``, ``fabric.xdmf``,
    snapshots, plots and the animation to ``out`` (see the module docstring).
    ``check_stop(where)`` is called after every row (raises to stop the run); ``summary`` is
    updated as the run goes. Raises :class:`SolverDivergence` when the integrator fails
    (the rows and fields written so far are kept, with a snapshot of the last state)."""
    write_events(scene, out, comm, summary)
    plan = run_plan(scene, body_motions(scene))
    control = control_from_scene(scene, plan.motions, plan.t_end)
    data = load_checkpoint(out, comm) if resume else None
    integ = _integrator(scene)(scene, model, control, comm, data=data)
    run = _Run(scene, out, model=model, comm=comm, plan=plan, control=control, integ=integ,
               data=data, t0=t0, check_stop=check_stop, summary=summary)  # fmt: skip
    keep, after = (run.c.row, run.c.time) if resume else (None, None)
    if resume:
        rank0_print(f"  resumed from the checkpoint at t = {run.c.time:.6g} s (row {keep})")
        if run.table is not None:
            keep_torque_rows(out, keep, comm)
    model.u.name = "displacement"
    end, name = plan.t_end, scene.scene.name
    progress = Progress(
        label=name, comm=comm, start=min(max(run.c.time / end, 0.0), 1.0) if end > 0 else 0.0
    )
    with ResultWriter(out, model, keep_rows=keep, resume_after=after) as writer:
        try:
            while not integ.done:
                run.on_step(integ.step(ends_row=run.ends_row), writer, progress)
                run.after_step(integ.state_arrays)
            run.snapshot("final", end)
        except integ.failures as exc:
            t, angle = run.t_last, plan.angle_at(run.t_last)
            run.snapshot(f"stopped_{angle:04.1f}deg", t)
            raise SolverDivergence(
                f"{integ.label} stopped at t = {t:.6g} s ({angle:.2f} deg): {exc}"
            ) from None
        finally:
            progress.close()
            end_together(comm)
            if scene.output.png and comm.rank == 0 and writer.csv_path.exists():
                _plots(scene, out, writer.csv_path, summary, control)
    return out


def _plots(scene: Scene, out: Path, csv_path: Path, summary, control: Control) -> None:
    """The torque plots and the animation of a run (rank 0)."""
    name, events = scene.scene.name, summary_events(summary)
    if scene.body:
        plot_torque_angle(csv_path, out / "torque_angle.png", name, events)
    if scene.torques:
        k = torque_segment_index(scene)
        primary = scene.body[k].name if k is not None else "[contact]"
        plot_torques(out, out / "torques.png", primary=primary, title=name, events=events)
    write_animation(scene, out, lambda t: control.bodies_at(t)[0])
