"""The quasi-static runner with a body, and what every runner derives from a scene's body.

:func:`run_contact_scene` runs ``solver.integrator = "static"`` with ``[[body]]`` segments;
the dynamic integrators run through :func:`clothfem.simulation.run_dynamic`. What both
derive from the body is in :mod:`clothfem.scene_body`, what both write in
:mod:`clothfem.run_output`.

Stages of the quasi-static run
------------------------------
1. **Settling** (``contact.settle``): the loads (gravity) are ramped from 0 to full in
   ``solver.steps`` equal steps with the body at rest, quasi-statically with contact
   (:meth:`LagrangeContact.advance`, automatic cut-back), so the sleeve comes to rest on the arm.
2. **Motion**: the hinge segments are turned to their ``angle_max`` in ``contact.increments``
   equal angle increments (each one solved by ``advance``: sub-steps with cut-back). Every
   increment is an equilibrium state with contact and friction history: no inertia, so
   ``omega`` only maps the angle to a time column.

After the settled state and after each increment one CSV row is written at once (angle, Eq. 28
torque about J over the node set AJ, its component along the hinge axis, resultant, active
nodes, max penetration, min multiplier, iterations, wall time), plus the fabric displacement
to XDMF. PNG snapshots (fabric + ellipsoids) are drawn at the settled state, at about every
quarter of the motion and at the end; ``torque_angle.png`` is (re)drawn at the end, also when
the run stops early.

Resistance measures (every integrator): ``joint_work`` [J] is the cumulative work the measured
joint (the torque segment's hinge) does against the garment, -int tau_seg . omega dt with
tau_seg the torque of the contact forces on that segment about its joint
(:func:`clothfem.report.joint_work`: trapezoid over the hinge angle of the quasi-static
increments and of the Newmark steps, one impulse per explicit step);
``dissipation_total`` [J] is the contact layers' frictional dissipation and
``dissipation_material`` [J] the fabric's (yarn friction, ``material.friction_*``; 0 for an
elastic fabric). :func:`clothfem.run.run_scene` adds the per-phase torque statistics to
``summary.json`` (:func:`clothfem.report.resistance_measures`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from .body import HingeMotion
from .contact.forces import joint_torque
from .contact.lagrange import ContactDivergence, LagrangeContact, LagrangeContactParameters
from .history import yarn_strain_columns
from .io import Progress, ResultWriter, rank0_print
from .report import joint_work
from .run_output import (
    end_together,
    plot_torque_angle,
    torque_columns,
    write_animation,
    write_snapshot,
)
from .scene_body import (
    aj_mask,
    body_motions,
    measured_hinge,
    summary_events,
    torque_centre,
    write_events,
)
from .shell import ShellModel
from .spec import Scene
from .static import SolverDivergence
from .torque_measure import torque_segment_index

__all__ = ["run_contact_scene"]


def _drive(
    contact,
    motions,
    hinge_ids,
    t0: float,
    t1: float,
    *,
    max_cutbacks: int = 8,
    max_substeps: int = 64,
    on_sub=None,
):
    """Move the hinge segments from their poses at ``t0`` to those at ``t1`` (s) in sub-steps
    on the exact hinge path: halve the sub-step after a failed one (state restored by
    ``solve_step``), double it after every converged one; give up after ``max_cutbacks``
    halvings in a row or ``max_substeps`` converged sub-steps. Returns the sub-step records."""

    def place(t: float) -> None:
        for i in hinge_ids:
            p = motions[i].pose(t)
            contact.set_pose(i, centre=p.centre, axes=p.rotation)

    span = t1 - t0
    t, h, cuts, recs = t0, span, 0, []
    while t < t1 - 1e-12 * span:
        if len(recs) >= max_substeps:  # creeping: fail rather than run for ever
            raise ContactDivergence(
                f"increment not done after {max_substeps} sub-steps (reached t = {t:.6g} s)"
            )
        trial = min(t1, t + h)
        place(trial)
        try:
            rec = contact.solve_step(1.0)
        except ContactDivergence:
            place(t)
            cuts += 1
            if cuts > max_cutbacks:
                raise ContactDivergence(
                    f"no convergence after {max_cutbacks} halvings of the sub-step at "
                    f"t = {t:.6g} s ({len(recs)} sub-steps converged in this increment)"
                ) from None
            h *= 0.5
            continue
        recs.append(rec)
        if on_sub is not None:
            on_sub(rec)
        t, cuts, h = trial, 0, min(2.0 * h, span)
    return recs


class _ViscousStabilization:
    """Artificial viscous damping of the quasi-static path (like Abaqus' STABILIZE): adds the
    nodal force ``-eta A_i (u_i - u_i^prev)`` (eta in Pa/m, A_i the lumped reference nodal
    area, ``u^prev`` the last converged sub-step) to the fabric's residual and ``eta A_i`` to
    the diagonal of its tangent. It lets the path pass wrinkling points where the tangent is
    singular; the force it leaves is reported (``stabilization_force``, N) to judge it."""

    def __init__(self, model: ShellModel, area: np.ndarray, eta: float) -> None:
        self.model, self.eta, self.n = model, eta, model.n_owned
        self.c = np.repeat(eta * area, 3)  # per u row, N/m
        self.u_prev = model.u.x.array[: 3 * self.n].copy()
        self.last = 0.0
        self._residual, self._jacobian = model.residual, model.jacobian
        model.residual = self.residual  # instance attributes shadow the methods
        model.jacobian = self.jacobian

    def commit(self, *_args) -> None:
        self.u_prev[:] = self.model.u.x.array[: 3 * self.n]

    def residual(self, x, f) -> None:
        self._residual(x, f)
        xa = x.getArray(readonly=True)[: 3 * self.n]
        fa = f.getArray()
        fa[: 3 * self.n] += self.c * (xa - self.u_prev)

    def jacobian(self, x, K=None):
        K = self._jacobian(x, K)
        d = K.createVecRight()
        arr = d.getArray()
        arr[:] = 0.0
        arr[: 3 * self.n] = self.c
        K.setDiagonal(d, addv=True)
        d.destroy()
        return K

    def force(self, comm: MPI.Comm) -> float:
        """Magnitude sum over nodes of the artificial force at the current state (N)."""
        du = (self.model.u.x.array[: 3 * self.n] - self.u_prev).reshape(-1, 3)
        f = np.linalg.norm(self.c.reshape(-1, 3) * du, axis=1).sum()
        return comm.allreduce(float(f), op=MPI.SUM)


def _segment_torque(contact, model: ShellModel, k: int, joint: np.ndarray, comm) -> np.ndarray:
    """Torque [N m] about ``joint`` of the contact forces on ellipsoid ``k`` at the last
    converged state of a :class:`LagrangeContact` (reduced over ranks)."""
    nodes, body, f_pairs, _ = contact.pair_forces()
    on = body == k
    x = contact.X + model.u.x.array[: 3 * contact.n].reshape(-1, 3)
    tau = joint_torque(x[nodes[on]], -f_pairs[on], joint) if on.any() else np.zeros(3)
    return comm.allreduce(np.asarray(tau, dtype=float), op=MPI.SUM)


def run_contact_scene(
    scene: Scene,
    out: Path,
    *,
    model: ShellModel,
    comm: MPI.Comm,
    t0: float,
    check_stop: Callable[[str], None],
    summary: dict[str, Any] | None = None,
) -> Path:
    """Settle, then drive the hinges; write ``history.csv``, ``fabric.xdmf`` and PNGs to ``out``.

    The quasi-static path (``solver.integrator = "static"``): a sequence of equilibria (the
    dynamic integrators run through :func:`clothfem.simulation.run_dynamic`).
    ``check_stop(where)`` is called after every written row and every converged sub-step
    (raises to stop the run). ``summary`` (dict) is updated as the run goes (final angle,
    steps, cut-backs, max penetration). Raises :class:`SolverDivergence` when a step fails
    below the smallest step (rows written so far are kept).
    """
    summary = summary if summary is not None else {}
    write_events(scene, out, comm, summary)
    c = scene.contact
    motions = body_motions(scene)
    bodies = []
    for seg, mo in zip(scene.body, motions, strict=True):
        pose = mo.pose(0.0)
        bodies.append((pose.centre, pose.rotation, np.asarray(seg.radii, dtype=float)))
    # quasi-static wrinkling paths have several equilibria: the paper's fixed-set passes
    # (no semismooth set changes inside Newton) keep the branch independent of round-off
    params = LagrangeContactParameters(
        mu=c.mu, semismooth_passes=0, tissue_stiffness=c.tissue_stiffness
    )
    contact = LagrangeContact(model, bodies, params=params)
    stab = None
    if c.stabilization > 0:
        stab = _ViscousStabilization(model, contact.lumped_area(), c.stabilization)
    J = torque_centre(scene)
    k_torque = torque_segment_index(scene)
    hinge_axis = (
        np.asarray(motions[k_torque].axis) if k_torque is not None else np.array([0.0, 0.0, 0.0])
    )
    aj = aj_mask(scene, J)
    png = scene.output.png
    every = scene.output.every
    name = scene.scene.name
    thickness = model.thickness

    def torque() -> np.ndarray:
        if c.aj != "touching":
            return contact.torque(J, nodes=aj)
        return _segment_torque(contact, model, k_torque, J, comm)

    hinge_motion = measured_hinge(motions, k_torque)
    # the measured joint's work against the garment, quasi-static: the trapezoid rule of
    # report.joint_work over the hinge angle, tau_seg . axis of the forces on the segment
    work = {"W": 0.0, "theta": 0.0, "tau": 0.0}

    def joint_work_at(stage: str, t: float) -> float:
        if hinge_motion is None:
            return 0.0
        seg = _segment_torque(contact, model, k_torque, hinge_motion.joint, comm)
        tau = float(seg @ hinge_axis)
        theta = hinge_motion.angle(t) if stage == "motion" else 0.0
        th, ta = np.array([work["theta"], theta]), np.array([work["tau"], tau])
        work["W"] += float(joint_work(th, ta, 1.0)[-1])
        work.update(theta=theta, tau=tau)
        return work["W"]

    pressure = fem.Function(contact.S, name="contact_pressure")  # Pa, nodal (lam / area)

    def update_pressure() -> None:
        pressure.x.array[: contact.n] = contact.state().pressure  # collective (areas)
        pressure.x.scatter_forward()

    def snapshot(tag: str) -> None:
        update_pressure()
        write_snapshot(scene, model, out, comm, tag, contact.bodies, pressure=pressure)

    increments = c.increments
    hinge_ids = [i for i, m in enumerate(motions) if isinstance(m, HingeMotion)]
    t_end = max((motions[i].t_end for i in hinge_ids), default=0.0)
    stage_wall = {"t": time.perf_counter()}

    def on_sub(rec) -> None:
        model.commit_material()  # a converged sub-step: yarn-friction history to it
        if stab is not None:  # force at the converged sub-step, then move the anchor
            stab.last = stab.force(comm)
            stab.commit()
        check_stop(f"a sub-step at load factor {rec.load_factor:g}")

    progress = Progress(label=scene.scene.name, comm=comm)
    with ResultWriter(out, model) as writer:

        def write_row(stage: str, inc: int, t: float, recs) -> None:
            tau = torque()
            res = contact.resultant()
            angle = math.degrees(motions[k_torque].angle(t)) if k_torque is not None else 0.0
            now = time.perf_counter()
            last = recs[-1]
            row = {
                "stage": stage,
                "increment": inc,
                "time": t,
                "load_factor": float(model.lam.value),
                "angle_deg": angle,
                **torque_columns(tau, res, float(tau @ hinge_axis)),
                "n_active": last.n_active,
                "max_penetration": max(r.max_penetration for r in recs),
                **(
                    {"tissue_indentation": max(r.max_indentation for r in recs)}
                    if c.tissue_stiffness is not None
                    else {}
                ),
                "min_multiplier": min(r.min_multiplier for r in recs),
                "complementarity": max(r.complementarity for r in recs),
                "sum_lam": last.total_normal_force,
                "n_stick": last.n_stick,
                "n_slip": last.n_slip,
                "substeps": len(recs),
                "active_set_iterations": sum(r.active_set_iterations for r in recs),
                "newton_iterations": sum(r.newton_iterations for r in recs),
                **yarn_strain_columns(model),
                "joint_work": joint_work_at(stage, t),
                "dissipation_total": contact.dissipation_total,
                "dissipation_material": model.dissipated_material(),
                "stabilization_force": stab.last if stab is not None else 0.0,
                "wall_time": now - stage_wall["t"],
                "elapsed": now - t0,
            }
            stage_wall["t"] = now
            summary.update(
                final_angle_deg=angle,
                steps=summary.get("steps", 0) + len(recs),
                cutbacks=0,
                max_penetration=max(summary.get("max_penetration", 0.0), row["max_penetration"]),
            )
            settled = stage == "settle" and row["load_factor"] == 1.0
            if settled or (stage == "motion" and (inc % every == 0 or inc == increments)):
                # fields of the settled state (t = 0) and the motion (t > 0); the partial-load
                # states of the settling share t = 0 and are not written
                update_pressure()
                writer.write(t, row, (pressure,))
            else:
                writer.append_row(row)
            n_settle = scene.solver.steps if c.settle else 1
            done = inc / n_settle if stage == "settle" else 1.0 + inc / max(increments, 1)
            progress.update(
                done / (2.0 if hinge_ids else 1.0),
                f"{stage} {inc}  angle {angle:6.2f} deg  |tau| {row['torque_mag']:.5g} N m"
                f"  active {last.n_active}  pen {row['max_penetration']:.1e} m  sub {len(recs)}"
                f"  newton {row['newton_iterations']}",
            )
            if row["max_penetration"] > 1e-3 * thickness:
                rank0_print(f"  warning: max penetration {row['max_penetration']:.2e} m > 1e-3 t")
            check_stop(f"{stage} increment {inc}")

        try:
            if c.settle:
                steps = scene.solver.steps
                for s in range(1, steps + 1):
                    try:
                        recs = contact.advance(s / steps, on_step=on_sub)
                    except ContactDivergence as exc:
                        snapshot(f"stopped_settle_{s - 1}")
                        raise SolverDivergence(
                            f"contact failed while settling (load step {s} of {steps}): {exc}"
                        ) from None
                    write_row("settle", s, 0.0, recs)
            else:
                rec = contact.solve_step(1.0)
                model.commit_material()
                write_row("settle", 0, 0.0, [rec])
            snapshot("settled")
            quarter = max(1, increments // 4)
            for inc in range(1, (increments if hinge_ids else 0) + 1):  # no hinge: settle only
                t = t_end * inc / increments
                try:
                    recs = _drive(
                        contact,
                        motions,
                        hinge_ids,
                        t_end * (inc - 1) / increments,
                        t,
                        on_sub=on_sub,
                    )
                except ContactDivergence as exc:
                    snapshot(f"stopped_{inc - 1:03d}")  # the last converged state
                    raise SolverDivergence(
                        f"contact failed in motion increment {inc} "
                        f"(towards {math.degrees(motions[k_torque].angle(t)):.2f} deg): {exc}"
                    ) from None
                write_row("motion", inc, t, recs)
                if inc % quarter == 0 and inc != increments:
                    snapshot(f"{inc:03d}")
            snapshot("final")
        finally:
            progress.close()
            end_together(comm)
            if png and comm.rank == 0 and writer.csv_path.exists():
                plot_torque_angle(
                    writer.csv_path, out / "torque_angle.png", name, summary_events(summary)
                )

                def posed(t: float) -> list:
                    poses = [m.pose(t) for m in motions]
                    return [
                        (p.centre, p.rotation, r)
                        for p, (_, _, r) in zip(poses, bodies, strict=True)
                    ]

                write_animation(scene, out, posed)
    return out
