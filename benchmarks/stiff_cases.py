"""Stiff and extreme cases of the sleeve (issue 3): implicit and explicit dynamics of a
clamped fabric tube for fabric-like to film-like stiffness and for thin / thick fabrics.

Run:  python benchmarks/stiff_cases.py --out results/stiff          (full table, <= 1 h:
      each implicit run stops after --max-implicit-wall 180 s, each explicit one is not run
      if projected past --max-explicit-wall 240 s; such a row says so in "completed")
      python benchmarks/stiff_cases.py --out results/stiff --quick  (2 cases, ~40 s)

The sleeve: open tube R = 0.06 m, L = 0.5 m along +x, 16 x 16 quadratic quadrilaterals
(Q2, 5280 unknowns), density 436 kg/m^3, E1 = E2 = E, G12 = G13 = G23 = E/200, nu12 = 0,
shoulder ring (x = 0) clamped. Loads, both switched on as a step at t = 0 from rest in the
straight reference shape (load factor 1 for t >= 0): gravity -z, plus a dead edge traction
-z on the cuff ring whose resultant is half the weight of the sleeve. The sleeve is released
and swings down: cantilever bending (shear-dominated for G12 = E/200) of the tube, with
transverse shear and bending of the shell at the loaded free edge. One extra case
(``*_grav``) has gravity only. t_end per case is in CASES (about one lowest period T1 for
the fabric, 2 periods for 350 MPa and 7.2 GPa).

Implicit steps: first dt = T1/40, dt_max = T1/20, dt_min = dt/1024, cut-back x0.5 and growth
x1.5 after <= 4 Newton iterations (clothfem defaults); Newton tolerances are the defaults of
clothfem.dynamics (rtol 1e-9 of the force scale, 15 iterations), not loosened here.
Explicit: dt = 0.9 dt_crit at t = 0 (``--safety``; ``--recheck-every N`` re-estimates
dt_crit every N steps and shrinks dt when needed), lumped (HRZ) mass, physical rotary
inertia.

Per case (E, t) the script computes the lowest natural period T1 of the linearised shell
(inverse iteration with the consistent mass), the explicit stable step dt_crit (Lanczos,
and the rigorous Gershgorin bound), then runs Newmark (average acceleration),
generalized-alpha (rho_inf = 0.8) and the central difference to t_end. An explicit run that
would need more than --max-steps steps or more than --max-explicit-wall seconds (projected
from a short run of --probe-steps steps) is not run; its row reports the projection and the
short run. Rows go to <out>/stiff_cases.csv as each run finishes; <out>/stiff_cases.md holds
the markdown table (also printed).
"""

from __future__ import annotations

import argparse
import csv
import logging
import math
import statistics
import sys
import time
import traceback
import weakref
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from clothfem import dynamics as dy
from clothfem import mesh as meshes
from clothfem.io import rank0_print
from clothfem.shell import Clamp, EdgeTraction, FabricMaterial, Gravity, ShellModel

R, L, RHO, G = 0.06, 0.5, 436.0, 9.81
TIP = (L, 0.0, -R)  # bottom node of the cuff ring

# (label, E [Pa], thickness [m], t_end [s], cuff traction on?)
CASES = [
    ("E1.2M_t1", 1.2e6, 1.0e-3, 0.8, True),
    ("E350M_t1", 350e6, 1.0e-3, 0.1, True),
    ("E7.2G_t1", 7.2e9, 1.0e-3, 0.02, True),
    ("E1.2M_t0.2", 1.2e6, 0.2e-3, 0.6, True),
    ("E1.2M_t2", 1.2e6, 2.0e-3, 0.8, True),
    ("E1.2M_t1_grav", 1.2e6, 1.0e-3, 0.4, False),
]
QUICK = {"E1.2M_t1", "E7.2G_t1"}
INTEGRATORS = ("newmark", "alpha0.8", "central")

COLUMNS = [
    "case",
    "E_Pa",
    "t_m",
    "integrator",
    "status",
    "t_end_s",
    "T1_s",
    "dt_crit_s",
    "dt_bound_s",
    "steps",
    "dt_min_s",
    "dt_med_s",
    "dt_max_s",
    "cutbacks",
    "newton_mean",
    "newton_max",
    "explicit_steps_needed",
    "wall_s",
    "wall_projected_s",
    "energy_err",
    "w_tip_min_m",
    "w_tip_end_m",
    "theta_max_rad",
    "t_reached_s",
    "load",
]


