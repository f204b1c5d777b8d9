"""Does a parallel run repeat itself? Run one scene N times on R ranks and count histories.

Each run's ``history.csv`` is hashed without its timing columns (``t_*``, ``wall_time``,
``elapsed``); the script prints one line per run (hash, Newton iterations per row, last
torque) and the number of different histories. Extra arguments after ``--`` go to the CLI
(``--set`` overrides and PETSc options), e.g. MUMPS's distributed LU instead of the default
redundant solve (docs/parallel.md):

    .venv/bin/python benchmarks/mpi_repeat.py --runs 6 --out results/mpi-repeat \\
        -- -contact_lagrange_pc_type lu
"""

import argparse
import csv
import hashlib
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"


def history_hash(path: Path) -> tuple[str, list[str], str]:
    """Hash of the history without timings, Newton iterations per row, last torque_flex."""
    rows = list(csv.DictReader(path.open()))
    keep = [k for k in rows[0] if not k.startswith("t_") and k not in ("wall_time", "elapsed")]
    text = "\n".join(",".join(r[k] for k in keep) for r in rows)
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    return digest, [r["newton_iterations"] for r in rows], rows[-1]["torque_flex"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(SCENE))
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--out", default="results/mpi-repeat")
    ap.add_argument("extra", nargs="*", help="after --: CLI arguments (--set k=v, PETSc options)")
    args = ap.parse_args()
    if args.runs < 1 or args.ranks < 1:
        ap.error("--runs and --ranks must be integers >= 1")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env["OPENBLAS_NUM_THREADS"] = "1"
    mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", str(args.ranks)]
    hashes = []
    for i in range(1, args.runs + 1):
        out = Path(args.out) / f"run{i}"
        cmd = [*mpi, sys.executable, "-m", "mpi4py", "-m", "clothfem.cli", "run", args.scene]
        cmd += ["--out", str(out), "--overwrite", *args.extra]
        res = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if res.returncode != 0:
            print(f"run {i}: exit {res.returncode}\n{res.stderr[-2000:]}", flush=True)
            continue
        digest, newton, torque = history_hash(out / "history.csv")
        hashes.append(digest)
        print(f"run {i}: {digest}  newton {' '.join(newton)}  torque_flex {torque}", flush=True)
    print(f"{len(hashes)} runs completed, {len(set(hashes))} different histories")


if __name__ == "__main__":
    main()
