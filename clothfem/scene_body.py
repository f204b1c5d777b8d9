"""What the runners derive from a scene's body: the segment motions (fixed, hinge,
keyframes, motion capture), the body's poses at time t, the Eq. 28 plan (torque segment,
joint, node set, flexion axis, the run's clock), the recorded gait events and the build log's
body and contact lines. Used by the dynamic runner (:mod:`clothfem.simulation`), the
quasi-static one (:mod:`clothfem.runners`) and the particle scenes."""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from .body import FixedMotion, HingeMotion, MarkerSet, Pose, segment_frames
from .body.motion import InterpolatedMotion
from .spec import Scene, SegmentSpec
from .torque_measure import TorqueMeasure, torque_measure, torque_segment_index

__all__ = [
    "PlayedMotion",
    "RunPlan",
    "aj_mask",
    "body_motions",
    "body_poses",
    "contact_log",
    "keyframe_motion",
    "measured_hinge",
    "recorded_events",
    "run_plan",
    "summary_events",
    "torque_centre",
    "write_events",
]


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


def _window(markers: MarkerSet, window: tuple[float, ...]) -> MarkerSet:
    """The rows of ``markers`` within ``window`` [s] (validated by the scene)."""
    t = markers.times
    tol = 1e-9 * max(1.0, abs(float(t[-1])))
    first = int(np.searchsorted(t, window[0] - tol))
    last = int(np.searchsorted(t, window[1] + tol, side="right")) - 1
    return markers.window(first=first, last=last)


def _mocap_motions(scene: Scene) -> dict[int, PlayedMotion]:
    """The motions of the ``type = "mocap"`` segments: each recording's window, moved by the
    rigid transform that puts the placing segment's Eq. 27 pose at the window start at its
    ``centre`` with axes (``axis``, ``up``) (none with ``placement = 'recording'``), played
    from t = 0; the ellipsoid centres moved by ``offset`` in the segment frame."""
    from .scene import _read_motion, repeated_markers

    segs = scene.body
    by_name = {seg.name: seg for seg in segs}
    files: dict[str, MarkerSet] = {}

    def part(seg: SegmentSpec) -> MarkerSet:
        if seg.file not in files:
            files[seg.file] = _read_motion(Path(seg.file))
        if seg.repeat > 1:  # the window as a gait cycle, repeated (times from 0)
            return repeated_markers(seg, files[seg.file]).markers
        return _window(files[seg.file], seg.window)

    def refs(seg: SegmentSpec) -> dict[str, Any]:
        return {"j1": seg.j1, "j2": seg.j2, "m": seg.m}

    out: dict[int, PlayedMotion] = {}
    for i, seg in enumerate(segs):
        if seg.type != "mocap":
            continue
        placing = by_name[seg.placed_by]
        ref = segment_frames(
            part(placing), marker_map={placing.name: refs(placing)}, max_gap=placing.max_gap
        )[placing.name]
        c0, q0 = ref.centres[0], ref.rotations[0]
        rot, shift = np.eye(3), np.zeros(3)  # placement = 'recording'
        if placing.placement == "centre":
            rot = _frame(placing.axis, placing.up) @ q0.T
            shift = np.asarray(placing.centre) - rot @ c0
        own = part(seg)
        moved = MarkerSet(
            times=own.times - own.times[0],
            names=own.names,
            positions=own.positions @ rot.T + shift,
            source=own.source,
            first_frame=own.first_frame,
        )
        fr = segment_frames(moved, marker_map={seg.name: refs(seg)}, max_gap=seg.max_gap)
        fr = fr[seg.name]
        offset = np.asarray(seg.offset or (0.0, 0.0, 0.0), dtype=float)
        motion = InterpolatedMotion(  # Eq. 27 centroids moved by the offset in the frame
            times=fr.times,
            centres=fr.centres + fr.rotations @ offset,
            rotations=fr.rotations,
            name=seg.name,
        )
        joint = -offset - [0.5 * float(np.mean(np.linalg.norm(fr.j2 - fr.j1, axis=1))), 0, 0]
        out[i] = PlayedMotion(motion=motion, t_end=float(motion.times[-1]), joint_local=joint)
    return out


def keyframe_motion(seg: SegmentSpec) -> PlayedMotion:
    """The motion of a ``type = "keyframes"`` segment: its centres and turned axes at the key
    times, interpolated (:class:`InterpolatedMotion`), played from t = 0 and resting at the
    last key (ValueError if two keys turn more than 90 deg apart)."""
    from scipy.spatial.transform import Rotation

    times = np.asarray(seg.times, dtype=float)
    turns = seg.turns if seg.turns is not None else np.zeros((times.size, 3))
    motion = InterpolatedMotion(
        times=times,
        centres=np.asarray(seg.centres, dtype=float),
        rotations=Rotation.from_rotvec(np.asarray(turns)).as_matrix() @ _frame(seg.axis, seg.up),
        name=seg.name,
    )
    return PlayedMotion(motion=motion, t_end=float(times[-1]), joint_local=np.zeros(3))


