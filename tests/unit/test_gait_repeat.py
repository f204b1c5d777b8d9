"""A recorded gait cycle repeated and shifted by the stride (clothfem.body.gait_repeat), on the
shipped gait capture: copies equal the shifted cycle, continuous seams, constant segment
lengths, duration, stride against the walking speed, gaps, events and argument errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clothfem.body import MarkerSet, read_c3d
from clothfem.body.gait_repeat import (
    RepeatedGait,
    gait_cycle,
    main,
    repeat_cycle,
    seam_jumps,
)
from clothfem.body.lower_body import (
    lower_body_from_markers,
    read_gait_events,
    read_subject_parameters,
)

WALK = Path(__file__).resolve().parents[2] / "data" / "mocap" / "walk_cgm_lowerlimb.c3d"
COPIES = 4
BLEND = 0.05  # s

#: Velocity jump allowed at a seam after blending: 5 % of the walking speed (0.89 m/s in this
#: file), i.e. about 45 mm/s; measured 22 mm/s (RFEA).  Without blending it is 7.4 m/s.
VEL_JUMP_FRACTION = 0.05


@pytest.fixture(scope="module")
def walk() -> MarkerSet:
    return read_c3d(WALK)


@pytest.fixture(scope="module")
def rg(walk: MarkerSet) -> RepeatedGait:
    start, end = gait_cycle(WALK, foot="Right")
    return repeat_cycle(
        walk, start=start, end=end, copies=COPIES, blend=BLEND, events=read_gait_events(WALK)
    )


def _walking_speed(m: MarkerSet) -> float:
    """Horizontal speed in m/s of the mean hip centre: slope of a line fit over the file."""
    hips = 0.5 * (m.positions[:, m.index("LFEP")] + m.positions[:, m.index("RFEP")])
    a = np.column_stack([m.times, np.ones(m.n_frames)])
    return float(np.linalg.norm(np.linalg.lstsq(a, hips[:, :2], rcond=None)[0][0]))


def _one_sided_jump(p: np.ndarray, r: int, h: float) -> np.ndarray:
    """|D- - D+| per marker at row r (second-order one-sided differences), m/s."""
    back = (3 * p[r] - 4 * p[r - 1] + p[r - 2]) / (2 * h)
    fwd = (-3 * p[r] + 4 * p[r + 1] - p[r + 2]) / (2 * h)
    return np.linalg.norm(back - fwd, axis=-1)


def test_gait_cycle_from_events() -> None:
    assert gait_cycle(WALK, foot="Right") == pytest.approx((0.1405, 1.2200), abs=1e-4)
    assert gait_cycle(WALK, foot="Left") == pytest.approx((0.7035, 1.8100), abs=1e-4)
    with pytest.raises(ValueError, match=r"^foot must be one of \['Left', 'Right'\]"):
        gait_cycle(WALK, foot="R")
    with pytest.raises(ValueError, match="index 1 needs 3 Right Foot Strike events"):
        gait_cycle(WALK, foot="Right", index=1)


def test_duration_rate_seams_and_description(rg: RepeatedGait, walk: MarkerSet) -> None:
    assert rg.rows == (14, 122)
    assert (rg.start, rg.end) == pytest.approx((0.14, 1.22))
    assert rg.cycle_time == pytest.approx(1.08)
    m = rg.markers
    assert m.n_frames == COPIES * 108 + 1
    assert m.times[0] == 0.0
    assert m.times[-1] == pytest.approx(COPIES * rg.cycle_time, abs=1e-12)
    assert rg.duration == pytest.approx(COPIES * 1.08)
    assert m.rate == pytest.approx(walk.rate)
    assert np.allclose(np.diff(m.times), 1.0 / walk.rate, atol=1e-12)
    assert rg.seam_times == pytest.approx((1.08, 2.16, 3.24))
    assert rg.seam_rows == (108, 216, 324)
    assert rg.repeated and m.names == walk.names
    assert rg.description == (
        "repeated cycle: 4 copies of the cycle 0.14-1.22 s, stride (-0.033, 0.996) m, "
        "blended over 0.05 s"
    )
    assert "repeated cycle x4" in m.source
    assert rg.gap_markers == ()


def test_copies_equal_the_shifted_cycle_outside_the_blend(
    rg: RepeatedGait, walk: MarkerSet
) -> None:
    x = walk.positions[14:123]
    p = rg.markers.positions
    nb = round(BLEND * walk.rate)  # rows with a correction: |row - seam| < nb
    rows = np.arange(p.shape[0])
    near = np.zeros(rows.size, bool)
    for r in rg.seam_rows:
        near |= np.abs(rows - r) < nb
    for k in range(COPIES):
        sel = np.arange(k * 108, (k + 1) * 108 + 1)
        keep = sel[~near[sel]]
        expect = x[keep - k * 108] + k * rg.stride
        np.testing.assert_allclose(p[keep], expect, rtol=0, atol=1e-12)
    # ... and the blend does change the windows (closure up to 48 mm).
    naive = repeat_cycle(walk, start=rg.start, end=rg.end, copies=COPIES, blend=0.0)
    assert np.max(np.abs(p[near] - naive.markers.positions[near])) > 0.02


def test_seams_continuous_positions_and_velocities(rg: RepeatedGait, walk: MarkerSet) -> None:
    h = 1.0 / walk.rate
    x = walk.positions[14:123]
    step_rec = np.linalg.norm(np.diff(x, axis=0), axis=-1).max(axis=0)  # per marker, m
    speed = _walking_speed(walk)
    bound = VEL_JUMP_FRACTION * speed
    naive = repeat_cycle(walk, start=rg.start, end=rg.end, copies=COPIES, blend=0.0)
    worst = 0.0
    for k, r in enumerate(rg.seam_rows, start=1):
        p = rg.markers.positions
        # The seam sample is the mean of the two sides.
        mean = 0.5 * (x[108] + (k - 1) * rg.stride + x[0] + k * rg.stride)
        np.testing.assert_allclose(p[r], mean, rtol=0, atol=1e-12)
        # Frame-to-frame steps across the seam are no larger than the recorded ones.
        steps = np.maximum(
            np.linalg.norm(p[r] - p[r - 1], axis=-1), np.linalg.norm(p[r + 1] - p[r], axis=-1)
        )
        assert np.all(steps <= step_rec + 1e-6)
        jump = _one_sided_jump(p, r, h)
        worst = max(worst, float(jump.max()))
        assert jump.max() < bound, (jump.max(), bound)
        np.testing.assert_allclose(seam_jumps(rg.markers, row=r)[1], jump, atol=1e-9)
        # Without blending the seam jumps: the test can tell.
        q = naive.markers.positions
        naive_steps = np.linalg.norm(q[r] - q[r - 1], axis=-1)
        assert np.any(naive_steps > step_rec + 5e-3)
        assert _one_sided_jump(q, r, h).max() > 10 * bound
    assert 0.010 < worst < 0.030  # measured 22 mm/s
    assert rg.closure_position.max() == pytest.approx(0.0477, abs=5e-4)  # LFEA, before
    assert rg.closure_velocity.max() == pytest.approx(0.278, abs=5e-3)  # RFEA, before


def test_segment_lengths_as_constant_as_recorded(rg: RepeatedGait, walk: MarkerSet) -> None:
    def length(m: MarkerSet, a: str, b: str) -> np.ndarray:
        return np.linalg.norm(m.positions[:, m.index(b)] - m.positions[:, m.index(a)], axis=1)

    for s in "LR":
        for a, b in ((f"{s}FEP", f"{s}FEO"), (f"{s}FEO", f"{s}TIO")):
            rec, rep = length(walk, a, b), length(rg.markers, a, b)
            assert rep.std() <= rec.std() + 0.5e-3, (a, b, rep.std(), rec.std())
            assert np.ptp(rep) <= np.ptp(rec) + 1e-3, (a, b)
            assert abs(rep.mean() - rec.mean()) < 1e-3


def test_stride_against_walking_speed(rg: RepeatedGait, walk: MarkerSet) -> None:
    speed = _walking_speed(walk)  # 0.892 m/s
    assert rg.stride_length == pytest.approx(0.9969, abs=1e-3)
    assert abs(rg.stride_length - speed * rg.cycle_time) < 0.05 * rg.stride_length  # 3.5 %
    # Adult walking: about 1.0-1.6 m per stride; this subject (1.64 m tall) walks slowly
    # (0.89 m/s) with a 0.997 m stride, so the lower bound is 0.9 m.
    assert 0.9 < rg.stride_length < 1.6
    assert abs(rg.stride_vertical) < 0.02  # 8.5 mm
    assert rg.stride[2] == 0.0
    assert rg.stride[1] > 0.9 and abs(rg.stride[0]) < 0.05  # walking along +Y


def test_events_repeated(rg: RepeatedGait) -> None:
    strikes = [e.time for e in rg.events if e.context == "Right" and e.label == "Foot Strike"]
    assert len(rg.events) == 4 * COPIES + 1
    # Each copy's first strike is 0.5 ms after its first frame (event 0.1405 s, frame 0.14 s);
    # the closing strike (file time 1.22 s = frame 122) ends the last copy.
    expect = [*(0.0005 + 1.08 * np.arange(COPIES)), COPIES * 1.08]
    np.testing.assert_allclose(strikes, expect, atol=1e-6)
    assert all(0.0 <= e.time <= rg.duration + 1e-9 for e in rg.events)


def test_one_copy_is_the_cycle(walk: MarkerSet) -> None:
    one = repeat_cycle(walk, start=0.1405, end=1.22, copies=1)
    assert not one.repeated and one.seam_times == ()
    assert "1 copy of the cycle" in one.description
    np.testing.assert_array_equal(one.markers.positions, walk.positions[14:123])


def test_gaps_kept_as_gaps(walk: MarkerSet) -> None:
    p = walk.positions[:40].copy()
    p[10:13, walk.index("LTOE")] = np.nan  # interior gap
    p[32, walk.index("RTOE")] = np.nan  # at the cycle's end (row 32 = end - 1)
    m = MarkerSet(times=walk.times[:40], names=walk.names, positions=p, source="gap")
    rg = repeat_cycle(m, start=0.0, end=0.33, copies=3, blend=0.04)
    q = rg.markers.positions
    lt, rt = walk.index("LTOE"), walk.index("RTOE")
    nan_rows = np.flatnonzero(np.isnan(q[:, lt, 0]))
    np.testing.assert_array_equal(nan_rows, [10, 11, 12, 43, 44, 45, 76, 77, 78])
    assert rg.gap_markers == ("RTOE",)
    rt_nan = set(np.flatnonzero(np.isnan(q[:, rt, 0])))
    assert {32, 65, 98} <= rt_nan  # the recorded gap, per copy
    assert set(range(30, 37)) <= rt_nan and set(range(63, 70)) <= rt_nan  # blend windows
    others = [i for i in range(len(walk.names)) if i not in (lt, rt)]
    assert np.all(np.isfinite(q[:, others]))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"start": 1.0, "end": 1.0}, r"^start must be < end \(s\)"),
        ({"start": 1.2, "end": 0.2}, r"^start must be < end \(s\)"),
        ({"copies": 0}, r"^copies must be an integer >= 1, got 0"),
        ({"copies": 2.5}, r"^copies must be an integer >= 1"),
        ({"start": -0.5}, r"^start: the cycle \[-0\.5, 1\.22\] s must lie within the recording"),
        ({"end": 3.0}, r"^end: the cycle \[0\.1405, 3\] s must lie within the recording"),
        ({"blend": 0.6}, r"^blend must be in \[0, 0\.54\] s \(half the cycle time 1\.08 s\)"),
        ({"blend": -0.01}, r"^blend must be in \[0, 0\.54\] s"),
        ({"blend": float("nan")}, r"^blend must be a finite number of seconds"),
        ({"pelvis_markers": ("PELVIS",)}, r"marker 'PELVIS' is not in the file"),
    ],
)
def test_bad_input(walk: MarkerSet, kwargs: dict, message: str) -> None:
    args = {"start": 0.1405, "end": 1.22, "copies": 2, "blend": 0.05} | kwargs
    with pytest.raises(ValueError, match=message) as err:
        repeat_cycle(walk, **args)
    assert "\n" not in str(err.value)


def test_repeated_markers_drive_the_lower_body(rg: RepeatedGait) -> None:
    lb = lower_body_from_markers(
        rg.markers, subject=read_subject_parameters(WALK), events=rg.events
    )
    pose = lb.motions["R_shank"].pose(rg.duration)
    assert np.all(np.isfinite(pose.centre))
    assert pose.centre[1] > 3.0  # four strides along +Y from about -0.66 m
    assert len(lb.events) == len(rg.events)


def test_main_prints_the_numbers(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    out = capsys.readouterr().out
    assert "repeated cycle: 4 copies of the cycle 0.14-1.22 s" in out
    assert "closure before blending: position max 47.7 mm (LFEA)" in out
