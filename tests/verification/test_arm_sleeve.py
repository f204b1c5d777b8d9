"""The arm-sleeve elbow-flexion scene (Man & Swan 2007, Sec. 4.1) end to end, very coarse.

``demos/scenes/arm_sleeve_ci.toml`` through the CLI: gravity settling with contact, then 4 deg
of quasi-static elbow flexion in 2 increments. Checks: finite torques, the contact KKT
conditions at every written state, the physics (the flexion-axis torque opposes the flexion
and grows with the angle; the y-symmetric scene gives no torque about x or z) and the
numbers themselves (serially; on 2 ranks while the run follows the serial run's contact
path, see the test).
"""

import csv
import math
from pathlib import Path

from mpi4py import MPI

from clothfem.cli import main

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"
THICKNESS = 1e-3

# serial run of the CI scene (2026-11-22; unchanged 2026-11-23): torque about the flexion
# axis [N m] and the path that gave it (active nodes, sub-steps of the increment)
EXPECTED = {0.0: (-0.035476, 38, 1), 2.0: (-0.060039, 45, 1), 4.0: (-0.083709, 40, 3)}


def test_arm_sleeve_ci_scene(tmp_path):
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "arm"
    assert main(["run", str(SCENE), "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert (out / "fabric.xdmf").is_file()
    settle = [r for r in rows if r["stage"] == "settle"]
    motion = [r for r in rows if r["stage"] == "motion"]
    assert len(settle) == 2 and len(motion) == 2
    assert float(settle[-1]["load_factor"]) == 1.0
    assert [float(r["angle_deg"]) for r in motion] == [2.0, 4.0]
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
    assert flex[0] > flex[1] > flex[2]
    # the settled (not yet moving) state only carries the sleeve's weight: under flexion the
    # contact torque is much larger than that
    assert abs(flex[2]) > 2.0 * abs(flex[0])
    # the numbers: serially (deterministic) every row is the reference's. On 2 ranks the
    # linear solves are not repeatable run to run (MUMPS; Newton iteration counts vary by
    # +-30 %), and at 4 deg the frictional contact path can then end in another equilibrium
    # (measured: 44 active nodes, -0.0795 N m, in some runs under load); rows are compared
    # while the 2-rank run is on the reference's path (same active nodes and sub-steps),
    # which must hold at least through the settled state and 2 deg
    same = True
    for r in [settle[-1], *motion]:
        expected, n_active, substeps = EXPECTED[float(r["angle_deg"])]
        same = same and (int(r["n_active"]), int(r["substeps"])) == (n_active, substeps)
        if COMM.size == 1 or float(r["angle_deg"]) <= 2.0:
            assert same, r
        if same:
            assert math.isclose(float(r["torque_flex"]), expected, rel_tol=1e-4), r


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
    ]:
        with pytest.raises(scenes.SceneError, match=message) as info:
            scenes.validate(scenes.apply_overrides(data, [override]))
        assert "\n" not in str(info.value)
    no_body = {k: v for k, v in data.items() if k != "body"}
    with pytest.raises(scenes.SceneError, match="'contact': needs a body"):
        scenes.validate(no_body)
    s = scenes.validate({k: v for k, v in no_body.items() if k != "contact"})
    assert s["body"] == [] and s["contact"]["mu"] == 0.0
