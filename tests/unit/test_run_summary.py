"""summary.json is complete on every rank when the run returns (rank 0 writes it)."""

from __future__ import annotations

import json
import time
from pathlib import Path

from mpi4py import MPI

from clothfem import run

COMM = MPI.COMM_WORLD


def test_summary_on_disk_for_every_rank(tmp_path, monkeypatch):
    """Rank 0 is slowed down while writing; every rank must still read the whole summary
    as soon as the write returns (fails without the barrier on 2 ranks: an absent file)."""
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "run"
    dumps = json.dumps

    def slow_dumps(*args, **kwargs):
        time.sleep(0.5)
        return dumps(*args, **kwargs)

    monkeypatch.setattr(run.json, "dumps", slow_dumps)
    summary = {"completed": True, "steps": 3}
    run._write_summary(out, summary, COMM)
    assert json.loads((out / "summary.json").read_text()) == summary
    assert not (out / "summary.json.tmp").exists()
