"""Progress of a run: a rich bar on a terminal, plain lines elsewhere and under mpirun (whose
ranks see a pseudo-terminal even when the output goes to a file)."""

import sys

from mpi4py import MPI

from clothfem.io import Progress


def _terminal(monkeypatch) -> None:
    monkeypatch.setattr(sys.stdout, "isatty", lambda: True)
    for key in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE"):
        monkeypatch.delenv(key, raising=False)


def test_bar_on_a_terminal(monkeypatch):
    _terminal(monkeypatch)
    p = Progress(label="run", comm=MPI.COMM_SELF)
    assert p._bar is not None
    p.close()


def test_plain_lines_under_mpirun(monkeypatch, capsys):
    _terminal(monkeypatch)
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    p = Progress(label="run", comm=MPI.COMM_SELF)
    assert p._bar is None
    p.update(0.5, "half way")
    line = capsys.readouterr().out
    assert "[##########          ]  50 %" in line and line.rstrip().endswith("half way")