def body_motions(scene: Scene) -> list[FixedMotion | HingeMotion | PlayedMotion]:
    """One motion per ``[[body]]`` segment (order kept), time in s."""
    out: list[FixedMotion | HingeMotion | PlayedMotion] = []
    mocap = _mocap_motions(scene)
    for i, seg in enumerate(scene.body):
        if seg.type == "mocap":
            out.append(mocap[i])
            continue
        if seg.type == "keyframes":
            out.append(keyframe_motion(seg))
            continue
        q0 = _frame(seg.axis, seg.up)
        if seg.type == "fixed":
            out.append(FixedMotion(centre=seg.centre, rotation=q0))
        else:
            out.append(
                HingeMotion(
                    joint=seg.joint,
                    axis=seg.hinge_axis,
                    omega=math.radians(seg.omega),
                    angle_max=math.radians(seg.angle_max),
                    centre0=seg.centre,
                    rotation0=q0,
                    t_ramp=seg.omega_ramp,
                )
            )
    return out


def recorded_events(scene: Scene) -> list[tuple[float, str, str]]:
    """The gait events (C3D ``EVENT`` group: foot strikes, foot offs) of the recordings the
    mocap segments play, on the run's clock: ``(solver.settle_time + event time - first
    played frame time + k T, context, label)`` [s], T the cycle of a repeated window (copy k),
    sorted; events within half a frame of the window count (an event just before the first
    played frame comes out just before it); an event on a seam is listed once. TRC files
    carry no events."""
    from .body.lower_body import read_gait_events
    from .scene import _read_motion, repeated_markers

    t_settle, seen, out, half = scene.solver.settle_time, set(), set(), 0.0
    for seg in scene.body:
        key = (seg.file, seg.window or ())
        if seg.type != "mocap" or key in seen or Path(seg.file).suffix.lower() != ".c3d":
            continue
        seen.add(key)
        markers = _read_motion(Path(seg.file))
        first = _window(markers, seg.window).times
        T = repeated_markers(seg, markers).cycle_time if seg.repeat > 1 else 0.0
        half = 0.5 * float(np.median(np.diff(first)))  # events lie between frames
        for e in read_gait_events(seg.file):
            if not seg.window[0] - half <= e.time <= seg.window[1] + half:
                continue
            for k in range(seg.repeat):
                t = round(t_settle + e.time - first[0] + k * T, 9)
                out.add((t, e.context, e.label))
    kept: list[tuple[float, str, str]] = []
    for ev in sorted(out):  # a seam's event from both copies (within a frame): once
        if not any(ev[1:] == k[1:] and ev[0] - k[0] < 2 * half for k in kept[-4:]):
            kept.append(ev)
    return kept


def write_events(scene: Scene, out: Path, comm: MPI.Comm, summary: dict) -> list:
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


def summary_events(summary: dict[str, Any]) -> list[tuple[float, str, str]]:
    """The gait events of ``summary`` (:func:`write_events`) as (time, context, label)."""
    return [(e["time"], e["context"], e["label"]) for e in summary.get("gait_events", ())]


def torque_centre(scene: Scene) -> np.ndarray | None:
    """Eq. 28 centre J in m: ``contact.torque_point`` or the hinge torque segment's joint;
    None for a recorded torque segment (J moves: :mod:`clothfem.torque_measure`)."""
    c = scene.contact
    if c.torque_point is not None:
        return np.asarray(c.torque_point, dtype=float)
    seg = scene.body[torque_segment_index(scene)]
    return np.asarray(seg.joint, dtype=float) if seg.type == "hinge" else None


def _torque_where(scene: Scene) -> str:
    """The log's words for J, AJ and the flexion axis of the Eq. 28 measure."""
    c, body = scene.contact, scene.body
    k = torque_segment_index(scene)
    J = torque_centre(scene)
    where = (
        f"J = {J.tolist()} m"
        if J is not None
        else f"the moving joint J1 of {body[k].name} (Eq. 27 frame), torque_flex about "
        f"+-{c.flexion_axis} of {c.flexion_frame or body[k].name} (flexion positive)"
    )
    if c.aj == "all":
        return f"{where} over AJ = all"
    also = "" if not c.torque_with else f" and {', '.join(c.torque_with)}"
    return f"{where} over AJ = {c.aj} of {body[k].name}{also}"


