"""Where the arm-sleeve step time goes, and the 2-rank speed-up (issue 5, item 7).

Runs a short version of the scene (dynamic settling 0.05 s, then `--angle` degrees of
flexion) serially and under `mpirun -n 2`, on each mesh of `--meshes`, and reads the
per-row timers the runner writes to `history.csv` (rank 0's share):

* assembly: fabric residual and tangent (UFL forms, the nodal chain rule P^T K P, inertia);
* contact: projections on the ellipsoids, friction, building the bordered KKT matrix;
* solve: the MUMPS factorisation and solve of the bordered system;
* io: XDMF fields and checkpoints; other = wall time - the rest (CSV, PNG, Python glue).

Speed-up = serial wall / 2-rank wall of the same command; since a different partition can
change Newton's path (iterations, cut-backs), the table also gives the time per Newton
iteration and its ratio. The 2-rank run is made twice: with the default direct solve
(redundant: every rank factors the gathered matrix, clothfem.petsc_options) and with
MUMPS's distributed LU (``-contact_lagrange_pc_type lu``). Writes `OUT/arm_perf.csv` and
`OUT/arm_perf.md`.

    .venv/bin/python benchmarks/arm_perf.py --out results/arm-perf [--meshes 8x10 16x20]
    .venv/bin/python benchmarks/arm_perf.py --integrator explicit --meshes 16x20 24x30 32x40 \
        --angle 10 --out results/arm-perf-explicit

With ``--integrator explicit`` (central difference + FILM: no linear solve) the split is
contact / io / other (other = the explicit step itself: forces, lumped solve, the
predictor) and there is one 2-rank run per mesh. ``--kernels numpy compiled`` runs every
explicit case with each implementation of the FILM correction (``contact.kernel``) and
reports the contact-layer and wall-time ratios of the two in the same run (``--repeat N``:
every case N times, the row of median wall time, ratios of medians):

    .venv/bin/python benchmarks/arm_perf.py --integrator explicit --meshes 16x20 24x30 32x40 \
        --angle 10 --kernels numpy compiled --repeat 3 --out results/arm-perf-explicit
"""

import argparse
import csv
import os
import subprocess
import sys
from pathlib import Path

from clothfem.report import read_history, read_summary

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve.toml"
PARTS = ("t_assembly", "t_contact", "t_solve", "t_io")


# the direct solve of the contact system on 2 ranks: the default, and MUMPS's distributed LU
SOLVES = {"redundant": [], "distributed": ["-contact_lagrange_pc_type", "lu"]}


