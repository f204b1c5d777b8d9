"""Cost of the Newmark self-contact barrier per Newton iterate (docs/results/self_contact.md).

The barrier of :mod:`clothfem.contact.self_barrier` on the sleeve (cylinder radius 0.06 m,
length 0.5 m, d = 1 mm) in two configurations:

* ``rest``: the mesh as built (no pair within d), the Newton step a sag of up to 2.5 mm
  (``dz = -2.5 mm (x / L)^2``), the candidate list the one the step filter builds for a
  step moving a node by 2.4 mm (skin 8 x that, 19 mm), as on the 8 x 10 arm run: the
  node-triangle and edge pairs of the curved cells within 20 mm;
* ``pressed``: the tube flattened about x = 0.3 m until its walls are 0.6 d apart there
  (the barrier's pairs within d), the Newton step a sag of up to 0.5 mm plus the walls
  pressed 95 % of the way towards each other (the step filter halves it once).

One Newton iterate as :class:`clothfem.contact.lagrange.LagrangeContact` calls the barrier:
the residual and the Jacobian at the iterate, the step filter ``max_step``, the residual at
the filtered trial point. Each repeat starts from a slightly different iterate (the start
moved by 1e-9 m x the repeat number) so that nothing cached for one iterate serves the
next. Times are CPU time (``time.process_time``) per iterate, the median of ``--repeat``,
split into gather (``_gather``), list validity (``CandidateList.valid``), the filter's
distance bounds (``FilterBounds``, where it exists), its crossing check
(``crossing_groups``), its exact distance checks (``_pt_distance``, ``_ee_distance``),
pairs + energy (``pairs`` less the list validity inside it, ``pair_energy``), the
Jacobian (``jacobian`` less the above: the shell's matrix and the pairs' Hessians into
the barrier's matrix) and the rest of ``add_residual`` and ``max_step`` (exclusive times of the
wrapped functions; the wrappers' own cost is in each column, the uninstrumented total
beside them).

``--base REV``: the same measurement of the code at git revision ``REV`` (its ``clothfem``
unpacked by ``git archive`` into a temporary folder), run alternately with the working
tree's in child processes (``--rounds`` each), and the ratios after / before of the
medians.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/barrier_cost.py [--meshes 8x10 24x30]
[--base REV]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
D, RADIUS, LENGTH, XJ = 1e-3, 0.06, 0.5, 0.3
SAG = {"rest": 2.5e-3, "pressed": 0.5e-3}  # largest sag of the Newton step [m]
GAP = 0.6  # wall distance of the pressed case at x = XJ [d]
REST_SKIN = 8 * 2.4e-3  # skin of the rest case's candidate list [m]
PRESS = 0.95  # fraction of the wall distance the pressed case's step closes
CATEGORIES = (
    "gather", "validity", "bounds", "crossing", "distance", "pairs", "jacobian", "other",
)  # fmt: skip


def flatten(X: np.ndarray, *, half: float = 0.08) -> np.ndarray:
    """The tube flattened about x = XJ (walls GAP d apart at the centre), the walls'
    normal z."""
    s = X[:, 0] - XJ
    f = np.exp(-0.5 * (s / (0.5 * half)) ** 2)
    z = X[:, 2] * (1 - (1 - 0.5 * GAP * D / RADIUS) * f)
    return np.column_stack([X[:, 0], X[:, 1], z])


class Timers:
    """Exclusive CPU time per category of the wrapped functions (nested calls are charged
    to the inner one)."""

    def __init__(self) -> None:
        self.t = dict.fromkeys(CATEGORIES, 0.0)
        self.stack: list[list] = []
        self.saved: list[tuple] = []

    def wrap(self, owner, name: str, category: str) -> None:
        f = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name, None)
        if f is None:
            return
        timers = self

        def g(*a, **k):
            frame = [category, time.process_time(), 0.0]
            timers.stack.append(frame)
            try:
                return f(*a, **k)
            finally:
                timers.stack.pop()
                dt = time.process_time() - frame[1]
                timers.t[category] += dt - frame[2]
                if timers.stack:
                    timers.stack[-1][2] += dt

        self.saved.append((owner, name, f))
        setattr(owner, name, g)

    def restore(self) -> None:
        for owner, name, f in reversed(self.saved):
            setattr(owner, name, f)
        self.saved = []

    def reset(self) -> None:
        self.t = dict.fromkeys(CATEGORIES, 0.0)


def instrument() -> Timers:
    from clothfem.contact import self_barrier as sb
    from clothfem.contact import self_contact as sc

    tm = Timers()
    tm.wrap(sb.SelfBarrier, "_gather", "gather")
    tm.wrap(sc.CandidateList, "valid", "validity")
    tm.wrap(sb, "crossing_groups", "crossing")
    for name in ("_pt_distance", "_ee_distance"):
        tm.wrap(sb, name, "distance")
    if hasattr(sc, "FilterBounds"):
        for name in ("__init__", "all_clear", "rows"):
            tm.wrap(sc.FilterBounds, name, "bounds")
    tm.wrap(sb.SelfBarrier, "pairs", "pairs")
    tm.wrap(sb, "pair_energy", "pairs")
    tm.wrap(sb.SelfBarrier, "jacobian", "jacobian")
    tm.wrap(sb.SelfBarrier, "max_step", "other")
    tm.wrap(sb.SelfBarrier, "add_residual", "other")
    return tm


def setup(na: int, nl: int, config: str):
    from mpi4py import MPI

    from clothfem import dynamics as dy
    from clothfem import mesh as meshes
    from clothfem.contact.self_barrier import SelfBarrier, SelfBarrierParameters
    from clothfem.contact.self_contact import build_candidates
    from clothfem.shell import FabricMaterial, ShellModel
    from clothfem.shell.conditions import Clamp

    sm = meshes.cylinder(MPI.COMM_WORLD, radius=RADIUS, length=LENGTH, n_around=na, n_along=nl)
    mat = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1e5, rho=436.0)
    model = ShellModel(sm, material=mat, thickness=D, supports=[Clamp("shoulder")])
    system = dy.ShellSystem(model, rotary_scale=1.0)
    bar = SelfBarrier(system, params=SelfBarrierParameters(distance=D))
    X = bar.X
    x = flatten(X) if config == "pressed" else X.copy()
    if config == "rest":
        bar.candidates = build_candidates(x, bar.surface, distance=D, skin=REST_SKIN)
    step = np.zeros_like(X)
    step[:, 2] = -SAG[config] * (X[:, 0] / LENGTH) ** 2
    if config == "pressed":
        step[:, 2] -= PRESS * x[:, 2] * (np.abs(x[:, 2]) < D)  # the walls towards z = 0
    n, lo = bar.n, bar.lo
    xv = system.create_vector()
    xv.set(0.0)
    xv.getArray()[: 3 * n] = (x[lo : lo + n] - X[lo : lo + n]).ravel()
    dx = np.zeros(len(xv.getArray()))
    dx[: 3 * n] = step[lo : lo + n].ravel()
    K = model.jacobian(xv)
    return bar, system, xv, dx, K


def iterate(bar, xv, dx, K, f, k: int) -> float:
    """One Newton iterate's barrier calls from the start ``xv`` moved by ``k`` x 1e-9 m."""
    x0 = xv.copy()
    a = x0.getArray()
    n = bar.n
    a[: 3 * n] += 1e-9 * k
    f.set(0.0)
    bar.add_residual(x0, f)
    bar.jacobian(x0, K)
    alpha = bar.max_step(x0.getArray(readonly=True).copy(), dx)
    x1 = x0.copy()
    x1.getArray()[:] += alpha * dx
    bar.add_residual(x1, f)
    x0.destroy()
    x1.destroy()
    return alpha


