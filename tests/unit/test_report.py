"""Post-processing of run folders: curve errors, interpolation, ``clothfem plot`` / ``report``.

Synthetic run folders in ``tmp_path`` (one per process, so this also runs under mpirun).
"""

import csv
import json
import math

import numpy as np
import pytest

from clothfem import report as R
from clothfem.cli import main

COLUMNS = ["stage", "time", "angle_deg", "torque_mag", "torque_flex", "n_active"]
COLUMNS += ["max_penetration", "newton_iterations", "elapsed", "cutbacks"]
COLUMNS += ["t_assembly", "t_solve", "t_contact", "t_io"]
MOTION_ANGLES = [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0]


def _run(folder, *, summary=None, columns=COLUMNS, tail=""):
    """Run folder: settle at half load (0.5 N m) and full load (1 N m) at 0 deg, then a motion
    to 40 deg with torque_mag = 1 + 0.1 angle and torque_flex = -torque_mag."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = [("settle", 0.0, 0.5), ("settle", 0.0, 1.0)]
    rows += [("motion", a / 10, 1 + 0.1 * a) for a in MOTION_ANGLES]
    with (folder / "history.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for i, (stage, t, tau) in enumerate(rows):
            angle = 10 * t
            vals = dict(stage=stage, time=t, angle_deg=angle, torque_mag=tau, torque_flex=-tau)
            vals.update(n_active=5, max_penetration=1e-9 * (i + 1), newton_iterations=4)
            vals.update(elapsed=1.5 * (i + 1), cutbacks=1 if i == 3 else 0)
            vals.update(t_assembly=1.0, t_solve=2.0, t_contact=1.0, t_io=0.0)
            w.writerow([vals.get(c, "") for c in columns])
        f.write(tail)
    if summary is not None:
        (folder / "summary.json").write_text(json.dumps(summary))
    return folder


STOPPED = {
    "scene": "demo",
    "completed": False,
    "reason": "contact failed at 42 deg",
    "final_angle_deg": 40.0,
    "steps": 10,
    "cutbacks": 3,
    "wall_time": 12.5,
}


def test_curve_error_constant_offset_is_exact():
    a = np.array([0.0, 20.0, 60.0])
    e = R.curve_error(a, np.full(3, 2.0), a, np.full(3, 2.0 * 1.05), lo=0.0, hi=50.0)
    assert e == pytest.approx(0.05, rel=1e-12)
    assert R.curve_error(a, 3 * a, a, 6 * a, lo=10.0, hi=40.0) == pytest.approx(1.0, rel=1e-12)


def test_curve_error_linear_ramp():
    # tau_ref = alpha, tau = alpha + 1 on [10, 30]: sqrt(20 / ((30^3 - 10^3) / 3)) = 0.0480384
    a = np.array([0.0, 30.0, 60.0])
    e = R.curve_error(a, a, a[::-1], a[::-1] + 1.0, lo=10.0, hi=30.0)  # unsorted input is fine
    assert e == pytest.approx(math.sqrt(20 / (26000 / 3)), rel=1e-4)  # trapezoid on 200 points
    # on [0, H]: c sqrt(3) / H
    assert R.curve_error(a, a, a, a + 2.0, lo=0.0, hi=60.0) == pytest.approx(
        2 * math.sqrt(3) / 60, rel=1e-4
    )


def test_curve_error_not_covered_is_nan():
    a, short = np.array([0.0, 60.0]), np.array([0.0, 40.0])
    assert math.isnan(R.curve_error(a, a + 1, short, short + 1, lo=0.0, hi=57.0))
    assert math.isnan(R.curve_error(short, short + 1, a, a + 1, lo=0.0, hi=57.0))
    assert math.isnan(R.curve_error(a, a + 1, a[1:], a[1:], lo=0.0, hi=57.0))
    assert R.curve_error(a, a + 1, a, a + 1, lo=0.0, hi=57.0) == 0.0
    with pytest.raises(ValueError):
        R.curve_error(a, a, a, a, lo=10.0, hi=10.0)


def test_moving_average_of_linear_function_is_exact_inside():
    rng = np.random.default_rng(0)
    a = np.sort(np.r_[0.0, rng.uniform(0.0, 30.0, 60), 30.0])  # non-uniform, ends 0 and 30
    f = 2.0 - 0.3 * a
    w = 4.0
    order = rng.permutation(a.size)  # unsorted input, values returned in the given order
    s = R.moving_average(a[order], f[order], w)
    inner = (a[order] >= w / 2) & (a[order] <= 30.0 - w / 2)
    assert inner.sum() > 40
    np.testing.assert_allclose(s[inner], f[order][inner], rtol=0, atol=1e-12)
    # at the ends the window is truncated to [0, w/2]: the mean of a line is its midpoint value
    at = np.array([0.0, 30.0, 15.0, -3.0, 40.0])
    s = R.moving_average(a, f, w, at=at)
    np.testing.assert_allclose(
        s[:3], [2.0 - 0.3 * w / 4, 2.0 - 0.3 * (30 - w / 4), -2.5], atol=1e-12
    )
    assert math.isnan(s[3]) and math.isnan(s[4])  # the window misses [0, 30]
    assert R.moving_average(a, f, 0.0).tolist() == f.tolist()  # window 0: unchanged


def test_curve_error_window_removes_a_full_period_of_noise():
    a = np.linspace(0.0, 20.0, 4001)
    ref = 1.0 + 0.1 * a
    noisy = ref + 0.5 * np.sin(2 * np.pi * a / 1.0)  # period 1 deg
    # raw: int_5^15 noise^2 = 0.5^2 / 2 * 10 (ten full periods); int_5^15 ref^2 = [ref^3 / 0.3]
    ref2 = ((1.0 + 0.1 * 15) ** 3 - (1.0 + 0.1 * 5) ** 3) / 0.3
    raw = math.sqrt(0.5**2 / 2 * 10 / ref2)
    assert R.curve_error(a, ref, a, noisy, lo=5.0, hi=15.0) == pytest.approx(raw, rel=1e-2)
    assert R.curve_error(a, ref, a, noisy, lo=5.0, hi=15.0, window=0.0) == pytest.approx(
        raw, rel=1e-2
    )
    assert R.curve_error(a, ref, a, noisy, lo=5.0, hi=15.0, window=1.0) < 1e-3
    # a curve that does not cover [lo, hi] stays nan with a window
    assert math.isnan(R.curve_error(a, ref, a[a < 14], noisy[a < 14], lo=5, hi=15, window=1.0))


@pytest.mark.parametrize("window", [-1.0, -1e-9, math.nan, math.inf])
def test_curve_error_bad_window_raises(window):
    a = np.array([0.0, 10.0])
    with pytest.raises(ValueError, match="window"):
        R.curve_error(a, a + 1, a, a + 1, lo=0.0, hi=10.0, window=window)
    with pytest.raises(ValueError, match="window"):
        R.moving_average(a, a, window)


def test_torque_at_interpolates_and_reports_unreached():
    a = np.array([0.0, 10.0, 20.0, 56.99999999999])
    t = np.array([1.0, 2.0, 4.0, 5.0])
    assert R.torque_at(a, t, 15.0) == pytest.approx(3.0)
    assert R.torque_at(a[::-1], t[::-1], 5.0) == pytest.approx(1.5)
    assert R.torque_at(a, t, 57.0) == pytest.approx(5.0)  # round-off at the end is "reached"
    assert R.torque_at(a, t, 57.1) is None and R.torque_at(a, t, -1.0) is None
    assert R.torque_at(np.array([]), np.array([]), 0.0) is None


def test_read_history_and_curve(tmp_path):
    d = _run(tmp_path / "r", tail="motion,4.5,45.0,5")  # incomplete last line: dropped
    h = R.read_history(d / "history.csv")
    assert h["stage"].size == 10 and h["angle_deg"].dtype == float
    a, tau = R.torque_curve(h)
    assert a.tolist() == [0.0, *MOTION_ANGLES]  # the last settle row only
    assert tau[0] == 1.0 and tau[-1] == pytest.approx(5.0)
    assert R.torque_at(a, tau, 12.5) == pytest.approx(2.25)
    assert R.torque_at(a, tau, 0.0) == 1.0


def test_plot_one_run_default_path(tmp_path, capsys):
    d = _run(tmp_path / "one", summary=STOPPED)
    assert main(["plot", str(d), "--y", "torque_flex", "--title", "t"]) == 0
    png = d / "torque_angle.png"
    assert png.is_file() and png.stat().st_size > 0
    assert capsys.readouterr().out.strip() == str(png)
    assert R._stopped_note(R.read_history(d / "history.csv"), STOPPED) == " (stopped at 40.0 deg)"
    assert R._stopped_note({}, {"completed": True}) == ""


def test_plotted_torque_without_the_pinched_fabric(tmp_path, capsys):
    h = {
        "stage": np.array(["settle", "motion", "motion"]),
        "angle_deg": np.array([0.0, 10.0, 20.0]),
        "time": np.array([0.2, 0.3, 0.4]),
        "torque_flex": np.array([-0.1, -2.0, -5.0]),
        "torque_flex_pinched": np.array([0.0, -1.5, -4.0]),
    }
    a, t = R.plotted(h, y="torque_flex_unpinched", x="angle")
    assert a.tolist() == [0.0, 10.0, 20.0] and t == pytest.approx([0.1, 0.5, 1.0])
    assert R.plotted(h, y="torque_flex", x="time")[0].tolist() == [0.2, 0.3, 0.4]
    d = _run(tmp_path / "r")  # a history without torque_flex_pinched
    assert main(["plot", str(d), "--y", "torque_flex_unpinched"]) == 2
    err = capsys.readouterr().err
    assert "missing column 'torque_flex_pinched'" in err and err.count("\n") == 1
    # an explicit run's history has the column, empty
    e = _run(tmp_path / "e", columns=[*COLUMNS, "torque_flex_pinched"])
    assert main(["plot", str(e), "--y", "torque_flex_unpinched"]) == 2
    err = capsys.readouterr().err
    assert "no values in column 'torque_flex_pinched'" in err and err.count("\n") == 1


def test_plot_compare_in_cwd(tmp_path, monkeypatch, capsys):
    a, b = _run(tmp_path / "a"), _run(tmp_path / "b", summary={"completed": False})
    monkeypatch.chdir(tmp_path)
    assert main(["plot", str(a), str(b), "--label", "A", "B"]) == 0
    png = tmp_path / "torque_angle_compare.png"
    assert png.is_file() and png.stat().st_size > 0
    assert capsys.readouterr().out.strip() == "torque_angle_compare.png"
    out = tmp_path / "sub" / "x.png"
    assert main(["plot", str(a), str(b), "--label", "A", "--label", "B", "--out", str(out)]) == 0
    assert out.is_file()
    assert main(["plot", str(a), str(b), "--label", "A"]) == 2  # one label for two runs
    assert capsys.readouterr().err.count("\n") == 1


def test_plot_against_time_reads_the_events(tmp_path, capsys):
    """--x time: the events of events.csv are read back (time, context, label)."""
    d = _run(tmp_path / "walk")
    (d / "events.csv").write_text("time_s,context,label\n0.25,Right,Foot Strike\n")
    assert R._events(d) == [(0.25, "Right", "Foot Strike")]
    assert R._events(tmp_path) == []
    assert main(["plot", str(d), "--x", "time", "--out", str(tmp_path / "t.png")]) == 0
    assert (tmp_path / "t.png").stat().st_size > 0
    assert main(["plot", str(d), "--x", "angle", "--y", "torque_flex"]) == 0


def test_report_of_a_recorded_motion(tmp_path, capsys):
    """No hinge (the angle column is constant): the peak is given at a time, no final angle,
    and the table is at the gait events of events.csv (interpolated in time)."""
    d = _run(tmp_path / "walk")
    rows = list(csv.DictReader((d / "history.csv").open()))
    for r in rows:
        r["angle_deg"] = "0.0"
    with (d / "history.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    (d / "events.csv").write_text("time_s,context,label\n2.5,Right,Foot Strike\n")
    assert main(["report", str(d)]) == 0
    text = capsys.readouterr().out
    assert "- peak torque |tau|: 5 N m at t = 4.000 s" in text and "final angle" not in text
    assert "| time [s] | event | torque_mag [N m] | -torque_flex [N m] |" in text
    assert "| 2.5 | Right Foot Strike | 3.5 | 3.5 |" in text  # halfway between rows 2.0, 3.0


def test_report_text(tmp_path, capsys):
    d = _run(tmp_path / "run", summary=STOPPED)
    md = tmp_path / "r.md"
    assert main(["report", str(d), "--markdown", str(md)]) == 0
    text = capsys.readouterr().out
    assert md.read_text() == text
    for expected in (
        "# Run report: demo",
        "status: stopped: contact failed at 42 deg",
        "final angle: 40.00 deg",
        "peak torque |tau|: 5 N m at 40.00 deg",
        "steps: 10 (10 rows: 2 settle, 8 motion)",
        "cut-backs: 3",
        "max penetration: 1e-08 m",
        "Newton iterations (total): 40",
        "wall time: 12.5 s",
        "assembly 25.0 %, solve 50.0 %, contact 25.0 %, io 0.0 %",
        "| 0 | 1 | 1 |",
        "| 10 | 2 | 2 |",
        "| 20 | 3 | 3 |",
        "| 50 | — | — |",
        "| 57 | — | — |",
    ):
        assert expected in text, expected


def test_report_time_shares_of_the_wall_time(tmp_path, capsys):
    """With a wall time above the timed parts (the explicit runs time only contact and
    output), the shares are of the wall time and the rest is "other"."""
    d = _run(tmp_path / "run", summary=dict(STOPPED, wall_time=80.0))
    assert main(["report", str(d)]) == 0
    text = capsys.readouterr().out
    expected = "time shares of the wall time: assembly 12.5 %, solve 25.0 %, contact 12.5 %, "
    assert expected + "io 0.0 %, other 50.0 %" in text


def test_report_of_a_resumed_run_still_running(tmp_path, capsys):
    """A resumed segment writes a summary marked running at its start: the report does not
    show the earlier stop as the status, takes the final angle and steps from the history
    and adds the earlier segments' wall times (15 s of this one's rows + 12.5 s + 7 s)."""
    earlier = [
        {"reason": "RunStopped: stopped by signal", "final_angle_deg": 20.0, "wall_time": 12.5},
        {"reason": "no end recorded: killed while running", "final_angle_deg": None},
        {"reason": "RunStopped: stopped by signal", "final_angle_deg": 30.0, "wall_time": 7.0},
    ]
    summary = {"scene": "demo", "completed": False, "running": True, "earlier": earlier}
    d = _run(tmp_path / "run", summary=summary)
    assert main(["report", str(d)]) == 0
    text = capsys.readouterr().out
    assert "status: not finished (a resumed run still running or killed" in text
    assert "final angle: 40.00 deg" in text and "steps: 10 (10 rows" in text
    assert "wall time: 34.5 s (4 segments, resumed after: RunStopped: stopped by signal at " in text
    assert "20.00 deg; no end recorded: killed while running, its wall time not known; " in text
    assert R._stopped_note(R.read_history(d / "history.csv"), summary) == (
        " (not finished: 40.0 deg so far)"
    )


def test_report_without_summary_or_optional_columns(tmp_path, capsys):
    required = ["stage", "time", "angle_deg", "torque_mag", "newton_iterations", "elapsed"]
    d = _run(tmp_path / "bare", columns=required)
    assert main(["report", str(d)]) == 0
    text = capsys.readouterr().out
    assert "# Run report: bare" in text and "status: unknown" in text
    assert "wall time: 15.0 s" in text and "steps: 10 " in text
    assert "cut-backs" not in text and "time shares" not in text and "penetration" not in text
    assert "| 30 | 4 |" in text and "torque_flex" not in text


def test_missing_history_and_malformed_csv(tmp_path, capsys):
    missing = tmp_path / "nothing"
    assert main(["report", str(missing)]) == 2
    assert capsys.readouterr().err == f"clothfem: {missing / 'history.csv'} not found\n"
    assert main(["plot", str(missing)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    bad = _run(tmp_path / "bad", columns=["stage", "time", "torque_mag"])
    for cmd in ("report", "plot"):
        assert main([cmd, str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "missing required column 'angle_deg'" in err


def test_report_warns_of_a_crushed_yarn(tmp_path, capsys):
    """With the yarn strain columns, the report gives their range, and warns from the first
    row whose smallest yarn strain is below report.CRUSHED (-0.2), naming its angle."""
    d = _run(tmp_path / "run", columns=[*COLUMNS, "min_yarn_strain", "max_yarn_strain"])
    with (d / "history.csv").open() as f:
        rows = list(csv.DictReader(f))
    for i, r in enumerate(rows):  # the 7th row (25 deg) on: -0.3
        r["min_yarn_strain"], r["max_yarn_strain"] = (-0.3 if i >= 6 else -0.01), 0.05
    with (d / "history.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    assert main(["report", str(d)]) == 0
    text = capsys.readouterr().out
    assert "yarn Green strain range: -0.3 to 0.05" in text
    assert (
        "warning: a yarn is compressed below E = -0.2 (stretch < 0.77) at some integration" in text
    )
    assert "point from 25.0 deg on" in text
    d2 = _run(tmp_path / "plain")
    assert main(["report", str(d2)]) == 0
    assert "yarn" not in capsys.readouterr().out


def test_timer_shares_bin_the_rows_by_angle():
    """Each row counts once, in the bin of its angle (the last bin closed at its top);
    the sums are the rows' own timer and wall seconds."""
    h = {
        "angle_deg": np.array([0.0, 0.0, 10.0, 44.9, 45.0, 60.0, 90.0]),
        "t_self_contact": np.array([1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
        "wall_time": np.array([10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0]),
    }
    rows = R.timer_shares(h, [0.0, 45.0, 60.0])
    assert rows == [(0.0, 45.0, 4, 7.0, 40.0), (45.0, 60.0, 2, 9.0, 20.0)]
    assert R.timer_shares(h, [0.0, 90.0])[0][2:] == (7, 22.0, 70.0)
