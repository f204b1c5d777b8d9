"""C3D/TRC readers and writer, units and up-axis, gap filling, marker maps, input errors."""

import tomllib
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from clothfem.body import (
    MarkerSet,
    arm_marker_map,
    lower_limb_marker_map,
    read_c3d,
    read_trc,
    segment_frames,
    validate_marker_map,
    write_trc,
)

DATA = Path(__file__).resolve().parents[2] / "data" / "mocap"


def _write_c3d(path, *, labels, pts, rate=100.0, units="mm", y_screen=None):
    """Write positions ``pts`` (F, N, 3), already in ``units``, with ezc3d."""
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    data = np.ones((4, len(labels), pts.shape[0]))
    data[:3] = np.transpose(pts, (2, 1, 0))
    c["data"]["points"] = data
    c.add_parameter("POINT", "UNITS", [units])
    if y_screen is not None:
        c.add_parameter("POINT", "Y_SCREEN", [y_screen])
    c.write(str(path))


def _known(n_frames=6):
    t = np.arange(n_frames) / 50.0
    a = np.stack([0.1 + t, 0.2 - 0.5 * t, 1.0 + 0 * t], axis=-1)
    b = np.stack([0.3 * np.cos(t), 0.3 * np.sin(t), 0.8 + t**2], axis=-1)
    return t, np.stack([a, b], axis=1)  # (F, 2, 3) in m


def test_c3d_round_trip_mm_to_m(tmp_path):
    t, p = _known()
    f = tmp_path / "known.c3d"
    _write_c3d(f, labels=["Subj:A", "Subj:B"], pts=p * 1000.0, rate=50.0, units="mm")
    ms = read_c3d(f)
    assert ms.names == ("A", "B")
    np.testing.assert_allclose(ms.times, t, atol=1e-15)
    assert ms.rate == pytest.approx(50.0)
    # C3D stores float32: 1e-4 mm relative is the storage precision here.
    np.testing.assert_allclose(ms.positions, p, atol=1e-6)
    assert read_c3d(f, strip_prefix=False).names == ("Subj:A", "Subj:B")


def test_c3d_metres_and_y_up(tmp_path):
    _, p = _known()
    f = tmp_path / "yup.c3d"
    p_yup = np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)  # Y-up file of the same scene
    _write_c3d(f, labels=["A", "B"], pts=p_yup, units="m", y_screen="+Y")
    np.testing.assert_allclose(read_c3d(f).positions, p, atol=1e-6)
    np.testing.assert_allclose(read_c3d(f, up_axis="z").positions, p_yup, atol=1e-6)


def test_c3d_nan_sample_is_missing(tmp_path):
    _, p = _known()
    p = p * 1000.0
    p[2, 1] = np.nan
    f = tmp_path / "gap.c3d"
    _write_c3d(f, labels=["A", "B"], pts=p)
    ms = read_c3d(f)
    assert np.all(np.isnan(ms.positions[2, 1])) and np.all(np.isfinite(ms.positions[2, 0]))


def test_c3d_unknown_units_and_one_frame(tmp_path):
    _, p = _known()
    f = tmp_path / "u.c3d"
    _write_c3d(f, labels=["A", "B"], pts=p, units="furlong")
    with pytest.raises(
        ValueError, match=r"POINT:UNITS must be one of \['cm', 'm', 'mm'\], got 'furlong'"
    ):
        read_c3d(f)
    g = tmp_path / "one.c3d"
    _write_c3d(g, labels=["A", "B"], pts=p[:1])
    with pytest.raises(ValueError, match="number of frames must be >= 2 to define a motion, got 1"):
        read_c3d(g)


def test_trc_round_trip_and_file_convention(tmp_path):
    t, p = _known()
    p[3, 0] = np.nan
    ms = MarkerSet(times=t, names=("A", "B"), positions=p, source="known")
    f = tmp_path / "known.trc"
    write_trc(f, ms)  # mm, Y up (OpenSim)
    back = read_trc(f)
    assert back.names == ("A", "B")
    np.testing.assert_allclose(back.times, t, rtol=0, atol=0)
    np.testing.assert_allclose(back.positions, p, rtol=1e-14, atol=1e-17)
    assert np.all(np.isnan(back.positions[3, 0]))
    lines = f.read_text().splitlines()
    assert lines[2].split("\t")[4] == "mm"
    row = [float(v) for v in lines[7].split("\t")[2:5]]  # frame 1, marker A, Y-up mm
    np.testing.assert_allclose(row, [1000 * p[1, 0, 0], 1000 * p[1, 0, 2], -1000 * p[1, 0, 1]])
    g = tmp_path / "zup_m.trc"
    write_trc(g, ms, units="m", up_axis="z")
    np.testing.assert_allclose(read_trc(g, up_axis="z").positions, p, rtol=1e-15)


def test_trc_unknown_units_and_one_frame(tmp_path):
    t, p = _known()
    f = tmp_path / "x.trc"
    write_trc(f, MarkerSet(times=t, names=("A", "B"), positions=p))
    text = f.read_text().splitlines()
    text[2] = text[2].replace("\tmm\t", "\tinch\t")
    f.write_text("\n".join(text) + "\n")
    with pytest.raises(
        ValueError, match=r"TRC Units must be one of \['cm', 'm', 'mm'\], got 'inch'"
    ):
        read_trc(f)
    g = tmp_path / "one.trc"
    g.write_text("\n".join(f.read_text().splitlines()[:7]).replace("\tinch\t", "\tmm\t") + "\n")
    with pytest.raises(ValueError, match="number of frames must be >= 2 to define a motion, got 1"):
        read_trc(g)
    with pytest.raises(ValueError, match="number of frames must be >= 2"):
        MarkerSet(times=[0.0], names=("A",), positions=np.zeros((1, 1, 3)))


