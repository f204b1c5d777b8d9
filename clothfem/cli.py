"""Command line: ``clothfem run|validate|schema|plot|report``.

    clothfem run SCENE.toml [--out DIR] [--set key=value ...] [--unset key ...]
                 [--resume | --overwrite] [PETSc options]
    clothfem validate SCENE.toml [--set key=value ...] [--unset key ...]
    clothfem schema            # the scene reference (docs/scene.md)
    clothfem plot RUN_DIR [RUN_DIR ...] [--out PNG] [--label NAME ...] [--y COLUMN]
                  [--x time]
    clothfem report RUN_DIR [--markdown FILE]

Works under ``mpirun -n N``; plot and report need neither MPI nor PETSc (docs/cli.md).
Exit status: 2 invalid scene, a results folder that holds another run (or files clothfem
did not write) or is not writable, or an unreadable run folder (one-line message), 3 solver
failure below the smallest step, 130 interrupted; results written so far are kept.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="clothfem", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scene")
    run.add_argument("scene")
    run.add_argument("--out", default=None, help="output folder (default results/<scene name>)")
    _scene_edits(run)
    run.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="log solver details (-v: step failures, -vv: every Newton iteration)",
    )
    run.add_argument(
        "--resume",
        action="store_true",
        help="continue a newmark or explicit run from the last checkpoint in --out (same "
        "number of ranks)",
    )
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run in --out (only files clothfem writes; a folder holding other "
        "files is refused)",
    )
    val = sub.add_parser("validate", help="check a scene file")
    val.add_argument("scene")
    _scene_edits(val)
    sub.add_parser("schema", help="print the scene reference")
    plot = sub.add_parser("plot", help="torque-angle plot of one or more run folders")
    plot.add_argument("run_dirs", nargs="+", metavar="RUN_DIR")
    plot.add_argument("--out", default=None, metavar="PNG", help="default RUN_DIR/torque_angle.png")
    plot.add_argument("--label", action="extend", nargs="+", default=[], metavar="NAME")
    from .report import PLOT_Y  # light: neither MPI nor dolfinx

    plot.add_argument("--y", choices=list(PLOT_Y), default="torque_mag")
    plot.add_argument("--x", choices=["angle", "time"], default="angle")
    plot.add_argument("--title", default=None)
    rep = sub.add_parser("report", help="short Markdown report of a run folder")
    rep.add_argument("run_dir", metavar="RUN_DIR")
    rep.add_argument("--markdown", default=None, metavar="FILE", help="also write it to FILE")
    args, petsc_args = parser.parse_known_args(argv)
    if args.command in ("plot", "report"):
        if petsc_args:
            parser.error(f"unrecognized arguments: {' '.join(petsc_args)}")
        return _post(args)

    import petsc4py

    petsc4py.init([sys.argv[0], *petsc_args])  # -static_snes_monitor etc.
    from . import scene as scenes

    if args.command == "schema":
        print(scenes.schema_markdown())
        return 0
    try:
        scene = scenes.load(args.scene, args.set, unset=args.unset)
    except scenes.SceneError as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 2
    if args.command == "validate":
        problem = scenes.mesh_file_problem(scene) if scene.mesh.generator == "file" else None
        if problem:
            print(f"clothfem: {problem}", file=sys.stderr)
            return 2
        print(f"{args.scene}: valid scene {scene.scene.name!r}")
        return 0
    from .run import RunStopped, run_scene
    from .static import SolverDivergence

    if args.verbose:
        import logging

        logging.basicConfig(format="%(name)s: %(message)s")
        logging.getLogger("clothfem").setLevel(logging.INFO if args.verbose == 1 else logging.DEBUG)
    out = Path(args.out or Path("results") / scene.scene.name)
    try:
        run_scene(scene, out, resume=args.resume, overwrite=args.overwrite)
    except scenes.SceneError as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 2
    except SolverDivergence as exc:
        print(f"clothfem: stopped: {exc}; steps written so far are kept in {out}", file=sys.stderr)
        return 3
    except RunStopped as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"clothfem: interrupted; results kept in {out}", file=sys.stderr)
        return 130
    return 0


def _scene_edits(parser: argparse.ArgumentParser) -> None:
    """``--set`` and ``--unset`` (both repeatable; the removals come first)."""
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument(
        "--unset",
        action="append",
        default=[],
        metavar="KEY",
        help="remove KEY (e.g. solver.dt) from the scene before --set and validation",
    )


def _post(args: argparse.Namespace) -> int:
    """``plot`` and ``report``: post-processing of run folders, no MPI/PETSc."""
    from . import report

    try:
        if args.command == "plot":
            png = report.plot_runs(
                args.run_dirs, args.out, labels=args.label, y=args.y, x=args.x, title=args.title
            )
            print(png)
            return 0
        text = report.report_markdown(args.run_dir)
    except report.ReportError as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 2
    print(text, end="")
    if args.markdown:
        Path(args.markdown).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
