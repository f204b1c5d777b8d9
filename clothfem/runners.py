"""The quasi-static runner with a body, and what every runner derives from a scene's body.

:func:`run_contact_scene` runs ``solver.integrator = "static"`` with ``[[body]]`` segments;
the dynamic integrators run through :func:`clothfem.simulation.run_dynamic`, which uses the
helpers here (segment motions, the Eq. 28 plan, body poses at t, snapshots, checkpoints).

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

import csv
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from .body import FixedMotion, HingeMotion, MarkerSet, Pose, segment_frames
from .body.motion import InterpolatedMotion
from .contact.forces import joint_torque
from .contact.lagrange import ContactDivergence, LagrangeContact, LagrangeContactParameters
from .history import yarn_strain_columns
from .io import Progress, ResultWriter, animate_series, rank0_print, snapshot_png
from .report import joint_work, mark_events
from .scene import SceneError
from .shell import ShellModel
from .static import SolverDivergence
from .torque_measure import TorqueMeasure, torque_measure, torque_segment_index

__all__ = ["body_motions", "contact_log", "run_contact_scene", "torque_centre"]


def _frame(axis, up) -> np.ndarray:
    """Rotation with columns e1 = axis, e2 = up made orthogonal, e3 = e1 x e2."""
    e1 = np.asarray(axis, dtype=float)
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.asarray(up, dtype=float)
    e2 = e2 - (e2 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


@dataclass(frozen=True)
class PlayedMotion:
    """A recorded segment motion (``motion``, an :class:`InterpolatedMotion` whose times start
    at 0 at the window start) played until ``t_end`` [s], then at rest in its last pose;
    ``joint_local`` [m] is the proximal joint J1 in the segment frame about the ellipsoid
    centre: ``-offset - (L/2, 0, 0)``, L the mean J1-J2 distance of the recording."""

    motion: Any
    t_end: float
    joint_local: np.ndarray
    # the last pose asked for: a step asks for the same time once per measure and body use
    _last: dict = field(default_factory=dict, compare=False, repr=False)

    def joint(self, t: float) -> np.ndarray:
        """The proximal joint J1 [m] at t [s], carried with the segment's frame."""
        p = self.pose(t)
        return p.centre + p.rotation @ self.joint_local

    def pose(self, t: float) -> Pose:
        """The pose at t [s] (read-only arrays; the last one is kept for the next call)."""
        if self._last.get("t") == t:
            return self._last["pose"]
        p = self._pose(t)
        for a in (p.centre, p.rotation, p.velocity, p.angular_velocity):
            a.setflags(write=False)
        self._last.update(t=t, pose=p)
        return p

    def _pose(self, t: float) -> Pose:
        if t >= self.t_end:
            p = self.motion.pose(self.t_end)
            zero = np.zeros(3)
            return Pose(
                time=t, centre=p.centre, rotation=p.rotation, velocity=zero, angular_velocity=zero
            )
        return self.motion.pose(max(t, 0.0))


def _window(markers: MarkerSet, window: list[float]) -> MarkerSet:
    """The rows of ``markers`` within ``window`` [s] (validated by the scene)."""
    t = markers.times
    tol = 1e-9 * max(1.0, abs(float(t[-1])))
    first = int(np.searchsorted(t, window[0] - tol))
    last = int(np.searchsorted(t, window[1] + tol, side="right")) - 1
    return markers.window(first=first, last=last)


