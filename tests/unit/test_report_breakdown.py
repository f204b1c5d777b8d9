"""clothfem report's warnings of a run that leaves its steady resistance: the self-contact
fail-safe's work, a jump of the fabric's kinetic energy, the crushed-yarn cause by element."""

import numpy as np

from clothfem.report import KE_BASE_ROWS, KE_JUMP, _crush_lines, _energy_lines, _failsafe_lines


def _hinge(ke: np.ndarray, settle: int = 3) -> dict[str, np.ndarray]:
    n = len(ke)
    stage = np.array(["settle"] * settle + ["motion"] * (n - settle))
    angle = np.r_[np.zeros(settle), np.linspace(0.5, 0.5 * (n - settle), n - settle)]
    return {
        "stage": stage,
        "angle_deg": angle,
        "time": 0.01 * np.arange(1, n + 1),
        "kinetic_energy": ke,
    }


def test_kinetic_energy_jump_is_named_at_its_angle():
    ke = np.r_[np.full(3, 1e-7), np.full(20, 1e-3), 0.5, np.full(5, 0.1)]
    h = _hinge(ke)
    (line,) = _energy_lines(h)
    assert line.startswith("- warning: the fabric's kinetic energy jumps to 0.5 J at 10.5 deg")
    assert "500 x the median" in line


def test_no_warning_for_a_smooth_start_a_steady_run_or_too_few_rows():
    x = np.linspace(0.0, 1.0, 12)
    ramp = (3 * x**2 - 2 * x**3) ** 2 * 2e-3  # the kinetic energy of a smoothly started turn
    assert _energy_lines(_hinge(np.r_[np.full(3, 1e-8), ramp, np.full(30, 2e-3)])) == []
    noisy = 1e-3 * (1.0 + 0.9 * np.sin(np.arange(60)))  # varies by 19x, no jump above 20x
    assert _energy_lines(_hinge(np.r_[np.full(3, 1e-8), noisy])) == []
    # a jump before KE_BASE_ROWS motion rows is not judged (the motion's own start)
    early = np.r_[np.full(3, 1e-8), np.full(KE_BASE_ROWS - 1, 1e-4), 1.0]
    assert _energy_lines(_hinge(early)) == []
    assert _energy_lines({"stage": np.array(["motion"])}) == []
    assert KE_JUMP > 19


def test_failsafe_counts_and_first_row():
    nan = np.nan
    h = _hinge(np.full(6, 1e-3))
    h["self_crossings"] = np.array([nan, 0.0, 0.0, 4.0, 0.0, 9.0])
    h["self_crossings_left"] = np.zeros(6)
    (line,) = _failsafe_lines(h, by_time=False)
    assert "13 in 2 of 6 rows, at most 9 in one, the first at 0.5 deg" in line
    (line,) = _failsafe_lines(h, by_time=True)
    assert line.endswith("the first at t = 0.040 s")
    h["self_crossings_left"] = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    assert _failsafe_lines(h, by_time=False)[1].startswith(
        "- warning: crossings left after the fail-safe from 1.5 deg on"
    )


def test_failsafe_clean_run_and_run_without_self_contact():
    h = _hinge(np.full(4, 1e-3))
    assert _failsafe_lines(h, by_time=False) == []
    h["self_crossings"] = np.zeros(4)
    assert _failsafe_lines(h, by_time=False) == [
        "- fabric crossings found by the self-contact fail-safe: none"
    ]


def test_crushed_yarn_cause_follows_the_element():
    h = _hinge(np.full(5, 1e-3))
    h["min_yarn_strain"] = np.array([0.0, -0.1, -0.1, -0.3, -0.3])
    h["max_yarn_strain"] = np.full(5, 0.1)
    mitc = _crush_lines(h, element="MITC9 (assumed membrane and shear strains)")[1]
    assert "a fold the mesh does not resolve (MITC9 has no spurious membrane mode)" in mitc
    psri = _crush_lines(h, element="partial selective reduced integration (...)")[1]
    assert "membrane mode of the partial selective element" in psri
    assert "from 0.5 deg on" in psri
