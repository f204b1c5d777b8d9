"""The run's history file when a run is resumed."""

import csv

import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.history import NAMES
from clothfem.io import ResultWriter
from clothfem.shell import FabricMaterial, ShellModel


@pytest.mark.serial
def test_resume_of_an_older_history_gets_todays_columns(tmp_path):
    """A history written before a column existed (here without ``tissue_indentation``, and
    with a column that no longer exists) is continued with today's columns: the kept rows
    keep their values, the new column is empty in them, the old column is kept."""
    old = [n for n in NAMES if n != "tissue_indentation"] + ["retired"]
    with open(tmp_path / "history.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=old)
        w.writeheader()
        for i in range(3):
            w.writerow({"increment": i, "time": 0.1 * i, "retired": 7})
    sm = meshes.strip(MPI.COMM_WORLD, length=1.0, width=0.1, nx=2, ny=1)
    mat = FabricMaterial.isotropic(E=1e6, nu=0.0, rho=1.0)
    model = ShellModel(sm, material=mat, thickness=0.01)
    with ResultWriter(tmp_path, model, keep_rows=2) as writer:
        writer.append_row({"increment": 2, "time": 0.25, "tissue_indentation": 1e-4})
    with open(tmp_path / "history.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
    assert reader.fieldnames == [*NAMES, "retired"]
    assert [r["time"] for r in rows] == ["0.0", "0.1", "0.25"]
    assert [r["tissue_indentation"] for r in rows] == ["", "", "0.0001"]
    assert [r["retired"] for r in rows] == ["7", "7", ""]
