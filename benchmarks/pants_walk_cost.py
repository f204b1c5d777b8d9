"""Cost of the pants walk (demos/scenes/pants_walk.toml) against the mesh size, measured.

For every mesh NAROUNDxNALONG: the donning (rank 0, serial particle model; its wall time),
then a short run with the shell on the ranks of the run (``--settle`` s at rest, then
``--walk`` s of walking; pictures and checkpoints off). Printed per mesh: nodes, the stable
step and the step used, steps, the run's wall time (with its set-up), the wall time per
step over the history rows after the first (which holds the set-up: form compilation, the
stable-step estimate) and its split (contact = the FILM body contact, io = fields and rows,
step = the rest: the explicit step's force assembly, self-contact, updates), the donning's
wall time, and the wall time
the scene's settling plus the recorded 2.2 s walk would take at this per-step cost (the
measured per-step time x that run's steps: an estimate, labelled so). Rows go to
``OUT/pants_walk_cost.csv``. ``--self-contact off`` runs the walks without fabric
self-contact (the scene has it on).

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 mpirun -n 2 .venv/bin/python \\
        benchmarks/pants_walk_cost.py --mesh 8x8 16x16 32x32 --settle 0.02 --walk 0.05 \\
        [--self-contact off] --out results/pants-cost
"""

import argparse
import csv
import time
from pathlib import Path

import numpy as np
from _arm_common import parse_mesh
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.io import rank0_print
from clothfem.particle import donning
from clothfem.report import read_history, read_summary
from clothfem.run import run_scene

COMM = MPI.COMM_WORLD
SCENE = Path(__file__).resolve().parents[1] / "demos" / "scenes" / "pants_walk.toml"
FIELDS = ["mesh", "nodes", "ranks", "dt_crit_s", "dt_s", "steps", "run_s", "ms_per_step"]
FIELDS += ["contact_share", "io_share", "step_share", "donning_s", "full_walk_estimate_s"]
FIELDS += ["self_contact"]


def _don(out: Path, mesh: tuple[int, int]) -> float:
    """Donning on rank 0 into ``out``; its wall time [s] (all ranks)."""
    seconds = None
    if COMM.rank == 0:
        t0 = time.perf_counter()
        cells = ["--n-around", str(mesh[0]), "--n-along", str(mesh[1])]
        code = donning.main(["--out", str(out), "--overwrite", *cells])
        seconds = time.perf_counter() - t0 if code == 0 else -1.0
    seconds = COMM.bcast(seconds, root=0)
    if seconds < 0:
        raise SystemExit(f"donning failed on {mesh}")
    return seconds


def _walk(
    out: Path, donned: Path, mesh: tuple[int, int], settle: float, walk: float, selfc: bool
) -> dict:
    """The short run; its row of the table."""
    sets = ["initial.don=false", f"initial.positions='{donned}'", f"mesh.n_around={mesh[0]}"]
    sets += [f"contact.self_contact={'true' if selfc else 'false'}"]
    sets += [f"mesh.n_along={mesh[1]}", "output.png=false", "output.checkpoint_every=0"]
    t_full = scenes.load(SCENE, sets).solver.settle_time + 2.2
    sets += [f"solver.settle_time={settle}", f"solver.duration={settle + walk}"]
    scene = scenes.load(SCENE, sets)
    run_scene(scene, out, comm=COMM, overwrite=True)
    COMM.barrier()
    h, s = read_history(out / "history.csv"), read_summary(out)
    # the rows after the first: the first also holds the set-up (form compilation, the
    # stable-step estimate, the first pictures)
    wall = float(np.sum(h["wall_time"][1:]))
    contact, io = float(np.sum(h["t_contact"][1:])), float(np.sum(h["t_io"][1:]))
    per_step = wall / float(np.sum(h["substeps"][1:]))
    return {
        "dt_crit_s": s["dt_crit"],
        "dt_s": s["dt"],
        "steps": s["steps"],
        "run_s": float(h["elapsed"][-1]),
        "ms_per_step": 1e3 * per_step,
        "contact_share": contact / wall,
        "io_share": io / wall,
        "step_share": 1.0 - (contact + io) / wall,
        "full_walk_estimate_s": per_step * t_full / s["dt"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", nargs="+", type=parse_mesh, default=[(8, 8), (16, 16)])
    parser.add_argument("--settle", type=float, default=0.02, help="time at rest [s]")
    parser.add_argument("--walk", type=float, default=0.05, help="walking time [s]")
    parser.add_argument(
        "--self-contact", choices=("on", "off"), default="on", help="fabric self-contact"
    )
    parser.add_argument("--out", default="results/pants-cost")
    args = parser.parse_args()
    if not (args.walk > 0 and args.settle >= 0):
        parser.error(f"--walk must be > 0 s and --settle >= 0 s, got {args.walk}, {args.settle}")
    out = Path(args.out)
    rows = []
    for mesh in args.mesh:
        name = f"{mesh[0]}x{mesh[1]}"
        t_don = _don(out / f"donned-{name}", mesh)
        row = {
            "mesh": name,
            "ranks": COMM.size,
            "donning_s": t_don,
            "self_contact": args.self_contact,
        }
        row.update(
            _walk(
                out / f"walk-{name}",
                out / f"donned-{name}" / "donned.npz",
                mesh,
                args.settle,
                args.walk,
                args.self_contact == "on",
            )
        )
        row["nodes"] = int(len(np.load(out / f"donned-{name}" / "donned.npz")["X"]))
        rows.append(row)
        rank0_print(" | ".join(f"{k} {row[k]:.4g}" if isinstance(row[k], float) else
                               f"{k} {row[k]}" for k in FIELDS))  # fmt: skip
    if COMM.rank == 0:
        with (out / "pants_walk_cost.csv").open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=FIELDS)
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
