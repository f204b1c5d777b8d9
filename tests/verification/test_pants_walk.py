"""The pants walk (demos/scenes/pants_walk.toml) at a small size, serially and on 2 ranks:
the scene dons the pants with the particle model onto the recording's first frame (8 x 6
cells) and starts the shell from the donned positions, 0.1 s of walking after 0.15 s of
settling.

- every node starts the walk outside the body (the donning's check, in donned.npz);
- the shell starts from the donned positions: the run's log says so, and the fabric is in
  contact with the body from the first row (the pants sit on the legs, not in the pattern);
- the gait events of the recording are on the run's clock (settle 0.15 s + the first right
  foot strike at 0.1405 s of the file);
- the right shank and foot carry contact forces once the walk starts (a knee torque).
The moving-knee measure itself is verified in tests/unit/test_torque_measure.py.
"""

import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem import torque_table
from clothfem.particle import donning
from clothfem.report import read_history, read_summary, report_markdown
from clothfem.run import run_scene

COMM = MPI.COMM_WORLD
SCENE = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "pants_walk.toml"


@pytest.fixture(scope="module")
def donned(tmp_path_factory) -> Path:
    """The coarse donning (8 x 6 cells), run once on rank 0."""
    base = tmp_path_factory.mktemp("donned") if COMM.rank == 0 else None
    base = Path(COMM.bcast(str(base) if base is not None else None, root=0))
    code = None
    if COMM.rank == 0:
        code = donning.main(
            ["--out", str(base), "--overwrite", "--n-around", "8", "--n-along", "6"]
        )
    assert COMM.bcast(code, root=0) == 0
    return base / "donned.npz"


def test_pants_walk_small(tmp_path):
    """The scene as shipped (but smaller): it dons the pants itself, then walks."""
    base = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))
    sets = [
        "mesh.n_around=8",
        "mesh.n_along=6",
        "solver.duration=0.25",
        "output.png=false",
        "output.checkpoint_every=0",
    ]
    out = run_scene(scenes.load(SCENE, sets), base / "walk", comm=COMM)
    COMM.barrier()
    s = read_summary(out)
    assert s["completed"] and "initial state: the positions of the donning" in " ".join(s["built"])
    gap = np.load(out / "donned.npz")["gap"]
    assert gap.min() >= -1e-6  # every node outside the body at the start of the walk
    assert s["donning"]["inside_end"] == 0 and s["donning"]["self_intersections"] == 0
    first = [e for e in s["gait_events"] if e["label"] == "Foot Strike"][0]
    assert first["context"] == "Right" and first["time"] == pytest.approx(0.15 + 0.1405, abs=1e-3)
    h = read_history(out / "history.csv")
    assert np.all(h["n_active"] > 0)  # on the body from the first row
    assert np.all(np.isfinite(h["torque_flex"]))
    assert np.any(h["torque_mag"][h["stage"] == "motion"] > 0.0)
    # the scene's [[torques]]: the left knee and both hips, a row each per history row
    t = _torques(out)
    assert set(t) == {"left_knee", "right_hip", "left_hip"}
    for rows in t.values():
        assert np.array_equal(rows["time"], h["time"]) and np.all(np.isfinite(rows["torque_flex"]))
    assert np.any(t["right_hip"]["torque_mag"][h["stage"] == "motion"] > 0.0)
    assert set(s["torques"]) == set(t)
    if COMM.rank == 0:
        text = report_markdown(out)
        assert all(f"| {name} |" in text for name in t)
        torque_table.plot(out, out / "torques.png", primary="R_shank", title="walk")
        assert (out / "torques.png").stat().st_size > 10_000


def _torques(out: Path) -> dict[str, dict[str, np.ndarray]]:
    """torques.csv as {name: {column: array}}."""
    import csv

    with (out / "torques.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    cols = ("time", "torque_x", "torque_y", "torque_z", "torque_mag", "torque_flex")
    return {
        name: {c: np.array([float(r[c]) for r in rows if r["name"] == name]) for c in cols}
        for name in dict.fromkeys(r["name"] for r in rows)
    }


def test_pants_walk_torque_table(tmp_path, donned):
    """[[torques]] against the history: a copy of the [contact] measure gives the history's
    torque row for row, and two 'all'-node measures about the origin and about P differ by
    P x R (Varignon), R the history's resultant of the contact forces on the body."""
    base = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))
    data = tomllib.loads(SCENE.read_text())
    P = [0.1, -0.2, 0.3]
    data["torques"] = [
        {"name": "copy", "segment": "R_shank", "aj": "touching", "torque_with": ["R_foot"],
         "flexion_frame": "R_thigh"},
        {"name": "about_o", "segment": "R_shank", "aj": "all", "torque_point": [0.0, 0.0, 0.0]},
        {"name": "about_p", "segment": "R_shank", "aj": "all", "torque_point": P},
    ]  # fmt: skip
    sets = [
        "initial.don=false",
        f"initial.positions={donned}",
        "mesh.n_around=8",
        "mesh.n_along=6",
        "solver.duration=0.2",
        "output.png=false",
        "output.checkpoint_every=0",
        "contact.self_contact=false",
    ]
    scene = scenes.validate(scenes.apply_overrides(data, sets), base=SCENE.parent)
    out = run_scene(scene, base / "walk", comm=COMM)
    COMM.barrier()
    h, t = read_history(out / "history.csv"), _torques(out)
    for c in ("torque_x", "torque_y", "torque_z", "torque_flex"):
        assert np.array_equal(t["copy"][c], h[c])
    R = np.column_stack([h[f"resultant_{k}"] for k in "xyz"])
    tau_o, tau_p = ([t[n][f"torque_{k}"] for k in "xyz"] for n in ("about_o", "about_p"))
    diff = np.column_stack(tau_o) - np.column_stack(tau_p)
    scale = np.abs(np.column_stack(tau_o)).max()
    assert scale > 0 and np.allclose(diff, np.cross(P, R), rtol=0, atol=1e-12 * scale)


@pytest.mark.serial
def test_particle_walk_small(tmp_path, donned):
    """The same walk with the particle fabric (python -m clothfem.particle.walk): one row per
    0.01 s, on the body from the first row, the events on the run's clock, a knee torque
    once the walk starts."""
    from clothfem.particle import walk

    sets = ["mesh.n_around=8", "mesh.n_along=6", "solver.duration=0.25"]
    args = ["--donned", str(donned), "--out", str(tmp_path / "p")]
    assert walk.main([*args, *[a for kv in sets for a in ("--set", kv)]]) == 0
    h = read_history(tmp_path / "p" / "history.csv")
    assert len(h["time"]) == 25 and np.all(h["n_active"] > 0)
    assert np.all(np.isfinite(h["torque_flex"]))
    assert np.any(h["torque_mag"][h["stage"] == "motion"] > 0.0)
    events = (tmp_path / "p" / "events.csv").read_text().splitlines()
    assert events[0] == "time_s,context,label" and events[1].startswith("0.2905")
    assert walk.main([*args, "--set", "solver.duration=0.1"]) == 2  # the folder is not empty
