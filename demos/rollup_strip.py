"""Roll a cantilever strip into a full circle with an end moment.

The strip of the shell verification (L = 10, b = 1, t = 0.1, E = 1.2e6, nu = 0) is clamped
at x = 0 and loaded at x = L by the end moment M = 2 pi EI / L. Euler-Bernoulli theory says
the strip bends into a circle of circumference L, so the tip comes back to the root: the
number printed last, |tip - root| / L, should be close to 0 (the test asks for < 0.5 %).

Run:  make demo-rollup   or   .venv/bin/python demos/rollup_strip.py --out results/rollup
      (also under mpirun -n 2). Writes fabric.xdmf (ParaView), history.csv and rollup.png.
"""

import argparse
import math
import time

import numpy as np
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.io import ResultWriter, rank0_print, snapshot_png
from clothfem.shell import Clamp, EdgeMoment, FabricMaterial, ShellModel
from clothfem.static import LoadStepping, solve_static

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="results/rollup")
parser.add_argument("--nx", type=int, default=20, help="cells along the strip")
parser.add_argument("--ny", type=int, default=2, help="cells across the strip")
parser.add_argument("--steps", type=int, default=10, help="load steps")
args, _ = parser.parse_known_args()  # the rest are PETSc options, e.g. -static_snes_monitor

L, b, t, E = 10.0, 1.0, 0.1, 1.2e6
EI = E * b * t**3 / 12
M = 2 * math.pi * EI / L

# The model: a 9-node quadrilateral mesh, an isotropic fabric, the clamp and the moment.
surface = meshes.strip(MPI.COMM_WORLD, length=L, width=b, nx=args.nx, ny=args.ny)
model = ShellModel(
    surface,
    material=FabricMaterial.isotropic(E=E, nu=0.0),
    thickness=t,
    loads=[EdgeMoment("tip", (0.0, -M / b, 0.0))],  # per unit edge length
    supports=[Clamp("root")],
)

# Load stepping; every converged step is written at once.
t0 = time.perf_counter()
inc = 1.0 / args.steps
columns = ("load_factor", "tip_ux", "tip_uz", "newton", "strain_energy", "wall_time")
with ResultWriter(args.out, model, columns=columns) as writer:

    def on_step(rec):
        tip = model.displacement_at((L, 0.0, 0.0))
        rank0_print(rec.line())
        writer.write(
            rec.load_factor,
            {
                "load_factor": rec.load_factor,
                "tip_ux": tip[0],
                "tip_uz": tip[2],
                "newton": rec.newton_iterations,
                "strain_energy": model.strain_energy(),
                "wall_time": time.perf_counter() - t0,
            },
        )

    solve_static(
        model, stepping=LoadStepping(initial_increment=inc, max_increment=inc), on_step=on_step
    )

snapshot_png(model, f"{args.out}/rollup.png", title="strip rolled up by M = 2 pi EI / L")
tip = np.array([L, 0.0, 0.0]) + model.displacement_at((L, 0.0, 0.0))
rank0_print(f"wall time {time.perf_counter() - t0:.1f} s; results in {args.out}/")
rank0_print(f"|tip - root| / L = {np.linalg.norm(tip) / L:.2e}")
