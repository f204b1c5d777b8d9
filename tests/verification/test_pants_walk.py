"""The pants walk (demos/scenes/pants_walk.toml) at a small size, serially and on 2 ranks:
the pants donned by the particle model onto the recording's first frame (8 x 6 cells), the
shell started from the donned positions, 0.1 s of walking after 0.15 s of settling.

- every node starts the walk outside the body (the donning's check, in donned.npz);
- the shell starts from the donned positions: the run's log says so, and the fabric is in
  contact with the body from the first row (the pants sit on the legs, not in the pattern);
- the gait events of the recording are on the run's clock (settle 0.15 s + the first right
  foot strike at 0.1405 s of the file);
- the right shank and foot carry contact forces once the walk starts (a knee torque).
The moving-knee measure itself is verified in tests/unit/test_torque_measure.py.
"""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.particle import donning
from clothfem.report import read_history, read_summary
from clothfem.run import run_scene

COMM = MPI.COMM_WORLD
SCENE = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "pants_walk.toml"


def test_pants_walk_small(tmp_path):
    base = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))
    don = base / "donned"
    code = None
    if COMM.rank == 0:
        code = donning.main(["--out", str(don), "--n-around", "8", "--n-along", "6"])
    assert COMM.bcast(code, root=0) == 0
    gap = np.load(don / "donned.npz")["gap"]
    assert gap.min() >= -1e-6  # every node outside the body at the start of the walk
    sets = [
        f"initial.positions={don / 'donned.npz'}",
        "mesh.n_around=8",
        "mesh.n_along=6",
        "solver.duration=0.25",
        "output.png=false",
        "output.checkpoint_every=0",
    ]
    out = run_scene(scenes.load(SCENE, sets), base / "walk", comm=COMM)
    COMM.barrier()
    s = read_summary(out)
    assert s["completed"] and any(x.startswith("initial state: the positions") for x in s["built"])
    first = [e for e in s["gait_events"] if e["label"] == "Foot Strike"][0]
    assert first["context"] == "Right" and first["time"] == pytest.approx(0.15 + 0.1405, abs=1e-3)
    h = read_history(out / "history.csv")
    assert np.all(h["n_active"] > 0)  # on the body from the first row
    assert np.all(np.isfinite(h["torque_flex"]))
    assert np.any(h["torque_mag"][h["stage"] == "motion"] > 0.0)
