"""Human body and motion: rigid ellipsoid segments posed from motion capture (numpy/scipy only).

Man & Swan (2007), Sec. 3.3: the body is an assemblage of overlapping rigid ellipsoids
(Eq. 26) whose centroids and orientations follow joint centres ``J1, J2`` and an auxiliary
marker ``M`` (Eq. 27).  Global frame: right-handed, metres, **Z up**.  Rotations ``Q`` have the
body axes ``e1, e2, e3`` as columns; :class:`Ellipsoid` stores them as rows (``axes = Q.T``).

Modules: :mod:`~clothfem.body.pose` (Pose, Motion), :mod:`~clothfem.body.ellipsoid`
(Ellipsoid, Segment, Body), :mod:`~clothfem.body.motion` (Eq. 27, interpolated and analytic
motions, joint angles), :mod:`~clothfem.body.mocap` (C3D/TRC, gap filling, marker maps),
:mod:`~clothfem.body.lower_body` (pelvis, thighs, shanks and feet from a gait capture),
:mod:`~clothfem.body.gait_repeat` (a recorded gait cycle repeated, shifted by the stride);
import those two from their modules (each also runs as ``python -m``).
"""

from clothfem.body.ellipsoid import Body, Ellipsoid, Segment, check_radii
from clothfem.body.mocap import (
    UNIT_SCALE,
    MarkerRef,
    MarkerSet,
    arm_marker_map,
    lower_limb_marker_map,
    read_c3d,
    read_trc,
    validate_marker_map,
    write_trc,
    y_up_to_z_up,
    z_up_to_y_up,
)
from clothfem.body.motion import (
    FixedMotion,
    HingeMotion,
    InterpolatedMotion,
    SegmentFrames,
    arm_flexion_body,
    body_from_markers,
    eq27_frames,
    joint_angle,
    segment_frames,
    segment_markers,
)
from clothfem.body.pose import Motion, Pose, check_rotation

__all__ = [
    "UNIT_SCALE",
    "Body",
    "Ellipsoid",
    "FixedMotion",
    "HingeMotion",
    "InterpolatedMotion",
    "MarkerRef",
    "MarkerSet",
    "Motion",
    "Pose",
    "Segment",
    "SegmentFrames",
    "arm_flexion_body",
    "arm_marker_map",
    "body_from_markers",
    "check_radii",
    "check_rotation",
    "eq27_frames",
    "joint_angle",
    "lower_limb_marker_map",
    "read_c3d",
    "read_trc",
    "segment_frames",
    "segment_markers",
    "validate_marker_map",
    "write_trc",
    "y_up_to_z_up",
    "z_up_to_y_up",
]
