"""benchmarks/_arm_common.py: a study case whose physics another study already ran is copied,
not run again (``find_twin``); the band-mean torque columns (``band_mean``); a case that
switches the scene's integrator runs without the scene's keys of the other one
(``scene_edits``).

No simulation runs: synthetic case folders (case.json, summary.json, history.csv) in
``tmp_path`` (one per process, so this also runs under mpirun).
"""

import json
import sys
from argparse import Namespace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import _arm_common as C  # noqa: E402

MESH = ["mesh.n_around=8", "mesh.n_along=10"]


def fake_case(folder: Path, sets: list[str], *, completed: bool = True, ranks: int = 1) -> None:
    folder.mkdir(parents=True)
    rec = {"sets": sets, "returncode": 0, "wall_s": 12.5, "scene": str(C.SCENE)}
    if ranks > 1:
        rec["ranks"] = ranks
    (folder / "case.json").write_text(json.dumps(rec))
    (folder / "summary.json").write_text(json.dumps({"completed": completed}))
    (folder / "history.csv").write_text("time,angle_deg\n0.0,0.0\n")


def test_same_physics_written_differently_is_a_twin(tmp_path):
    ran = tmp_path / "friction" / "mu0.5"
    fake_case(ran, [*MESH, "contact.mu=0.5"])
    # the scene's default radius and thickness spelled out: same physics
    fit = tmp_path / "fit" / "R0.06"
    assert C.find_twin(fit, C.SCENE, [*MESH, "mesh.radius=0.06", "contact.mu=0.5"]) == ran
    thick = tmp_path / "thickness" / "t1mm"
    assert C.find_twin(thick, C.SCENE, [*MESH, "material.thickness=1e-3", "contact.mu=0.5"]) == ran
    # output cadence does not change the answer either
    assert C.find_twin(fit, C.SCENE, [*MESH, "contact.mu=0.5", "output.every=1"]) == ran


def test_other_physics_ranks_or_unfinished_runs_are_not_twins(tmp_path):
    fake_case(tmp_path / "friction" / "mu0.5", [*MESH, "contact.mu=0.5"])
    fake_case(tmp_path / "friction" / "mu0.1", [*MESH, "contact.mu=0.1"], completed=False)
    new = tmp_path / "fit" / "R0.07"
    assert C.find_twin(new, C.SCENE, [*MESH, "mesh.radius=0.07", "contact.mu=0.5"]) is None
    assert C.find_twin(new, C.SCENE, [*MESH, "contact.mu=0.5"], ranks=2) is None
    assert C.find_twin(new, C.SCENE, [*MESH, "contact.mu=0.1"]) is None  # not completed
    # a bad override is no twin of anything (the run itself reports the error)
    assert C.find_twin(new, C.SCENE, [*MESH, "contact.mu=-1"]) is None


def test_run_cases_copies_the_twin_and_reports_its_row(tmp_path, capsys):
    ran = tmp_path / "friction" / "mu0.5"
    fake_case(ran, [*MESH, "contact.mu=0.5"])
    args = Namespace(
        scene=C.SCENE, only=None, dry_run=False, force=False, extra_set=[], timeout=None
    )
    case = C.Case("t1mm", ["material.thickness=0.001", "contact.mu=0.5"])
    rows = C.run_cases([case], tmp_path / "thickness", args, settings=MESH)
    copy = tmp_path / "thickness" / "t1mm"
    rec = json.loads((copy / "case.json").read_text())
    assert rec["same_as"] == str(ran)
    assert rec["sets"] == [*MESH, "material.thickness=0.001", "contact.mu=0.5"]
    assert (copy / "history.csv").read_text() == (ran / "history.csv").read_text()
    assert rows[0]["completed"] == "yes" and rows[0]["wall_s"] == 12.5
    assert "same physics as" in capsys.readouterr().out
    # a copy is never itself offered as a twin (without the run it copied: no twin)
    (ran / "case.json").unlink()
    assert C.find_twin(tmp_path / "fit" / "R0.06", C.SCENE, [*MESH, "contact.mu=0.5"]) is None


def test_band_mean_is_the_exact_mean_of_the_curve():
    """Mean of |tau| over an angle band: for tau = a^2 sampled finely, the piecewise-linear
    interpolant's mean over [lo, hi] tends to (hi^3 - lo^3) / (3 (hi - lo)); a linear curve
    gives its midpoint value exactly; a band outside the curve is nan."""
    a = np.linspace(0.0, 57.0, 5701)
    assert C.band_mean(a, a**2, 15.0, 30.0) == pytest.approx((30**3 - 15**3) / 45.0, rel=1e-6)
    assert C.band_mean(a, 0.1 + 0.002 * a, 2.0, 15.0) == pytest.approx(0.1 + 0.002 * 8.5)
    assert np.isnan(C.band_mean(a[:3000], a[:3000], 45.0, 57.0))


def test_integrator_switch_removes_the_scene_keys_of_the_other_integrators(tmp_path):
    """arm_sleeve.toml (explicit) switched to the static path: its dynamic keys are unset,
    the settling takes 2 load steps and the hinge 1-degree increments over the angle; the
    command and the twin lookup load it. A switch to newmark needs nothing."""
    sets = ["solver.integrator=static", "body.1.angle_max=3"]
    unset, add = C.scene_edits(C.SCENE, sets)
    dynamic = ["solver.rotary_scale", "solver.settle_time", "solver.ramp_time"]
    assert unset == [*dynamic, "output.checkpoint_every"]
    assert add == ["solver.steps=2", "contact.increments=3"]
    s = C.load_scene(C.SCENE, [*sets, *add], unset=unset)
    assert s.solver.integrator == "static" and s.contact.increments == 3
    cmd = C.command(C.Case("static", sets), tmp_path)
    assert [cmd[i + 1] for i, w in enumerate(cmd) if w == "--unset"] == unset
    assert cmd[-4:] == ["--set", "solver.steps=2", "--set", "contact.increments=3"]
    assert C._physics(C.SCENE, sets) is not None
    assert C.scene_edits(C.SCENE, ["solver.integrator=newmark"]) == ([], [])