def contact_log(scene: Scene) -> list[str]:
    """Log lines describing the body, contact and friction a scene builds."""
    segs = []
    for seg in scene.body:
        r = ", ".join(f"{v:g}" for v in seg.radii)
        if seg.type == "fixed":
            segs.append(f"{seg.name} fixed (radii {r} m)")
        elif seg.type == "keyframes":
            n, t = len(seg.times), seg.times[-1]
            segs.append(f"{seg.name} keyframes, {n} poses over {t:g} s (radii {r} m)")
        elif seg.type == "mocap":
            w = seg.window
            rep = (
                f", a repeated cycle: {seg.repeat} copies shifted by the stride of "
                f"{'/'.join(seg.stride_markers)}, blended over {seg.repeat_blend:g} s"
                if seg.repeat > 1
                else ""
            )
            segs.append(
                f"{seg.name} motion capture {Path(seg.file).name} {w[0]:g}-{w[1]:g} s"
                f"{rep} (placed by {seg.placed_by}; radii {r} m)"
            )
        else:
            segs.append(
                f"{seg.name} hinge about {list(seg.hinge_axis)} through {list(seg.joint)} m to "
                f"{seg.angle_max:g} deg (radii {r} m)"
            )
    c = scene.contact
    integrator = scene.solver.integrator
    if integrator == "static":
        how = (
            f"quasi-static, settle {'on' if c.settle else 'off'}, {c.increments} motion "
            "increments, "
        )
    else:
        how = f"dynamic ({integrator}), settling {scene.solver.settle_time:g} s, "
    film = c.method == "film"
    body = (
        f"body: {len(segs)} ellipsoid(s), soft tissue k_w {c.tissue_stiffness:g} Pa/m: "
        if c.tissue_stiffness is not None
        else f"body: {len(segs)} rigid ellipsoid(s): "
    )
    return [
        body + "; ".join(segs),
        f"contact: {c.method} "
        + (
            f"(forward-increment Lagrange multipliers, non-resilient, {c.kernel} kernel), "
            if film
            else "(implicit Lagrange multipliers, active set), "
        )
        + how
        + f"torque about {_torque_where(scene)}",
        (
            f"friction: Coulomb mu {c.mu:g} "
            + ("(limits each step's tangential impulse)" if film else "(regularised return map)")
            if c.mu > 0
            else "friction: not built (mu = 0)"
        ),
        *_torques_log(scene),
    ]


def _torques_log(scene: Scene) -> list[str]:
    """The log line of the ``[[torques]]`` measures (none without)."""
    if not scene.torques:
        return []
    return ["torques: " + ", ".join(f"{t.name} about {t.segment}" for t in scene.torques)]


def aj_mask(scene: Scene, J: np.ndarray) -> Callable[[np.ndarray], np.ndarray] | None:
    """Reference-coordinate node selector of a hinge's ``beyond_joint`` (None otherwise)."""
    c = scene.contact
    seg = scene.body[torque_segment_index(scene)] if c.aj == "beyond_joint" else None
    if seg is None or seg.type != "hinge":
        return None
    e1 = np.asarray(seg.axis, dtype=float)
    e1 = e1 / np.linalg.norm(e1)
    return lambda X: (X.T - J) @ e1 > 0.0


def measured_hinge(motions, k_torque: int | None) -> HingeMotion | None:
    """The hinge motion of the measured joint (the torque segment), if it is a hinge."""
    if k_torque is None or not isinstance(motions[k_torque], HingeMotion):
        return None
    return motions[k_torque]


def body_poses(scene: Scene, motions: list) -> Callable[[float], tuple[list, list]]:
    """``t -> (ellipsoids, velocities)`` of the dynamic runs: at rest until
    ``solver.settle_time``, then each segment follows its motion."""
    radii = [np.asarray(seg.radii, dtype=float) for seg in scene.body]
    t_settle = scene.solver.settle_time
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
class RunPlan:
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


def run_plan(scene: Scene, motions: list) -> RunPlan:
    k = torque_segment_index(scene)
    hinged = k is not None and isinstance(motions[k], HingeMotion)
    J = torque_centre(scene) if scene.body else np.zeros(3)
    aj = aj_mask(scene, J) if scene.body and J is not None else None
    t_settle = scene.solver.settle_time
    moving = [m for m in motions if not isinstance(m, FixedMotion)]
    t_end = scene.solver.duration
    if t_end is None:
        t_end = t_settle + max((m.t_end for m in moving), default=0.0)
    return RunPlan(
        motions=motions,
        k_torque=k,
        J=J,
        aj=aj,
        hinge_axis=np.asarray(motions[k].axis) if hinged else np.zeros(3),
        hinged=hinged,
        measure=torque_measure(scene, motions, reference_mask=aj) if scene.body else None,
        t_settle=t_settle,
        t_end=t_end,
    )
