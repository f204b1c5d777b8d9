r"""Stiff and extreme cases of the arm-sleeve scene: does the run finish, or stop with a reason?

Each case is one ``clothfem run demos/scenes/arm_sleeve.toml`` subprocess with ``--set``
overrides (CASES below), kept in ``OUT/extreme/<case>/``; a case whose summary.json already
says completed (same overrides) is skipped unless ``--force``. A failed case (exit status 3,
2, a crash, a ``--timeout``) is recorded and the next one runs.

Cases (all on the mesh ``--mesh``, default 16x20, ``--quick`` 8x10):

* ``baseline``: the scene as it is (crimped cotton, mu = 0.1, R = 0.06 m, t = 1 mm), to compare;
* ``kevlar``: set III, E1 = E2 = 7.2 GPa, G12 = E/200, rho = 700 kg/m^3;
* ``mu0.5``: friction mu = 0.5;
* ``tight_R0.055``: sleeve radius 0.055 m < arm radius 0.06 m: the sleeve starts inside the
  arm, so the run must push it out or stop with a diagnosis;
* ``fast_omega285``: 5x the flexion speed (omega = 285 deg/s);
* ``thin_t0.2mm`` / ``thick_t2mm``: t = 0.2 mm / 2 mm.

Table ``OUT/extreme.csv`` (a row as each case finishes) and ``OUT/extreme.md``: case,
completed ("yes" / "no: <reason>" from summary.json, else the last stderr line), steps,
cut-backs, max penetration, final angle, wall time, NaN in output (any nan/inf in
history.csv), exit status; plus ``OUT/extreme.png`` (|tau| against angle, log y).

Run (full set: an hour or more on 2 cores; ``--timeout`` bounds a creeping case):

    nice -n 10 .venv/bin/python benchmarks/arm_extreme.py --out results/arm-extreme --timeout 3600
    .venv/bin/python benchmarks/arm_extreme.py --dry-run --out results/arm-extreme

Plumbing check measured 2026-11-22 (2 cores shared with another run; 8x10, 1 degree; the
scene's integrator was static then):

    nice -n 10 .venv/bin/python benchmarks/arm_extreme.py --quick --angle-max 1 \
        --only tight_R0.055 --out /tmp/ext                             # 30 s, exit status 3
    nice -n 10 .venv/bin/python benchmarks/arm_extreme.py --quick --angle-max 1 \
        --only baseline --out /tmp/ext                                 # 8 s

(static tight fit: the settling pushes the sleeve out, 192 of 336 nodes active, then the
first motion increment fails after 8 halvings: recorded as "no: SolverDivergence: ...").
Other options: ``--extra-set KEY=VALUE`` (every case, after its own overrides, e.g.
``solver.integrator=static``), ``--only CASE ...``, ``--angle-max DEG``, ``--timeout S``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _arm_common import (  # noqa: E402
    HINGE,
    Case,
    RowWriter,
    add_common_args,
    angle_max_sets,
    markdown_table,
    mesh_sets,
    parse_mesh,
    run_cases,
    set_arg,
    torque_plot,
)

E_KEVLAR = 7.2e9
# (name, overrides of arm_sleeve.toml, what it tests) -- edit here
CASES: list[tuple[str, dict, str]] = [
    ("baseline", {}, "the scene as it is"),
    (
        "kevlar",
        {
            "material.E1": E_KEVLAR,
            "material.E2": E_KEVLAR,
            "material.G12": E_KEVLAR / 200,
            "material.rho": 700.0,
        },
        "E = 7.2 GPa, G12 = E/200, rho = 700",
    ),
    ("mu0.5", {"contact.mu": 0.5}, "friction mu = 0.5"),
    ("tight_R0.055", {"mesh.radius": 0.055}, "sleeve R 0.055 m < arm 0.06 m"),
    ("fast_omega285", {f"{HINGE}.omega": 285.0}, "5x flexion speed"),
    ("thin_t0.2mm", {"material.thickness": 2e-4}, "t = 0.2 mm"),
    ("thick_t2mm", {"material.thickness": 2e-3}, "t = 2 mm"),
]
COLUMNS = [
    "case",
    "what",
    "completed",
    "steps",
    "cutbacks",
    "max_penetration_m",
    "final_angle_deg",
    "wall_s",
    "nan_in_output",
    "exit_status",
    "peak_torque",
    "reason",
]
MD_COLUMNS = COLUMNS[: COLUMNS.index("nan_in_output") + 1]  # the table in the .md


def cases() -> list[Case]:
    return [
        Case(name, [set_arg(k, v) for k, v in sets.items()], {"what": what})
        for name, sets, what in CASES
    ]


def table_row(row: dict) -> dict:
    """The completed column as the table shows it: "yes" or "no: <reason>"."""
    done = row["completed"] == "yes"
    return {**row, "completed": "yes" if done else f"no: {row['reason'] or 'unknown'}"}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_args(parser, default_out="results/arm-extreme")
    parser.add_argument(
        "--mesh",
        type=parse_mesh,
        default=None,
        metavar="NAxNL",
        help="mesh of every case (default 16x20, --quick 8x10)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    mesh = args.mesh or ((8, 10) if args.quick else (16, 20))
    settings = [*mesh_sets(mesh), *angle_max_sets(args.angle_max)]
    study_dir = out / "extreme"
    todo = cases()
    if args.dry_run:
        print(f"# extreme: {len(todo)} case(s) in {study_dir}/, mesh {mesh[0]}x{mesh[1]}")
        run_cases(todo, study_dir, args, settings=settings)
        return 0
    writer = RowWriter(out / "extreme.csv", COLUMNS)
    rows = run_cases(
        todo, study_dir, args, settings=settings, on_result=lambda _c, r: writer.write(table_row(r))
    )
    rows = [table_row(r) for r in rows]
    writer.rewrite(rows)
    writer.close()
    head = (
        f"# Arm-sleeve extreme cases (mesh {mesh[0]}x{mesh[1]}"
        + (f", angle_max {args.angle_max:g} deg" if args.angle_max else "")
        + (f", extra: {' '.join(args.extra_set)}" if args.extra_set else "")
        + ")\n\n"
    )
    md = markdown_table(
        [{**r, "completed": r["completed"].replace("|", "/")} for r in rows], MD_COLUMNS
    )
    (out / "extreme.md").write_text(head + md)
    torque_plot(
        [(c.name, study_dir / c.name) for c in todo],
        out / "extreme.png",
        title=f"arm-sleeve extreme cases, mesh {mesh[0]}x{mesh[1]}",
        logy=True,
    )
    print(head + md, end="")
    print(f"written: {out / 'extreme.csv'}, {out / 'extreme.md'}, {out / 'extreme.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
