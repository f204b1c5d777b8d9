"""Cost of the fabric laws in the explicit step, measured in one run: the part of a step
that depends on the material (one internal-force assembly at a new state, then the history
commit) for the linear crimped cotton, the decrimping law, the decrimping law with yarn
friction and the linear law with membrane viscosity, as ratios to the linear law.

All models are built on the same sleeve (the scene's n_around x n_along cells, t = 1 mm)
with the presets of clothfem.scene.MATERIALS; each round times ``--calls`` steps of every
model in turn (the models alternate, so that a drift of the machine's speed falls on all
of them), on states that change every call, by the process CPU time (time.process_time:
other jobs on the machine change it less than wall time). The ratio of the medians over the
rounds is printed, and, with ``--step-ms``, the ratio for a whole explicit step whose
material-independent part (contact, integrator, output) takes that many milliseconds.

``--scheme`` picks the element (``psri``, the default, or ``mitc9``, whose kernels evaluate
the laws at their 3 x 3 points).

    .venv/bin/python benchmarks/material_cost.py [--mesh 24x30] [--calls 200] [--rounds 5] \
        [--scheme mitc9]
"""

import argparse
import time

import numpy as np
from _arm_common import parse_mesh
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem import scene as scenes
from clothfem.io import rank0_print
from clothfem.run import build_material
from clothfem.shell import Quadrature, ShellModel

LAWS = {
    "linear": {"preset": "crimped-cotton"},
    "decrimping": {"preset": "decrimping-cotton"},
    "decrimping+friction": {"preset": "decrimping-cotton-hysteretic"},
    "linear+viscosity": {
        "preset": "crimped-cotton",
        "viscosity1": 20.0,
        "viscosity2": 20.0,
        "viscosity12": 40.0,
    },
}


def material(table: dict) -> object:
    data = {
        "scene": {"name": "cost"},
        "mesh": {"generator": "strip", "length": 1.0, "width": 1.0, "nx": 1, "ny": 1},
        "material": {**table, "thickness": 1e-3},
        # the explicit integrator's scene (membrane viscosity is a key of the dynamic ones)
        "solver": {"integrator": "explicit", "duration": 1.0},
    }
    return build_material(scenes.validate(data).material)


def _positive(text: str) -> int:
    """An integer >= 1 (argparse type)."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return int(text)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--mesh", type=parse_mesh, default=(24, 30), help="NAxNL, e.g. 24x30")
    parser.add_argument("--calls", type=_positive, default=200, help="steps per model and round")
    parser.add_argument("--rounds", type=_positive, default=5)
    parser.add_argument("--step-ms", type=float, default=None, help="rest of a step [ms]")
    parser.add_argument("--scheme", choices=("psri", "mitc9"), default="psri", help="element")
    args = parser.parse_args()
    na, nl = args.mesh
    comm = MPI.COMM_WORLD
    sleeve = meshes.cylinder(comm, radius=0.06, length=0.5, n_around=na, n_along=nl)
    models = {
        name: ShellModel(
            sleeve,
            material=material(table),
            thickness=1e-3,
            quadrature=Quadrature(scheme=args.scheme),
        )
        for name, table in LAWS.items()
    }
    rng = np.random.default_rng(1 + comm.rank)
    states = {}
    for name, model in models.items():
        model.set_load_factor(1.0)
        model.set_time_step(1e-4)
        x = model.create_vector()
        x.setArray(1e-3 * rng.standard_normal(x.getLocalSize()))
        dx = x.duplicate()
        dx.setArray(1e-6 * rng.standard_normal(x.getLocalSize()))
        states[name] = (x, dx)
    times: dict[str, list[float]] = {name: [] for name in models}
    for _ in range(args.rounds):
        for name, model in models.items():
            x, dx = states[name]
            r, fe = x.duplicate(), x.duplicate()
            model.forces(x, r, fe)  # warm-up (and JIT on the first round)
            comm.Barrier()
            t0 = time.process_time()
            for i in range(args.calls):
                x.axpy(1.0 if i % 2 == 0 else -1.0, dx)  # a new state every call
                model.forces(x, r, fe)
                model.commit_material()
            comm.Barrier()
            times[name].append((time.process_time() - t0) / args.calls)
    med = {name: float(np.median(v)) for name, v in times.items()}
    base = med["linear"]
    rank0_print(
        f"sleeve {na}x{nl} ({na * nl} cells), element {args.scheme}, {comm.size} rank(s), "
        f"{args.rounds} rounds of "
        f"{args.calls} steps; median CPU ms per force assembly + commit:"
    )
    for name, v in med.items():
        line = f"  {name:22s} {1e3 * v:7.3f} ms  x {v / base:.3f}"
        if args.step_ms is not None:
            rest = 1e-3 * args.step_ms
            line += f"   whole step x {(v + rest) / (base + rest):.3f}"
        rank0_print(line)


if __name__ == "__main__":
    main()
