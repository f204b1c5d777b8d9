"""The arm-sleeve elbow-flexion scene (Man & Swan 2007, Sec. 4.1) end to end, very coarse.

``demos/scenes/arm_sleeve_ci.toml`` through the CLI: gravity settling with contact, then 4 deg
of quasi-static elbow flexion in 8 increments. Checks: finite torques, the contact KKT
conditions at every written state, the physics (the flexion-axis torque opposes the flexion
and grows with the angle; the y-symmetric scene gives no torque about x or z) and the
numbers themselves, the same on 1 and 2 ranks (contact path and torques).
"""

import csv
import json
import math
import tomllib
from pathlib import Path

import pytest
from mpi4py import MPI

from clothfem.cli import main

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"
THICKNESS = 1e-3
# the CI scene's keys of the static integrator, removed to run it with another one
UNSET_STATIC = ["--unset", "solver.steps", "--unset", "contact.increments"]

# the serial run of the CI scene (2026-12-01, the default element: partial selective
# reduced integration): torque about the flexion axis [N m] and the path that gave it
# (active nodes, sub-steps of the increment) after settling and at each angle; a regression
# guard, also of serial = 2 ranks (the same active nodes and sub-steps, torques within
# 1e-7). The selective rule gave -0.035476 settled and -0.083710 at 4 deg (2026-11-23): the
# element moves them by +0.4 % and -0.7 %. With 16 increments instead of 8 the torques
# moved by <= 1e-3 (0.5 deg) and <= 2e-5 (1.5-4 deg) (2026-11-23), so these are the
# quasi-static path, not an increment artefact
EXPECTED = {
    0.0: (-0.035619236, 39, 1),
    0.5: (-0.042902102, 41, 1),
    1.0: (-0.048525308, 43, 1),
    1.5: (-0.054277823, 43, 1),
    2.0: (-0.060047408, 43, 1),
    2.5: (-0.065731328, 41, 1),
    3.0: (-0.071220685, 38, 1),
    3.5: (-0.077255774, 33, 1),
    4.0: (-0.083154605, 34, 2),
}


