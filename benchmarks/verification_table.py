"""Shell verification table (docs/results/verification.md): error and wall time per benchmark
and mesh, and the locking measurements behind the element choice.

Run:  make verification   (writes results/verification.md and prints it)
Wall times include the one-off JIT compilation of each distinct form when it is not cached.
"""

import argparse
import math
import time
from pathlib import Path

from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem import verification as V
from clothfem.io import rank0_print
from clothfem.shell import Clamp, EdgeTraction, FabricMaterial, Quadrature, ShellModel
from clothfem.static import NewtonSolver

parser = argparse.ArgumentParser()
parser.add_argument("--out", default="results")
args, _ = parser.parse_known_args()

rows = []
for nx, ny in ((10, 1), (20, 2)):
    res, _ = V.run_rollup(nx=nx, ny=ny, steps=10)
    rows.append(res)
for k in (1.0, 2.0, 4.0):
    for nx, ny in ((10, 1), (20, 2)):
        rows.extend(V.run_elastica(k=k, nx=nx, ny=ny))
for n in (8, 16):
    rows.append(V.run_scordelis_lo(n=n))
rows.append(V.run_scordelis_lo(n=16, half=True))
arc = [V.run_arc_bending(nx=n) for n in (4, 8, 16)]
rows.extend(arc)


def locking_ratio(*, quadrature, nx, slender):
    """Tip deflection / Euler-Bernoulli P L^3 / 3 EI of a clamped strip, small load."""
    L, b, E = 1.0, 0.1, 1.0e6
    t = L / slender
    sm = meshes.strip(MPI.COMM_WORLD, length=L, width=b, nx=nx, ny=1)
    P = 1e-6 * E * b * t**3 / 12 / L**2
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=0.0),
        thickness=t,
        loads=[EdgeTraction("tip", (0.0, 0.0, P / b))],
        supports=[Clamp("root")],
        quadrature=quadrature,
    )
    NewtonSolver(model, prefix="lock_").solve(1.0)
    w = model.displacement_at((L, 0.0, 0.0))[2]
    return w / (P * L**3 / (3 * E * b * t**3 / 12))


def scordelis_full(n):
    """Scordelis-Lo with full 3x3 quadrature for membrane and shear too (membrane locking)."""
    import clothfem.verification as mod

    orig = mod.ShellModel

    def full(*a, **kw):
        return orig(*a, quadrature=Quadrature(full=4, reduced=4), **kw)

    mod.ShellModel = full
    try:
        return mod.run_scordelis_lo(n=n).value
    finally:
        mod.ShellModel = orig


lock = []
for nx in (4, 8):
    for name, q in (
        ("selective reduced (3x3 / 2x2)", Quadrature()),
        ("full 3x3", Quadrature(full=4, reduced=4)),
    ):
        t0 = time.perf_counter()
        r = locking_ratio(quadrature=q, nx=nx, slender=500)
        lock.append((f"strip t/L=1/500, {nx}x1", name, r, time.perf_counter() - t0))
for n in (8, 16):
    t0 = time.perf_counter()
    lock.append(
        (
            f"Scordelis-Lo {n}x{n}",
            "selective reduced (3x3 / 2x2)",
            V.run_scordelis_lo(n=n).value / V.SCORDELIS_LO_REFERENCE,
            time.perf_counter() - t0,
        )
    )
    t0 = time.perf_counter()
    lock.append(
        (
            f"Scordelis-Lo {n}x{n}",
            "full 3x3",
            scordelis_full(n) / V.SCORDELIS_LO_REFERENCE,
            time.perf_counter() - t0,
        )
    )

lines = [
    f"Shell verification on {MPI.COMM_WORLD.size} rank(s) ({time.strftime('%Y-%m-%d')}); "
    "Q2 9-node quadrilaterals, selective reduced integration.",
    "",
    "| benchmark | mesh | computed | reference | rel. error | wall time [s] | Newton its |",
    "|---|---|---|---|---|---|---|",
]
for r in rows:
    ref = f"{r.reference:.5f}" if r.reference else "0 (exact)"
    lines.append(
        f"| {r.name} | {r.mesh} | {r.value:.5g} | {ref} | {r.error:.2e} "
        f"| {r.wall_time:.2f} | {r.newton} |"
    )
rates = [math.log2(arc[i].value / arc[i + 1].value) for i in range(len(arc) - 1)]
lines += [
    "",
    "Observed L2 convergence rates (arc bending, 4->8->16 cells): "
    + ", ".join(f"{r:.2f}" for r in rates)
    + " (theory for quadratic elements: 3)",
    "",
]
lines += [
    "Locking: computed / reference deflection (1 = no locking)",
    "",
    "| problem | quadrature (bending / membrane+shear) | ratio | wall time [s] |",
    "|---|---|---|---|",
]
lines += [f"| {p} | {q} | {r:.4f} | {w:.2f} |" for p, q, r, w in lock]
text = "\n".join(lines)
rank0_print(text)
if MPI.COMM_WORLD.rank == 0:
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "verification.md").write_text(text + "\n")
