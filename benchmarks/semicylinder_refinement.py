"""The pinched semi-cylinder (Sze, Liu & Lo 2004, problem 3.7) under mesh refinement at
the load levels of its published curve: where does each element's deflection under the
load converge, and how far is that limit from the published (ABAQUS S4R, 40 x 40) value?

For each element and load fraction the deflections on the meshes are extrapolated from
the three finest with an error ~ C n^-p (Richardson: p and the limit w_inf fitted to the
two differences, n the cells per side); the table gives w per mesh, p, w_inf and its
distance from the published value.

Run:  .venv/bin/python benchmarks/semicylinder_refinement.py --out results
Writes results/semicylinder_refinement.md (the table, printed too).
"""

import argparse
from pathlib import Path

from mpi4py import MPI
from scipy.optimize import brentq

from clothfem import verification as V
from clothfem.io import rank0_print
from clothfem.shell import Quadrature

parser = argparse.ArgumentParser()
parser.add_argument("--meshes", type=int, nargs="+", default=[12, 16, 24, 32, 48])
parser.add_argument("--schemes", nargs="+", default=["mitc9", "psri"])
parser.add_argument("--fractions", type=float, nargs="+", default=[0.1, 0.25, 0.5])
parser.add_argument("--out", default="results")
args = parser.parse_args()
if len(args.meshes) < 3 or sorted(args.meshes) != args.meshes:
    parser.error("--meshes: at least three, increasing")
bad = [f for f in args.fractions if f not in V.SEMICYLINDER_REFERENCE]
if bad:
    parser.error(f"--fractions: published at {sorted(V.SEMICYLINDER_REFERENCE)}, not {bad}")


def extrapolate(n: list[int], w: list[float]) -> tuple[float, float] | None:
    """(p, w_inf) of w_n = w_inf - C n^-p through the three points, None when no p in
    (0.05, 12) fits (the differences change sign or do not shrink like a power)."""
    d1, d2 = w[1] - w[0], w[2] - w[1]
    if d1 == 0 or d2 / d1 <= 0:
        return None

    def gap(p: float) -> float:
        return (n[0] ** -p - n[1] ** -p) / (n[1] ** -p - n[2] ** -p) - d1 / d2

    try:
        p = brentq(gap, 0.05, 12.0)
    except ValueError:
        return None
    c = d2 / (n[1] ** -p - n[2] ** -p)
    return p, w[2] + c * n[2] ** -p


heads = " | ".join(f"{n}x{n}" for n in args.meshes)
lines = [
    f"Pinched semi-cylinder, -w under the load, n x n cells, {MPI.COMM_WORLD.size} rank(s).",
    "",
    f"| element | P / Pmax | published | {heads} | p | w_inf | w_inf vs published |",
    "|---|---|---|" + "---|" * len(args.meshes) + "---|---|---|",
]
for scheme in args.schemes:
    w: dict[float, list[float]] = {f: [] for f in args.fractions}
    for n in args.meshes:
        pts = V.run_semicylinder(
            n=n, fractions=tuple(args.fractions), quadrature=Quadrature(scheme=scheme)
        )
        for pt in pts:
            w[pt.fraction].append(pt.result.value)
        rank0_print(f"{scheme} {n}x{n}: " + ", ".join(f"{p.result.value:.6f}" for p in pts)
                    + f" ({pts[-1].result.wall_time:.1f} s)")  # fmt: skip
    for f in args.fractions:
        ref = V.SEMICYLINDER_REFERENCE[f]
        fit = extrapolate(args.meshes[-3:], w[f][-3:])
        cells = " | ".join(f"{x:.6f} ({100 * (x / ref - 1):+.2f} %)" for x in w[f])
        tail = "- | - | -" if fit is None else (
            f"{fit[0]:.2f} | {fit[1]:.6f} | {100 * (fit[1] / ref - 1):+.2f} %"
        )  # fmt: skip
        lines.append(f"| {scheme} | {f:g} | {ref:g} | {cells} | {tail} |")
text = "\n".join(lines) + "\n"
rank0_print(text)
if MPI.COMM_WORLD.rank == 0:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "semicylinder_refinement.md").write_text(text)
