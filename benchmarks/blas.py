"""OpenBLAS vs Debian's reference BLAS for the shell's sparse direct solve (MUMPS).

Times Jacobian assembly + MUMPS LU factorisation/solve of one Newton iteration of the
sleeve-sized tube (quadratic quadrilaterals), in two child processes: one with the
system's BLAS (OpenBLAS after `make env`), one with the reference BLAS forced through
LD_LIBRARY_PATH. Prints both times and their ratio, measured in this one run.

Run:  make bench-blas
"""

import json
import os
import subprocess
import sys
import time

REFERENCE = "/usr/lib/x86_64-linux-gnu/blas:/usr/lib/x86_64-linux-gnu/lapack"


def sleeve_jacobian(n_around: int, n_along: int):
    """The sleeve-sized tube (radius 0.06 m, length 0.5 m, Q2 quadrilaterals, cotton,
    clamped shoulder, gravity) at rest at load factor 1: (model, x, residual f, Jacobian K),
    supports not yet applied to K."""
    from mpi4py import MPI

    from clothfem import mesh as meshes
    from clothfem.shell import Clamp, FabricMaterial, Gravity, ShellModel

    sm = meshes.cylinder(
        MPI.COMM_WORLD, radius=0.06, length=0.5, n_around=n_around, n_along=n_along
    )
    model = ShellModel(
        sm,
        material=FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1e5, rho=436.0),
        thickness=1e-3,
        loads=[Gravity()],
        supports=[Clamp("shoulder")],
    )
    model.set_load_factor(1.0)
    x = model.create_vector()
    f = x.duplicate()
    model.residual(x, f)
    return model, x, f, model.jacobian(x)


def child(n_around: int, n_along: int, repeats: int) -> None:
    import numpy as np
    from mpi4py import MPI
    from petsc4py import PETSc

    model, x, f, K = sleeve_jacobian(n_around, n_along)
    rows, _ = model.bc_rows_and_values(1.0)
    K.zeroRows(rows + model.v_range[0], diag=1.0)
    times = []
    for _ in range(repeats):
        ksp = PETSc.KSP().create(MPI.COMM_WORLD)
        ksp.setOperators(K)
        ksp.setType("preonly")  # direct solve only
        ksp.getPC().setType("lu")
        ksp.getPC().setFactorSolverType("mumps")
        dx = x.duplicate()
        t0 = time.perf_counter()
        ksp.solve(f, dx)
        times.append(time.perf_counter() - t0)
        ksp.destroy()
    print(json.dumps({"dofs": x.getSize(), "solve": float(np.median(times))}))


def main() -> None:
    n_around, n_along, repeats = 64, 80, 3
    args = [sys.executable, __file__, "--child", str(n_around), str(n_along), str(repeats)]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = {}
    for name, extra in (
        ("system (OpenBLAS)", {}),
        ("reference BLAS", {"LD_LIBRARY_PATH": REFERENCE}),
    ):
        res = subprocess.run(
            args, env=dict(env, **extra), capture_output=True, text=True, check=True
        )
        out[name] = json.loads(res.stdout.strip().splitlines()[-1])
    a, b = out["system (OpenBLAS)"], out["reference BLAS"]
    print(
        f"tube {n_around}x{n_along} Q2 quads, {a['dofs']} dofs, MUMPS LU, 1 rank, "
        f"median of {repeats}"
    )
    print(f"  system (OpenBLAS): {a['solve']:.2f} s   reference BLAS: {b['solve']:.2f} s")
    print(f"  reference / OpenBLAS = {b['solve'] / a['solve']:.2f}")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(*map(int, sys.argv[2:5]))
    else:
        main()
