"""The arm-sleeve scene solved dynamically (Newmark + Lagrange contact), very coarse.

The CI scene with ``solver.integrator = "newmark"``: dynamic settling for 0.05 s, then 3 deg
of elbow flexion. Checks: the contact conditions and the sign of the resistance at every
step; the same torques on 1 and 2 MPI ranks (the 2-rank run under its own mpirun); and an
interrupted run (SIGTERM) resumed from its checkpoint repeats the uninterrupted history bit
for bit.
"""

import csv
import math
import os
import signal
import subprocess
import sys
import time
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
    "output.checkpoint_every=2",
]
# the CI scene's keys of the static integrator, removed for the dynamic runs
UNSET_STATIC = ["--unset", "solver.steps", "--unset", "contact.increments"]
THICKNESS = 1e-3
# a child process must not inherit this (singleton) MPI process's environment
ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
ENV["OPENBLAS_NUM_THREADS"] = "1"

pytestmark = [
    pytest.mark.serial,
    pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own processes"),
]


def _cmd(out: Path, *extra: str, ranks: int = 1, scene_sets: list[str] = SETS) -> list[str]:
    sets = [a for s in scene_sets for a in ("--set", s)]
    run = [sys.executable, "-m", "clothfem.cli", "run", str(SCENE), "--out", str(out)]
    run += [*UNSET_STATIC, *sets]
    if ranks == 1:
        return [*run, *extra]
    mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)]
    return [*mpi, sys.executable, "-m", "mpi4py", *run[1:], *extra]


def _rows(out: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((out / "history.csv").open()))


