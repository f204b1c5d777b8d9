"""Write a pair of pants (clothfem.pants_mesh) to a gmsh .msh file with physical groups.

    .venv/bin/python meshes/pants.py --out pants.msh [--n-around 16 --n-along 20 ...]

The file loads with clothfem.mesh.load_msh, e.g. from a scene: [mesh] generator = "file",
file = "pants.msh"; boundaries "waist", "left_hem", "right_hem".
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from clothfem.pants_mesh import write_pants_msh

GEOMETRY = {  # option -> (keyword, type, default, help)
    "--waist-radius": ("waist_radius", float, 0.14, "waist circle radius [m]"),
    "--hip-radius": ("hip_radius", float, None, "radius of the hip section's girth [m]"),
    "--leg-radius": ("leg_radius", float, 0.09, "leg tube radius [m]"),
    "--leg-length": ("leg_length", float, 0.75, "crotch to hem [m]"),
    "--crotch-depth": ("crotch_depth", float, 0.25, "waist to crotch [m]"),
    "--leg-spacing": ("leg_spacing", float, 0.22, "distance between the leg axes [m]"),
    "--n-around": ("n_around", int, 16, "cells around each leg (multiple of 4)"),
    "--n-along": ("n_along", int, 20, "rows of cells along each leg"),
    "--n-rise": ("n_rise", int, None, "rows from the crotch to the waist"),
    "--n-bridge": ("n_bridge", int, None, "cells of each leg's top row at the crotch"),
    "--order": ("order", int, 2, "1 or 2 (9-node quadrilaterals)"),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="the .msh file to write")
    parser.add_argument("--cell", default="quadrilateral", choices=("quadrilateral", "triangle"))
    for option, (dest, kind, default, text) in GEOMETRY.items():
        parser.add_argument(option, dest=dest, type=kind, default=default, help=text)
    args = vars(parser.parse_args(argv))
    out, cell = args.pop("out"), args.pop("cell")
    try:
        lattice = write_pants_msh(out, cell=cell, **args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    lengths = lattice.edge_lengths()
    print(
        f"wrote {out}: {len(lattice.cells)} quadrilaterals, {len(lattice.x)} nodes, "
        f"edge lengths {lengths.min():.4f}-{lengths.max():.4f} m "
        f"(min/max {lengths.min() / lengths.max():.2f}), hip semi-axes "
        f"{np.round(lattice.hip_semi_axes, 4).tolist()} m"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
