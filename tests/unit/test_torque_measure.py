"""Eq. 28 about a moving joint (clothfem.torque_measure): the knee of the shipped gait
recording as the shank's J1 carried with its Eq. 27 frame, the thigh's e3 as the knee's
flexion axis, the node sets, and the gait events on the run's clock."""

import numpy as np
import pytest
from _gait import WALK, right_leg

from clothfem import scene as scenes
from clothfem.body.gait_repeat import gait_cycle
from clothfem.body.lower_body import read_gait_events
from clothfem.scene_body import body_motions, contact_log, recorded_events
from clothfem.spec import Scene
from clothfem.torque_measure import TorqueMeasure, pinched, torque_measure

SETTLE = 0.1


def _raw_knee(*, repeat: int = 1, contact: dict | None = None) -> dict:
    """Right thigh and shank of the gait recording, one right-foot cycle; torque about the
    knee (the shank's J1) over the nodes touching the shank, the thigh's flexion axis."""
    start, end = gait_cycle(WALK, foot="Right")
    seg = {"type": "mocap", "file": str(WALK), "window": [start, end], "repeat": repeat}
    if repeat > 1:
        seg["stride_markers"] = ["LFEP", "RFEP"]
    knee = {"torque_segment": "R_shank", "aj": "touching", "flexion_frame": "R_thigh"}
    return {
        "scene": {"name": "knee"},
        "mesh": {"generator": "strip", "length": 0.1, "width": 0.1, "nx": 1, "ny": 1},
        "material": {"preset": "crimped-cotton", "thickness": 1e-3},
        "body": right_leg(seg),
        "contact": contact if contact is not None else knee,
        "solver": {"integrator": "explicit", "settle_time": SETTLE},
    }


def _knee_scene(*, repeat: int = 1) -> Scene:
    return scenes.validate(_raw_knee(repeat=repeat))


@pytest.fixture(scope="module")
def knee():
    scene = _knee_scene()
    motions = body_motions(scene)
    return scene, motions, torque_measure(scene, motions, reference_mask=None)


def test_knee_centre_moves_with_the_shank_and_meets_the_thigh(knee):
    """J(t) is the shank's J1 carried with its frame: at rest in the first pose until the
    settle time, then on the recording; it stays within 3 mm of the thigh's J2 (both are the
    recorded knee centre RFEO; the difference is the recording's segment-length scatter)."""
    _, (thigh, shank), m = knee
    assert np.allclose(m.centre_at(0.0), shank.joint(0.0))
    assert np.allclose(m.centre_at(SETTLE / 2), shank.joint(0.0))
    for t in np.linspace(0.0, shank.t_end, 23):
        assert np.allclose(m.centre_at(SETTLE + t), shank.joint(t))
        p = thigh.pose(t)
        knee_of_thigh = p.centre - p.rotation @ thigh.joint_local  # J2 = c + L/2 e1
        assert np.linalg.norm(shank.joint(t) - knee_of_thigh) < 3e-3


def test_thigh_e3_is_the_knee_flexion_axis(knee):
    """The flexion axis a(t) is the thigh's e3 (M anterior) signed so that flexion is a
    positive rotation about it, as for a hinge: a = -e3 (e3 points to the subject's right),
    within 8 degrees of e1_thigh x e1_shank at every frame where the knee is flexed more than
    10 degrees."""
    _, (thigh, shank), m = knee
    for t in np.linspace(0.0, shank.t_end, 40):
        a = m.axis_at(SETTLE + t)
        assert np.allclose(a, -thigh.pose(t).rotation[:, 2], atol=1e-12)
        n = np.cross(thigh.pose(t).rotation[:, 0], shank.pose(t).rotation[:, 0])
        if np.degrees(np.arcsin(np.linalg.norm(n))) > 10.0:
            assert n @ a / np.linalg.norm(n) > np.cos(np.radians(8.0))


def test_moving_torque_is_eq28_about_the_moving_centre(knee):
    """local() is sum (x_i - J(t)) x f_i over AJ: for random forces it equals the torque about
    the origin minus J(t) x (resultant over AJ) (Varignon), at any time."""
    _, _, m = knee
    rng = np.random.default_rng(1)
    x, f = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    body = rng.integers(-1, 2, size=50)  # -1: free, 0: thigh, 1: shank
    for t in (0.0, SETTLE + 0.3, SETTLE + 0.8):
        tau, flex = m.local(t=t, x=x, force_on_body=f, body=body)
        on = body == 1  # touching the torque segment only
        expected = np.cross(x[on], f[on]).sum(0) - np.cross(m.centre_at(t), f[on].sum(0))
        assert np.allclose(tau, expected, atol=1e-12)
        assert flex == pytest.approx(tau @ m.axis_at(t), abs=1e-12)


