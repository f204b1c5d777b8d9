"""Resistance measures and the torque-roughness metric (clothfem.report), against closed forms.

Pure numpy on synthetic histories (one folder per process, so this also runs under mpirun).
"""

import csv
import math

import numpy as np
import pytest

from clothfem import report as R


def test_joint_work_constant_torque_over_a_known_angle():
    """A hinge about -y turning at 1 rad/s through 1 rad against a constant garment torque
    tau = +0.3 N m about the hinge axis (it opposes the motion): W = 0.3 N m x 1 rad."""
    axis = np.array([0.0, -1.0, 0.0])
    t = np.linspace(0.0, 1.0, 11)
    omega = np.outer(np.ones_like(t), axis)  # 1 rad/s
    tau = np.outer(np.full_like(t, -0.3), axis)  # garment on the segment, against omega
    for rule in ("trapezoid", "impulse"):
        w = R.joint_work(t, tau, omega, rule=rule)
        assert w[0] == 0.0
        np.testing.assert_allclose(w, 0.3 * t, rtol=0, atol=1e-15)
    # the same with components about the axis, and over the angle as the parameter
    np.testing.assert_allclose(R.joint_work(t, tau @ axis, 1.0), 0.3 * t, atol=1e-15)
    # a garment that drives the joint (torque along omega) gives negative work
    assert R.joint_work(t, -tau, omega)[-1] == pytest.approx(-0.3, abs=1e-15)
    # a torque normal to omega does no work
    assert R.joint_work(t, np.outer(np.ones_like(t), [1.0, 0, 0]), omega)[-1] == 0.0


def test_joint_work_linear_torque_is_exact_with_the_trapezoid_rule():
    """tau(theta) = -(a + b theta) about the axis, theta from 0 to T on a non-uniform grid:
    W = a T + b T^2 / 2 (the trapezoid rule is exact for a linear integrand)."""
    a, b, T = 0.05, 0.2, math.radians(57.0)
    theta = np.sort(np.r_[0.0, np.random.default_rng(1).uniform(0, T, 40), T])
    w = R.joint_work(theta, -(a + b * theta), 1.0)
    np.testing.assert_allclose(w, a * theta + 0.5 * b * theta**2, rtol=1e-13, atol=1e-16)
    # the impulse rule (sample k = mean over the interval ending at it): first order
    wi = R.joint_work(theta, -(a + b * theta), 1.0, rule="impulse")
    assert wi[-1] > w[-1] and wi[-1] == pytest.approx(w[-1], rel=0.05)
    with pytest.raises(ValueError, match="rule"):
        R.joint_work(theta, theta, 1.0, rule="simpson")


def test_roughness_of_a_synthetic_signal():
    """tau_k = m + A (-1)^k on rows 0.5 deg apart: every difference is 2A, so the roughness
    is 2A / m; rows outside [2, 20] deg and non-finite rows do not count."""
    angle = np.arange(0.0, 30.0, 0.5)
    k = np.arange(angle.size)
    m, amp = 0.1, 0.004
    tau = m + amp * (-1.0) ** k
    tau[angle < 2.0] = 5.0  # outside the range: ignored
    tau[angle > 20.0] = -3.0
    sel = (angle >= 2.0) & (angle <= 20.0)  # 37 rows: their mean is m + A / 37
    assert R.roughness(angle, tau) == pytest.approx(2 * amp / tau[sel].mean(), rel=1e-12)
    assert tau[sel].mean() == pytest.approx(m + amp / 37, rel=1e-12)
    # a linear trend of slope s per row adds in quadrature: sqrt(mean (s +- 2A)^2) = sqrt(s^2
    # + 4A^2) (alternating signs), over the mean of the rows in range
    s = 0.001
    ramp = m + s * k + amp * (-1.0) ** k
    expect = math.sqrt(s**2 + 4 * amp**2) / ramp[sel].mean()
    assert R.roughness(angle, ramp) == pytest.approx(expect, rel=1e-12)
    assert R.roughness(angle, np.full(angle.size, 0.2)) == 0.0
    # the trend part: the roughness of the least-squares line, here m + s k exactly (the
    # alternation is orthogonal to a line only approximately: compare to 1e-3)
    line = m + s * k
    assert R.roughness_trend(angle, line) == pytest.approx(R.roughness(angle, line), rel=1e-12)
    assert R.roughness_trend(angle, line) == pytest.approx(s / line[sel].mean(), rel=1e-12)
    assert R.roughness_trend(angle, ramp) == pytest.approx(s / ramp[sel].mean(), rel=1e-3)
    ang_nan = angle.copy()
    ang_nan[10] = np.nan  # a dropped row: its neighbours become consecutive
    assert np.isfinite(R.roughness(ang_nan, tau))
    assert math.isnan(R.roughness(angle[:3], tau[:3]))  # < 2 rows in [2, 20]


