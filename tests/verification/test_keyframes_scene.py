"""A body moved by keyframes through the dynamic runner: the arm-sleeve CI scene with its
forearm hinge replaced by keys sampled from the same hinge gives the hinge run's contact
forces and Eq. 28 torque (about the elbow over all nodes), serially and on 2 ranks."""

import tomllib
from pathlib import Path

import numpy as np
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.report import read_history
from clothfem.run import run_scene
from clothfem.scene_body import body_motions
from clothfem.spec import Scene

COMM = MPI.COMM_WORLD
CI = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "arm_sleeve_ci.toml"
SETS = [
    "solver.integrator=explicit",
    "solver.rotary_scale=1000",
    "solver.settle_time=0.05",
    "solver.ramp_time=0.05",
    "body.1.angle_max=3.0",
    "output.interval=0.004",
    "output.checkpoint_every=0",
    "output.png=false",
    "contact.aj=all",
    "contact.torque_point=[0.3, 0.0, 0.0]",
]


def _scenes() -> tuple[Scene, Scene]:
    from scipy.spatial.transform import Rotation

    data = scenes.apply_overrides(
        scenes.remove_keys(tomllib.loads(CI.read_text()), ["solver.steps", "contact.increments"]),
        SETS,
    )
    data["contact"].pop("torque_segment")
    hinged = scenes.validate(data, base=CI.parent)
    hinge = body_motions(hinged)[1]
    times = np.linspace(0.0, hinge.t_end, 13)  # every 0.25 deg
    poses = [hinge.pose(t) for t in times]
    turns = [Rotation.from_matrix(p.rotation @ poses[0].rotation.T).as_rotvec() for p in poses]
    arm = data["body"][1]
    for k in ("joint", "hinge_axis", "angle_max", "omega", "centre"):
        arm.pop(k, None)
    arm.update(
        type="keyframes",
        times=times.tolist(),
        centres=[p.centre.tolist() for p in poses],
        turns=[t.tolist() for t in turns],
    )
    return hinged, scenes.validate(data, base=CI.parent)


def test_keyframes_sampled_from_the_hinge_give_its_forces(tmp_path):
    """Between keys 0.25 deg apart the played pose is the hinge's to about 1e-10 m (the
    splines' fourth-order error, tests/unit/test_keyframes.py), far below the 1 mm
    fabric; the forces then agree to 1e-8 of the largest value (4e-10 measured serially on
    2026-12-02: the pose error passed through the contact over the run's 300 steps); a
    forearm that does not move, or moves at another rate, is off by order one."""
    base = Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))
    hinged, keyed = _scenes()
    a = read_history(run_scene(hinged, base / "hinge", comm=COMM) / "history.csv")
    b = read_history(run_scene(keyed, base / "keys", comm=COMM) / "history.csv")
    assert np.array_equal(a["time"], b["time"]) and np.array_equal(a["n_active"], b["n_active"])
    for cols in (
        ("torque_x", "torque_y", "torque_z"),
        ("resultant_x", "resultant_y", "resultant_z"),
    ):
        x, y = (np.column_stack([h[c] for c in cols]) for h in (a, b))
        assert np.abs(x - y).max() <= 1e-8 * np.abs(x).max()
    moving = a["stage"] == "motion"
    assert moving.any() and np.abs(a["torque_y"][moving]).max() > 0.0
