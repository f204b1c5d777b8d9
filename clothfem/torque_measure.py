"""Eq. 28 of Man & Swan (2007) as a measure that may move with the body.

``tau(t) = sum_{i in AJ(t)} (x_i - J(t)) x lambda_i`` with three time-dependent parts:

* **J(t)**, the joint centre [m]: a hinge's fixed joint, ``contact.torque_point``, or the
  proximal joint J1 of a recorded (``mocap``) torque segment carried with its Eq. 27 frame
  (``J1 = c(t) - L/2 e1(t)``, L the mean J1-J2 distance of the recording), e.g. the knee for
  a shank, the elbow for a forearm;
* **a(t)**, the unit flexion axis of ``torque_flex = tau . a``: a hinge's rotation axis, or
  the ``contact.flexion_axis`` column (``e2`` towards the roll marker M, or ``e3 = e1 x e2``)
  of the ``contact.flexion_frame`` segment's Eq. 27 frame, signed so that flexion is a
  positive rotation about it as for a hinge (the sign of the median of
  ``(e1_frame x e1_segment) . e`` over the recording; for the lower body's thigh frame, M
  anterior, e3 points to the subject's right and knee flexion turns the shank about -e3, so
  a = -e3). A garment that resists flexion gives ``torque_flex < 0``, as for a hinge;
* **AJ(t)**, the node set: every node (``all``), the nodes in contact with the torque
  segment and the ``contact.torque_with`` segments (``touching``), or the nodes past the plane
  through J normal to the torque segment's axis (``beyond_joint``: in reference positions for
  a hinge, as in the paper's arm scene; in current positions, through J(t) normal to e1(t),
  for a recorded segment).

Times are scene times [s]: the body rests in its first pose until ``solver.settle_time``.
No MPI here: :meth:`TorqueMeasure.local` sums over the points it is given
(:func:`clothfem.contact.forces.joint_torque`); callers reduce.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .contact.forces import joint_torque
from .spec import Scene

__all__ = ["TorqueMeasure", "torque_measure", "torque_segment_index"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class TorqueMeasure:
    """What Eq. 28 measures at scene time t (see the module docstring).

    Attributes
    ----------
    mode : str
        ``'all'``, ``'touching'`` or ``'beyond_joint'``.
    centre_at : callable
        ``t [s] -> J (3,) [m]``.
    axis_at : callable
        ``t [s] -> a (3,)`` unit flexion axis (zeros: no axis; ``torque_flex`` is then 0).
    normal_at : callable or None
        ``t -> n (3,)``: moving ``beyond_joint`` selects ``(x - J(t)) . n(t) > 0``; None with a
        fixed (reference) selector.
    reference_mask : callable or None
        Fixed ``beyond_joint``: reference coordinates (3, N) -> mask.
    segments : tuple of int
        ``touching``: the bodies whose contact forces count.
    """

    mode: str
    centre_at: Callable[[float], FloatArray]
    axis_at: Callable[[float], FloatArray]
    normal_at: Callable[[float], FloatArray] | None = None
    reference_mask: Callable[[FloatArray], NDArray[np.bool_]] | None = None
    segments: tuple[int, ...] = ()

    @property
    def moving(self) -> bool:
        """Whether AJ depends on the current positions (moving ``beyond_joint``)."""
        return self.mode == "beyond_joint" and self.normal_at is not None

    def fixed_mask(self, X: FloatArray) -> NDArray[np.bool_] | None:
        """The fixed node set of reference positions ``X`` (N, 3), or None (all or per step)."""
        if self.mode != "beyond_joint" or self.reference_mask is None:
            return None
        return np.asarray(self.reference_mask(np.ascontiguousarray(X.T)), dtype=bool)

    def select(
        self,
        *,
        t: float,
        x: FloatArray,
        body: NDArray[np.integer],
        fixed: NDArray[np.bool_] | None = None,
    ) -> NDArray[np.bool_] | None:
        """AJ among points at positions ``x`` (N, 3) [m] touching ``body`` (N,) (-1: none),
        ``fixed`` the :meth:`fixed_mask` of their reference positions; None = all."""
        if self.mode == "touching":
            return np.isin(body, self.segments)
        if self.mode == "beyond_joint":
            if self.normal_at is None:
                return fixed
            return (x - self.centre_at(t)) @ self.normal_at(t) > 0.0
        return None

    def local(
        self,
        *,
        t: float,
        x: FloatArray,
        force_on_body: FloatArray,
        body: NDArray[np.integer],
        fixed: NDArray[np.bool_] | None = None,
    ) -> tuple[FloatArray, float]:
        """``(tau (3,) [N m], tau . a(t) [N m])`` of the given points' forces on the body
        (N, 3) [N] about J(t), summed over AJ (this rank only: the caller reduces)."""
        on = self.select(t=t, x=x, body=body, fixed=fixed)
        tau = np.asarray(joint_torque(x, force_on_body, self.centre_at(t), nodes=on), dtype=float)
        return tau, float(tau @ self.axis_at(t))


def pinched(nodes: NDArray[np.integer]) -> NDArray[np.bool_]:
    """Mask of the (node, body) pairs whose node (index array ``nodes``, one entry per pair)
    is in two or more pairs: fabric pressed by two segments at once."""
    nodes = np.asarray(nodes)
    if not len(nodes):
        return np.zeros(0, dtype=bool)
    return (np.bincount(nodes) > 1)[nodes]


def torque_segment_index(scene: Scene) -> int | None:
    """Index of the torque segment: ``contact.torque_segment`` (a hinge or a recorded
    segment), else the first hinge; None if there is none."""
    named = scene.contact.torque_segment
    for i, seg in enumerate(scene.body):
        if (named is None and seg.type == "hinge") or seg.name == named:
            return i
    return None


def _flexion_sign(frame: Any, segment: Any, column: int, samples: int = 64) -> float:
    """+1 or -1: the sign that makes flexion a positive rotation about the frame's axis, i.e.
    of the median of ``(e1_frame x e1_segment) . e_column`` over the recorded motion (the
    distal segment turns that way as the joint flexes); +1 when the frame is the segment."""
    if frame is segment:
        return 1.0
    ts = np.linspace(0.0, segment.t_end, samples)
    dots = []
    for t in ts:
        a, b = frame.pose(t).rotation, segment.pose(t).rotation
        dots.append(np.cross(a[:, 0], b[:, 0]) @ a[:, column])
    return 1.0 if np.median(dots) >= 0.0 else -1.0


def _constant(v: Any) -> Callable[[float], FloatArray]:
    a = np.asarray(v, dtype=float).copy()
    a.setflags(write=False)
    return lambda _t: a


def torque_measure(
    scene: Scene,
    motions: list,
    *,
    reference_mask: Callable[[FloatArray], NDArray[np.bool_]] | None,
) -> TorqueMeasure:
    """The measure of a validated body scene; ``motions`` from
    :func:`clothfem.scene_body.body_motions`; ``reference_mask`` the hinge ``beyond_joint``
    selector (:func:`clothfem.scene_body.aj_mask`)."""
    c, body = scene.contact, scene.body
    k = torque_segment_index(scene)
    t_settle = scene.solver.settle_time
    segments = tuple([k] if k is not None else [])
    names = [seg.name for seg in body]
    segments += tuple(names.index(n) for n in c.torque_with or ())
    if k is None or body[k].type != "mocap":
        centre = c.torque_point if c.torque_point is not None else body[k].joint
        axis = np.asarray(motions[k].axis, dtype=float) if k is not None else np.zeros(3)
        return TorqueMeasure(
            mode=c.aj,
            centre_at=_constant(centre),
            axis_at=_constant(axis),
            reference_mask=reference_mask,
            segments=segments,
        )
    seg_motion = motions[k]
    frame = motions[names.index(c.flexion_frame or body[k].name)]
    column = {"e2": 1, "e3": 2}[c.flexion_axis]
    sign = _flexion_sign(frame, seg_motion, column)

    def clock(t: float) -> float:
        return max(t - t_settle, 0.0)

    def joint(t: float) -> FloatArray:
        return seg_motion.joint(clock(t))

    centre = _constant(c.torque_point) if c.torque_point is not None else joint
    return TorqueMeasure(
        mode=c.aj,
        centre_at=centre,
        axis_at=lambda t: sign * frame.pose(clock(t)).rotation[:, column],
        normal_at=lambda t: seg_motion.pose(clock(t)).rotation[:, 0],
        segments=segments,
    )