def run(
    out: Path, mesh: str, angle: float, ranks: int, solve: str, integrator: str, kernel: str
) -> dict:
    na, nl = mesh.split("x")
    sets = [
        f"solver.integrator={integrator}",
        f"mesh.n_around={na}",
        f"mesh.n_along={nl}",
        "solver.settle_time=0.05",
        "solver.ramp_time=0.05",
        f"body.1.angle_max={angle}",
        "output.png=false",
    ]
    sets += [f"contact.kernel={kernel}"] if integrator == "explicit" else []
    cmd = [
        sys.executable,
        "-m",
        "clothfem.cli",
        "run",
        str(SCENE),
        "--out",
        str(out),
        "--overwrite",
    ]
    cmd += [a for s in sets for a in ("--set", s)]
    cmd += SOLVES[solve] if integrator == "newmark" else []
    if ranks > 1:
        mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)]
        cmd = [*mpi, sys.executable, "-m", "mpi4py", *cmd[1:]]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env["OPENBLAS_NUM_THREADS"] = "1"
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    h, s = read_history(out / "history.csv"), read_summary(out)
    wall = float(s.get("wall_time", h["elapsed"][-1]))
    row = {"mesh": mesh, "ranks": ranks, "solve": solve if ranks > 1 else "serial"}
    if integrator == "explicit":  # no linear solves: the 2-rank row has no solve variant
        row["solve"] = "explicit" + ("" if ranks > 1 else ", serial")
        row["kernel"] = kernel
    row |= {"exit": res.returncode, "wall_s": wall}
    row["steps"] = int(s.get("steps", len(h["time"])))
    row["newton"] = int(h["newton_iterations"].sum()) if "newton_iterations" in h else 0
    row["final_angle"] = float(h["angle_deg"][-1])
    parts = {p: float(h[p].sum()) if p in h else 0.0 for p in PARTS}
    for p in PARTS:
        row[p[2:] + "_s"] = parts[p]
        row[p[2:] + "_pct"] = 100 * parts[p] / wall
    row["other_pct"] = 100 * (wall - sum(parts.values())) / wall
    row["ms_per_newton"] = 1000 * wall / max(row["newton"], 1) if row["newton"] else 0.0
    row["ms_per_step"] = 1000 * wall / max(row["steps"], 1)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/arm-perf")
    ap.add_argument("--meshes", nargs="+", default=["8x10", "16x20"])
    ap.add_argument("--angle", type=float, default=5.0, help="flexion of the short run [deg]")
    ap.add_argument(
        "--integrator",
        choices=("newmark", "explicit"),
        default="newmark",
        help="solver.integrator (explicit: no linear solve, one 2-rank run per mesh)",
    )
    ap.add_argument(
        "--kernels",
        nargs="+",
        choices=("compiled", "numpy"),
        default=["compiled"],
        help="explicit: run every case with each FILM implementation (contact.kernel)",
    )
    ap.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="runs of every case; its row is the run of median wall time, with the min and "
        "max (wall_min_s, wall_max_s), and ratios are of medians (run times vary by 10-25 %% "
        "from run to run on a shared machine)",
    )
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error(f"--repeat must be >= 1, got {args.repeat}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    kernels = args.kernels if args.integrator == "explicit" else ["compiled"]

    def median_run(path: Path, *case) -> dict:
        runs = [
            run(path.with_name(path.name + (f"_r{i}" if args.repeat > 1 else "")), *case)
            for i in range(args.repeat)
        ]
        walls = sorted(r["wall_s"] for r in runs)
        row = sorted(runs, key=lambda r: r["wall_s"])[(len(runs) - 1) // 2]
        return row | {"wall_min_s": walls[0], "wall_max_s": walls[-1], "runs": len(runs)}

    for mesh in args.meshes:
        for kernel in kernels:
            tag = f"_{kernel}" if len(kernels) > 1 else ""
            case = (mesh, args.angle, 1, "redundant", args.integrator, kernel)
            one = median_run(out / f"{mesh}_np1{tag}", *case)
            rows.append(one)
            solves = list(SOLVES) if args.integrator == "newmark" else ["redundant"]
            for solve in solves:
                path = out / f"{mesh}_np2_{solve}{tag}"
                two = median_run(path, mesh, args.angle, 2, solve, args.integrator, kernel)
                two["speedup"] = one["wall_s"] / two["wall_s"]
                if one["newton"] and two["newton"]:
                    two["speedup_per_newton"] = one["ms_per_newton"] / two["ms_per_newton"]
                rows.append(two)
            for r in rows[-(1 + len(solves)) :]:
                print({k: round(v, 3) if isinstance(v, float) else v for k, v in r.items()})
    if len(kernels) > 1:  # the same case with the other kernel: contact and wall ratios
        base = {(r["mesh"], r["ranks"]): r for r in rows if r.get("kernel") == kernels[0]}
        for r in rows:
            b = base[(r["mesh"], r["ranks"])]
            r[f"contact_vs_{kernels[0]}"] = r["contact_s"] / b["contact_s"]
            r[f"wall_vs_{kernels[0]}"] = r["wall_s"] / b["wall_s"]
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "arm_perf.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    cols = ["mesh", "ranks", "solve", "kernel", "wall_s", "wall_min_s", "wall_max_s", "runs"]
    cols += ["steps", "newton", "ms_per_newton"]
    cols += ["ms_per_step", "assembly_pct", "contact_s"]
    cols += ["contact_pct", "solve_pct", "io_pct", "other_pct", "speedup", "speedup_per_newton"]
    cols += [c for c in keys if c.startswith(("contact_vs_", "wall_vs_"))]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        cells = [r.get(c, "") for c in cols]
        lines.append(
            "| " + " | ".join(f"{c:.3g}" if isinstance(c, float) else str(c) for c in cells) + " |"
        )
    (out / "arm_perf.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