def _history(folder, rows):
    folder.mkdir(parents=True, exist_ok=True)
    cols = list(rows[0])
    with (folder / "history.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    return folder / "history.csv"


def test_resistance_measures_and_report(tmp_path, capsys):
    """Settle rows at 0.02 N m, then a motion whose torque is 0.1 + 0.01 angle with a +-0.002
    alternation; the work column is the explicit runner's kind (cumulative)."""
    rows = []
    for i in range(1, 5):
        rows.append(
            dict(
                stage="settle",
                time=0.05 * i,
                angle_deg=0.0,
                torque_mag=0.02 * i / 4,
                torque_flex=-0.02 * i / 4,
                joint_work=0.0,
                dissipation_total=1e-4 * i,
            )
        )
    for i in range(1, 41):
        a = 0.5 * i
        tau = 0.1 + 0.01 * a + 0.002 * (-1) ** i
        rows.append(
            dict(
                stage="motion",
                time=0.2 + 0.01 * i,
                angle_deg=a,
                torque_mag=tau,
                torque_flex=-tau,
                joint_work=0.001 * i,
                dissipation_total=4e-4 + 1e-4 * i,
            )
        )
    path = _history(tmp_path / "run", rows)  # fmt: skip
    m = R.resistance_measures(R.read_history(path), joint="forearm")
    assert m["joints"]["forearm"] == {
        "work": pytest.approx(0.04),
        "work_flexion": pytest.approx(0.04),
    }
    d = m["dissipation"]
    assert d["friction"] == pytest.approx(4.4e-3) and d["material"] == 0.0
    assert d["total"] == pytest.approx(4.4e-3) and "no material dissipation" in d["material_note"]
    st, fl = m["torque"]["settle"], m["torque"]["flexion"]
    assert st["rows"] == 4 and st["peak"] == pytest.approx(0.02)
    assert st["mean"] == pytest.approx(0.0125)  # time average, equally spaced rows
    assert fl["rows"] == 40 and fl["peak"] == pytest.approx(0.1 + 0.2 + 0.002)
    assert fl["peak_flex"] == pytest.approx(fl["peak"])
    # the time-weighted mean of the alternation cancels to O(A / n): 0.1 + 0.01 x 10.25 deg
    assert fl["mean"] == pytest.approx(0.1 + 0.01 * 10.25, abs=1e-4)
    sel = [r for r in rows if r["stage"] == "motion" and 2.0 <= r["angle_deg"] <= 20.0]
    tau = np.array([r["torque_mag"] for r in sel])
    assert fl["roughness"] == pytest.approx(
        math.sqrt(np.mean(np.diff(tau) ** 2)) / tau.mean(), rel=1e-12
    )
    text = R.report_markdown(tmp_path / "run")
    assert "work of the measured joint against the garment: 0.04 J (flexion 0.04 J)" in text
    assert "energy dissipated by the clothing: 0.0044 J = friction 0.0044 J + material 0 J" in text
    assert "flexion torque |tau|: peak 0.302 N m" in text
    assert "torque roughness over 2-20 deg" in text


def test_dissipation_counts_the_friction_between_layers(tmp_path):
    """With self-contact the clothing's dissipation adds the layers' friction
    (self_friction_work) to the body contact's and the material's."""
    rows = [
        dict(stage="motion", time=0.01 * i, angle_deg=1.0 * i, torque_mag=0.1, torque_flex=-0.1,
             joint_work=0.01 * i, dissipation_total=1e-3 * i, self_friction_work=2e-4 * i,
             dissipation_material=5e-5 * i)
        for i in range(1, 6)
    ]  # fmt: skip
    d = R.resistance_measures(R.read_history(_history(tmp_path / "run", rows)))["dissipation"]
    assert d["friction"] == pytest.approx(5e-3) and d["self_friction"] == pytest.approx(1e-3)
    assert d["total"] == pytest.approx(5e-3 + 1e-3 + 2.5e-4)
    text = R.report_markdown(tmp_path / "run")
    assert "= friction 0.005 J + between layers 0.001 J + material 0.00025 J" in text


def test_hinge_smooth_start_angle_and_rate():
    """HingeMotion t_ramp: the rate rises as omega (3 x^2 - 2 x^3) over the ramp, the angle
    is its integral (omega t_ramp / 2 behind the constant rate afterwards), angle_max is
    reached t_ramp / 2 later (or inside the ramp, for a smaller angle_max), and t_ramp = 0 is
    the constant rate bit for bit."""
    from clothfem.body.motion import HingeMotion

    kw = dict(joint=[0.3, 0, 0], axis=[0, -1, 0], centre0=[0.42, 0, 0], rotation0=np.eye(3))
    om, amax, tr = 1.0, math.radians(57.0), 0.1
    m = HingeMotion(omega=om, angle_max=amax, t_ramp=tr, **kw)
    assert m.t_end == pytest.approx(amax / om + tr / 2, rel=1e-15)
    t = np.linspace(0.0, m.t_end, 20001)
    theta = np.array([m.angle(x) for x in t])
    rate = np.array([m.rate(x) for x in t[:-1]])
    # the angle is the integral of the rate (trapezoid on a fine grid), continuous at the end
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t[:-1]))))
    np.testing.assert_allclose(theta[:-1], integral, atol=1e-7)  # trapezoid error ~1e-8
    assert m.angle(tr / 2) == pytest.approx(om * tr * (0.125 - 0.5 / 16))
    assert m.rate(0.0) == 0.0 and m.rate(tr / 2) == pytest.approx(om / 2)
    assert m.angle(tr + 0.2) == pytest.approx(om * (0.2 + tr / 2))  # lags by omega tr / 2
    assert m.angle(m.t_end) == pytest.approx(amax, abs=1e-15) and m.rate(m.t_end) == 0.0
    assert np.allclose(m.pose(tr / 2).angular_velocity, [0, -om / 2, 0])
    step = HingeMotion(omega=om, angle_max=amax, **kw)
    for x in (0.0, 0.3, 0.7, 5.0):
        assert step.angle(x) == om * min(max(x, 0.0), amax / om)
    # an angle_max inside the ramp: reached where the ramp's angle equals it, then rest
    short = HingeMotion(omega=om, angle_max=0.01, t_ramp=tr, **kw)
    x = short.t_end / tr  # t_start = 0
    assert 0.0 < x < 1.0
    assert om * tr * x**3 * (1.0 - 0.5 * x) == pytest.approx(0.01, rel=1e-15)
    assert short.angle(short.t_end) == pytest.approx(0.01, rel=1e-15)
    assert short.angle(short.t_end + 1.0) == 0.01 and short.rate(short.t_end) == 0.0
    assert short.rate(0.5 * short.t_end) > 0.0
    at_end = HingeMotion(omega=om, angle_max=om * tr / 2, t_ramp=tr, **kw)
    assert at_end.t_end == pytest.approx(tr, rel=1e-15)


def test_roughness_split_of_a_trend_plus_alternation():
    """tau_k = m + s k + A (-1)^k on rows 0.5 deg apart (0-30 deg): the piecewise-linear
    interpolant of the alternation is a triangle wave of period 1 deg, whose mean over a
    2-deg window is exactly 0, and the centred average keeps the line; so over 2-20 deg
    the averaged curve's roughness is the trend's s / mean and the oscillation about it
    is A / mean (closed forms, 1e-12)."""
    angle = np.arange(0.0, 30.0, 0.5)
    k = np.arange(angle.size)
    m, s, amp = 0.1, 0.001, 0.004
    tau = m + s * k + amp * (-1.0) ** k
    sel = (angle >= 2.0) & (angle <= 20.0)
    smooth_r, osc = R.roughness_split(angle, tau)
    assert smooth_r == pytest.approx(s / tau[sel].mean(), rel=1e-12)
    assert osc == pytest.approx(amp / tau[sel].mean(), rel=1e-12)
    assert all(math.isnan(v) for v in R.roughness_split(angle[:1], tau[:1]))
