"""Command line: ``clothfem run|validate|schema``.

    clothfem run SCENE.toml [--out DIR] [--set key=value ...] [PETSc options]
    clothfem validate SCENE.toml [--set key=value ...]
    clothfem schema            # the scene reference (docs/scene.md)

Works under ``mpirun -n N``. Exit status: 2 invalid scene (one-line message), 3 solver
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
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    val = sub.add_parser("validate", help="check a scene file")
    val.add_argument("scene")
    val.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    sub.add_parser("schema", help="print the scene reference")
    args, petsc_args = parser.parse_known_args(argv)

    import petsc4py

    petsc4py.init([sys.argv[0], *petsc_args])  # -static_snes_monitor etc.
    from . import scene as scenes

    if args.command == "schema":
        print(scenes.schema_markdown())
        return 0
    try:
        scene = scenes.load(args.scene, args.set)
    except scenes.SceneError as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 2
    if args.command == "validate":
        print(f"{args.scene}: valid scene {scene['scene']['name']!r}")
        return 0
    from .run import RunStopped, run_scene
    from .static import SolverDivergence

    out = Path(args.out or Path("results") / scene["scene"]["name"])
    try:
        run_scene(scene, out)
    except scenes.SceneError as exc:
        print(f"clothfem: {exc}", file=sys.stderr)
        return 2
    except SolverDivergence as exc:
        print(f"clothfem: stopped: {exc}; steps written so far are kept in {out}", file=sys.stderr)
        return 3
    except (RunStopped, KeyboardInterrupt) as exc:
        print(f"clothfem: {exc or 'interrupted'}; results kept in {out}", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
