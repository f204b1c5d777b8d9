"""The donning figure of docs/donning.md: the skinned (start) and donned pants of a
``donned.npz`` with the body's ellipsoids at the donning's frame, front and side views.

    .venv/bin/python benchmarks/donning_figure.py results/pants-donned/donned.npz \\
        --out docs/img/donning.png
"""

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _ellipsoid_points(body, frame: int) -> np.ndarray:
    """Surface points of every ellipsoid of ``body`` at ``frame`` [m], (n, 3)."""
    pts = []
    for name in body.names:
        grid = body.ellipsoids[name].ellipsoid(frame).surface_grid(n_u=24, n_v=12)
        pts.append(np.stack([g.ravel() for g in grid], axis=1))
    return np.concatenate(pts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("donned", help="donned.npz of python -m clothfem.particle.donning")
    parser.add_argument("--out", default="donning.png")
    args = parser.parse_args()
    if not Path(args.donned).is_file():
        parser.error(f"{args.donned} does not exist (a donned.npz of the donning)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clothfem.body.lower_body import lower_body_from_c3d

    d = np.load(args.donned)
    frame = int(d["frame"])
    body = lower_body_from_c3d(ROOT / "data" / "mocap" / str(d["c3d"]))
    skin = _ellipsoid_points(body, frame)
    n_around, n_along = int(d["mesh_n_around"]), int(d["mesh_n_along"])
    fig, axes = plt.subplots(1, 4, figsize=(13, 5))
    views = [("x_start", 0, "skinned (start), front"), ("x_start", 1, "skinned (start), side")]
    views += [("x", 0, "donned, front"), ("x", 1, "donned, side")]
    for ax, (key, h, title) in zip(axes, views, strict=True):
        ax.scatter(skin[:, h], skin[:, 2], s=0.2, c="0.5")
        x = d[key]
        ax.scatter(x[:, h], x[:, 2], s=1.0, c="C2" if key == "x_start" else "C0")
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=9)
    fig.suptitle(
        f"pants ({n_around} x {n_along} cells, {len(d['X'])} nodes) donned on frame {frame} "
        f"of {d['c3d']}",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(args.out)


if __name__ == "__main__":
    main()