def test_arm_sleeve_ci_scene(tmp_path):
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "arm"
    assert main(["run", str(SCENE), "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert (out / "fabric.xdmf").is_file()
    settle = [r for r in rows if r["stage"] == "settle"]
    motion = [r for r in rows if r["stage"] == "motion"]
    assert len(settle) == 2 and len(motion) == 8
    assert float(settle[-1]["load_factor"]) == 1.0
    assert [float(r["angle_deg"]) for r in motion] == pytest.approx([0.5 * k for k in range(1, 9)])
    for r in rows:
        tau = [float(r[f"torque_{c}"]) for c in "xyz"]
        assert all(math.isfinite(v) for v in tau)
        # KKT: no penetration beyond 1e-3 t, compressive multipliers, lam gap = 0
        assert float(r["max_penetration"]) <= 1e-3 * THICKNESS
        assert float(r["min_multiplier"]) >= 0.0
        assert float(r["complementarity"]) <= 1e-12
        assert int(r["n_active"]) > 0
        # symmetric about y = 0: the torque is about the flexion (y) axis only
        assert abs(tau[0]) + abs(tau[2]) <= 1e-6 * abs(tau[1])
    # resistance: the torque about the hinge axis opposes the flexion and grows with it
    flex = [float(r["torque_flex"]) for r in [settle[-1], *motion]]
    assert all(f < 0 for f in flex)
    assert all(a > b for a, b in zip(flex[:-1], flex[1:], strict=True))
    # the settled (not yet moving) state only carries the sleeve's weight: under flexion the
    # contact torque is much larger than that
    assert abs(flex[-1]) > 2.0 * abs(flex[0])
    # the numbers, on any number of ranks: the same contact path and the same torques (the
    # 2-rank linear solves are repeatable, clothfem.petsc_options)
    for r in [settle[-1], *motion]:
        expected, n_active, substeps = EXPECTED[float(r["angle_deg"])]
        assert (int(r["n_active"]), int(r["substeps"])) == (n_active, substeps), r
        assert math.isclose(float(r["torque_flex"]), expected, rel_tol=1e-7), r


# the explicit run of the CI scene (2026-12-01, serial, the default element): the mean Eq. 28
# flexion torque of the rows at t = 0.15-0.20 s (dynamic settling) and of the last row
# (4 deg); a regression guard, also of serial = 2 ranks. (The selective rule gave
# -0.0355191 and -0.0703176 on 2026-11-23.)
EXPLICIT = {"settled": -0.035516231873352525, "final": -0.07030387064271114}


def test_arm_sleeve_ci_scene_explicit(tmp_path):
    """The same scene through the explicit integrator: central difference with the lumped
    mass and forward-increment Lagrange-multiplier contact (Eqs. 22-25), undamped, settling
    dynamically over 0.2 s before the forearm turns. Against the quasi-static solve above: the
    settled torque is a static equilibrium both reach, by different methods."""
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "arm"
    sets = ["solver.integrator=explicit", "solver.rotary_scale=1000"]
    args = ["run", str(SCENE), "--out", str(out), *UNSET_STATIC]
    assert main([*args, *sum((["--set", s] for s in sets), [])]) == 0
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert math.isclose(float(rows[-1]["angle_deg"]), 4.0, rel_tol=1e-12)
    for r in rows:
        tau = [float(r[f"torque_{c}"]) for c in "xyz"]
        assert all(math.isfinite(v) for v in tau)
        assert float(r["max_penetration"]) <= 1e-3 * THICKNESS  # after the FILM correction
        assert abs(tau[0]) + abs(tau[2]) <= 1e-6 * max(abs(tau[1]), 1e-12)
    settled = [float(r["torque_flex"]) for r in rows if 0.15 <= float(r["time"]) <= 0.2]
    mean = sum(settled) / len(settled)
    # the quasi-static settled torque (Lagrange multipliers, EXPECTED[0.0]): within 1 %
    # measured, 3 % allowed for the undamped oscillation left at 0.2 s (rows spread 5 %)
    assert math.isclose(mean, EXPECTED[0.0][0], rel_tol=0.03)
    motion = [float(r["torque_flex"]) for r in rows if r["stage"] == "motion"]
    assert all(f < 0 for f in motion) and abs(motion[-1]) > 1.5 * abs(mean)
    assert math.isclose(mean, EXPLICIT["settled"], rel_tol=1e-9)
    assert math.isclose(motion[-1], EXPLICIT["final"], rel_tol=1e-9)


def test_body_and_contact_keys_validate():
    """One-line errors for the [[body]] / [contact] keys; contact without a body is refused."""
    import pytest

    from clothfem import scene as scenes

    data = scenes.apply_overrides(scenes.tomllib.loads(SCENE.read_text()), [])
    for override, message in [
        ("contact.mu=-0.1", r"'contact.mu': must be a number in \[0, inf\]"),
        ("contact.torque_segment='elbow'", r"'contact.torque_segment': must name a hinge"),
        ("body.1.radii=[0.2, 0.0, 0.06]", r"'body\[1\].radii': must be 3 numbers > 0 m"),
        ("body.1.up=[2.0, 0.0, 0.0]", r"'body\[1\].up': must not be parallel"),
        ("body.1.type='slide'", r"'body\[1\].type': must be one of 'fixed', 'hinge'"),
        ("contact.method='film'", r"'contact.method': must be 'lagrange' with solver.integr"),
        ("solver.safety=1.5", r"'solver.safety': must be a number in \(0, 1\]"),
    ]:
        with pytest.raises(scenes.SceneError, match=message) as info:
            scenes.validate(scenes.apply_overrides(data, [override]))
        assert "\n" not in str(info.value)
    no_body = {k: v for k, v in data.items() if k != "body"}
    with pytest.raises(scenes.SceneError, match="'contact': needs a body"):
        scenes.validate(no_body)
    s = scenes.validate({k: v for k, v in no_body.items() if k != "contact"})
    assert s.body == () and s.contact.mu == 0.0


def test_arm_sleeve_ci_scene_explicit_with_self_contact(tmp_path, capsys):
    """contact.self_contact = true builds the fabric self-contact after FILM in the explicit
    runner (the log says so) and the CI scene runs through it to 4 deg with finite torques."""
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "arm"
    sets = ["solver.integrator=explicit", "solver.rotary_scale=1000", "contact.self_contact=true"]
    args = ["run", str(SCENE), "--out", str(out), *UNSET_STATIC]
    assert main([*args, *sum((["--set", s] for s in sets), [])]) == 0
    if COMM.rank == 0:
        assert "self-contact: built" in capsys.readouterr().out
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert math.isclose(float(rows[-1]["angle_deg"]), 4.0, rel_tol=1e-12)
    assert all(math.isfinite(float(r["torque_flex"])) for r in rows)
    # the self-contact columns in every row; the independent intersection check at the field
    # frames (every output.every rows and the last) only: the sleeve never touches itself here
    every = tomllib.loads(SCENE.read_text())["output"]["every"]
    checked = [i for i, r in enumerate(rows) if r["self_intersections"] != ""]
    assert checked == [i for i in range(len(rows)) if (i + 1) % every == 0 or i == len(rows) - 1]
    assert all(int(rows[i]["self_intersections"]) == 0 for i in checked)
    assert all(int(r["self_crossings_left"]) == 0 and float(r["t_self_contact"]) > 0 for r in rows)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["self_intersections_max"] == 0 and summary["self_crossings_left"] == 0