def measure(meshes: list[str], repeat: int) -> dict:
    """Per mesh and configuration: the uninstrumented CPU time per iterate (median), the
    instrumented split (medians per category), pairs within d, listed pairs, alpha."""
    out = {}
    for spec in meshes:
        na, nl = (int(k) for k in spec.split("x"))
        for config in ("rest", "pressed"):
            bar, system, xv, dx, K = setup(na, nl, config)
            f = xv.duplicate()
            for k in range(3):  # warm-up: the list, the pattern, numba
                alpha = iterate(bar, xv, dx, K, f, -1 - k)
            plain = []
            for k in range(repeat):
                t0 = time.process_time()
                iterate(bar, xv, dx, K, f, k)
                plain.append(time.process_time() - t0)
            tm = instrument()
            split = {c: [] for c in CATEGORIES}
            try:
                for k in range(repeat):
                    tm.reset()
                    iterate(bar, xv, dx, K, f, repeat + k)
                    for c in CATEGORIES:
                        split[c].append(tm.t[c])
            finally:
                tm.restore()
            c = bar.candidates
            out[f"{spec} {config}"] = {
                "total_ms": 1e3 * statistics.median(plain),
                **{c_: 1e3 * statistics.median(v) for c_, v in split.items()},
                "near": bar.record().pairs,
                "listed": len(c.pt_node) + len(c.ee),
                "alpha": alpha,
            }
    return out