def build(E: float, t: float, n_around: int, n_along: int, cuff: bool = True) -> ShellModel:
    sm = meshes.cylinder(MPI.COMM_WORLD, radius=R, length=L, n_around=n_around, n_along=n_along)
    mat = FabricMaterial(E1=E, E2=E, G12=E / 200, nu12=0.0, rho=RHO)
    weight = RHO * t * 2 * math.pi * R * L * G
    q = 0.5 * weight / (2 * math.pi * R)  # N/m on the cuff ring: resultant = weight / 2
    loads = [Gravity((0.0, 0.0, -G))]
    if cuff:
        loads.append(EdgeTraction("cuff", (0.0, 0.0, -q)))
    return ShellModel(
        sm,
        material=mat,
        thickness=t,
        loads=loads,
        supports=[Clamp("shoulder")],
    )


_REFERENCE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # model -> state at build


def reset(model: ShellModel) -> None:
    """Back to the reference state: u = theta = 0 and the nodal fibre bases of the reference
    (a run re-bases them; zeroing u and theta alone would leave the next run of the same
    model starting from the previous run's directors)."""
    ref = _REFERENCE.setdefault(model, model.state_arrays())
    model.restore_arrays({k: v.copy() for k, v in ref.items()})


def lowest_period(system: dy.ShellSystem, iterations: int = 40) -> float:
    """Lowest natural period of the shell linearised about the reference state [s]:
    inverse iteration K z = lambda M z (consistent mass, supports removed)."""
    model = system.model
    x = model.create_vector()
    model.get_state(x)
    model.set_load_factor(0.0)
    K = model.jacobian(x).copy()
    rows, _ = system.bc(0.0)
    K.zeroRows(rows + system.offset, diag=1.0)
    M = system.mass_matrix().copy()
    M.zeroRows(rows + system.offset, diag=0.0)
    ksp = PETSc.KSP().create(system.comm)
    ksp.setOperators(K)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    z, y, mz = x.duplicate(), x.duplicate(), x.duplicate()
    system.start_vector(z)
    z.getArray()[rows] = 0.0
    lam = lam_old = 0.0
    for _ in range(iterations):
        M.mult(z, mz)
        ksp.solve(mz, y)
        y.getArray()[rows] = 0.0
        M.mult(y, mz)
        ymy = y.dot(mz)
        K.mult(y, z)
        lam = y.dot(z) / ymy
        y.copy(z)
        z.scale(1.0 / math.sqrt(ymy))
        if abs(lam - lam_old) <= 1e-8 * lam:
            break
        lam_old = lam
    for obj in (ksp, K, M, z, y, mz, x):
        obj.destroy()
    return 2 * math.pi / math.sqrt(lam)


class WallLimit(RuntimeError):
    """An implicit run used up its wall-time budget (--max-implicit-wall)."""


class Recorder:
    """on_step callback: the step records, the cuff-bottom deflection and the largest nodal
    rotation |theta| (the director parametrisation is singular at |theta| = pi). With a
    ``budget`` [s] it raises :class:`WallLimit` after the first step past the budget (rank 0's
    clock, broadcast, so every rank stops at the same step)."""

    def __init__(self, model: ShellModel, budget: float = math.inf) -> None:
        self.model, self.records, self.w, self.theta = model, [], [], []
        self.deadline = time.perf_counter() + budget

    def __call__(self, rec: dy.DynamicStep) -> None:
        self.records.append(rec)
        self.w.append(float(self.model.displacement_at(TIP)[2]))
        th = self.model.theta.x.array.reshape(-1, 2)
        loc = float(np.max(np.linalg.norm(th, axis=1))) if len(th) else 0.0
        self.theta.append(self.model.comm.allreduce(loc, op=MPI.MAX))
        if self.model.comm.bcast(time.perf_counter() > self.deadline, root=0):
            raise WallLimit(f"wall budget used up at t = {rec.time:.4g} s")


FAILURES = (dy.DynamicsDivergence, FloatingPointError, np.linalg.LinAlgError)


def summarise(rec: Recorder) -> dict:
    recs, w = rec.records, rec.w
    out: dict = {"steps": len(recs)}
    if not recs:
        return out
    dts = [r.dt for r in recs]
    its = [r.newton_iterations for r in recs]
    e_max = max(max(r.total for r in recs), max(abs(r.external_work) for r in recs))
    diss = max(abs(r.dissipation) for r in recs)
    out.update(
        dt_min_s=min(dts),
        dt_med_s=statistics.median(dts),
        dt_max_s=max(dts),
        cutbacks=sum(r.cutbacks for r in recs),
        newton_mean=statistics.fmean(its),
        newton_max=max(its),
        energy_err=diss / e_max if e_max > 0 else math.nan,
        w_tip_min_m=min(w),
        w_tip_end_m=w[-1],
        theta_max_rad=max(rec.theta),
        t_reached_s=recs[-1].time,
    )
    if not all(math.isfinite(r.total) for r in recs):
        out["status"] = "no: non-finite energy"
    return out