def _run(
    out: Path, *extra: str, ranks: int = 1, scene_sets: list[str] = SETS
) -> subprocess.CompletedProcess:
    res = subprocess.run(
        _cmd(out, *extra, ranks=ranks, scene_sets=scene_sets),
        capture_output=True,
        text=True,
        timeout=900,
        env=ENV,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    return res


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> list[dict[str, str]]:
    out = tmp_path_factory.mktemp("dyn") / "reference"
    _run(out)
    return _rows(out)


def test_dynamic_scene_contact_and_resistance(reference):
    motion = [r for r in reference if r["stage"] == "motion"]
    assert len(motion) >= 3 and math.isclose(float(motion[-1]["angle_deg"]), 3.0)
    for r in reference:
        assert all(math.isfinite(float(r[f"torque_{c}"])) for c in "xyz")
        assert float(r["max_penetration"]) <= 1e-3 * THICKNESS
        assert float(r["min_multiplier"]) >= 0.0
        assert float(r["complementarity"]) <= 1e-12
    # the sleeve resists the flexion: torque about the hinge axis opposes it
    assert all(float(r["torque_flex"]) < 0 for r in motion)


@pytest.mark.skipif(
    subprocess.run(["which", "mpirun"], capture_output=True).returncode != 0, reason="no mpirun"
)
def test_dynamic_scene_same_on_two_ranks(reference, tmp_path):
    """Rank-independent answers. Newton's path (iteration counts, active-set passes) may differ
    with the partition and MUMPS' parallel pivoting; the solutions must not. A step that
    fails on one run and is retried with dt/2 on one side only changes the time grid from
    there on, so the rows are compared up to the first cut-back of either run (measured:
    a 2-rank run may cut a step of the settling that the serial run passes, after which
    the torques differ by the time-step error, ~1-2 %, not by round-off)."""
    _run(tmp_path / "two", ranks=2)
    rows = _rows(tmp_path / "two")
    assert math.isclose(float(rows[-1]["angle_deg"]), 3.0)
    compared = 0
    for a, b in zip(reference, rows, strict=False):
        if int(a["cutbacks"]) or int(b["cutbacks"]):
            break
        assert float(a["time"]) == pytest.approx(float(b["time"]), rel=1e-12)
        assert float(b["torque_flex"]) == pytest.approx(float(a["torque_flex"]), rel=1e-6, abs=1e-9)
        assert int(a["n_active"]) == int(b["n_active"])
        compared += 1
    assert compared >= 3


def _interrupt_and_resume(reference, out: Path, scene_sets: list[str]) -> list[dict[str, str]]:
    """SIGTERM a run once half of the reference's rows are written, resume it; its rows."""
    cmd = _cmd(out, scene_sets=scene_sets)
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    n_ref = len(reference)
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None:
        path = out / "history.csv"
        if path.exists() and path.read_text().count("\n") >= n_ref // 2:
            proc.send_signal(signal.SIGTERM)
            break
        time.sleep(0.05)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 130, err.decode()[-2000:]  # stopped cleanly by the signal
    stopped = _rows(out)
    assert len(stopped) < n_ref
    res = _run(out, "--resume", scene_sets=scene_sets)
    assert "resumed from the checkpoint" in res.stdout
    rows = _rows(out)
    assert len(rows) == n_ref
    return rows


SAME = ("time", "angle_deg", "torque_x", "torque_y", "torque_z", "n_active", "joint_work")


def test_resume_after_sigterm_reproduces_the_history(reference, tmp_path):
    rows = _interrupt_and_resume(reference, tmp_path / "interrupted", SETS)
    for a, b in zip(reference, rows, strict=True):
        for key in (*SAME, "newton_iterations", "kinetic_energy"):
            assert b[key] == a[key], key  # bit for bit


EXPLICIT_SETS = [
    "solver.integrator=explicit",
    "solver.rotary_scale=1000",
    "solver.settle_time=0.05",
    "solver.ramp_time=0.05",
    "body.1.angle_max=3.0",
    "output.interval=0.004",
    "output.checkpoint_every=2",
]


@pytest.mark.parametrize("recheck", [0, 20])
def test_explicit_resume_after_sigterm_reproduces_the_history(tmp_path, recheck):
    """The explicit run (central difference + FILM) checkpoints every 2 rows; stopped by
    SIGTERM and resumed, it gives the uninterrupted rows (the state, velocity, acceleration
    and step size are restored, so the same steps follow). With solver.recheck_every = 20
    the step shrinks at t = 0.0476 s (row 12 of 26, before the checkpoint the resumed run
    starts from), so the resume continues with the shrunk step and its clock."""
    sets = [*EXPLICIT_SETS, f"solver.recheck_every={recheck}"]
    _run(tmp_path / "reference", scene_sets=sets)
    reference = _rows(tmp_path / "reference")
    assert math.isclose(float(reference[-1]["angle_deg"]), 3.0)
    dts = [float(r["dt"]) for r in reference]
    if recheck:
        first = next(i for i, d in enumerate(dts) if d < dts[0])
        assert first < len(reference) // 2 - 1 and min(dts) < dts[0]
    else:
        assert len(set(dts)) == 1
    rows = _interrupt_and_resume(reference, tmp_path / "interrupted", sets)
    for a, b in zip(reference, rows, strict=True):
        for key in (*SAME, "external_work", "kinetic_energy"):
            assert b[key] == a[key], key  # bit for bit
        assert float(b["max_penetration"]) <= 1e-3 * THICKNESS


def test_main_demo_small(tmp_path):
    """`make demo`'s script at a small size: the default scene to 2 degrees; it ends by
    printing the torque at the angle reached, and writes the plot, snapshots and summary."""
    cmd = [sys.executable, str(ROOT / "demos" / "arm_sleeve.py"), "--out", str(tmp_path)]
    cmd += ["--set", "body.1.angle_max=2.0", "--set", "solver.settle_time=0.05"]
    cmd += ["--set", "solver.ramp_time=0.05"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=ENV)
    assert res.returncode == 0, res.stderr[-3000:]
    last = res.stdout.strip().splitlines()[-1]
    assert last.startswith("reached 2.0 deg of 2; torque there = ")
    assert float(last.split("=")[1].split()[0]) > 0
    for name in ("torque_angle.png", "snapshot_settled.png", "snapshot_final.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert '"completed": true' in (tmp_path / "summary.json").read_text()
