r"""The five parameter studies of Man & Swan (2007), Sec. 4.1, on the arm-sleeve scene.

Every case is one ``clothfem run demos/scenes/arm_sleeve.toml`` subprocess with ``--set``
overrides, kept in ``OUT/<study>/<case>/`` (history.csv, summary.json, logs, PNGs). A case
whose summary.json already says completed (same overrides) is skipped unless ``--force``,
so an interrupted study resumes. One CSV per study, ``OUT/<study>.csv``, gets a row as each
case finishes (case, parameters, completed, final angle, |tau| at 10/20/30/40/50/57 deg, peak
torque, wall time, steps, cut-backs, max penetration); columns that need every case of the
study (errors against the finest mesh, ratios) and the resistance measures of each case
(``clothfem.report.resistance_measures``: the elbow's work against the sleeve [J], its part
in the flexion, the friction and material dissipation [J], the flexion's peak and mean |tau|
[N m] and its 2-20 deg roughness) are filled in when the study ends; the measures of every
case run are also printed as one table across the studies, ``OUT/measures.md``.

Studies (``--study``, default all):

* ``mesh``: n_around x n_along = 8x10, 12x16, 16x20, 24x30 (``--quick``: 8x10, 12x16), each
  at mu = 0.1 and 0.5 -> ``mesh_mu0.1.png``, ``mesh_mu0.5.png``; ``err_vs_finest`` = relative
  L2 error (``clothfem.report.curve_error``) of |tau|(angle) against the finest mesh of the
  same mu over [lo, A], A = the smallest final angle of the two runs, lo = min(2, A/2) deg
  (both in the CSV); ``err_smooth_vs_finest`` = the same norm of the curves' centred
  moving averages over SMOOTH_DEG = 2 deg (``curve_error(..., window=SMOOTH_DEG)``, see
  ``arm_ladder.py``): the error of the trend, without the step-to-step dynamic oscillation;
* ``friction``: mu = 0.1 vs 0.5 -> ``friction.png`` (the paper's Fig. 8);
* ``fit``: sleeve radius 0.06 vs 0.07 m at mu = 0.5 -> ``fit.png``;
* ``thickness``: t = 1 vs 2 mm at mu = 0.5 -> ``thickness.png``; ``ratio_at_<a>deg`` =
  torque(t) / torque(1 mm) at 10..50 deg;
* ``material``: sets I-III at mu = 0.1 (table MATERIALS below: E = 1.2 MPa / 350 MPa /
  7.2 GPa, rho = 436 / 436 / 700; G12 = E/200 for all three, as the paper states, so set I
  is softer in shear than the scene's crimped-cotton preset, G = 0.1 MPa) ->
  ``material.png`` (log y);
  ``torque_per_E_at_<a>deg`` = torque / E1 [N m / Pa];
* ``law``: the fabric law at mu = 0.1 and 0.5: linear crimped cotton (``crimped-cotton``),
  the decrimping law (``decrimping-cotton``: 1.2 MPa stiffening to 350 MPa) and the same
  with yarn friction (``decrimping-cotton-hysteretic``) -> ``law_mu0.1.png``,
  ``law_mu0.5.png``; ``torque_vs_linear_at_<a>deg`` = torque / the linear case's (same mu).

A case whose physics a completed case of another study already ran (same scene after
overrides and defaults, but for its name and output sections; e.g. friction's mu = 0.5, fit's
R = 0.06 m and thickness's 1 mm cases) is copied from it, not run again (``case.json`` then
names it under ``same_as``; ``--force`` runs it).

Integrator: ``--integrator`` (default ``explicit``: central difference + FILM contact at
0.9 dt_crit; ``newmark`` = implicit Newmark, dt 0.01 s) for every case. The explicit step is
bounded by the membrane wave speed sqrt(E / rho), 17x (set II) and 61x (set III) faster
than in cotton, so material sets II and III take 17x / 61x the cotton run's steps; with the
compiled contact kernel an explicit 16x20 step costs ~4 ms, so they are minutes to half an
hour).
``--stiff-integrator newmark`` runs sets II and III implicitly whatever ``--integrator``
says. The ladder (``arm_ladder.py``) puts explicit 16x20 within a few % of implicit 16x20.

Studies b-e use the mesh ``--mesh`` (default 16x20, ``--quick`` 8x10). ``--angle-max DEG``
overrides the forearm's angle_max (and scales contact.increments to keep 1-degree
increments); ``--extra-set KEY=VALUE`` (repeatable) is passed to every case after its own
overrides (e.g. ``--extra-set solver.integrator=static``); ``--only CASE ...`` runs only
the named cases; ``--timeout S`` stops a case after S seconds.

Run (with ``nice`` on a shared machine; full studies take hours):

    nice -n 10 .venv/bin/python benchmarks/arm_studies.py --out results/arm-studies
    nice -n 10 .venv/bin/python benchmarks/arm_studies.py --study friction fit \
        --out results/arm-studies
    .venv/bin/python benchmarks/arm_studies.py --dry-run --out results/arm-studies   # commands only

Plumbing check measured 2026-11-22 (2 cores shared with another run; 8x10 mesh, 1 degree;
the scene's integrator was still static then):

    nice -n 10 .venv/bin/python benchmarks/arm_studies.py --study friction --quick \
        --angle-max 1 --only mu0.1 --out /tmp/st                       # static: 13 s
    nice -n 10 .venv/bin/python benchmarks/arm_studies.py --study friction --quick \
        --angle-max 1 --only mu0.5 --out /tmp/st \
        --extra-set solver.integrator=newmark                          # newmark dt 0.01: 35 s

(the Newmark run's cost is mostly the 0.2 s of dynamic settling, 23 steps). A full case
on 16x20 to 57 degrees takes from minutes to an hour or more.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _arm_common import (  # noqa: E402
    SMOOTH_DEG,
    Case,
    RowWriter,
    add_common_args,
    angle_max_sets,
    curve_error,
    mesh_sets,
    parse_mesh,
    read_history,
    result_columns,
    run_cases,
    torque_curve,
    torque_plot,
)

STUDIES = ("mesh", "friction", "fit", "thickness", "material", "law")
LAWS = ("crimped-cotton", "decrimping-cotton", "decrimping-cotton-hysteretic")
MESHES = [(8, 10), (12, 16), (16, 20), (24, 30)]
QUICK_MESHES = [(8, 10), (12, 16)]
RATIO_ANGLES = (10, 20, 30, 40, 50)
STIFF_SETS = ("II", "III")  # --stiff-integrator applies to these (module docstring)
# Sec. 4.1.5 material sets: E1 = E2 = E, nu12 = 0 and, as the paper says for all three sets,
# G12 = E / 200 (so set I here is softer in shear than the crimped-cotton preset's 0.1 MPa).
MATERIALS = {
    "I": dict(E=1.2e6, G12=1.2e6 / 200, rho=436.0),
    "II": dict(E=350e6, G12=350e6 / 200, rho=436.0),
    "III": dict(E=7.2e9, G12=7.2e9 / 200, rho=700.0),
}


def _mesh_name(m: tuple[int, int]) -> str:
    return f"{m[0]}x{m[1]}"


def study_cases(study: str, args: argparse.Namespace) -> list[Case]:
    """The cases of one study (the study's default mesh is prepended by main)."""
    if study == "mesh":
        cases = []
        for mu in (0.1, 0.5):
            for m in QUICK_MESHES if args.quick else MESHES:
                cases.append(
                    Case(
                        f"mu{mu:g}_{_mesh_name(m)}",
                        [*mesh_sets(m), f"contact.mu={mu:g}"],
                        {"n_around": m[0], "n_along": m[1], "mu": mu},
                    )
                )
        return cases
    if study == "friction":
        return [Case(f"mu{mu:g}", [f"contact.mu={mu:g}"], {"mu": mu}) for mu in (0.1, 0.5)]
    if study == "fit":
        return [
            Case(f"R{r:g}", [f"mesh.radius={r:g}", "contact.mu=0.5"], {"radius_m": r, "mu": 0.5})
            for r in (0.06, 0.07)
        ]
    if study == "thickness":
        return [
            Case(
                f"t{1e3 * t:g}mm",
                [f"material.thickness={t:g}", "contact.mu=0.5"],
                {"thickness_m": t, "mu": 0.5},
            )
            for t in (1e-3, 2e-3)
        ]
    if study == "material":
        return [
            Case(
                f"set{name}",
                [
                    f"material.E1={m['E']:g}",
                    f"material.E2={m['E']:g}",
                    f"material.G12={m['G12']:g}",
                    f"material.rho={m['rho']:g}",
                    "contact.mu=0.1",
                    *(
                        [f"solver.integrator={args.stiff_integrator}"]
                        if name in STIFF_SETS and args.stiff_integrator
                        else []
                    ),
                ],
                {"set": name, "E_Pa": m["E"], "G12_Pa": m["G12"], "rho": m["rho"], "mu": 0.1},
            )
            for name, m in MATERIALS.items()
        ]
    if study == "law":
        return [
            Case(
                f"{law}_mu{mu:g}",
                [f"material.preset={law}", f"contact.mu={mu:g}"],
                {"law": law, "mu": mu},
            )
            for mu in (0.1, 0.5)
            for law in LAWS
        ]
    raise ValueError(study)


PARAMS = {
    "mesh": ["n_around", "n_along", "mu", "integrator"],
    "friction": ["n_around", "n_along", "mu", "integrator"],
    "fit": ["n_around", "n_along", "radius_m", "mu", "integrator"],
    "thickness": ["n_around", "n_along", "thickness_m", "mu", "integrator"],
    "material": ["n_around", "n_along", "set", "E_Pa", "G12_Pa", "rho", "mu", "integrator"],
    "law": ["n_around", "n_along", "law", "mu", "integrator"],
}
EXTRA = {
    "mesh": ["err_vs_finest", "err_smooth_vs_finest", "err_lo_deg", "err_hi_deg", "finest"],
    "thickness": [f"ratio_at_{a}deg" for a in RATIO_ANGLES],
    "material": [f"torque_per_E_at_{a}deg" for a in (*RATIO_ANGLES, 57)],
    "law": [f"torque_vs_linear_at_{a}deg" for a in (*RATIO_ANGLES, 57)],
}


# the clothing-resistance measures of every case (clothfem.report.resistance_measures of its
# history: the elbow's work against the sleeve, the dissipation, the flexion torque's peak,
# mean and roughness), read from the case folder; one table across all studies run
MEASURES = [
    "joint_work_J",
    "work_flexion_J",
    "dissipation_friction_J",
    "dissipation_material_J",
    "peak_torque_flexion",
    "mean_torque_flexion",
    "roughness_2_20deg",
]


def measures_row(folder: Path) -> dict[str, float]:
    """The MEASURES columns of one case folder (nan where the history lacks them)."""
    from clothfem.report import resistance_measures

    try:
        m = resistance_measures(read_history(folder / "history.csv"))
    except Exception:
        return dict.fromkeys(MEASURES, math.nan)
    (j,) = m["joints"].values()
    d, f = m["dissipation"], m["torque"]["flexion"]
    vals = (j["work"], j["work_flexion"], d["friction"], d["material"], f["peak"], f["mean"])
    vals += (f.get("roughness"),)
    return {k: math.nan if v is None else float(v) for k, v in zip(MEASURES, vals, strict=True)}


def measures_table(rows: list[tuple[str, dict]]) -> str:
    """Markdown table of the MEASURES of (study/case, row) pairs."""
    head = "| case | " + " | ".join(MEASURES) + " |"
    lines = [head, "|---|" + "---|" * len(MEASURES)]
    for name, r in rows:
        cells = " | ".join(f"{r.get(k, math.nan):.4g}" for k in MEASURES)
        lines.append(f"| {name} | {cells} |")
    return "\n".join(lines) + "\n"


def _integrator(sets: list[str]) -> str:
    """The solver.integrator the last of ``sets`` gives (``""`` if none does)."""
    found = [v for k, _, v in (x.partition("=") for x in sets) if k == "solver.integrator"]
    return found[-1] if found else ""


def _curve(folder: Path):
    try:
        return torque_curve(read_history(folder / "history.csv"))
    except Exception:
        return None


def compare(ref: Path, run: Path) -> tuple[float, float, float, float]:
    """(error, smoothed error, lo, hi): curve_error of run against ref over [min(2, A/2), A],
    A = the smallest final angle of the two, raw and with window=SMOOTH_DEG; nan if a curve
    is missing or A <= 0."""
    c_ref, c_run = _curve(ref), _curve(run)
    if c_ref is None or c_run is None or not c_ref[0].size or not c_run[0].size:
        return math.nan, math.nan, math.nan, math.nan
    hi = min(c_ref[0][-1], c_run[0][-1])
    lo = min(2.0, 0.5 * hi)
    if not hi > lo:
        return math.nan, math.nan, lo, hi
    err = curve_error(*c_ref, *c_run, lo=lo, hi=hi)
    smooth = curve_error(*c_ref, *c_run, lo=lo, hi=hi, window=SMOOTH_DEG)
    return err, smooth, lo, hi


def post_process(study: str, rows: list[dict], study_dir: Path) -> None:
    """Fill the columns that need every case of the study (in place)."""
    by_name = {r["case"]: r for r in rows}
    for r in rows:
        r.update(measures_row(study_dir / r["case"]))
    if study == "mesh":
        for mu in (0.1, 0.5):
            mine = [r for r in rows if r["mu"] == mu]
            if not mine:
                continue
            finest = max(mine, key=lambda r: r["n_around"] * r["n_along"])
            for r in mine:
                err, smooth, lo, hi = compare(study_dir / finest["case"], study_dir / r["case"])
                r.update(err_vs_finest=err, err_smooth_vs_finest=smooth, err_lo_deg=lo)
                r.update(err_hi_deg=hi, finest=finest["case"])
    elif study == "thickness":
        base = by_name.get("t1mm")
        for r in rows:
            for a in RATIO_ANGLES:
                num, den = r[f"torque_at_{a}deg"], base[f"torque_at_{a}deg"] if base else math.nan
                r[f"ratio_at_{a}deg"] = num / den if den and math.isfinite(den) else math.nan
    elif study == "material":
        for r in rows:
            for a in (*RATIO_ANGLES, 57):
                r[f"torque_per_E_at_{a}deg"] = r[f"torque_at_{a}deg"] / r["E_Pa"]
    elif study == "law":
        for r in rows:
            base = by_name.get(f"{LAWS[0]}_mu{r['mu']:g}")
            for a in (*RATIO_ANGLES, 57):
                num, den = r[f"torque_at_{a}deg"], base[f"torque_at_{a}deg"] if base else math.nan
                ok = den and math.isfinite(den)
                r[f"torque_vs_linear_at_{a}deg"] = num / den if ok else math.nan


def plots(study: str, cases: list[Case], study_dir: Path, out: Path, title_mesh: str) -> None:
    def folder(c: Case) -> Path:
        return study_dir / c.name

    if study == "mesh":
        for mu in (0.1, 0.5):
            sel = [c for c in cases if c.params["mu"] == mu]
            torque_plot(
                [(f"{c.params['n_around']}x{c.params['n_along']}", folder(c)) for c in sel],
                out / f"mesh_mu{mu:g}.png",
                title=f"arm-sleeve: mesh study, mu = {mu:g}, {title_mesh.split(', ')[-1]}",
            )
        return
    if study == "law":
        for mu in (0.1, 0.5):
            sel = [c for c in cases if c.params["mu"] == mu]
            torque_plot(
                [(c.params["law"], folder(c)) for c in sel],
                out / f"law_mu{mu:g}.png",
                title=f"arm-sleeve: fabric law, mu = {mu:g}, {title_mesh}",
            )
        return
    labels = {
        "friction": lambda c: f"mu = {c.params['mu']:g}",
        "fit": lambda c: f"sleeve radius {c.params['radius_m']:g} m",
        "thickness": lambda c: f"t = {1e3 * c.params['thickness_m']:g} mm",
        "material": lambda c: (
            f"set {c.params['set']} (E = {c.params['E_Pa']:.3g} Pa, {c.params['integrator']})"
        ),
    }
    titles = {
        "friction": "friction",
        "fit": "fit (mu = 0.5)",
        "thickness": "thickness (mu = 0.5)",
        "material": "material sets (mu = 0.1)",
    }
    torque_plot(
        [(labels[study](c), folder(c)) for c in cases],
        out / f"{study}.png",
        title=f"arm-sleeve: {titles[study]}, {title_mesh}",
        logy=study == "material",
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_args(parser, default_out="results/arm-studies")
    parser.add_argument("--study", nargs="+", choices=STUDIES, default=list(STUDIES))
    parser.add_argument(
        "--mesh",
        type=parse_mesh,
        default=None,
        metavar="NAxNL",
        help="mesh of studies friction..material (default 16x20, --quick 8x10)",
    )
    parser.add_argument(
        "--integrator",
        choices=("explicit", "newmark", "static"),
        default="explicit",
        help="solver.integrator of every case (default %(default)s)",
    )
    parser.add_argument(
        "--stiff-integrator",
        choices=("explicit", "newmark"),
        default=None,
        help="solver.integrator of material sets II and III (default: --integrator's)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    mesh = args.mesh or ((8, 10) if args.quick else (16, 20))
    common = [f"solver.integrator={args.integrator}", *angle_max_sets(args.angle_max)]
    table: list[tuple[str, dict]] = []
    for study in args.study:
        cases = study_cases(study, args)
        settings = list(common) if study == "mesh" else [*mesh_sets(mesh), *common]
        for c in cases:
            if study != "mesh":
                c.params = {"n_around": mesh[0], "n_along": mesh[1], **c.params}
            c.params["integrator"] = _integrator([*settings, *c.sets])
        study_dir = out / study
        if args.dry_run:
            print(f"# study {study}: {len(cases)} case(s) in {study_dir}/")
            run_cases(cases, study_dir, args, settings=settings)
            continue
        columns = ["case", *PARAMS[study], *result_columns(), *EXTRA.get(study, []), *MEASURES]
        writer = RowWriter(out / f"{study}.csv", columns)
        rows = run_cases(
            cases, study_dir, args, settings=settings, on_result=lambda _c, r, w=writer: w.write(r)
        )
        post_process(study, rows, study_dir)
        writer.rewrite(rows)
        writer.close()
        plots(study, cases, study_dir, out, f"mesh {mesh[0]}x{mesh[1]}, {args.integrator}")
        print(f"study {study}: {out / f'{study}.csv'}, figure(s) in {out}/")
        table += [(f"{study}/{r['case']}", r) for r in rows]
    if table:
        text = measures_table(table)
        (out / "measures.md").write_text(text)
        print(f"resistance measures ({out / 'measures.md'}):\n{text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
