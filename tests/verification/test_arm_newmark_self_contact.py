"""Smoke test: the very coarse arm-sleeve scene (8 x 10 cells) on the Newmark path with
fabric self-contact on: it runs to 3 degrees of flexion, the history carries the
self-contact columns, no written frame intersects itself (independent checker) and the
summary says so."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"
SETS = [
    "solver.integrator=newmark",
    "solver.settle_time=0.05",
    "solver.ramp_time=0.05",
    "solver.dt=0.005",
    "body.1.angle_max=3.0",
    "contact.self_contact=true",
]
ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
ENV["OPENBLAS_NUM_THREADS"] = "1"

pytestmark = [
    pytest.mark.serial,
    pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own process"),
]


def test_arm_newmark_with_self_contact(tmp_path):
    out = tmp_path / "arm"
    cmd = [sys.executable, "-m", "clothfem.cli", "run", str(SCENE), "--out", str(out)]
    cmd += ["--unset", "solver.steps", "--unset", "contact.increments"]
    cmd += [a for s in SETS for a in ("--set", s)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=ENV, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "self-contact: built" in res.stdout
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert float(rows[-1]["angle_deg"]) == pytest.approx(3.0)
    assert all(int(r["self_crossings"]) == 0 for r in rows)
    assert all(int(float(r["self_intersections"])) == 0 for r in rows if r["self_intersections"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] and summary["self_intersections_max"] == 0
