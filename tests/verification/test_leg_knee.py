"""The pants check scene (demos/scenes/leg_knee.toml): one loose pant leg on a thigh and a
shank, the knee flexed. On 8 x 10 cells to 8 degrees, serially and on 2 ranks:

- while the leg rests, the pant leg (radius 0.09 m) hangs along the leg under gravity
  without touching the ellipsoids (radii 0.066 / 0.063 m; crimped cotton with nu = 0 does
  not contract under its axial weight): no contact node, torque exactly 0;
- as the shank turns, its surface meets the fabric (the far end of the shank, 0.43 m from
  the knee, has to move the 24-27 mm gap sideways: from about 3.2 degrees on), and the knee
  torque about the hinge axis resists the flexion (-tau . axis > 0) at the end.
"""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.report import read_history
from clothfem.run import run_scene

COMM = MPI.COMM_WORLD
SCENE = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "leg_knee.toml"


def test_leg_knee_check_scene(tmp_path):
    out = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0)) / "leg"
    sets = [
        "mesh.n_around=8",
        "mesh.n_along=10",
        "body.1.angle_max=8",
        "output.png=false",
        "output.checkpoint_every=0",
    ]
    run_scene(scenes.load(SCENE, sets), out, comm=COMM)
    COMM.barrier()
    h = read_history(out / "history.csv")
    settle = h["stage"] == "settle"
    assert settle.sum() >= 19 and np.all(h["n_active"][settle] == 0)
    assert np.all(h["torque_mag"][settle] == 0.0)
    first = float(h["angle_deg"][np.flatnonzero(h["n_active"] > 0)[0]])
    assert 2.0 < first < 8.0  # contact starts with the flexion, not before
    assert h["angle_deg"][-1] == pytest.approx(8.0)
    assert -h["torque_flex"][-1] > 0.0 and h["n_active"][-1] > 0