def test_node_sets():
    """'touching' counts the torque segment and contact.torque_with; a moving 'beyond_joint'
    keeps the points past the plane through J(t) normal to n(t); 'all' keeps every one."""
    J, n = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    x = np.array([[0.0, 0.0, 1.0], [3.0, 2.0, -0.5], [1.0, 5.0, 0.2]])
    body = np.array([2, 1, -1])

    def measure(mode: str) -> TorqueMeasure:
        return TorqueMeasure(
            mode=mode,
            centre_at=lambda _t: J,
            axis_at=lambda _t: n,
            normal_at=lambda _t: n,
            segments=(1, 2),
        )

    assert measure("touching").select(t=0.0, x=x, body=body).tolist() == [True, True, False]
    assert measure("beyond_joint").select(t=0.0, x=x, body=body).tolist() == [True, False, True]
    assert measure("all").select(t=0.0, x=x, body=body) is None


def test_gait_events_on_the_run_clock():
    """The C3D EVENT group's events inside the played cycle, shifted to the run's clock
    (settle time + time since the first played frame); a repeated cycle lists each copy's
    events once (the seam event, foot strike to foot strike, is shared)."""
    scene = _knee_scene()
    start, end = scene.body[0].window
    inside = [e for e in read_gait_events(WALK) if start - 0.005 <= e.time <= end + 0.005]
    got = recorded_events(scene)
    assert len(got) == len(inside) >= 2  # this cycle: both right foot strikes at least
    for (t, ctx, label), e in zip(got, inside, strict=True):
        assert (ctx, label) == (e.context, e.label)
        assert t == pytest.approx(SETTLE + e.time - start, abs=0.0101)  # frames: 0.01 s
    twice = recorded_events(_knee_scene(repeat=2))
    assert len(twice) == 2 * len(inside) - 1


def test_log_names_the_moving_joint():
    line = [s for s in contact_log(_knee_scene()) if s.startswith("contact:")][0]
    assert "the moving joint J1 of R_shank" in line and "+-e3 of R_thigh" in line
    assert "AJ = touching of R_shank" in line


@pytest.mark.parametrize(
    ("contact", "message"),
    [
        ({"torque_segment": "hip"}, r"'contact.torque_segment': must name a hinge or mocap"),
        ({"torque_with": ["R_thigh"]}, r"'contact.torque_with': counts with aj = 'touching'"),
        ({"aj": "touching", "torque_with": ["foot"]}, r"'contact.torque_with': must name body"),
        ({"flexion_frame": "knee"}, r"'contact.flexion_frame': must name a mocap segment"),
    ],
)
def test_torque_keys_one_line_errors(contact, message):
    with pytest.raises(scenes.SceneError, match=message) as info:
        scenes.validate(_raw_knee(contact={"torque_segment": "R_shank", **contact}))
    assert "\n" not in str(info.value)


def test_a_fixed_centre_is_required_without_a_torque_segment():
    with pytest.raises(scenes.SceneError, match=r"'contact.torque_point': required when") as info:
        scenes.validate(_raw_knee(contact={"aj": "all"}))
    assert "\n" not in str(info.value)


def test_offset_moves_the_ellipsoid_not_the_joint(knee):
    """body.offset (segment frame) moves the ellipsoid centre by Q offset; J1 stays put."""
    data = _raw_knee()
    data["body"][1]["offset"] = [0.02, -0.03, 0.01]
    shifted = body_motions(scenes.validate(data))[1]
    shank = knee[1][1]
    for t in (0.0, 0.37, 0.9):
        p, q = shank.pose(t), shifted.pose(t)
        assert np.allclose(q.centre, p.centre + p.rotation @ [0.02, -0.03, 0.01], atol=1e-12)
        assert np.allclose(shifted.joint(t), shank.joint(t), atol=1e-12)


def test_recording_placement_keeps_the_recorded_coordinates():
    """placement = 'recording' (no centre): the thigh's pose at t = 0 is its Eq. 27 frame at
    the first played frame of the file, in m."""
    from clothfem.body import read_c3d, segment_frames

    data = _raw_knee()
    thigh = data["body"][0]
    for k in ("centre", "axis", "up"):
        del thigh[k]
    thigh["placement"] = "recording"
    motion = body_motions(scenes.validate(data))[0]
    markers = read_c3d(WALK)
    row = int(np.searchsorted(markers.times, thigh["window"][0] - 1e-9))
    ref = segment_frames(markers, marker_map={"t": {"j1": "RFEP", "j2": "RFEO", "m": "RFEA"}})
    assert np.allclose(motion.pose(0.0).centre, ref["t"].centres[row], atol=1e-12)
    assert np.allclose(motion.pose(0.0).rotation, ref["t"].rotations[row], atol=1e-9)
    data["body"][0]["centre"] = [0.0, 0.0, 0.0]
    with pytest.raises(scenes.SceneError, match=r"'body\[0\].centre': is not used with"):
        scenes.validate(data)


def test_pinched_pairs_are_the_nodes_on_two_bodies():
    nodes = np.array([4, 7, 4, 2, 9, 9, 9])
    assert pinched(nodes).tolist() == [True, False, True, False, True, True, True]
    assert pinched(np.zeros(0, dtype=int)).shape == (0,)
