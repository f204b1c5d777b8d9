"""How the PSRI weight constant c (alpha = min(1, c t^2 / h^2), `element.psri_factor`) moves
the shell benchmarks: does a larger full-rule share lock?

Run:  .venv/bin/python benchmarks/psri_weight.py --factors 1 10 100 --out results
Writes results/psri_weight.md (the table, printed too). Each cell is value / reference
(the semi-cylinder: -w at P = Pmax / 1.71505; the locking cylinder: the ratio to SRI, which
does not lock in membrane or shear).
"""

import argparse
import time
from pathlib import Path

from mpi4py import MPI

from clothfem import verification as V
from clothfem.io import rank0_print
from clothfem.shell import Quadrature

parser = argparse.ArgumentParser()
parser.add_argument("--factors", type=float, nargs="+", default=[1.0, 10.0, 100.0])
parser.add_argument("--out", default="results")
args = parser.parse_args()


def ratio(r) -> str:
    return f"{r.value / r.reference:.4f}"


def cases():
    """(label, function of a Quadrature returning the cell text)."""
    out = []
    for s in (1000.0, 10000.0):
        for n in (8, 16):
            out.append(
                (
                    f"clamped plate t/a = 1/{s:g}, {n}x{n}",
                    lambda q, n=n, s=s: ratio(
                        V.run_clamped_plate(n=n, slenderness=s, quadrature=q)
                    ),
                )
            )
    for n in (8, 16):
        out.append(
            (f"Scordelis-Lo, {n}x{n}", lambda q, n=n: ratio(V.run_scordelis_lo(n=n, quadrature=q)))
        )
        out.append(
            (f"hemisphere, {n}x{n}", lambda q, n=n: ratio(V.run_hemisphere(n=n, quadrature=q)))
        )
        out.append(
            (
                f"pinched cylinder t/R = 1/100, {n}x{n}",
                lambda q, n=n: ratio(V.run_pinched_cylinder(n=n, quadrature=q)),
            )
        )
    sri = Quadrature(scheme="sri")
    for t in (0.3, 0.03):
        out.append(
            (
                f"pinched cylinder t/R = 1/{300 / t:g}, 16x16, / SRI",
                lambda q, t=t: "{:.4f}".format(
                    V.run_pinched_cylinder(n=16, thickness=t, quadrature=q).value
                    / V.run_pinched_cylinder(n=16, thickness=t, quadrature=sri).value
                ),
            )
        )
    out.append(
        (
            "arc bending L/t = 100, 8 cells: L2 error",
            lambda q: f"{V.run_arc_bending(nx=8, quadrature=q).value:.2e}",
        )
    )
    out.append(
        (
            "pinched semi-cylinder 16x16, P = Pmax",
            lambda q: ratio(V.run_semicylinder(n=16, quadrature=q)[-1].result),
        )
    )
    return out


factors = args.factors
lines = [
    f"PSRI weight study, {MPI.COMM_WORLD.size} rank(s), {time.strftime('%Y-%m-%d')}: value / "
    "reference per psri_factor c.",
    "",
    "| case | " + " | ".join(f"c = {c:g}" for c in factors) + " |",
    "|---|" + "---|" * len(factors),
]
for label, fn in cases():
    cells = []
    for c in factors:
        try:
            cells.append(fn(Quadrature(psri_factor=c)))
        except RuntimeError as err:  # a divergence is a result
            cells.append(f"failed ({str(err)[:40]})")
    lines.append(f"| {label} | " + " | ".join(cells) + " |")
    rank0_print(lines[-1])
text = "\n".join(lines)
rank0_print(text)
if MPI.COMM_WORLD.rank == 0:
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "psri_weight.md").write_text(text + "\n")