def run_implicit(model, system, scheme, T1, t_end, budget: float) -> dict:
    reset(model)
    dt = T1 / 40
    stepping = dy.TimeStepping(dt=dt, t_end=t_end, dt_max=T1 / 20, dt_min=dt / 1024)
    rec = Recorder(model, budget)
    t0 = time.perf_counter()
    status = "yes"
    try:
        dy.integrate_implicit(system, stepping=stepping, scheme=scheme, on_step=rec)
    except WallLimit as exc:
        status = f"no: {exc} ({budget:.0f} s, --max-implicit-wall)"
    except FAILURES as exc:
        status = f"no: {type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    out = {"status": status, "wall_s": wall}
    out.update(summarise(rec))
    if rec.records and rec.records[-1].time < t_end * (1 - 1e-9) and status == "yes":
        out["status"] = f"no: stopped at t = {rec.records[-1].time:.4g} s"
    return out


def run_explicit(model, system, stable, t_end, args) -> dict:
    dt = args.safety * stable.dt_crit
    n_needed = max(1, math.ceil(t_end / dt - 1e-9))
    out: dict = {"explicit_steps_needed": n_needed}

    def go(span: float) -> tuple[str, Recorder, float]:
        reset(model)
        rec = Recorder(model)
        t0 = time.perf_counter()
        status = "yes"
        try:
            dy.integrate_explicit(
                system,
                t_end=span,
                dt=dt,
                on_step=rec,
                stable=stable,
                safety=args.safety,
                recheck_every=args.recheck_every,
            )
        except FAILURES as exc:  # FloatingPointError: the NaN / inf guard
            status = f"no: {type(exc).__name__}: {exc}"
        return status, rec, time.perf_counter() - t0

    n_probe = min(args.probe_steps, n_needed)
    status, rec, wall = go(n_probe * dt)
    per_step = wall / max(len(rec.records), 1)
    projected = per_step * n_needed
    out["wall_projected_s"] = projected
    if n_probe < n_needed and status == "yes":
        if n_needed > args.max_steps or projected > args.max_explicit_wall:
            out.update(summarise(rec))
            out["status"] = (
                f"not run: {n_needed} steps needed (budget {args.max_steps} steps, "
                f"{args.max_explicit_wall:.0f} s); {n_probe}-step probe to "
                f"t = {n_probe * dt:.3g} s ok in {wall:.1f} s"
            )
            out["wall_s"] = wall
            return out
        status, rec, wall = go(t_end)
    out.update(summarise(rec))
    out["status"] = out.get("status", status) if status == "yes" else status
    out["wall_s"] = wall
    return out


def _no_newton(out: dict) -> dict:
    """Explicit rows: no Newton iterations to report."""
    for key in ("newton_mean", "newton_max"):
        out.pop(key, None)
    return out


def fmt(value, key: str) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        return "nan"
    if key.endswith("wall_s") or key == "wall_projected_s":
        return f"{value:.1f}"
    if key == "newton_mean":
        return f"{value:.2f}"
    return f"{value:.3g}"


MD_COLUMNS = [
    ("case", "case"),
    ("integrator", "integrator"),
    ("status", "completed"),
    ("t_end_s", "t_end [s]"),
    ("T1_s", "T1 [s]"),
    ("dt_crit_s", "dt_crit [s]"),
    ("steps", "steps"),
    ("dt_min_s", "dt min [s]"),
    ("dt_med_s", "dt median [s]"),
    ("dt_max_s", "dt max [s]"),
    ("cutbacks", "cut-backs"),
    ("newton_mean", "Newton mean"),
    ("newton_max", "Newton max"),
    ("explicit_steps_needed", "explicit steps needed"),
    ("wall_s", "wall [s]"),
    ("wall_projected_s", "projected wall [s]"),
    ("energy_err", "energy error"),
    ("w_tip_min_m", "w_tip min [m]"),
    ("theta_max_rad", "max abs theta [rad]"),
    ("t_reached_s", "t reached [s]"),
]


def short_status(status: str) -> str:
    """The status for the table: the exception name or the budget note (full text in CSV)."""
    if status.startswith("not run"):
        return "not run (budget)"
    if status.startswith("no: "):
        return "no: " + status[4:].split(":")[0]
    return status