def _cubic_set(n=60, gaps=()):
    t = np.linspace(0.0, 0.59, n)
    x = np.stack([1 + 2 * t - t**2 + 0.5 * t**3, -(t**3), 0.3 + 0 * t], axis=-1)
    p = x.copy()
    for a, b in gaps:
        p[a : b + 1] = np.nan
    return t, x, MarkerSet(times=t, names=("A",), positions=p[:, None, :], source="synth")


def test_gap_interpolation_exact_for_cubic_path():
    # Not-a-knot cubic spline through the valid samples reproduces a cubic polynomial exactly.
    _, x, ms = _cubic_set(gaps=[(5, 9), (30, 39)])
    np.testing.assert_allclose(ms.trajectory("A", max_gap=10), x, atol=1e-12)


def test_edge_gap_holds_nearest_value():
    _, x, ms = _cubic_set(gaps=[(0, 2), (57, 59)])
    y = ms.trajectory("A")
    np.testing.assert_allclose(y[:3], np.broadcast_to(x[3], (3, 3)))
    np.testing.assert_allclose(y[57:], np.broadcast_to(x[56], (3, 3)))
    np.testing.assert_allclose(y[3:57], x[3:57])


def test_long_gap_error_names_marker_and_frames():
    _, x, ms = _cubic_set(gaps=[(20, 31)])
    with pytest.raises(
        ValueError, match=r"marker 'A' has a gap of 12 frames \(frames 20-31\) > max_gap=10"
    ):
        ms.trajectory("A")
    np.testing.assert_allclose(ms.trajectory("A", max_gap=12), x, atol=1e-12)


def test_nan_only_marker_and_missing_marker():
    t = np.arange(4) * 0.01
    p = np.zeros((4, 2, 3))
    p[:, 1] = np.nan
    ms = MarkerSet(times=t, names=("A", "DEAD"), positions=p, source="synth")
    with pytest.raises(ValueError, match="marker 'DEAD' has no valid sample"):
        ms.trajectory("DEAD")
    with pytest.raises(
        ValueError,
        match=r"marker 'NOPE' is not in the file; available \(2, closest first\): A, DEAD$",
    ):
        ms.trajectory("NOPE")


def test_marker_map_errors():
    with pytest.raises(
        ValueError, match=r"segment 'thigh': keys must be exactly \['j1', 'j2', 'm'\]"
    ):
        validate_marker_map({"thigh": {"j1": "A", "j2": "B"}})
    with pytest.raises(ValueError, match=r"segment 'thigh' key 'j2': marker reference must be"):
        validate_marker_map({"thigh": {"j1": "A", "j2": {"midpoint": ["B"]}, "m": "C"}})
    validate_marker_map(arm_marker_map())
    validate_marker_map(lower_limb_marker_map())


@pytest.fixture(scope="module")
def arm():
    return read_c3d(DATA / "arm_elbow_box_lift.c3d")


def test_real_arm_file(arm):
    assert arm.n_frames == 580 and arm.rate == pytest.approx(100.0)
    assert {"ACRO_tip", "EPICl", "EPICm", "STYLr", "STYLu", "LARM_ant", "ARMl"} <= set(arm.names)
    # Elbow epicondyles are a few cm apart (mm -> m conversion applied).
    d = np.linalg.norm(arm.trajectory("EPICl") - arm.trajectory("EPICm"), axis=1)
    assert 0.04 < d.mean() < 0.10
    # STYLu has a 14-frame gap at 137-150 (README: gaps 137-168): whole file refused.
    with pytest.raises(
        ValueError, match=r"marker 'STYLu' has a gap of 14 frames \(frames 137-150\)"
    ):
        segment_frames(arm, marker_map=arm_marker_map())
    bad = arm_marker_map()
    bad["forearm"]["m"] = "RADIUS"
    with pytest.raises(
        ValueError, match=r"marker 'RADIUS' is not in the file; available \(51, closest first\): "
    ):
        segment_frames(arm.window(first=0, last=80), marker_map=bad)


def test_real_walk_file_excludes_model_outputs():
    ms = read_c3d(DATA / "walk_cgm_lowerlimb.c3d")
    assert ms.n_frames == 221 and ms.first_frame == 152
    assert "LKneeAngles" not in ms.names and "LFEP" in ms.names
    # Hip joint centre about 0.8 m above the floor (Z up, metres).
    assert 0.6 < np.nanmean(ms.positions[:, ms.index("LFEP"), 2]) < 1.0


def test_marker_map_from_toml_with_virtual_midpoint():
    text = """
    [forearm]
    j1 = { midpoint = ["EL", "EM"] }
    j2 = "W"
    m = "R"
    """
    mm = tomllib.loads(text)
    validate_marker_map(mm)
    t = np.arange(3) * 0.01
    p = np.zeros((3, 4, 3))
    p[:, 0] = [0.1, 0.0, 0.0]  # EL
    p[:, 1] = [-0.1, 0.0, 0.0]  # EM
    p[:, 2] = [0.0, 0.0, -0.3]  # W
    p[:, 3] = [0.0, 0.05, -0.1]  # R
    ms = MarkerSet(times=t, names=("EL", "EM", "W", "R"), positions=p)
    f = segment_frames(ms, marker_map=mm)["forearm"]
    np.testing.assert_allclose(f.j1, 0.0, atol=1e-15)  # midpoint of EL/EM
    np.testing.assert_allclose(f.centres, np.broadcast_to([0.0, 0.0, -0.15], (3, 3)))
    # e1 = -z (down the forearm), e2 = +y (towards R), e3 = e1 x e2 = +x.
    np.testing.assert_allclose(f.rotations[0], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)