def table(runs: dict[str, list[dict]]) -> None:
    keys = list(next(iter(runs.values()))[0])
    names = list(runs)
    cols = ("total_ms", *CATEGORIES)
    head = " | ".join(f"{c.removesuffix('_ms')} ms" for c in cols)
    print(f"| case | pairs in d | listed | alpha | code | {head} |")
    print("|---|---|---|---|---|" + "---|" * len(cols))
    med = {}
    for key in keys:
        for name in names:
            rows = [r[key] for r in runs[name]]
            med[name, key] = {c: statistics.median(r[c] for r in rows) for c in cols}
            r0 = rows[0]
            vals = " | ".join(f"{med[name, key][c]:.3f}" for c in cols)
            print(f"| {key} | {r0['near']} | {r0['listed']} | {r0['alpha']:g} | {name} | {vals} |")
        if len(names) == 2:
            a, b = names
            ratio = " | ".join(
                f"{med[b, key][c] / med[a, key][c]:.2f}" if med[a, key][c] > 0 else "-"
                for c in cols
            )
            print(f"| {key} | | | | {b} / {a} | {ratio} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["8x10", "24x30"])
    ap.add_argument("--repeat", type=int, default=21)
    ap.add_argument("--base", help="git revision to compare against (before)")
    ap.add_argument("--rounds", type=int, default=3, help="child runs of each code (--base)")
    ap.add_argument("--json", action="store_true", help="print the measurement as JSON")
    args = ap.parse_args()
    if args.json or not args.base:
        res = measure(args.meshes, args.repeat)
        if args.json:
            print(json.dumps(res))
        else:
            table({"this": [res]})
        return
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory() as tmp:
        arch = subprocess.run(
            ["git", "archive", args.base, "clothfem"], cwd=ROOT, check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=arch, check=True)
        trees = {"before": tmp, "after": str(ROOT)}
        cmd = [sys.executable, __file__, "--json", "--repeat", str(args.repeat), "--meshes"]
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        for _ in range(args.rounds):
            for name, tree in trees.items():
                res = subprocess.run(
                    cmd + args.meshes,
                    env={**env, "PYTHONPATH": tree},
                    check=True,
                    capture_output=True,
                    text=True,
                )
                runs[name].append(json.loads(res.stdout.strip().splitlines()[-1]))
    print(f"before: {args.base}, after: the working tree; {args.rounds} runs of each")
    table(runs)


if __name__ == "__main__":
    main()
