"""The same answers on 1 and 2 MPI ranks: run a demo under mpirun and compare."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

from clothfem import verification as V

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.serial
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own mpirun")
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_rollup_same_on_two_ranks(tmp_path):
    serial, _ = V.run_rollup(nx=10, ny=1, steps=10)
    cmd = [
        "mpirun",
        "--allow-run-as-root",
        "--oversubscribe",
        "-n",
        "2",
        sys.executable,
        "-m",
        "mpi4py",
        str(ROOT / "demos" / "rollup_strip.py"),
        "--out",
        str(tmp_path),
        "--nx",
        "10",
        "--ny",
        "1",
        "--steps",
        "10",
    ]
    # a child mpirun must not inherit this (singleton) MPI process's environment
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr[-2000:]
    out = res.stdout
    value = float(re.search(r"\|tip - root\| / L = (\S+)", out).group(1))
    assert abs(value - serial.error) <= 1e-2 * serial.error  # printed with 3 digits
    assert (tmp_path / "history.csv").read_text().count("\n") == 11


_ONE_RANK_FAILS = """
from mpi4py import MPI
from clothfem.run_output import end_together
from clothfem.static import SolverDivergence
comm = MPI.COMM_WORLD
kind = {kind!r}
try:
    try:
        if kind == "bug" and comm.rank == 1:
            raise RuntimeError("only on rank 1")
        if kind == "shared":
            raise SolverDivergence("on every rank")
    finally:
        {closing}
        print(f"rank {{comm.rank}} past the barrier", flush=True)
finally:
    comm.allreduce(1)  # like the closing writes after a runner (XDMF close, summary)
"""


@pytest.mark.serial
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own mpirun")
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
@pytest.mark.parametrize("kind", ["bug", "shared"])
def test_an_error_on_one_rank_aborts_instead_of_hanging(tmp_path, kind):
    """The scene runners' closing barrier: an error raised on one rank alone aborts the job
    with a message naming the rank, before the failing rank reaches collective calls the
    others are not in (mismatched collectives are undefined behaviour; they hung a 2-rank
    explicit run); an error every rank raises (a solver stop) passes the
    barrier and propagates normally on every rank."""
    script = tmp_path / "fail.py"
    script.write_text(_ONE_RANK_FAILS.format(kind=kind, closing="end_together(comm)"))
    cmd = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", "2", sys.executable]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    res = subprocess.run([*cmd, str(script)], capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode != 0
    if kind == "bug":
        assert "rank 1 stopped alone (RuntimeError: only on rank 1)" in res.stderr
        assert "past the barrier" not in res.stdout  # rank 0 never got through
    else:
        assert "stopped alone" not in res.stderr
        assert res.stdout.count("past the barrier") == 2
        # (mpirun may kill the second rank before it prints its traceback)
        assert "SolverDivergence: on every rank" in res.stderr
