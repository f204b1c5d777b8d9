r"""Error against run time on the arm-sleeve scene: a ladder of discretisation settings.

Each rung of LADDER (below: a dict of ``--set`` overrides on top of BASE) is one
``clothfem run demos/scenes/arm_sleeve.toml`` subprocess in ``OUT/ladder/<name>/``; a rung
whose summary.json already says completed (same overrides and ranks) is skipped unless
``--force``. The rungs vary one thing at a time around BASE (16x20 quadratic mesh, explicit
central difference + FILM contact at dt = 0.9 dt_crit): the mesh (8x10, 12x16, 16x20,
24x30), the time step (solver.safety 0.45: half the base's dt), the geometry order
(mesh.order 1 vs 2), the element order (element.degree 1 on a mesh with the base's node
count) and the integrator (implicit Newmark dt = 0.01 s on 8x10 (the default scene), 12x16
and 16x20; quasi-static on 8x10); one more rung repeats the reference on 2 MPI ranks (the
round-off floor, below).

**Reference** = the rung marked ``"reference": True``: the finest setting, the explicit run
on a 32x40 quadratic mesh (``--quick``: implicit 16x20, dt = 0.005 s, around the implicit
8x10 run; measured 2026-11-23 with commit 1bcdfe2, that reference is 11-14 % from the
explicit 24x30 curve, i.e. not mesh-converged, which is why the full ladder's reference is
the explicit 32x40 run: the implicit path does not reach 57 degrees on 24x30 in useful
time).

**Round-off floor.** The scene is sensitive to round-off: the same default scene run
serially and under ``mpirun -n 2`` differed by 3.3 % (raw relative L2 over 2-40 deg) and
10 % (40-57 deg), measured 2026-11-23. So both ladders end with the rung
``<reference>_np2`` (``"floor": True``, ``"ranks": 2``): the reference's settings run as
``mpirun --allow-run-as-root --oversubscribe -n 2 <python> -m mpi4py -m clothfem.cli run
...``. Its errors against the serial reference (raw and smoothed, each in its own norm) are
the round-off floor F of that norm: differences smaller than F are not resolved by the
scene. The floor rung is never a candidate for "cheapest within X"; a threshold X below F
is flagged in those statements (printed and in ladder.md), F is stated in ladder.md and
drawn in ladder.png. If the floor rung has no error (not run, no rows, or it stopped
before A), the floor is "not measured" and nothing is flagged. (With several floor rungs,
F is the largest of their errors.)

A rung is a dict: ``"name"``, optionally ``"reference": True``, ``"floor": True`` and
``"ranks": N`` (int >= 1, default 1; ``mpirun -n N`` if N > 1), every other key a scene key
(a ``--set`` path) replacing BASE's. ``ranks`` and ``floor`` are not scene keys and never
become ``--set`` overrides.

**Errors**, both ``clothfem.report.curve_error`` of |tau| (torque_mag) against the angle,
relative L2 over [2, A] deg, where A is the largest angle every compared run reached: the
smallest final angle of the reference and of the rungs that completed (if no rung completed:
of all rungs); the floor rung counts here like any other rung (if it completed, its final
angle can lower A; if it stopped early while others completed, it does not lower A and has
no error, so the floor is not measured); ``--angle A`` sets it:

* ``error`` (raw): the curves themselves, pointwise. The Newmark curves carry step-to-step
  dynamic oscillation (period of a few degrees) that differs from rung to rung and counts
  in this error in full;
* ``error_smooth``: the same norm of the curves' centred moving averages over SMOOTH_DEG =
  2 deg (``curve_error(..., window=SMOOTH_DEG)``: each curve averaged exactly, as its
  piecewise-linear interpolant, over [a - 1, a + 1] deg cut to its own angle range, so the
  window is one-sided near its ends): the error of the trend, with the oscillation filtered.

Rungs that stopped before A are listed with their reached angle and no error. If A <= 2 deg
(quick checks) the range is [A/2, A]. Wall time = summary wall_time (else the last
``elapsed`` of history.csv).

Outputs: ``OUT/ladder.csv`` (a row as each rung finishes, with its ``ranks`` and ``floor``
columns; the error columns are filled when the ladder ends), ``OUT/ladder.md`` (table, the
round-off floor of each norm, the cheapest rungs), ``OUT/ladder.png`` (log-log error vs wall
time, raw as filled circles, smoothed as open squares, points labelled; the floors as
horizontal dashed lines in the colour of their norm); printed: the floors and the cheapest
rung (floor rung excluded) within 5 %, 2 % and 1 % of the reference, for each of the two
errors, a threshold below that norm's floor flagged as not resolved. The wall time of the
floor rung is that of its 2-rank run.

Run (full ladder: hours on 2 cores):

    nice -n 10 .venv/bin/python benchmarks/arm_ladder.py --out results/arm-ladder
    .venv/bin/python benchmarks/arm_ladder.py --dry-run --out results/arm-ladder

Plumbing check measured 2026-11-22 (2 cores shared with another run; 8x10, 1 degree),
one rung at a time:

    nice -n 10 .venv/bin/python benchmarks/arm_ladder.py --quick --angle-max 1 \
        --only static --out /tmp/ladder                                # 8 s
    nice -n 10 .venv/bin/python benchmarks/arm_ladder.py --quick --angle-max 1 \
        --only base8x10 --out /tmp/ladder                              # newmark: 21 s

(the Newmark rungs' cost at 1 degree is mostly the 0.2 s of dynamic settling). Other
options: ``--extra-set KEY=VALUE`` (every rung, after its own overrides), ``--timeout S``
per rung, ``--angle-max DEG``, ``--only NAME ...``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _arm_common import (  # noqa: E402
    SMOOTH_DEG,
    Case,
    RowWriter,
    add_common_args,
    angle_max_sets,
    curve_error,
    fmt,
    markdown_table,
    read_history,
    run_cases,
    set_arg,
    torque_curve,
)

# --- the ladder (edit here) -------------------------------------------------------------------
# BASE: overrides of every rung; a rung: "name", optional "reference": True, "floor": True,
# "ranks": N (MPI ranks, default 1), other keys are scene keys (--set paths) replacing BASE's.
BASE: dict[str, Any] = {
    "mesh.n_around": 16,
    "mesh.n_along": 20,
    "mesh.order": 2,
    "solver.integrator": "explicit",
}
RUNG_KEYS = ("name", "reference", "floor", "ranks")  # rung keys that are not scene keys


def floor_rung(rung: dict[str, Any], ranks: int = 2) -> dict[str, Any]:
    """The round-off floor rung of a reference rung: its settings on ``ranks`` MPI ranks,
    named ``<name>_np<ranks>``."""
    keys = {k: v for k, v in rung.items() if k not in RUNG_KEYS}
    return {"name": f"{rung['name']}_np{ranks}", "floor": True, "ranks": ranks, **keys}


MESH24: dict[str, Any] = {"mesh.n_around": 24, "mesh.n_along": 30}
NEWMARK: dict[str, Any] = {"solver.integrator": "newmark", "solver.dt": 0.01}
REF: dict[str, Any] = {
    "name": "ref32x40",
    "reference": True,
    "mesh.n_around": 32,
    "mesh.n_along": 40,
}
LADDER: list[dict[str, Any]] = [
    # explicit (central difference + FILM contact, dt = 0.9 dt_crit): the mesh
    {"name": "explicit8x10", "mesh.n_around": 8, "mesh.n_along": 10},
    {"name": "explicit12x16", "mesh.n_around": 12, "mesh.n_along": 16},
    {"name": "base16x20"},  # = BASE: mesh 16x20, order 2, explicit
    {"name": "explicit24x30", **MESH24},
    # the time step (half the base's), the geometry order, the element order
    {"name": "safety0.45", "solver.safety": 0.45},
    {"name": "order1", "mesh.order": 1, "element.scheme": "psri"},  # MITC9: 9-node cells
    # degree-1 u and theta on the mesh with the base's node count
    {
        "name": "degree1_32x40",
        "element.degree": 1,
        "mesh.n_around": 32,
        "mesh.n_along": 40,
        "element.scheme": "psri",
    },
    # implicit: Newmark (gamma 0.6) + Lagrange-multiplier contact, dt 0.01 s; quasi-static
    {"name": "newmark8x10", **NEWMARK, "mesh.n_around": 8, "mesh.n_along": 10},
    {"name": "newmark12x16", **NEWMARK, "mesh.n_around": 12, "mesh.n_along": 16},
    {"name": "newmark16x20", **NEWMARK},
    {"name": "static8x10", "solver.integrator": "static", "mesh.n_around": 8, "mesh.n_along": 10},
    REF,
    floor_rung(REF),  # ref32x40_np2: the reference on 2 ranks (round-off floor)
]
QUICK_REF: dict[str, Any] = {
    "name": "ref16x20_dt0.005",
    "reference": True,
    "mesh.n_around": 16,
    "mesh.n_along": 20,
    "solver.dt": 0.005,
}
# the quick ladder varies the implicit 8x10 run (its dt rungs mean nothing explicitly, so it
# sets its own integrator instead of BASE's)
QUICK_BASE: dict[str, Any] = {
    **BASE,
    "mesh.n_around": 8,
    "mesh.n_along": 10,
    "solver.integrator": "newmark",
}
QUICK_LADDER: list[dict[str, Any]] = [
    {"name": "base8x10"},  # 8x10, newmark dt 0.01
    {"name": "dt0.02", "solver.dt": 0.02},
    {"name": "dt0.005", "solver.dt": 0.005},
    {"name": "mesh12x16", "mesh.n_around": 12, "mesh.n_along": 16},
    {"name": "mesh16x20", "mesh.n_around": 16, "mesh.n_along": 20},  # dt error of the reference
    {"name": "static", "solver.integrator": "static"},
    # explicit: central difference + FILM contact, dt = 0.9 dt_crit (not a scene dt)
    {"name": "explicit8x10", "solver.integrator": "explicit"},
    {
        "name": "explicit12x16",
        "solver.integrator": "explicit",
        "mesh.n_around": 12,
        "mesh.n_along": 16,
    },
    {
        "name": "explicit16x20",
        "solver.integrator": "explicit",
        "mesh.n_around": 16,
        "mesh.n_along": 20,
    },
    {"name": "explicit24x30", "solver.integrator": "explicit", **MESH24},
    # element order: degree-1 u and theta, node counts of the 8x10 and 16x20 rungs
    {
        "name": "explicit_deg1_16x20",
        "solver.integrator": "explicit",
        "element.degree": 1,
        "mesh.n_around": 16,
        "mesh.n_along": 20,
    },
    {
        "name": "explicit_deg1_32x40",
        "solver.integrator": "explicit",
        "element.degree": 1,
        "mesh.n_around": 32,
        "mesh.n_along": 40,
    },
    QUICK_REF,
    floor_rung(QUICK_REF),  # ref16x20_dt0.005_np2: the reference on 2 ranks (round-off floor)
]
LO = 2.0  # deg: start of the compared range (skips the start-up transient of the motion)
THRESHOLDS = (0.05, 0.02, 0.01)
NORMS = (("error", "raw"), ("error_smooth", f"{SMOOTH_DEG:g}-deg moving average"))


def rung_cases(base: dict[str, Any], ladder: list[dict[str, Any]]) -> tuple[list[Case], str]:
    """(cases, name of the reference) of a ladder. The reference is the rung marked
    ``"reference"`` (else the last rung that is not a floor rung); ``"ranks"`` becomes
    :attr:`Case.ranks`, ``"floor"`` a table column; neither is a ``--set``."""
    cases = []
    plain = [r for r in ladder if not r.get("floor")]
    ref = next((r["name"] for r in ladder if r.get("reference")), (plain or ladder)[-1]["name"])
    for rung in ladder:
        if rung.get("floor") and rung["name"] == ref:
            raise ValueError(f"rung {ref}: the reference cannot be a floor rung")
        ranks = rung.get("ranks", 1)
        keys = {k: v for k, v in rung.items() if k not in RUNG_KEYS}
        merged = {**base, **keys}
        if merged.get("solver.integrator") in ("static", "explicit"):
            merged.pop("solver.dt", None)  # a Newmark-only key (explicit: safety x dt_crit)
        changed = "; ".join(f"{k}={v}" for k, v in keys.items()) or "base"
        params = {
            "reference": "yes" if rung["name"] == ref else "",
            "floor": "yes" if rung.get("floor") else "",
            "ranks": ranks,
            "settings": changed,
            "mesh": f"{merged.get('mesh.n_around', '?')}x{merged.get('mesh.n_along', '?')}",
            "order": merged.get("mesh.order", ""),
            "integrator": merged.get("solver.integrator", ""),
            "dt_s": merged.get("solver.dt", ""),
        }
        sets = [set_arg(k, v) for k, v in merged.items()]
        cases.append(Case(rung["name"], sets, params, ranks=ranks))
    return cases, ref


COLUMNS = [
    "case",
    "reference",
    "floor",
    "ranks",
    "settings",
    "mesh",
    "order",
    "integrator",
    "dt_s",
    "completed",
    "reason",
    "final_angle_deg",
    "error",
    "error_smooth",
    "err_lo_deg",
    "err_hi_deg",
    "wall_s",
    "steps",
    "cutbacks",
    "max_penetration_m",
    "nan_in_output",
]
MD_COLUMNS = [
    "case",
    "settings",
    "ranks",
    "completed",
    "final_angle_deg",
    "error",
    "error_smooth",
    "wall_s",
    "steps",
    "cutbacks",
]


def compare_angle(rows: list[dict], ref: str, given: float | None) -> float:
    """A: ``given``, else the smallest final angle of the reference and the completed rungs
    (if no other rung completed: of all rungs with a result)."""
    if given is not None:
        return given
    reached = {r["case"]: r["final_angle_deg"] for r in rows if math.isfinite(r["final_angle_deg"])}
    if ref not in reached:
        return math.nan
    others = [r for r in rows if r["case"] != ref and r["case"] in reached]
    pool = [r for r in others if r["completed"] == "yes"] or others
    return min([reached[ref], *(reached[r["case"]] for r in pool)])


def add_errors(rows: list[dict], ref: str, study_dir: Path, angle: float) -> None:
    """Fill error / error_smooth / err_lo_deg / err_hi_deg (in place)."""
    lo = LO if angle > LO else 0.5 * angle
    curves = {}
    for r in rows:
        try:
            curves[r["case"]] = torque_curve(read_history(study_dir / r["case"] / "history.csv"))
        except Exception:
            curves[r["case"]] = None
    for r in rows:
        r.update(error=math.nan, error_smooth=math.nan, err_lo_deg=lo, err_hi_deg=angle)
        c, c_ref = curves.get(r["case"]), curves.get(ref)
        if not (math.isfinite(angle) and angle > lo) or c is None or c_ref is None:
            continue
        if r["final_angle_deg"] < angle - 1e-6:
            r["reason"] = (r["reason"] + "; " if r["reason"] else "") + (
                f"did not reach A = {angle:g} deg (reached {r['final_angle_deg']:.3g}): no error"
            )
            continue
        if r["case"] == ref:
            r.update(error=0.0, error_smooth=0.0)
            continue
        r["error"] = curve_error(*c_ref, *c, lo=lo, hi=angle)
        r["error_smooth"] = curve_error(*c_ref, *c, lo=lo, hi=angle, window=SMOOTH_DEG)


def _is_floor(r: dict) -> bool:
    return r.get("floor") == "yes"


def round_off_floor(rows: list[dict]) -> dict[str, float]:
    """The round-off floor F of each norm (``error``, ``error_smooth``): the error of the
    floor rung against the reference (the largest, if several); nan if no floor rung has
    that error (not run, no rows, stopped before A)."""
    out = {}
    for key, _ in NORMS:
        vals = [r[key] for r in rows if _is_floor(r) and math.isfinite(r.get(key, math.nan))]
        out[key] = max(vals) if vals else math.nan
    return out


def floor_line(rows: list[dict], floor: dict[str, float]) -> str:
    """One line stating the round-off floor of both norms (or that it was not measured)."""
    names = [r["case"] for r in rows if _is_floor(r)]
    if not any(math.isfinite(floor.get(key, math.nan)) for key, _ in NORMS):
        why = (
            f"{', '.join(names)} has no error against the reference (not run, or stopped before A)"
            if names
            else "no floor rung"
        )
        return f"round-off floor: not measured ({why}); no threshold is flagged"
    ranks = ", ".join(str(r.get("ranks", "?")) for r in rows if _is_floor(r))
    parts = [
        f"F = {100 * floor[key]:.3g} % ({norm})"
        if math.isfinite(floor.get(key, math.nan))
        else f"not measured ({norm})"
        for key, norm in NORMS
    ]
    return (
        f"round-off floor ({', '.join(names)}: the reference's settings on {ranks} MPI ranks,"
        f" against the serial reference): {', '.join(parts)}; differences below F are not"
        " resolved by the scene"
    )


def cheapest(rows: list[dict], ref: str, floor: dict[str, float] | None = None) -> list[str]:
    """For each threshold and each norm (raw, smoothed): the rung with the least wall time
    whose error is within the threshold, as one line; neither the reference nor a floor rung
    is a candidate. A threshold below that norm's round-off floor ``floor[key]`` (default:
    :func:`round_off_floor` of ``rows``; nan = not measured, nothing flagged) is flagged."""
    if floor is None:
        floor = round_off_floor(rows)
    out = []
    for tol in THRESHOLDS:
        for key, norm in NORMS:
            ok = [
                r
                for r in rows
                if r["case"] != ref
                and not _is_floor(r)
                and math.isfinite(r.get(key, math.nan))
                and r[key] <= tol
            ]
            head = f"within {100 * tol:g} % ({norm}): "
            f = floor.get(key, math.nan)
            flag = (
                f" (below the round-off floor F = {100 * f:.3g} %: differences this small are"
                " not resolved)"
                if math.isfinite(f) and tol < f
                else ""
            )
            if ok:
                best = min(
                    ok, key=lambda r: r["wall_s"] if math.isfinite(r["wall_s"]) else math.inf
                )
                out.append(
                    f"{head}{best['case']} ({best['settings']}), error "
                    f"{100 * best[key]:.2f} %, {fmt(best['wall_s'])} s{flag}"
                )
            else:
                out.append(head + "none of the rungs" + flag)
    return out


def plot(
    rows: list[dict],
    ref: str,
    angle: float,
    lo: float,
    png: Path,
    floor: dict[str, float] | None = None,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))

    def shown(r: dict, key: str) -> bool:
        e = r.get(key, math.nan)
        return r["case"] != ref and math.isfinite(e) and e > 0 and math.isfinite(r["wall_s"])

    styles = {
        "error": dict(marker="o", ls="none", color="C0"),
        "error_smooth": dict(marker="s", ls="none", color="C1", mfc="none"),
    }
    drawn = False
    for key, norm in NORMS:
        pts = [r for r in rows if shown(r, key)]
        if pts:
            xs, ys = [r["wall_s"] for r in pts], [r[key] for r in pts]
            ax.plot(xs, ys, label=f"{key}: {norm}", **styles[key])
            drawn = True
    for r in rows:  # one label per rung, at its raw point (else at its smoothed one)
        key = next((k for k, _ in NORMS if shown(r, k)), None)
        if key is not None:
            ax.annotate(
                r["case"],
                (r["wall_s"], r[key]),
                fontsize=8,
                xytext=(4, 3),
                textcoords="offset points",
            )
    for tol in THRESHOLDS:
        ax.axhline(tol, color="0.6", lw=0.8, ls="--")
    for key, _norm in NORMS:  # the round-off floors, in the colour of their norm's points
        f = (floor or {}).get(key, math.nan)
        if math.isfinite(f) and f > 0:
            ax.axhline(
                f,
                color=styles[key]["color"],
                lw=1.0,
                ls="--",
                label=f"round-off floor, {key}: {100 * f:.3g} %",
            )
    ref_row = next((r for r in rows if r["case"] == ref), None)
    if ref_row is not None and math.isfinite(ref_row["wall_s"]):
        ax.axvline(ref_row["wall_s"], color="C3", lw=0.8, ls=":", label=f"reference {ref}")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    if drawn:
        ax.margins(x=0.2, y=0.2)
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel(f"relative L2 error of |tau| over [{lo:g}, {angle:.3g}] deg")
    ax.set_title("arm-sleeve: error against run time")
    ax.grid(True, which="both", alpha=0.4)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_args(parser, default_out="results/arm-ladder")
    parser.add_argument(
        "--angle",
        type=float,
        default=None,
        metavar="A",
        help="compare over [2, A] deg (default: the largest angle every compared run reached)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    base, ladder = (QUICK_BASE, QUICK_LADDER) if args.quick else (BASE, LADDER)
    cases, ref = rung_cases(base, ladder)
    study_dir = out / "ladder"
    settings = angle_max_sets(args.angle_max)
    if args.dry_run:
        print(f"# ladder: {len(cases)} rung(s) in {study_dir}/, reference {ref}")
        run_cases(cases, study_dir, args, settings=settings)
        return 0
    writer = RowWriter(out / "ladder.csv", COLUMNS)
    rows = run_cases(
        cases, study_dir, args, settings=settings, on_result=lambda _c, r: writer.write(r)
    )
    angle = compare_angle(rows, ref, args.angle)
    add_errors(rows, ref, study_dir, angle)
    lo = rows[0]["err_lo_deg"] if rows else LO
    writer.rewrite(rows)
    writer.close()
    ref_row = next((r for r in rows if r["case"] == ref), None)
    head = [
        "# Arm-sleeve ladder: error against wall time",
        "",
        f"- reference: **{ref}** ({ref_row['settings'] if ref_row else 'not run'}), "
        f"BASE = {', '.join(f'{k}={v}' for k, v in base.items())}",
        f"- compared over [{lo:g}, {angle:.4g}] deg ("
        + (
            "A given by --angle"
            if args.angle is not None
            else "A = the smallest final angle of the reference and the completed rungs"
        )
        + "), two relative L2 norms of |tau|(angle):",
        "- error (raw): ||tau - tau_ref|| / ||tau_ref||, the curves pointwise, including the"
        " step-to-step dynamic oscillation",
        f"- error_smooth: the same of the curves' centred {SMOOTH_DEG:g}-deg moving averages"
        " (each cut to its own angle range): the trend, oscillation filtered",
        "",
        "",
    ]
    floor = round_off_floor(rows)
    floor_text = floor_line(rows, floor)
    verdict = cheapest(rows, ref, floor)
    text = "\n".join(head) + markdown_table(rows, MD_COLUMNS) + "\n"
    text += f"- {floor_text}\n"
    text += "".join(f"- cheapest {v}\n" for v in verdict)
    (out / "ladder.md").write_text(text)
    plot(rows, ref, angle, lo, out / "ladder.png", floor)
    if math.isfinite(angle):
        print(f"reference {ref}; compared over [{lo:g}, {angle:.4g}] deg")
    else:
        print(f"reference {ref} has no result (not run, or no rows): no errors")
    print(floor_text)
    for v in verdict:
        print("cheapest " + v)
    print(f"written: {out / 'ladder.csv'}, {out / 'ladder.md'}, {out / 'ladder.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