def _mocap_motions(scene: dict[str, Any]) -> dict[int, PlayedMotion]:
    """The motions of the ``type = "mocap"`` segments: each recording's window, moved by the
    rigid transform that puts the placing segment's Eq. 27 pose at the window start at its
    ``centre`` with axes (``axis``, ``up``) (none with ``placement = 'recording'``), played
    from t = 0; the ellipsoid centres moved by ``offset`` in the segment frame."""
    from .scene import _read_motion, repeated_markers

    segs = scene["body"]
    by_name = {seg["name"]: seg for seg in segs}
    files: dict[str, MarkerSet] = {}

    def part(seg) -> MarkerSet:
        if seg["file"] not in files:
            files[seg["file"]] = _read_motion(Path(seg["file"]))
        if seg["repeat"] > 1:  # the window as a gait cycle, repeated (times from 0)
            return repeated_markers(seg, files[seg["file"]]).markers
        return _window(files[seg["file"]], seg["window"])

    def refs(seg) -> dict[str, Any]:
        return {k: seg[k] for k in ("j1", "j2", "m")}

    out: dict[int, PlayedMotion] = {}
    for i, seg in enumerate(segs):
        if seg["type"] != "mocap":
            continue
        placing = by_name[seg["placed_by"]]
        ref = segment_frames(
            part(placing), marker_map={placing["name"]: refs(placing)}, max_gap=placing["max_gap"]
        )[placing["name"]]
        c0, q0 = ref.centres[0], ref.rotations[0]
        rot, shift = np.eye(3), np.zeros(3)  # placement = 'recording'
        if placing["placement"] == "centre":
            rot = _frame(placing["axis"], placing["up"]) @ q0.T
            shift = np.asarray(placing["centre"]) - rot @ c0
        own = part(seg)
        moved = MarkerSet(
            times=own.times - own.times[0],
            names=own.names,
            positions=own.positions @ rot.T + shift,
            source=own.source,
            first_frame=own.first_frame,
        )
        fr = segment_frames(moved, marker_map={seg["name"]: refs(seg)}, max_gap=seg["max_gap"])
        fr = fr[seg["name"]]
        offset = np.asarray(seg["offset"] or (0.0, 0.0, 0.0), dtype=float)
        motion = InterpolatedMotion(  # Eq. 27 centroids moved by the offset in the frame
            times=fr.times,
            centres=fr.centres + fr.rotations @ offset,
            rotations=fr.rotations,
            name=seg["name"],
        )
        joint = -offset - [0.5 * float(np.mean(np.linalg.norm(fr.j2 - fr.j1, axis=1))), 0, 0]
        out[i] = PlayedMotion(motion=motion, t_end=float(motion.times[-1]), joint_local=joint)
    return out


def keyframe_motion(seg: dict[str, Any]) -> PlayedMotion:
    """The motion of a ``type = "keyframes"`` segment: its centres and turned axes at the key
    times, interpolated (:class:`InterpolatedMotion`), played from t = 0 and resting at the
    last key (ValueError if two keys turn more than 90 deg apart)."""
    from scipy.spatial.transform import Rotation

    times = np.asarray(seg["times"], dtype=float)
    turns = seg["turns"] if seg["turns"] is not None else np.zeros((times.size, 3))
    motion = InterpolatedMotion(
        times=times,
        centres=np.asarray(seg["centres"], dtype=float),
        rotations=Rotation.from_rotvec(np.asarray(turns)).as_matrix()
        @ _frame(seg["axis"], seg["up"]),
        name=seg["name"],
    )
    return PlayedMotion(motion=motion, t_end=float(times[-1]), joint_local=np.zeros(3))


def body_motions(scene: dict[str, Any]) -> list[FixedMotion | HingeMotion | PlayedMotion]:
    """One motion per ``[[body]]`` segment (order kept), time in s."""
    out: list[FixedMotion | HingeMotion | PlayedMotion] = []
    mocap = _mocap_motions(scene)
    for i, seg in enumerate(scene["body"]):
        if seg["type"] == "mocap":
            out.append(mocap[i])
            continue
        if seg["type"] == "keyframes":
            out.append(keyframe_motion(seg))
            continue
        q0 = _frame(seg["axis"], seg["up"])
        if seg["type"] == "fixed":
            out.append(FixedMotion(centre=seg["centre"], rotation=q0))
        else:
            out.append(
                HingeMotion(
                    joint=seg["joint"],
                    axis=seg["hinge_axis"],
                    omega=math.radians(seg["omega"]),
                    angle_max=math.radians(seg["angle_max"]),
                    centre0=seg["centre"],
                    rotation0=q0,
                    t_ramp=seg["omega_ramp"],
                )
            )
    return out


