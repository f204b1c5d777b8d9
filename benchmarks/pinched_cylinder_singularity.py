"""The pinched cylinder (MacNeal & Harder 1985) under mesh refinement: does the deflection
under the load grow like the point-load singularity of a shear-deformable shell?

Under a point load P a Reissner-Mindlin shell's transverse shear gives a deflection
-P ln(r) / (2 pi k G t) near the load: the exact answer is infinite, and a mesh of size h
sees P ln(1/h) / (2 pi k G t) of it. Each halving of h should then add

    P ln 2 / (2 pi k G t)      (k = 5/6, G = E / (2 (1 + nu)))

to the deflection, whatever the element, once the mesh resolves the rest of the solution.
The thin-shell (Flugge) reference 1.8248e-5 has no such term.

Run:  .venv/bin/python benchmarks/pinched_cylinder_singularity.py --out results
Writes results/pinched_cylinder_singularity.md (the table, printed too).
"""

import argparse
import math
from pathlib import Path

from mpi4py import MPI

from clothfem import verification as V
from clothfem.io import rank0_print
from clothfem.shell import Quadrature

parser = argparse.ArgumentParser()
parser.add_argument("--meshes", type=int, nargs="+", default=[8, 16, 32, 64, 128])
parser.add_argument("--schemes", nargs="+", default=["psri", "mitc9", "sri"])
parser.add_argument("--out", default="results")
args = parser.parse_args()

E, NU, T, K = 3.0e6, 0.3, 3.0, 5.0 / 6.0  # the benchmark's material and thickness
G = E / (2.0 * (1.0 + NU))
SLOPE = 1.0 * math.log(2.0) / (2.0 * math.pi * K * G * T)  # P = 1
REF = V.PINCHED_CYLINDER_REFERENCE

lines = [
    f"Pinched cylinder (octant, n x n cells), {MPI.COMM_WORLD.size} rank(s). Predicted "
    f"growth per halving of h: P ln 2 / (2 pi k G t) = {SLOPE:.4e} "
    f"({100 * SLOPE / REF:.3f} % of the thin-shell reference {REF:g}).",
    "",
    "| element | mesh | w under the load | error vs thin shell | growth since the coarser "
    "mesh / predicted | wall [s] |",
    "|---|---|---|---|---|---|",
]
for scheme in args.schemes:
    prev = None
    for n in args.meshes:
        r = V.run_pinched_cylinder(n=n, quadrature=Quadrature(scheme=scheme))
        growth = "" if prev is None else f"{(r.value - prev) / SLOPE:.2f}"
        lines.append(
            f"| {scheme} | {n}x{n} | {r.value:.6e} | {100 * (r.value / REF - 1):+.3f} % "
            f"| {growth} | {r.wall_time:.1f} |"
        )
        rank0_print(lines[-1])
        prev = r.value
text = "\n".join(lines) + "\n"
if MPI.COMM_WORLD.rank == 0:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "pinched_cylinder_singularity.md").write_text(text)
    print(text)
