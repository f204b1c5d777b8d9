"""Cost of the shell element's force assembly, the explicit step's dominant part (or with
--jacobian of its Jacobian assembly, Newton's): partial selective reduced integration
(PSRI), the selective rule (SRI) and the assumed-strain MITC9 element, on the arm-sleeve
mesh, measured in one run.

The models are built on the same sleeve (crimped cotton, t = 1 mm, the scene's n_around x
n_along cells) with the same random state; ``ShellModel.forces`` (one internal-force
assembly with the director update and the nodal chain rule, what the explicit step calls
once per step on a new state) is timed on two alternating states, in rounds that alternate
the models, and the ratios of the medians are reported. With --jacobian,
``ShellModel.jacobian`` is timed instead, each call after an untimed ``forces`` at its state
(Newton assembles the residual first, which the Jacobian reuses). Times are the process CPU
time (time.process_time), so that other jobs on the machine change them less than wall time.

    .venv/bin/python benchmarks/element_cost.py [--mesh 24x30] [--calls 200] [--rounds 5]
        [--jacobian]
"""

import argparse
import time

import numpy as np
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.io import rank0_print
from clothfem.shell import FabricMaterial, Quadrature, ShellModel

parser = argparse.ArgumentParser()
parser.add_argument("--mesh", default="24x30", help="n_around x n_along")
parser.add_argument("--calls", type=int, default=200, help="assemblies per round")
parser.add_argument("--rounds", type=int, default=5)
parser.add_argument("--jacobian", action="store_true", help="time the Jacobian assembly")
args = parser.parse_args()
na, nl = (int(v) for v in args.mesh.split("x"))
comm = MPI.COMM_WORLD

sleeve = meshes.cylinder(comm, radius=0.06, length=0.5, n_around=na, n_along=nl)
cotton = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=0.4e6, nu12=0.0, rho=1500.0)
models = {
    name: ShellModel(sleeve, material=cotton, thickness=1e-3, quadrature=q)
    for name, q in (
        ("PSRI", Quadrature()),
        ("SRI", Quadrature(scheme="sri")),
        ("MITC9", Quadrature(scheme="mitc9")),
    )
}
rng = np.random.default_rng(1 + comm.rank)
operation = "Jacobian" if args.jacobian else "force"


def timed_call(model, x, r, fe, K) -> float:
    """CPU seconds of one force (or Jacobian) assembly at x."""
    if args.jacobian:
        model.forces(x, r, fe)  # untimed: the residual at x, which the Jacobian reuses
    t0 = time.process_time()
    if args.jacobian:
        model.jacobian(x, K)
    else:
        model.forces(x, r, fe)
    return time.process_time() - t0


times: dict[str, list[float]] = {name: [] for name in models}
states = {}
for name, model in models.items():
    model.set_load_factor(1.0)
    states[name] = []
    for _ in range(2):
        x = model.create_vector()
        x.setArray(1e-3 * rng.standard_normal(x.getLocalSize()))
        states[name].append(x)
for _ in range(args.rounds):
    for name, model in models.items():
        xs = states[name]
        r, fe = xs[0].duplicate(), xs[0].duplicate()
        model.forces(xs[1], r, fe)  # warm-up (and JIT on the first round)
        K = model.jacobian(xs[1]) if args.jacobian else None
        comm.Barrier()
        total = sum(timed_call(model, xs[i % 2], r, fe, K) for i in range(args.calls))
        comm.Barrier()
        times[name].append(total / args.calls)
med = {name: float(np.median(v)) for name, v in times.items()}
rank0_print(
    f"sleeve {args.mesh} ({na * nl} cells), {comm.size} rank(s), {args.rounds} rounds of "
    f"{args.calls} {operation} assemblies; median CPU ms per assembly: "
    + ", ".join(f"{k} {1e3 * v:.3f}" for k, v in med.items())
    + f"; PSRI / SRI = {med['PSRI'] / med['SRI']:.3f}, MITC9 / PSRI = "
    + f"{med['MITC9'] / med['PSRI']:.3f}"
)