def recorded_events(scene: dict[str, Any]) -> list[tuple[float, str, str]]:
    """The gait events (C3D ``EVENT`` group: foot strikes, foot offs) of the recordings the
    mocap segments play, on the run's clock: ``(solver.settle_time + event time - first
    played frame time + k T, context, label)`` [s], T the cycle of a repeated window (copy k),
    sorted; events within half a frame of the window count (an event just before the first
    played frame comes out just before it); an event on a seam is listed once. TRC files
    carry no events."""
    from .body.lower_body import read_gait_events
    from .scene import _read_motion, repeated_markers

    t_settle, seen, out, half = scene["solver"]["settle_time"], set(), set(), 0.0
    for seg in scene["body"]:
        key = (seg.get("file"), tuple(seg.get("window") or ()))
        if seg["type"] != "mocap" or key in seen or Path(seg["file"]).suffix.lower() != ".c3d":
            continue
        seen.add(key)
        markers = _read_motion(Path(seg["file"]))
        first = _window(markers, seg["window"]).times
        T = repeated_markers(seg, markers).cycle_time if seg["repeat"] > 1 else 0.0
        half = 0.5 * float(np.median(np.diff(first)))  # events lie between frames
        for e in read_gait_events(seg["file"]):
            if not seg["window"][0] - half <= e.time <= seg["window"][1] + half:
                continue
            for k in range(seg["repeat"]):
                t = round(t_settle + e.time - first[0] + k * T, 9)
                out.add((t, e.context, e.label))
    kept: list[tuple[float, str, str]] = []
    for ev in sorted(out):  # a seam's event from both copies (within a frame): once
        if not any(ev[1:] == k[1:] and ev[0] - k[0] < 2 * half for k in kept[-4:]):
            kept.append(ev)
    return kept


def _write_events(scene: dict[str, Any], out: Path, comm: MPI.Comm, summary: dict) -> list:
    """``out/events.csv`` (time_s, context, label) of :func:`recorded_events` (rank 0), also
    in ``summary["gait_events"]``; nothing without events."""
    events = recorded_events(scene) if comm.rank == 0 else None
    events = comm.bcast(events, root=0)
    if events:
        summary["gait_events"] = [{"time": t, "context": c, "label": lb} for t, c, lb in events]
        if comm.rank == 0:
            out.mkdir(parents=True, exist_ok=True)
            with (out / "events.csv").open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["time_s", "context", "label"])
                w.writerows(events)
    return events


def _events(summary: dict[str, Any]) -> list[tuple[float, str, str]]:
    """The gait events of ``summary`` (:func:`_write_events`) as (time, context, label)."""
    return [(e["time"], e["context"], e["label"]) for e in summary.get("gait_events", ())]


def torque_centre(scene: dict[str, Any]) -> np.ndarray | None:
    """Eq. 28 centre J in m: ``contact.torque_point`` or the hinge torque segment's joint;
    None for a recorded torque segment (J moves: :mod:`clothfem.torque_measure`)."""
    c = scene["contact"]
    if c["torque_point"] is not None:
        return np.asarray(c["torque_point"], dtype=float)
    seg = scene["body"][torque_segment_index(scene)]
    return np.asarray(seg["joint"], dtype=float) if seg["type"] == "hinge" else None


def _torque_where(scene: dict[str, Any]) -> str:
    """The log's words for J, AJ and the flexion axis of the Eq. 28 measure."""
    c, body = scene["contact"], scene["body"]
    k = torque_segment_index(scene)
    J = torque_centre(scene)
    where = (
        f"J = {J.tolist()} m"
        if J is not None
        else f"the moving joint J1 of {body[k]['name']} (Eq. 27 frame), torque_flex about "
        f"+-{c['flexion_axis']} of {c['flexion_frame'] or body[k]['name']} (flexion positive)"
    )
    if c["aj"] == "all":
        return f"{where} over AJ = all"
    also = "" if not c["torque_with"] else f" and {', '.join(c['torque_with'])}"
    return f"{where} over AJ = {c['aj']} of {body[k]['name']}{also}"