def markdown(rows: list[dict]) -> str:
    head = "| " + " | ".join(h for _, h in MD_COLUMNS) + " |"
    sep = "|" + "---|" * len(MD_COLUMNS)
    body = []
    for r in rows:
        r = {**r, "status": short_status(str(r.get("status", "")))}
        cells = (fmt(r.get(k, ""), k).replace("|", "/") for k, _ in MD_COLUMNS)
        body.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, sep, *body]) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/stiff")
    parser.add_argument("--quick", action="store_true", help="2 cases, Newmark and central")
    parser.add_argument("--n-around", type=int, default=16)
    parser.add_argument("--n-along", type=int, default=16)
    parser.add_argument(
        "--max-steps", type=int, help="explicit step budget (default 20000, 2000 with --quick)"
    )
    parser.add_argument(
        "--max-explicit-wall", type=float, default=240.0, help="explicit wall budget [s]"
    )
    parser.add_argument(
        "--max-implicit-wall",
        type=float,
        default=180.0,
        help="wall budget of one implicit run [s]; past it the run stops and says so",
    )
    parser.add_argument("--probe-steps", type=int, default=200)
    parser.add_argument(
        "--safety", type=float, default=0.9, help="explicit dt = SAFETY x dt_crit (default 0.9)"
    )
    parser.add_argument(
        "--recheck-every",
        type=int,
        default=0,
        metavar="N",
        help="explicit: re-estimate dt_crit every N steps, shrink dt when needed (0: never)",
    )
    parser.add_argument("--cases", nargs="*", help="labels to run (default: all)")
    parser.add_argument("--integrators", nargs="*", choices=INTEGRATORS)
    args = parser.parse_args()
    if not args.max_implicit_wall > 0:
        parser.error(
            f"--max-implicit-wall: must be a number of seconds > 0, got {args.max_implicit_wall}"
        )
    if not 0 < args.safety <= 1:
        parser.error(f"--safety: must be in (0, 1], got {args.safety}")
    if args.recheck_every < 0:
        parser.error(f"--recheck-every: must be an integer >= 0, got {args.recheck_every}")
    if args.max_steps is None:
        args.max_steps = 2000 if args.quick else 20000
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    cases = [c for c in CASES if (not args.quick or c[0] in QUICK)]
    if args.cases:
        cases = [c for c in cases if c[0] in args.cases]
    integrators = args.integrators or (("newmark", "central") if args.quick else INTEGRATORS)
    out = Path(args.out)
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    csv_path, md_path = out / "stiff_cases.csv", out / "stiff_cases.md"
    fh = open(csv_path, "w", newline="") if comm.rank == 0 else None  # noqa: SIM115
    writer = csv.DictWriter(fh, fieldnames=COLUMNS) if fh else None
    if writer:
        writer.writeheader()
        fh.flush()
    rows: list[dict] = []
    t_script = time.perf_counter()
    for label, E, t, t_end, cuff in cases:
        t0 = time.perf_counter()
        model = build(E, t, args.n_around, args.n_along, cuff)
        reset(model)  # records its reference state
        system = dy.ShellSystem(model)
        T1 = lowest_period(system)
        stable = dy.stable_time_step(system, lam=1.0, iterations=5000)
        rank0_print(
            f"== {label}: T1 = {T1:.4g} s, dt_crit = {stable.dt_crit:.4g} s "
            f"({stable.iterations} Lanczos its, converged {stable.converged}), "
            f"Gershgorin {stable.dt_bound:.3g} s, t_end = {t_end} s, "
            f"setup {time.perf_counter() - t0:.1f} s"
        )
        for name in integrators:
            base = {
                "case": label,
                "E_Pa": E,
                "t_m": t,
                "integrator": name,
                "t_end_s": t_end,
                "load": "gravity + cuff step" if cuff else "gravity only",
                "T1_s": T1,
                "dt_crit_s": stable.dt_crit,
                "dt_bound_s": stable.dt_bound,
            }
            try:
                if name == "newmark":
                    newmark = dy.ImplicitScheme.newmark()
                    res = run_implicit(model, system, newmark, T1, t_end, args.max_implicit_wall)
                elif name == "alpha0.8":
                    scheme = dy.ImplicitScheme.generalized_alpha(rho_inf=0.8)
                    res = run_implicit(model, system, scheme, T1, t_end, args.max_implicit_wall)
                else:
                    res = _no_newton(run_explicit(model, system, stable, t_end, args))
            except Exception as exc:  # report and go on with the next run
                traceback.print_exc()
                res = {"status": f"no: {type(exc).__name__}: {exc}"}
            row = {**base, **res}
            rows.append(row)
            if writer:
                writer.writerow({k: row.get(k, "") for k in COLUMNS})
                fh.flush()
            rank0_print(
                f"   {name:9s} {row['status'][:90]}  steps {row.get('steps', '')}  "
                f"wall {fmt(row.get('wall_s', math.nan), 'wall_s')} s  "
                f"energy err {fmt(row.get('energy_err', math.nan), 'e')}  "
                f"w_tip min {fmt(row.get('w_tip_min_m', math.nan), 'w')} m"
            )
    if fh:
        fh.close()
    table = markdown(rows)
    if comm.rank == 0:
        md_path.write_text(table)
    rank0_print(table)
    rank0_print(f"total wall time {time.perf_counter() - t_script:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
