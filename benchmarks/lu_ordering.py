"""MUMPS fill-reducing orderings for the sleeve's Newton matrix (docs/results/performance.md).

Builds the sleeve tube (radius 0.06 m, length 0.5 m, quadratic quadrilaterals, clamped
shoulder, gravity) on each mesh, its Jacobian at rest plus the Newmark mass term of a
2.5 ms step (M / (beta dt^2), beta = 1/4), and times MUMPS LU through a ``preonly`` KSP for
each ordering (``-mat_mumps_icntl_7``): the first solve (analysis, factorisation, solve)
and the median of ``--repeat`` refactorisations with the same pattern (the values bumped by a
shift of 1e-30 so that PETSc factors again), which is what a Newton iteration pays.
The orderings run in turns, ``--rounds`` times, in this one process; the ratios are to
MUMPS's automatic choice (7), measured in this run. Factor entries are MUMPS's INFOG(9)
+ INFOG(10) (entries of the factors; MUMPS gives millions as negative numbers).

Run: ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/lu_ordering.py
[--meshes 8x10 16x20 24x30] [--orderings 7 0 3 4 5 6]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

NAMES = {0: "AMD", 2: "AMF", 3: "SCOTCH", 4: "PORD", 5: "METIS", 6: "QAMD", 7: "auto"}
DT, BETA = 2.5e-3, 0.25


def _matrix(n_around: int, n_along: int):
    """The sleeve's Newmark matrix at rest, with the clamp's rows set to identity."""
    from blas import sleeve_jacobian

    from clothfem import dynamics as dy

    model, _, _, K = sleeve_jacobian(n_around, n_along)
    system = dy.ShellSystem(model, rotary_scale=1.0)
    K.axpy(1.0 / (BETA * DT**2), system.mass_matrix())
    rows, _ = model.bc_rows_and_values(1.0)
    K.zeroRows(rows + model.v_range[0], diag=1.0)
    return K


def _entries(F) -> float:
    """Real entries of the factors (INFOG(9) + INFOG(10); negative: x 1e6)."""
    total = 0.0
    for i in (9, 10):
        v = F.getMumpsInfog(i)
        total += -v * 1e6 if v < 0 else v
    return total


def _time(K, ordering: int, repeats: int) -> tuple[float, float, float, int]:
    """(first solve [s], median refactorisation + solve [s], factor entries, the ordering
    MUMPS applied (INFOG(7)))."""
    from petsc4py import PETSc

    prefix = f"lu_ordering_{ordering}_"
    opts = PETSc.Options()
    for key, value in (
        ("ksp_type", "preonly"),
        ("pc_type", "lu"),
        ("pc_factor_mat_solver_type", "mumps"),
        ("mat_mumps_icntl_7", ordering),
    ):
        opts.setValue(prefix + key, value)
    ksp = PETSc.KSP().create(K.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(K)
    ksp.setFromOptions()
    b = K.createVecLeft()
    b.set(1.0)
    s = b.duplicate()
    t = time.perf_counter()
    ksp.solve(b, s)
    first = time.perf_counter() - t
    times = []
    for k in range(repeats):
        K.shift(1e-30 if k % 2 == 0 else -1e-30)  # new values, same pattern
        ksp.setOperators(K)
        t = time.perf_counter()
        ksp.solve(b, s)
        times.append(time.perf_counter() - t)
    F = ksp.getPC().getFactorMatrix()
    used = F.getMumpsInfog(7)  # the ordering MUMPS applied
    entries = _entries(F)
    ksp.destroy()
    return first, statistics.median(times), entries, used


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["8x10", "16x20", "24x30"])
    ap.add_argument("--orderings", nargs="+", type=int, default=[7, 0, 3, 4, 5, 6])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    for o in args.orderings:
        if o not in NAMES:
            ap.error(f"--orderings: {o} is not a MUMPS ordering (allowed: {sorted(NAMES)})")
    if 7 not in args.orderings:
        ap.error("--orderings: must include 7 (MUMPS's automatic choice, the reference)")
    if args.repeat < 1 or args.rounds < 1:
        ap.error("--repeat and --rounds must be >= 1")
    meshes = []
    for m in args.meshes:
        parts = m.split("x")
        if len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts):
            ap.error(f"--meshes: {m!r} is not N_AROUNDxN_ALONG (e.g. 24x30)")
        meshes.append((int(parts[0]), int(parts[1])))
    print(
        "| mesh | unknowns | ordering | factor entries | first solve [ms] "
        "| refactor + solve [ms] | ratio to auto |"
    )
    print("|---|---|---|---|---|---|---|")
    for na, nl in meshes:
        K = _matrix(na, nl)
        res: dict[int, list[tuple[float, float, float, int]]] = {o: [] for o in args.orderings}
        for _ in range(args.rounds):
            for o in args.orderings:
                res[o].append(_time(K, o, args.repeat))
        med = {o: statistics.median(r[1] for r in res[o]) for o in args.orderings}
        for o in args.orderings:
            first = statistics.median(r[0] for r in res[o])
            applied = NAMES.get(res[o][0][3], str(res[o][0][3]))
            print(
                f"| {na}x{nl} | {K.getSize()[0]} | {NAMES[o]} ({o}; applied: {applied}) "
                f"| {res[o][0][2]:.3g} "
                f"| {1e3 * first:.1f} | {1e3 * med[o]:.1f} | {med[o] / med[7]:.2f} |",
                flush=True,
            )
        K.destroy()
    return 0


if __name__ == "__main__":
    sys.exit(main())