def contact_log(scene: dict[str, Any]) -> list[str]:
    """Log lines describing the body, contact and friction a scene builds."""
    segs = []
    for seg in scene["body"]:
        r = ", ".join(f"{v:g}" for v in seg["radii"])
        if seg["type"] == "fixed":
            segs.append(f"{seg['name']} fixed (radii {r} m)")
        elif seg["type"] == "keyframes":
            n, t = len(seg["times"]), seg["times"][-1]
            segs.append(f"{seg['name']} keyframes, {n} poses over {t:g} s (radii {r} m)")
        elif seg["type"] == "mocap":
            w = seg["window"]
            rep = (
                f", a repeated cycle: {seg['repeat']} copies shifted by the stride of "
                f"{'/'.join(seg['stride_markers'])}, blended over {seg['repeat_blend']:g} s"
                if seg["repeat"] > 1
                else ""
            )
            segs.append(
                f"{seg['name']} motion capture {Path(seg['file']).name} {w[0]:g}-{w[1]:g} s"
                f"{rep} (placed by {seg['placed_by']}; radii {r} m)"
            )
        else:
            segs.append(
                f"{seg['name']} hinge about {seg['hinge_axis']} through {seg['joint']} m to "
                f"{seg['angle_max']:g} deg (radii {r} m)"
            )
    c = scene["contact"]
    integrator = scene["solver"]["integrator"]
    if integrator == "static":
        how = (
            f"quasi-static, settle {'on' if c['settle'] else 'off'}, {c['increments']} motion "
            "increments, "
        )
    else:
        how = f"dynamic ({integrator}), settling {scene['solver']['settle_time']:g} s, "
    film = c["method"] == "film"
    return [
        f"body: {len(segs)} rigid ellipsoid(s): " + "; ".join(segs),
        f"contact: {c['method']} "
        + (
            f"(forward-increment Lagrange multipliers, non-resilient, {c['kernel']} kernel), "
            if film
            else "(implicit Lagrange multipliers, active set), "
        )
        + how
        + f"torque about {_torque_where(scene)}",
        (
            f"friction: Coulomb mu {c['mu']:g} "
            + ("(limits each step's tangential impulse)" if film else "(regularised return map)")
            if c["mu"] > 0
            else "friction: not built (mu = 0)"
        ),
        *_torques_log(scene),
    ]


def _torques_log(scene: dict[str, Any]) -> list[str]:
    """The log line of the ``[[torques]]`` measures (none without)."""
    if not scene["torques"]:
        return []
    return ["torques: " + ", ".join(f"{t['name']} about {t['segment']}" for t in scene["torques"])]


def _aj_mask(scene: dict[str, Any], J: np.ndarray) -> Callable[[np.ndarray], np.ndarray] | None:
    """Reference-coordinate node selector of a hinge's ``beyond_joint`` (None otherwise)."""
    c = scene["contact"]
    seg = scene["body"][torque_segment_index(scene)] if c["aj"] == "beyond_joint" else None
    if seg is None or seg["type"] != "hinge":
        return None
    e1 = np.asarray(seg["axis"], dtype=float)
    e1 = e1 / np.linalg.norm(e1)
    return lambda X: (X.T - J) @ e1 > 0.0


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


def _measured_hinge(motions, k_torque: int | None) -> HingeMotion | None:
    """The hinge motion of the measured joint (the torque segment), if it is a hinge."""
    if k_torque is None or not isinstance(motions[k_torque], HingeMotion):
        return None
    return motions[k_torque]


def _segment_torque(contact, model: ShellModel, k: int, joint: np.ndarray, comm) -> np.ndarray:
    """Torque [N m] about ``joint`` of the contact forces on ellipsoid ``k`` at the last
    converged state of a :class:`LagrangeContact` (reduced over ranks)."""
    nodes, body, f_pairs, _ = contact.pair_forces()
    on = body == k
    x = contact.X + model.u.x.array[: 3 * contact.n].reshape(-1, 3)
    tau = joint_torque(x[nodes[on]], -f_pairs[on], joint) if on.any() else np.zeros(3)
    return comm.allreduce(np.asarray(tau, dtype=float), op=MPI.SUM)


def _torque_columns(tau: np.ndarray, res: np.ndarray, flex: float) -> dict:
    """CSV columns of the Eq. 28 torque [N m], its component ``flex`` about the flexion axis
    [N m] and the resultant on the body [N]."""
    return {
        "torque_x": tau[0],
        "torque_y": tau[1],
        "torque_z": tau[2],
        "torque_mag": float(np.linalg.norm(tau)),
        "torque_flex": flex,
        "resultant_x": res[0],
        "resultant_y": res[1],
        "resultant_z": res[2],
    }


