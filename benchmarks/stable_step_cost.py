"""Cost of the explicit stable-step estimate (``clothfem.dynamics.stable_time_step``: Lanczos
with full reorthogonalisation) on the arm-sleeve scene's model at its start, at the default
tolerance and at a tight one (many more Lanczos steps: what the reorthogonalisation's cost
grows with).

Times are the process CPU time (time.process_time) of each call, median over --repeat calls
on the same state; the estimate and its number of Lanczos steps are printed with them.

    .venv/bin/python benchmarks/stable_step_cost.py [--repeat 3] [--rtol 1e-4 1e-10]
        [--set KEY=VALUE ...]
"""

import argparse
import statistics
import time

from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.dynamics import ShellSystem, stable_time_step
from clothfem.io import rank0_print
from clothfem.run import build_model

parser = argparse.ArgumentParser()
parser.add_argument("--repeat", type=int, default=3)
parser.add_argument("--rtol", type=float, nargs="+", default=[1e-4, 1e-10])
parser.add_argument("--iterations", type=int, default=2000, help="most Lanczos steps")
parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
args = parser.parse_args()

scene = scenes.load("demos/scenes/arm_sleeve.toml", args.set + ["output.png=false"])
model, _ = build_model(scene, MPI.COMM_WORLD)
system = ShellSystem(model, rotary_scale=scene.solver.rotary_scale)
m = scene.mesh
rank0_print(f"arm sleeve {m.n_around}x{m.n_along}, {MPI.COMM_WORLD.size} rank(s)")
for rtol in args.rtol:
    times = []
    for _ in range(args.repeat):
        t0 = time.process_time()
        st = stable_time_step(system, iterations=args.iterations, rtol=rtol)
        times.append(time.process_time() - t0)
    rank0_print(
        f"rtol {rtol:g}: dt_crit {st.dt_crit:.10e} s, {st.iterations} Lanczos steps "
        f"(converged: {st.converged}), CPU {statistics.median(times):.3f} s per call "
        f"(median of {args.repeat})"
    )