def _ellipsoid_meshes(bodies, *, scale: float = 0.985) -> list:
    """pyvista surfaces of ellipsoids given as (centre, axes as columns, radii), drawn with
    the radii x ``scale``: contact holds the fabric's nodes on the surface and the flat facets
    of the drawn fabric between them would otherwise cut into the body."""
    import pyvista as pv

    meshes = []
    for c, Q, r in bodies:
        e = pv.ParametricEllipsoid(*(scale * np.asarray(r)), u_res=60, v_res=30, w_res=10)
        e.points = np.asarray(e.points) @ Q.T + c
        meshes.append(e)
    return meshes


def _torque_plot(
    csv_path: Path, png: Path, title: str, events: Sequence[tuple[float, str, str]] = ()
) -> None:
    """|tau| and the flexion component against the hinge angle, or against time (a recorded
    motion) with the gait ``events`` (time [s], context, label) marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [  # the settled state (full load) and the motion; not the partial-load rows
        r
        for r in csv.DictReader(csv_path.open())
        if r["stage"] == "motion" or float(r["load_factor"]) == 1.0
    ]
    if not rows:
        return
    a = [float(r["angle_deg"]) for r in rows]
    hinged = max(a) > min(a)  # else (no hinge: a recorded motion) against time
    x = a if hinged else [float(r["time"]) for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(
        x, [float(r["torque_mag"]) for r in rows], "o-", color="C0", ms=4, label="|tau| (Eq. 28)"
    )
    tf = [-float(r["torque_flex"]) for r in rows]
    if any(tf):
        label = "-tau . hinge axis" if hinged else "-tau . flexion axis"
        ax.plot(x, tf, "s--", color="C1", ms=4, mfc="none", label=label)
    if not hinged:
        mark_events(ax, events)
    ax.set_xlabel("flexion angle [deg]" if hinged else "time [s]")
    ax.set_ylabel("torque about the joint [N m]")
    ax.set_title(title)
    ax.grid(True)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def run_contact_scene(
    scene: dict[str, Any],
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
    _write_events(scene, out, comm, summary)
    c = scene["contact"]
    motions = body_motions(scene)
    bodies = []
    for seg, mo in zip(scene["body"], motions, strict=True):
        pose = mo.pose(0.0)
        bodies.append((pose.centre, pose.rotation, np.asarray(seg["radii"], dtype=float)))
    # quasi-static wrinkling paths have several equilibria: the paper's fixed-set passes
    # (no semismooth set changes inside Newton) keep the branch independent of round-off
    params = LagrangeContactParameters(mu=c["mu"], semismooth_passes=0)
    contact = LagrangeContact(model, bodies, params=params)
    stab = None
    if c["stabilization"] > 0:
        stab = _ViscousStabilization(model, contact.lumped_area(), c["stabilization"])
    J = torque_centre(scene)
    k_torque = torque_segment_index(scene)
    hinge_axis = (
        np.asarray(motions[k_torque].axis) if k_torque is not None else np.array([0.0, 0.0, 0.0])
    )
    aj = _aj_mask(scene, J)
    png = scene["output"]["png"]
    every = scene["output"]["every"]
    name = scene["scene"]["name"]
    thickness = model.thickness

    def torque() -> np.ndarray:
        if c["aj"] != "touching":
            return contact.torque(J, nodes=aj)
        return _segment_torque(contact, model, k_torque, J, comm)

    hinge_motion = _measured_hinge(motions, k_torque)
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
        _snapshot(scene, model, out, comm, tag, contact.bodies, pressure=pressure)

    increments = c["increments"]
    hinge_ids = [i for i, m in enumerate(motions) if isinstance(m, HingeMotion)]
    t_end = max((motions[i].t_end for i in hinge_ids), default=0.0)
    stage_wall = {"t": time.perf_counter()}

    def on_sub(rec) -> None:
        model.commit_material()  # a converged sub-step: yarn-friction history to it
        if stab is not None:  # force at the converged sub-step, then move the anchor
            stab.last = stab.force(comm)
            stab.commit()
        check_stop(f"a sub-step at load factor {rec.load_factor:g}")

    progress = Progress(label=scene["scene"]["name"], comm=comm)
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
                **_torque_columns(tau, res, float(tau @ hinge_axis)),
                "n_active": last.n_active,
                "max_penetration": max(r.max_penetration for r in recs),
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
            n_settle = scene["solver"]["steps"] if c["settle"] else 1
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
            if c["settle"]:
                steps = scene["solver"]["steps"]
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
            _end_together(comm)
            if png and comm.rank == 0 and writer.csv_path.exists():
                _torque_plot(writer.csv_path, out / "torque_angle.png", name, _events(summary))

                def posed(t: float) -> list:
                    poses = [m.pose(t) for m in motions]
                    return [
                        (p.centre, p.rotation, r)
                        for p, (_, _, r) in zip(poses, bodies, strict=True)
                    ]

                _animation(scene, out, posed)
    return out


def _animation(scene: dict[str, Any], out: Path, bodies_at: Callable[[float], list]) -> None:
    """``out/animation.gif`` from the field series (rank 0; scenes with PNG output)."""
    if not scene["output"]["png"] or not (out / "fabric.h5").exists():
        return
    animate_series(
        out / "fabric.h5",
        out / "animation.gif",
        bodies_at=lambda t: _ellipsoid_meshes(bodies_at(t)),
        title=scene["scene"]["name"],
        view="xz",
        max_frames=scene["output"]["frames"],
    )


def _stop_with_fields(
    check_stop: Callable[[str], None], where: str, writer: ResultWriter, t: float, fields
) -> None:
    """``check_stop(where)``; when it stops the run, the fields at ``t`` (``fields()``: the
    functions to write besides the displacement) are written first unless they were."""
    from .errors import RunStopped

    try:
        check_stop(where)
    except RunStopped:
        if writer.last_time < t:  # the same on every rank
            writer.write_fields(t, fields())
        raise


def _end_together(comm: MPI.Comm) -> None:
    """The runners' ``finally``: wait for every rank before the closing writes, unless this
    rank is leaving with an error the other ranks do not share. The solver stops and the
    signal stop are decided on reduced values, so every rank raises them at the same point;
    any other error (a bug, an I/O error, Ctrl-C) may be this rank's alone, and the others
    would wait in their next collective call forever: under MPI it aborts the job instead
    (the history rows already written are kept)."""
    from .dynamics import DynamicsDivergence
    from .errors import RunStopped

    exc = sys.exc_info()[1]
    shared = (SolverDivergence, ContactDivergence, DynamicsDivergence, RunStopped, SceneError)
    if comm.size > 1 and exc is not None and not isinstance(exc, shared):
        sys.stderr.write(
            f"clothfem: rank {comm.rank} stopped alone ({type(exc).__name__}: {exc}); "
            "aborting the MPI job (rows written so far are kept)\n"
        )
        sys.stderr.flush()
        comm.Abort(1)
    comm.barrier()


def save_checkpoint(out: Path, comm: MPI.Comm, data: dict[str, Any]) -> None:
    """Write this rank's restart file atomically (``out/checkpoint/rank<r>-of-<n>.npz``)."""
    folder = out / "checkpoint"
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    path = folder / f"rank{comm.rank}-of-{comm.size}.npz"
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as fh:
        np.savez(fh, **data)
    os.replace(tmp, path)  # a run killed while writing keeps the previous checkpoint
    comm.barrier()


def load_checkpoint(out: Path, comm: MPI.Comm) -> dict[str, np.ndarray]:
    path = out / "checkpoint" / f"rank{comm.rank}-of-{comm.size}.npz"
    ok = comm.allreduce(path.exists(), op=MPI.LAND)
    if not ok:
        raise SceneError(
            f"--resume: no checkpoint for {comm.size} rank(s) in {out / 'checkpoint'} "
            "(resume with the same number of ranks as the interrupted run)"
        )
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def _bodies_at(scene: dict[str, Any], motions: list) -> Callable[[float], tuple[list, list]]:
    """``t -> (ellipsoids, velocities)`` of the dynamic runs: at rest until
    ``solver.settle_time``, then each segment follows its motion."""
    radii = [np.asarray(seg["radii"], dtype=float) for seg in scene["body"]]
    t_settle = scene["solver"]["settle_time"]
    zero = np.zeros(3)
    # poses evaluated once: every segment's until t_settle, a fixed segment's for good
    rest = [m.pose(0.0) for m in motions]
    fixed = [isinstance(m, FixedMotion) for m in motions]

    def bodies_at(t: float):
        moving = t > t_settle
        poses = [
            m.pose(t - t_settle) if moving and not f else p
            for m, f, p in zip(motions, fixed, rest, strict=True)
        ]
        vel = [(p.velocity, p.angular_velocity) if moving else (zero, zero) for p in poses]
        return [(p.centre, p.rotation, r) for p, r in zip(poses, radii, strict=True)], vel

    return bodies_at


@dataclass(frozen=True)
class _Plan:
    """What the dynamic runners derive from a scene: the Eq. 28 measure (centre J, node set AJ,
    flexion axis; J is None when it moves with a recorded segment) and the clock (at rest
    until ``t_settle``, then the motion until ``t_end``)."""

    motions: list
    k_torque: int | None
    J: np.ndarray | None
    aj: Callable[[np.ndarray], np.ndarray] | None
    hinge_axis: np.ndarray
    hinged: bool
    measure: TorqueMeasure | None
    t_settle: float
    t_end: float

    def angle_at(self, t: float) -> float:
        """Flexion angle [deg] of the hinge torque segment at time t [s] (0 without one)."""
        if not self.hinged:
            return 0.0
        return math.degrees(self.motions[self.k_torque].angle(max(t - self.t_settle, 0.0)))

    def quarters(self) -> list[float]:
        """The angles [deg] of the first three quarters of the motion (snapshots)."""
        return [self.angle_at(self.t_end) * q / 4 for q in (1, 2, 3)]


def _plan(scene: dict[str, Any], motions: list) -> _Plan:
    k = torque_segment_index(scene)
    hinged = k is not None and isinstance(motions[k], HingeMotion)
    J = torque_centre(scene) if scene["body"] else np.zeros(3)
    aj = _aj_mask(scene, J) if scene["body"] and J is not None else None
    t_settle = scene["solver"]["settle_time"]
    moving = [m for m in motions if not isinstance(m, FixedMotion)]
    t_end = scene["solver"]["duration"]
    if t_end is None:
        t_end = t_settle + max((m.t_end for m in moving), default=0.0)
    return _Plan(
        motions=motions,
        k_torque=k,
        J=J,
        aj=aj,
        hinge_axis=np.asarray(motions[k].axis) if hinged else np.zeros(3),
        hinged=hinged,
        measure=torque_measure(scene, motions, reference_mask=aj) if scene["body"] else None,
        t_settle=t_settle,
        t_end=t_end,
    )


def _snapshot(
    scene: dict[str, Any],
    model: ShellModel,
    out: Path,
    comm: MPI.Comm,
    tag: str,
    bodies,
    *,
    pressure: fem.Function | None = None,
) -> None:
    """``out/snapshot_<tag>.png`` of the fabric, coloured by the contact ``pressure`` (else
    by |u|), with the ellipsoids ``bodies`` opaque (if PNGs)."""
    if scene["output"]["png"]:
        snapshot_png(
            model,
            out / f"snapshot_{tag}.png",
            title=f"{scene['scene']['name']} {tag}",
            extra_meshes=_ellipsoid_meshes(bodies) if comm.rank == 0 and bodies else (),
            view="xz",
            pressure=pressure,
        )


def _progress_snapshots(
    plan: _Plan, taken: int, stage: str, angle: float, snap, *, t: float = 0.0
) -> int:
    """``snap("settled")`` when the motion starts, then ``snap(<angle>deg)`` at each quarter of
    the hinge motion (without a hinge: ``snap(t<time>s)`` at each quarter of the time after
    the settling); ``taken``: the snapshots taken so far (checkpointed); returns the new
    count."""
    if stage == "motion" and taken == 0:
        taken = 1
        snap("settled")
    if not plan.hinged:
        span = plan.t_end - plan.t_settle
        while 1 <= taken <= 3 and t >= plan.t_settle + span * taken / 4 - 1e-12:
            snap(f"t{plan.t_settle + span * taken / 4:.3f}s")
            taken += 1
        return taken
    quarters = plan.quarters()
    while taken <= 3 and angle >= quarters[taken - 1] - 1e-9:
        snap(f"{quarters[taken - 1]:04.1f}deg")
        taken += 1
    return taken
